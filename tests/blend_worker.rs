//! The planner's blend worker (motion/src/plan/ahead.rs) changes no bit of
//! a plan, on real programs and machines: LinuxCNC's stellabee1.ngc on
//! mill3 (corners and dense polylines, a box-shaped travel the worker
//! never checks itself) and rounded CAM circles on the O-X glide, whose
//! reach the planner checks through its kinematics for every blend.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::plan_program;
use kerf_motion::PlannerConfig;
use std::fmt::Write;

/// Every segment of `text` on `machine`, with or without the worker, as
/// text that shows every bit of every number.
fn plan(machine: &str, start: Position, text: &str, blend_worker: bool) -> Vec<String> {
    let machine = kerf_machines::load(machine).unwrap();
    let config = PlannerConfig {
        blend_worker,
        ..PlannerConfig::default()
    };
    let program = Interpreter::from_text(text, "t.ngc", start);
    let segments = plan_program(program, &*machine.kinematics, start, config, 0).unwrap();
    segments.iter().map(|s| format!("{s:?}")).collect()
}

fn assert_same(machine: &str, start: Position, text: &str) {
    let alone = plan(machine, start, text, false);
    let helped = plan(machine, start, text, true);
    assert!(
        alone.len() > 1000,
        "{machine}: only {} segments",
        alone.len()
    );
    assert_eq!(alone.len(), helped.len(), "{machine}: segment count");
    for (k, (a, h)) in alone.iter().zip(&helped).enumerate() {
        assert_eq!(a, h, "{machine}: segment {k} differs");
    }
}

#[test]
fn stellabee_plans_the_same_with_the_blend_worker() {
    let path = "../shared/conformance/linuxcnc-programs/tp-stress/performance/stellabee1.ngc";
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("{path} not found; skipped");
        return;
    };
    // The first 30,000 lines (all of it takes long in a debug build), in
    // mill3's travel as the benchmark places it.
    let head: String = text.lines().take(30_000).fold(String::new(), |mut t, l| {
        t += l;
        t += "\n";
        t
    });
    let program = format!("G21 G10 L2 P1 X100 Y50 Z-20\nG54\n{head}M2\n");
    assert_same("mill3", Position::ZERO, &program);
}

#[test]
fn rounded_circles_on_the_ox_glide_plan_the_same_with_the_blend_worker() {
    // Circles of 0.02 mm chords in the XZ plane around the paper's pose,
    // to 5, 4 and 3 decimals, with a dwell between them.
    let mut t = String::from("G21 G90 G18 G64 P0.01 Q0 F1200\nG0 X270 Z-320\nG1\n");
    for decimals in [5, 4, 3] {
        let n = (2.0 * std::f64::consts::PI * 20.0 / 0.02) as usize;
        for k in 1..=n {
            let a = k as f64 * 0.02 / 20.0;
            let (x, z) = (250.0 + 20.0 * a.cos(), -320.0 + 20.0 * a.sin());
            writeln!(t, "X{x:.decimals$} Z{z:.decimals$}").unwrap();
        }
        t += "G4 P0.1\n";
    }
    t += "M2\n";
    let home = Position {
        x: 250.0,
        z: -300.0,
        ..Position::ZERO
    };
    assert_same("oxglide-x", home, &t);
}

#[test]
fn polygons_at_the_edge_of_the_tolerance_plan_the_same_with_the_blend_worker() {
    // Circles of R5 in 40 to 60 chords under G64 P0.01: around 49 chords
    // the sag reaches the tolerance and the midpoint frames take a share
    // of the vertices' curvature (the planner's MID_SHARES), which the
    // worker must pick as the planner does.
    let mut t = String::from("G21 G90 G17 G64 P0.01 Q0 F3000\nG0 X105 Y100 Z-10\nG1\n");
    for n in 40..=60 {
        for k in 1..=n {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            let (x, y) = (100.0 + 5.0 * a.cos(), 100.0 + 5.0 * a.sin());
            writeln!(t, "X{x:.4} Y{y:.4}").unwrap();
        }
    }
    t += "M2\n";
    assert_same("mill3", Position::ZERO, &t);
}
