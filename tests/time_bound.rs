//! The time-optimal lower bound (`kerf_motion::bound`) against closed forms
//! and against the planner and executor it is meant to bound.

#[path = "../benches/programs.rs"]
mod programs;

use kerf_interp::{Interpreter, Position};
use kerf_motion::bound::{lower_bound, BoundConfig, Profile};
use kerf_motion::offline::{self, plan_program, RunConfig};
use kerf_motion::{Kinematics, PathMode, PlannerConfig};

fn mill3() -> kerf_machines::Machine {
    kerf_machines::load("mill3").unwrap()
}

fn config() -> PlannerConfig {
    PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        ..PlannerConfig::default()
    }
}

fn bound(program: &str, kins: &dyn Kinematics, start: Position) -> Profile {
    bound_with(program, kins, start, BoundConfig::default())
}

fn bound_with(
    program: &str,
    kins: &dyn Kinematics,
    start: Position,
    bound: BoundConfig,
) -> Profile {
    let segments = plan_program(
        Interpreter::from_text(program, "t.ngc", start),
        kins,
        start,
        config(),
        1,
    )
    .unwrap();
    lower_bound(&segments, kins, bound)
}

fn no_jerk() -> BoundConfig {
    BoundConfig {
        jerk: false,
        ..BoundConfig::default()
    }
}

/// The bound's speeds at the nodes strictly between path positions `from`
/// and `to`, mm.
fn speeds_between(p: &Profile, from: f64, to: f64) -> Vec<f64> {
    p.s.iter()
        .zip(&p.v)
        .filter(|(s, _)| **s > from && **s < to)
        .map(|(_, v)| *v)
        .collect()
}

/// Rest-to-rest time over `len` with speed cap `v` and acceleration `a`.
fn trapezoid(len: f64, v: f64, a: f64) -> f64 {
    if v * v / a >= len {
        2.0 * (len / a).sqrt()
    } else {
        len / v + v / a
    }
}

/// Second-order bound (acceleration, no jerk) of `program`.
fn bound2(program: &str, kins: &dyn Kinematics, start: Position) -> Profile {
    bound_with(program, kins, start, no_jerk())
}

#[test]
fn a_line_from_rest_to_rest_takes_the_trapezoid_time() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    // Along X at F6000: 100 mm/s, 1500 mm/s².
    let p = bound2("G1 X210 F6000\nM2\n", kins, start);
    let want = trapezoid(200.0, 100.0, 1500.0);
    assert!((p.time / want - 1.0).abs() < 0.005, "{} vs {want}", p.time);
    // Diagonal X Y Z, rapid: every axis limit divides by its direction
    // cosine; Z (100 mm/s, 1000 mm/s²) binds.
    let (dx, dy, dz): (f64, f64, f64) = (120.0, 90.0, -60.0);
    let len = (dx * dx + dy * dy + dz * dz).sqrt();
    let t = [dx / len, dy / len, dz / len];
    let limits = [(150.0, 1500.0), (150.0, 1500.0), (100.0, 1000.0)];
    let v = (0..3)
        .map(|i| limits[i].0 / t[i].abs())
        .fold(f64::INFINITY, f64::min);
    let a = (0..3)
        .map(|i| limits[i].1 / t[i].abs())
        .fold(f64::INFINITY, f64::min);
    let p = bound2("G0 X130 Y100 Z-70\nM2\n", kins, start);
    let want = trapezoid(len, v, a);
    assert!((p.time / want - 1.0).abs() < 0.005, "{} vs {want}", p.time);
    // Too short to reach the feed: a triangle.
    let p = bound2("G1 X12 F6000\nM2\n", kins, start);
    let want = trapezoid(2.0, 100.0, 1500.0);
    assert!(want < 2.0 / 100.0 + 100.0 / 1500.0 - 1e-3);
    assert!((p.time / want - 1.0).abs() < 0.005, "{} vs {want}", p.time);
}

/// The jerk-limited (S-curve) optimum from rest to rest over `len` with
/// speed cap `v`, acceleration `a` and jerk `j`: the true optimum under the
/// same limits, which a lower bound must not exceed. Speeding up to a peak
/// w takes 2·√(w/j) (below a²/j) or w/a + a/j and covers w times half that
/// by symmetry; slowing down mirrors it.
fn s_curve(len: f64, v: f64, a: f64, j: f64) -> f64 {
    let ramp = |w: f64| {
        if w <= a * a / j {
            2.0 * (w / j).sqrt()
        } else {
            w / a + a / j
        }
    };
    if v * ramp(v) <= len {
        return len / v + ramp(v);
    }
    // The peak where the two ramps meet: w·ramp(w) = len grows with w.
    let (mut lo, mut hi) = (0.0, v);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if mid * ramp(mid) < len {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    2.0 * ramp(lo)
}

#[test]
fn the_tangential_jerk_limit_slows_a_lines_start_and_end_but_not_below_the_s_curve() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let (a, j, feed) = (1500.0_f64, 75_000.0_f64, 100.0_f64);
    // The bound's relaxation of the jerk limit, from rest: u ≤ √(2·j·v),
    // so v^{3/2} grows by 1.5·√(2j)·ds, up to the knee w = a²/(2j) where
    // √(2jw) = a (taking a/j and covering a³/(6j²)); then u = a.
    let c = (2.0 * j).sqrt();
    let knee = a * a / (2.0 * j);
    let up = |w: f64| {
        if w <= knee {
            (2.0 / c * w.sqrt(), 2.0 / (3.0 * c) * w.powf(1.5))
        } else {
            (
                a / j + (w - knee) / a,
                a.powi(3) / (6.0 * j * j) + (w * w - knee * knee) / (2.0 * a),
            )
        }
    };
    // The ramps alone: the crests' rounding is left out here (see the
    // next test).
    let ramps = BoundConfig {
        crests: false,
        ..BoundConfig::default()
    };
    for len in [0.05_f64, 0.5, 2.0, 200.0] {
        let program = format!("G1 X{} F6000\nM2\n", 10.0 + len);
        let got = bound_with(&program, kins, start, ramps).time;
        let (t, d) = up(feed);
        let relaxed = if 2.0 * d <= len {
            2.0 * t + (len - 2.0 * d) / feed
        } else {
            // The ramps meet halfway.
            let (mut lo, mut hi) = (0.0, feed);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if up(mid).1 < len / 2.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            2.0 * up(lo).0
        };
        let optimum = s_curve(len, feed, a, j);
        let second = trapezoid(len, feed, a);
        assert!(
            (got / relaxed - 1.0).abs() < 1e-3,
            "{len}: {got} vs {relaxed}"
        );
        assert!(got <= optimum, "{len}: {got} above the S-curve {optimum}");
        assert!(got > second, "{len}: {got} vs {second}");
        // Rounding the crests only adds time, and stays below the S-curve.
        let crested = bound(&program, kins, start).time;
        assert!(
            crested >= got && crested <= optimum,
            "{len}: {crested} outside [{got}, {optimum}]"
        );
    }
    // On the shortest lines the S-curve is all there is, and the ramps
    // alone get within 2·3^{1/3} / 4·2^{-1/3} = 0.909 of it.
    let len = 0.05;
    let program = format!("G1 X{} F6000\nM2\n", 10.0 + len);
    let got = bound_with(&program, kins, start, ramps).time;
    let optimum = s_curve(len, feed, a, j);
    assert!(
        got / optimum > 0.905 && got / optimum < 0.91,
        "{got} vs {optimum}"
    );
    assert!(trapezoid(len, feed, a) / optimum < 0.5);
}

/// ∫ f(s) ds over [a, b] by Simpson's rule on `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let inner: f64 = (1..n)
        .map(|i| f(a + h * i as f64) * if i % 2 == 1 { 4.0 } else { 2.0 })
        .sum();
    (f(a) + f(b) + inner) * h / 3.0
}

#[test]
fn the_crests_of_a_short_line_are_rounded_as_v_cubed_bends_at_most_three_times_the_jerk() {
    // From rest to rest on a line too short to reach the acceleration
    // limit, the ramps let v^{3/2} grow by 1.5·√(2J)·s: f = v³ = 4.5·J·s²
    // from each end. Every trajectory has f″ = 3·s⃛ + 3·u²/v ≥ −3·J, so
    // the fastest has f = P − 1.5·J·(s − L/2)² in the middle, tangent to
    // the ramps: 9·J·s₁ = 3·J·(L/2 − s₁) at s₁ = L/8, P = (18/64)·J·L².
    // Its time is 2·(3·(s₁)^{1/3}/(4.5·J)^{1/3} + ∫ over the parabola):
    // 0.980 of the S-curve's 4·(L/2J)^{1/3} on every length, against the
    // ramps' 0.909.
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let (a, j) = (1500.0_f64, 75_000.0_f64);
    let fine = BoundConfig {
        ds: 1e-4,
        ..BoundConfig::default()
    };
    for len in [0.01_f64, 0.02, 0.05] {
        // Below the knee a²/(2J) = 15 mm/s all the way: the ramps meet at
        // (4.5·J·(L/2)²)^{1/3}.
        assert!((4.5 * j * (len / 2.0).powi(2)).cbrt() < a * a / (2.0 * j));
        let s1 = len / 8.0;
        let peak = 18.0 / 64.0 * j * len * len;
        let ramp = 3.0 * s1.cbrt() / (4.5 * j).cbrt();
        let crest = simpson(
            |w| (peak - 1.5 * j * w * w).powf(-1.0 / 3.0),
            0.0,
            len / 2.0 - s1,
            2000,
        );
        let want = 2.0 * (ramp + crest);
        let program = format!("G1 X{} F6000\nM2\n", 10.0 + len);
        let got = bound_with(&program, kins, start, fine).time;
        assert!((got / want - 1.0).abs() < 1e-3, "{len}: {got} vs {want}");
        let optimum = s_curve(len, 100.0, a, j);
        assert!(
            got < optimum && got / optimum > 0.975,
            "{len}: {got} vs {optimum}"
        );
        // The peak speed is the parabola's.
        let top = bound_with(&program, kins, start, fine)
            .v
            .iter()
            .fold(0.0_f64, |m, v| m.max(*v));
        assert!(
            top <= peak.cbrt() * (1.0 + 1e-9),
            "{len}: {top} vs {}",
            peak.cbrt()
        );
    }
}

#[test]
fn rounded_crests_stay_below_the_s_curve_on_every_line() {
    // From rest to rest at several feeds and lengths, short of the
    // acceleration limit and past it, short of the feed and cruising:
    // the bound with its crests rounded is never above the S-curve
    // optimum, and never below the bound without them.
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let (a, j) = (1500.0_f64, 75_000.0_f64);
    let ramps = BoundConfig {
        crests: false,
        ..BoundConfig::default()
    };
    for feed in [10.0_f64, 40.0, 100.0] {
        for len in [0.003_f64, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0] {
            let program = format!("G1 X{} F{}\nM2\n", 10.0 + len, feed * 60.0);
            let got = bound(&program, kins, start).time;
            let before = bound_with(&program, kins, start, ramps).time;
            let optimum = s_curve(len, feed, a, j);
            eprintln!("F{feed} {len}: {got} ({before}) vs {optimum}");
            assert!(got <= optimum, "F{feed} {len}: {got} above {optimum}");
            assert!(got >= before, "F{feed} {len}: {got} below {before}");
        }
    }
}

#[test]
fn dwells_and_exact_stops_stop_the_tool_and_dwells_add_their_time() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    // Collinear moves run through at speed unless a dwell stops them.
    let through = bound2("G1 X60 F6000\nX110\nM2\n", kins, start);
    let want = trapezoid(100.0, 100.0, 1500.0);
    assert!(
        (through.time / want - 1.0).abs() < 0.005,
        "{}",
        through.time
    );
    let dwell = bound2("G1 X60 F6000\nG4 P0.5\nG1 X110\nM2\n", kins, start);
    let want = 2.0 * trapezoid(50.0, 100.0, 1500.0) + 0.5;
    assert!(
        (dwell.time / want - 1.0).abs() < 0.005,
        "{} vs {want}",
        dwell.time
    );
    // Where the time goes: the steps before the dwell take one move's
    // time, and all of them the cycle less the dwell.
    let moving: f64 = dwell.step.iter().sum();
    assert!((moving + 0.5 - dwell.time).abs() < 1e-9, "{moving}");
    let first: f64 = (0..dwell.s.len())
        .filter(|&k| dwell.s[k] < 50.0 - 1e-9)
        .map(|k| dwell.step[k])
        .sum();
    let want = trapezoid(50.0, 100.0, 1500.0);
    assert!((first / want - 1.0).abs() < 0.005, "{first} vs {want}");
}

#[test]
fn a_circle_above_its_cornering_speed_runs_at_sqrt_a_r() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    for (plane, text, a_eff) in [
        ("G17", "G17 G2 X155 Y100 I-5 J0 P4 F9000\nM2\n", 1500.0),
        ("G18", "G18 G2 X155 Z-20 I-5 K0 P4 F9000\nM2\n", 1000.0),
    ] {
        let start = Position::xyz(155.0, 100.0, -20.0);
        let p = bound(text, kins, start);
        let r: f64 = 5.0;
        let len = 4.0 * 2.0 * std::f64::consts::PI * r;
        // Per-axis limits: at the points where the tangent is along one axis,
        // the other carries all the centripetal acceleration, v²/R ≤ A; in
        // between, the two axes share it and the optimum runs faster. The
        // slowest point is sqrt(A_eff·R), A_eff the weaker axis of the plane.
        // Middle two turns, away from the start and end ramps.
        let mid = speeds_between(&p, len / 4.0, 3.0 * len / 4.0);
        let lo = mid.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = mid.iter().copied().fold(0.0, f64::max);
        let want = (a_eff * r).sqrt();
        assert!((lo / want - 1.0).abs() < 0.005, "{plane}: {lo} vs {want}");
        // Nowhere faster than both axes' limits together allow:
        // v² ≤ (A_1·|t_2| + A_2·|t_1|)·R ≤ √2 · 1500 · R.
        let top = (2f64.sqrt() * 1500.0 * r).sqrt();
        assert!(hi <= top * 1.001 && hi > want, "{plane}: {hi} vs {top}");
    }
}

/// Planned (executed offline) cycle time and the bound, for `program`.
fn planned_and_bound(program: &str, kins: &dyn Kinematics) -> (f64, f64) {
    let run = offline::run(
        Interpreter::from_text(program, "t.ngc", Position::ZERO),
        kins,
        Position::ZERO,
        RunConfig {
            planner: config(),
            record: 0,
            follow: None,
        },
    )
    .unwrap();
    (run.cycle_time, bound(program, kins, Position::ZERO).time)
}

/// Issue 5's time-optimality targets, planned cycle time over the bound:
/// at most 1.05 on the circle of small segments, 1.10 on the zig-zag
/// pocket (the benchmark's programs; `cargo bench --bench motion` prints
/// the same ratios with stellabee1.ngc's, which misses its 1.10).
const CIRCLE_TARGET: f64 = 1.05;
const POCKET_TARGET: f64 = 1.10;

#[test]
fn the_bound_is_below_the_planned_cycle_time_and_the_met_targets_hold() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    let mut programs = vec![
        (
            "circle",
            programs::circle_small_segments(),
            Some(CIRCLE_TARGET),
        ),
        ("zig-zag", programs::zigzag_pocket(), Some(POCKET_TARGET)),
        ("spiral", programs::spiral(20_000), None),
    ];
    // The first 4000 lines of stellabee1.ngc (its G18 arcs and dense
    // lines; the whole file is a benchmark row, too slow for a debug test).
    match programs::stellabee() {
        Some(text) => {
            let head: Vec<&str> = text.lines().take(4000).collect();
            programs.push(("stellabee", head.join("\n") + "\nM2\n", None));
        }
        None => eprintln!("stellabee1.ngc not under ../shared; skipped"),
    }
    for (name, text, target) in programs {
        let (planned, bound) = planned_and_bound(&text, kins);
        let ratio = planned / bound;
        eprintln!("{name}: planned {planned:.3} s, bound {bound:.3} s, ratio {ratio:.3}");
        assert!(bound.is_finite() && bound > 0.0, "{name}: bound {bound}");
        assert!(
            bound <= planned,
            "{name}: bound {bound} > planned {planned}"
        );
        if let Some(target) = target {
            assert!(
                ratio <= target,
                "{name}: planned {planned:.3} s is {ratio:.3} times the bound, over the target {target}"
            );
        }
    }
}

#[test]
fn joints_of_non_trivial_kinematics_limit_the_bound() {
    // CoreXY: motor a = x + y. On a 45° rapid it turns at √2 times the
    // path speed, so its 300 mm/s and 4500 mm/s² bind before the axes'
    // 200·√2 mm/s and 3000·√2 mm/s².
    let machine = kerf_machines::load("corexy").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let p = bound2("G0 X110 Y110\nM2\n", kins, start);
    let root2 = 2f64.sqrt();
    let want = trapezoid(100.0 * root2, 300.0 / root2, 4500.0 / root2);
    assert!((p.time / want - 1.0).abs() < 0.005, "{} vs {want}", p.time);
    // The same machine with motors weaker than the axes (2000 mm/s²) on a
    // circle of R = 5 mm at a feed it cannot reach. The motors see the
    // circle turned by 45°: the pair (a, b) allows v² ≤ A·R·max(|cos θ|,
    // |sin θ|), least on the diagonals, where motor a alone carries the
    // centripetal acceleration: sqrt(2000 · 5 / √2). The axes alone would
    // allow sqrt(3000 · 5).
    let text = include_str!("../machines/corexy.toml").replace(
        "max_velocity = 300.0\nmax_acceleration = 4500.0",
        "max_velocity = 300.0\nmax_acceleration = 2000.0",
    );
    let weak = kerf_machines::from_toml(&text, "corexy-weak").unwrap();
    let p = bound(
        "G17 G2 X15 Y10 I-5 J0 P4 F30000\nM2\n",
        &*weak.kinematics,
        Position::xyz(15.0, 10.0, -10.0),
    );
    let len = 4.0 * 2.0 * std::f64::consts::PI * 5.0;
    let lo = speeds_between(&p, len / 4.0, 3.0 * len / 4.0)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let want = (2000.0 * 5.0 / root2).sqrt();
    assert!((lo / want - 1.0).abs() < 0.005, "{lo} vs {want}");
}

#[test]
fn the_jerk_constraint_leaves_a_circles_cruise_speed_alone() {
    // On a circle κ′ = −|κ|²·t, so κ′·n = 0: at constant speed the normal
    // jerk is 0 and the cruise speed sqrt(A_eff·R) stays. Only the ramps
    // from and to rest, where 3·|κ|·v·a ≤ J_n and the tangential jerk
    // limit a, get slower.
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(155.0, 100.0, -20.0);
    let text = "G17 G2 X155 Y100 I-5 J0 P4 F9000\nM2\n";
    let with = bound(text, kins, start);
    let without = bound_with(text, kins, start, no_jerk());
    let len = 4.0 * 2.0 * std::f64::consts::PI * 5.0;
    let lowest = |p: &Profile| {
        speeds_between(p, len / 4.0, 3.0 * len / 4.0)
            .into_iter()
            .fold(f64::INFINITY, f64::min)
    };
    let (a, b) = (lowest(&with), lowest(&without));
    assert!((a / b - 1.0).abs() < 0.005, "{a} vs {b}");
    assert!(
        with.time >= without.time,
        "{} < {}",
        with.time,
        without.time
    );
    // The ramps cost about what the jerk limit costs an S-curve over a
    // trapezoid on a line, A/J = 20 ms in all (here 19 ms).
    assert!(
        with.time - without.time < 1500.0 / 75_000.0,
        "{} vs {}",
        with.time,
        without.time
    );
}

#[test]
fn the_tangential_jerk_binds_a_ramp_from_rest_onto_a_curve() {
    // Axes with a large acceleration limit (A = 1e5 mm/s²) and a jerk
    // limit J = 75,000 mm/s³ on a short arc of R = 10 mm around its
    // X-most point, from rest to rest at F1200 (20 mm/s). The centripetal
    // v²·κ ≤ 40 mm/s² is next to nothing against A, and so is the normal
    // jerk's 3·κ·v·u ≤ J_n ≈ J (n within 0.05 rad of −X) below v1
    // (below). What binds is the tangential jerk: u ≤ √(2·Ĵ·v), with Ĵ =
    // J·(|t_x| + |t_y|) + κ²·v³ at its largest on the arc (t turns ±φ off
    // Y; v ≤ F). That grows v^{3/2} by 1.5·√(2Ĵ) per mm and takes
    // 2·√v/√(2Ĵ). The same down at the end; F in between.
    let text = include_str!("../machines/mill3.toml").replace(
        "max_acceleration = 1500.0",
        "max_acceleration = 100000.0\nmax_jerk = 75000.0",
    );
    let machine = kerf_machines::from_toml(&text, "mill3-stiff").unwrap();
    let kins = &*machine.kinematics;
    let (r, phi, feed, j, a) = (10.0_f64, 0.05_f64, 20.0_f64, 75_000.0_f64, 1e5_f64);
    let (c, s) = (r * phi.cos(), r * phi.sin());
    let start = Position::xyz(150.0 + c, 100.0 - s, -20.0);
    let text = format!(
        "G17 G3 X{:.9} Y{:.9} I{:.9} J{s:.9} F1200\nM2\n",
        150.0 + c,
        100.0 + s,
        -c
    );
    // The ramps alone: rounding the crest into the cruise would add to
    // it (`crests`).
    let fine = BoundConfig {
        ds: 1e-4,
        crests: false,
        ..BoundConfig::default()
    };
    let len = 2.0 * phi * r;
    let kappa = 1.0 / r;
    let c = (2.0 * (j * (phi.cos() + phi.sin()) + kappa * kappa * feed.powi(3))).sqrt();
    // Where u = J/(3κv) would take over, and where u = A would.
    let v1 = (j / (3.0 * kappa * c)).powf(2.0 / 3.0);
    assert!(v1 > 2.0 * feed && c * feed.sqrt() < a);
    let s_f = 2.0 / (3.0 * c) * feed.powf(1.5);
    assert!(s_f < len / 4.0);
    let ramp = 2.0 / c * feed.sqrt();
    let want = 2.0 * ramp + (len - 2.0 * s_f) / feed;
    let got = bound_with(&text, kins, start, fine).time;
    assert!((got / want - 1.0).abs() < 0.005, "{got} vs {want}");
    // Without the jerk limit the ramps take next to no time.
    let free = bound_with(
        &text,
        kins,
        start,
        BoundConfig {
            jerk: false,
            ..fine
        },
    )
    .time;
    let want_free = len / feed + feed / a;
    assert!(
        (free / want_free - 1.0).abs() < 0.005,
        "{free} vs {want_free}"
    );
    assert!(got > free * 1.03, "{got} vs {free}");
}

#[test]
fn a_curvature_jump_caps_the_junction_at_four_times_the_planners_jerk_budget() {
    // A line along X into a tangent arc of R = 5 mm: Y's curvature jumps
    // by 1/5 mm⁻¹. The planner passes at v² = J·T/Δκ (J = 50·1500 mm/s³,
    // mill3's default, T = 1 ms); a trajectory sampled at T and measured
    // within J could pass at up to v² = 4·J·T/Δκ, which the bound allows.
    let machine = mill3();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    // G61: under G64 P the planner blends such a junction instead.
    let text = "G61 G1 X20 F6000\nG3 X25 Y15 I0 J5\nM2\n";
    let speed_at_junction = |p: &Profile| {
        speeds_between(p, 10.0 - 1e-9, 10.0 + 1e-9)
            .into_iter()
            .fold(0.0, f64::max)
    };
    let want = (4.0 * 75_000.0 * 0.001 * 5.0f64).sqrt();
    let got = speed_at_junction(&bound(text, kins, start));
    assert!((got / want - 1.0).abs() < 0.005, "{got} vs {want}");
    // Without jerk limits only the arc's own limits (v² ≤ A·R at its
    // start, where Y carries all of it) hold the speed down.
    let free = speed_at_junction(&bound_with(text, kins, start, no_jerk()));
    assert!(free > 1.5 * want, "{free}");
}

/// Discretisation study (not run by default): the bound at ds = 0.01 mm
/// against finer steps. `cargo test --release --test time_bound -- --ignored --nocapture`
#[test]
#[ignore]
fn discretisation() {
    let machine = mill3();
    let kins = &*machine.kinematics;
    let mut programs = vec![
        ("circle", programs::circle_small_segments()),
        ("zig-zag", programs::zigzag_pocket()),
        ("spiral", programs::spiral(20_000)),
    ];
    if let Some(text) = programs::stellabee() {
        let head: Vec<&str> = text.lines().take(20000).collect();
        programs.push(("stellabee", head.join("\n") + "\nM2\n"));
    }
    for (name, text) in programs {
        let mut times = Vec::new();
        for ds in [0.01, 0.0025, 0.000625] {
            let b = bound_with(
                &text,
                kins,
                Position::ZERO,
                BoundConfig {
                    ds,
                    ..BoundConfig::default()
                },
            );
            times.push(b.time);
        }
        let j0 = bound_with(&text, kins, Position::ZERO, no_jerk()).time;
        eprintln!(
            "{name}: no jerk {j0:.4}, ds 0.01 {:.4}, 0.0025 {:.4}, 0.000625 {:.4} ({:+.3} %)",
            times[0],
            times[1],
            times[2],
            (times[0] / times[2] - 1.0) * 100.0
        );
    }
}
