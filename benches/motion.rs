//! Motion benchmark: planning throughput, time-optimality against an
//! independent lower bound, path deviation and limit use.
//!
//! Run: `cargo bench --bench motion` (add `-- --quick` to skip the
//! 1,000,000-segment throughput run).
//!
//! The lower bound is computed here, independently of the planner: a
//! forward/backward pass on a fine discretisation of the *programmed*
//! polyline with only velocity and acceleration limits (no jerk limit), and
//! corner speeds capped by the largest arc that fits within the path
//! tolerance, driven by the largest acceleration the axes allow along the
//! corner's normal (min over axes of A_i / |n_i|). Any trajectory that respects the machine's limits and the
//! tolerance takes at least that long.

use std::time::Instant;

use kerf_interp::{CanonCmd, Interpreter, Position};
use kerf_motion::offline::{self, RunConfig};
use kerf_motion::{Kinematics, PathMode, Planner, PlannerConfig};

const TOLERANCE: f64 = 0.01;

fn circle_small_segments() -> String {
    // R = 20 mm in 0.05 mm chords (2513 segments) at 3000 mm/min.
    let r = 20.0;
    let n = (2.0 * std::f64::consts::PI * r / 0.05).round() as usize;
    let mut t = format!("G21 G90\nG0 X{:.6} Y100\nG1 F3000\n", 150.0 + r);
    for k in 1..=n {
        let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        t += &format!("X{:.6} Y{:.6}\n", 150.0 + r * a.cos(), 100.0 + r * a.sin());
    }
    t + "M2\n"
}

fn zigzag_pocket() -> String {
    // 60 x 40 mm pocket, 1 mm stepover, at 2400 mm/min.
    let mut t = "G21 G90\nG0 X20 Y20\nG1 Z-2 F600\nG1 F2400\n".to_string();
    let mut y = 20.0;
    let mut left = true;
    while y <= 60.0 + 1e-9 {
        t += &format!("X{} Y{y}\n", if left { 80 } else { 20 });
        left = !left;
        y += 1.0;
        if y <= 60.0 + 1e-9 {
            t += &format!("Y{y}\n");
        }
    }
    t + "G0 Z0\nM2\n"
}

fn spiral(segments: usize) -> String {
    // Archimedean spiral in 0.02 mm chords: a smooth curve of tiny moves.
    let mut t = String::with_capacity(segments * 24);
    t += "G21 G90\nG0 X150 Y100\nG1 F3000\n";
    let (mut theta, b) = (0.0f64, 0.5 / (2.0 * std::f64::consts::PI));
    for _ in 0..segments {
        let r = 1.0 + b * theta;
        theta += 0.02 / r;
        let r = 1.0 + b * theta;
        let (x, y) = (150.0 + r * theta.cos(), 100.0 + r * theta.sin());
        t += &format!("X{x:.5} Y{y:.5}\n");
        if r > 90.0 {
            theta = 0.0;
            t += "G0 X150 Y100\nG1\n";
        }
    }
    t + "M2\n"
}

/// The independent lower bound on cycle time, s.
fn lower_bound(program: &str, kins: &dyn Kinematics, tolerance: f64) -> f64 {
    let mut limits = [(f64::INFINITY, f64::INFINITY); 3];
    for spec in kins.axes() {
        let i = spec.axis.index();
        if i < 3 {
            limits[i] = (spec.limits.max_velocity, spec.limits.max_acceleration);
        }
    }
    // The largest acceleration along a unit direction n with every axis
    // within its limit: min over axes of A_i / |n_i|.
    let along = |n: &[f64; 3]| {
        (0..3)
            .filter(|&i| n[i].abs() > 1e-12)
            .map(|i| limits[i].1 / n[i].abs())
            .fold(f64::INFINITY, f64::min)
    };
    // Moves: (start, end, speed cap).
    let mut moves: Vec<([f64; 3], [f64; 3], f64)> = Vec::new();
    let mut feed = 0.0;
    let mut at = [0.0; 3];
    for c in Interpreter::from_text(program, "bound", Position::ZERO) {
        let c = c.expect("benchmark programs interpret");
        let (end, cap) = match c.cmd {
            CanonCmd::SetFeedRate { mm_per_min } => {
                feed = mm_per_min / 60.0;
                continue;
            }
            CanonCmd::StraightTraverse { end } => (end, f64::INFINITY),
            CanonCmd::StraightFeed { end } => (end, feed),
            _ => continue,
        };
        let e = [end.x, end.y, end.z];
        if e != at {
            moves.push((at, e, cap));
        }
        at = e;
    }
    let dir = |m: &([f64; 3], [f64; 3], f64)| {
        let d: [f64; 3] = std::array::from_fn(|i| m.1[i] - m.0[i]);
        let l = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        (std::array::from_fn::<f64, 3, _>(|i| d[i] / l), l)
    };
    // Nodes along the path with a speed cap and the acceleration to the next.
    let mut caps: Vec<f64> = vec![0.0];
    let mut steps: Vec<(f64, f64)> = Vec::new(); // (ds, a)
    for (k, m) in moves.iter().enumerate() {
        let (t, len) = dir(m);
        let mut v = m.2;
        let mut a = f64::INFINITY;
        for i in 0..3 {
            if t[i].abs() > 0.0 {
                v = v.min(limits[i].0 / t[i].abs());
                a = a.min(limits[i].1 / t[i].abs());
            }
        }
        let n = ((len / 0.01).ceil() as usize).clamp(4, 400);
        let last = caps.len() - 1;
        caps[last] = caps[last].min(v);
        for _ in 0..n {
            steps.push((len / n as f64, a));
            caps.push(v);
        }
        // Corner to the next move: the largest arc within the tolerance and
        // within half of each move.
        let corner = match moves.get(k + 1) {
            None => 0.0,
            Some(next) => {
                let (t2, len2) = dir(next);
                let cos = (0..3).map(|i| t[i] * t2[i]).sum::<f64>().clamp(-1.0, 1.0);
                let theta = cos.acos();
                if theta < 1e-9 {
                    f64::INFINITY
                } else if theta > std::f64::consts::PI - 1e-6 {
                    0.0
                } else {
                    let half = theta / 2.0;
                    let r_tol = tolerance / (1.0 / half.cos() - 1.0);
                    let r_len = len.min(len2) / 2.0 / half.tan();
                    // Centripetal acceleration points along t2 − t1.
                    let d: [f64; 3] = std::array::from_fn(|i| t2[i] - t[i]);
                    let dn = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let n: [f64; 3] = std::array::from_fn(|i| d[i] / dn);
                    (along(&n) * r_tol.min(r_len)).sqrt()
                }
            }
        };
        let last = caps.len() - 1;
        caps[last] = caps[last].min(corner);
    }
    let n = caps.len();
    caps[n - 1] = 0.0;
    let mut v = caps.clone();
    for i in 0..steps.len() {
        v[i + 1] = v[i + 1].min((v[i] * v[i] + 2.0 * steps[i].1 * steps[i].0).sqrt());
    }
    for i in (0..steps.len()).rev() {
        v[i] = v[i].min((v[i + 1] * v[i + 1] + 2.0 * steps[i].1 * steps[i].0).sqrt());
    }
    steps
        .iter()
        .enumerate()
        .map(|(i, (ds, _))| {
            if v[i] + v[i + 1] > 0.0 {
                2.0 * ds / (v[i] + v[i + 1])
            } else {
                0.0
            }
        })
        .sum()
}

/// LinuxCNC's planner stress file stellabee1.ngc (G18 profiles in inches,
/// arcs and dense lines), shifted into mill3's travel with a G54 offset.
fn stellabee() -> Option<String> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/conformance/linuxcnc-programs/tp-stress/performance/stellabee1.ngc"
    );
    let text = std::fs::read_to_string(path).ok()?;
    Some(format!("G21 G10 L2 P1 X100 Y50 Z-20\nG54\n{text}"))
}

fn throughput(name: &str, program: &str, kins: &dyn Kinematics) {
    let t0 = Instant::now();
    let mut canon = 0usize;
    for c in Interpreter::from_text(program, name, Position::ZERO) {
        c.unwrap();
        canon += 1;
    }
    let interp = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let mut planner = Planner::new(kins, Position::ZERO, PlannerConfig::default());
    let mut segments = 0usize;
    for c in Interpreter::from_text(program, name, Position::ZERO) {
        planner.plan(&c.unwrap()).unwrap();
        while planner.next_segment().is_some() {
            segments += 1;
        }
    }
    planner.finish();
    while planner.next_segment().is_some() {
        segments += 1;
    }
    let total = t0.elapsed().as_secs_f64();
    let plan = (total - interp).max(1e-9);
    println!(
        "{name:<28} {segments:>9} segments  interp+plan {:>10.0} seg/s  plan alone {:>10.0} seg/s  ({canon} canon)",
        segments as f64 / total,
        segments as f64 / plan
    );
}

fn quality(name: &str, program: &str, kins: &dyn Kinematics) {
    let config = RunConfig {
        planner: PlannerConfig {
            mode: PathMode::Blend {
                tolerance: TOLERANCE,
            },
            ..PlannerConfig::default()
        },
        record: 0,
    };
    let t0 = Instant::now();
    let report = offline::run(
        Interpreter::from_text(program, name, Position::ZERO),
        kins,
        Position::ZERO,
        config,
    )
    .expect("benchmark programs run");
    let wall = t0.elapsed().as_secs_f64();
    let bound = lower_bound(program, kins, TOLERANCE);
    let axes = report.axes.iter().map(|u| u.worst()).fold(0.0, f64::max);
    let joints = report.joints.iter().map(|u| u.worst()).fold(0.0, f64::max);
    println!(
        "{name:<28} {:>8.3} s {:>8.3} s {:>7.3} {:>9.5} mm {:>9.6} {:>9.6} {:>8.2} s",
        report.cycle_time,
        bound,
        report.cycle_time / bound,
        report.max_deviation,
        axes,
        joints,
        wall
    );
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    println!("machine mill3, path tolerance {TOLERANCE} mm, servo period 1 ms");
    println!();
    println!("Planning throughput");
    throughput("spiral 0.02 mm, 20k seg", &spiral(20_000), kins);
    match stellabee() {
        Some(text) => throughput("stellabee1.ngc (169k lines)", &text, kins),
        None => println!("stellabee1.ngc: not found under ../shared/conformance; skipped"),
    }
    if !quick {
        throughput("spiral 0.02 mm, 1M seg", &spiral(1_000_000), kins);
    }
    println!();
    println!(
        "Time-optimality (planned / lower bound), deviation, limit use (must stay <= 1 + 1e-6)"
    );
    println!(
        "{:<28} {:>10} {:>10} {:>7} {:>12} {:>9} {:>9} {:>10}",
        "program", "planned", "bound", "ratio", "deviation", "axes", "joints", "run time"
    );
    quality("circle R20, 0.05 mm chords", &circle_small_segments(), kins);
    quality("zig-zag pocket 60x40", &zigzag_pocket(), kins);
    quality("spiral 0.02 mm, 20k seg", &spiral(20_000), kins);
}
