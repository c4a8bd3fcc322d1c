//! The jerk-limited schedule (`kerf_motion::schedule`) against the closed
//! form of the S-curve and against the lower bound it sits above.

#[path = "../benches/programs.rs"]
mod programs;

use kerf_interp::{Interpreter, Position};
use kerf_motion::bound::{lower_bound, BoundConfig};
use kerf_motion::offline::plan_program;
use kerf_motion::schedule::{
    schedule, Interpolant, Schedule, ScheduleConfig, ScheduleError, Window,
};
use kerf_motion::{Kinematics, PathMode, PlannerConfig, Segment};

fn planned(program: &str, kins: &dyn Kinematics, start: Position) -> Vec<Segment> {
    let config = PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        ..PlannerConfig::default()
    };
    plan_program(
        Interpreter::from_text(program, "t.ngc", start),
        kins,
        start,
        config,
        1,
    )
    .unwrap()
}

/// How far past a limit a schedule may go at its nodes: the linear
/// programs keep the limits exactly, the interior-point solver to its
/// tolerance, about 1e-5 where it reports reduced accuracy
/// (`Schedule::scaled_time` takes that off).
const SOLVER_TOLERANCE: f64 = 1e-4;

/// Coarser than the default, to keep the unoptimised test build quick.
fn config() -> ScheduleConfig {
    ScheduleConfig {
        ds: 0.02,
        ..ScheduleConfig::default()
    }
}

/// The time-optimal rest-to-rest motion over `len` under speed `v`,
/// acceleration `a` and jerk `j` (the seven-phase S-curve): accelerate to
/// a peak speed w and straight back, cruising at v only if the length
/// leaves room. Ramping 0 → w takes [`s_curve_ramp`] and covers w times
/// half that.
fn s_curve_time(len: f64, v: f64, a: f64, j: f64) -> f64 {
    let ramp = |w: f64| s_curve_ramp(w, a, j);
    if v * ramp(v) <= len {
        return 2.0 * ramp(v) + (len - v * ramp(v)) / v;
    }
    // Both ramps, no cruise: the peak speed from which stopping takes
    // half the line.
    2.0 * ramp(s_curve_speed_stopping_in(len / 2.0, a, j))
}

/// How long the S-curve takes from rest to speed `w` (or back): w/a + a/j
/// where the acceleration reaches a (w ≥ a²/j), 2·√(w/j) where it does
/// not.
fn s_curve_ramp(w: f64, a: f64, j: f64) -> f64 {
    if w >= a * a / j {
        w / a + a / j
    } else {
        2.0 * (w / j).sqrt()
    }
}

fn solved(program: &str, kins: &dyn Kinematics, start: Position) -> (Vec<Segment>, Schedule) {
    solved_with(program, kins, start, config())
}

fn solved_with(
    program: &str,
    kins: &dyn Kinematics,
    start: Position,
    config: ScheduleConfig,
) -> (Vec<Segment>, Schedule) {
    let segments = planned(program, kins, start);
    let schedule = schedule(&segments, kins, config).unwrap();
    assert_eq!(schedule.failed, 0, "every linear program solved");
    (segments, schedule)
}

/// On a line the S-curve is the time-optimal jerk-limited motion, so the
/// schedule (a feasible motion) cannot be quicker, and its discretisation
/// should leave it within a few per cent. Lengths where the acceleration
/// limit is never reached, where it is but the feed is not, and where
/// the feed is cruised at.
#[test]
fn a_line_from_rest_to_rest_takes_the_s_curve_time() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    // mill3's X: 150 mm/s, 1500 mm/s², 75,000 mm/s³; F6000 is 100 mm/s.
    for len in [0.5, 3.0, 12.0] {
        let program = format!("G21 G90 G1 F6000 X{}\nM2\n", 10.0 + len);
        let (_, schedule) = solved(&program, kins, start);
        let exact = s_curve_time(len, 100.0, 1500.0, 75_000.0);
        let ratio = schedule.time / exact;
        assert!(
            (0.995..1.03).contains(&ratio),
            "{len} mm: schedule {:.5} s against the S-curve's {exact:.5} s ({ratio:.4})",
            schedule.time
        );
        eprintln!(
            "{len} mm: schedule {:.5} s, S-curve {exact:.5} s ({ratio:.4})",
            schedule.time
        );
        let used = schedule.limit_use(kins).unwrap();
        assert!(
            used.slowdown() <= 1.0 + SOLVER_TOLERANCE,
            "{len} mm: {used:?}"
        );
    }
}

/// The bound is a lower bound on every motion within the limits, the
/// schedule is one such motion: corners, arcs and a dense curve, with
/// stops and blends; and a dense CAM profile, where the bound's rounded
/// crests (session 35) bind on almost every line.
#[test]
fn the_schedule_is_no_quicker_than_the_lower_bound() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let (program, start) = stellabee_excerpt();
    let (segments, schedule) = solved(&program, kins, start);
    let bound = lower_bound(&segments, kins, BoundConfig::default()).time;
    let uncrested = BoundConfig {
        crests: false,
        ..BoundConfig::default()
    };
    let before = lower_bound(&segments, kins, uncrested).time;
    eprintln!(
        "excerpt: schedule {:.5} s, bound {bound:.5} s ({before:.5} s without crests)",
        schedule.time
    );
    assert!(
        schedule.time >= bound && bound > before,
        "excerpt: schedule {:.5} s, bound {bound:.5} s, without crests {before:.5} s",
        schedule.time
    );
    let start = Position::xyz(50.0, 50.0, -10.0);
    let (segments, schedule) = solved(&programs::corners_arc_and_curve(), kins, start);
    let bound = lower_bound(&segments, kins, BoundConfig::default()).time;
    eprintln!("schedule {:.5} s, bound {bound:.5} s", schedule.time);
    assert!(
        schedule.time >= bound,
        "schedule {:.5} s below the lower bound {bound:.5} s",
        schedule.time
    );
    // Not far above it either: the program has room to speed up and slow
    // down, which a schedule stuck at its first guess would not use.
    assert!(
        schedule.time <= 1.5 * bound,
        "schedule {:.5} s, bound {bound:.5} s",
        schedule.time
    );
    let used = schedule.limit_use(kins).unwrap();
    assert!(used.slowdown() <= 1.0 + SOLVER_TOLERANCE, "{used:?}");
    assert!(
        used.acceleration > 0.99 && used.jerk > 0.99,
        "limits reached: {used:?}"
    );
}

/// The distance the seven-phase S-curve takes to stop from speed `v`
/// (ramping down from v to rest mirrors ramping up, which covers v times
/// half its duration).
fn s_curve_stop(v: f64, a: f64, j: f64) -> f64 {
    v * s_curve_ramp(v, a, j) / 2.0
}

/// The speed from which the S-curve stops in `distance`.
fn s_curve_speed_stopping_in(distance: f64, a: f64, j: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1e4);
    for _ in 0..200 {
        let v = 0.5 * (lo + hi);
        if s_curve_stop(v, a, j) > distance {
            hi = v;
        } else {
            lo = v;
        }
    }
    lo
}

/// Solved in windows, as a planner running ahead must be, the schedule
/// can go no faster than it could stop within one window: every window
/// ends at rest. With windows longer than the stop, a line runs as it
/// does solved whole; with shorter ones, its top speed is between the
/// speeds that stop within the window's unkept part and within the
/// whole window, and the seams between windows keep every limit.
#[test]
fn windows_cap_the_speed_at_what_stops_within_them() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    // mill3's X: 1500 mm/s², 75,000 mm/s³; F6000 is 100 mm/s, which
    // takes 4.33 mm to stop.
    let program = "G21 G90 G1 F6000 X40\nM2\n";
    let (segments, whole) = solved(program, kins, start);
    let windowed = |horizon: usize, commit: usize| {
        let config = ScheduleConfig {
            window: Some(Window { horizon, commit }),
            ..config()
        };
        let found = schedule(&segments, kins, config).unwrap();
        assert_eq!(found.failed, 0, "every linear program solved");
        assert!(found.windows > 1, "solved in {} windows", found.windows);
        assert_eq!(found.window_rests, 0, "every window solved");
        let used = found.limit_use(kins).unwrap();
        assert!(
            used.slowdown() <= 1.0 + SOLVER_TOLERANCE,
            "windows of {horizon}: {used:?}"
        );
        found
    };
    let ds = config().ds;

    // 8 mm windows, 2 mm kept of each.
    let long = windowed(400, 100);
    let top = long.v.iter().copied().fold(0.0, f64::max);
    assert!((top - 100.0).abs() < 1e-3, "top speed {top} mm/s");
    assert!(
        (long.time / whole.time - 1.0).abs() < 2e-3,
        "in windows {:.5} s, whole {:.5} s",
        long.time,
        whole.time
    );

    // 2 mm windows, 0.5 mm kept of each.
    let (horizon, commit) = (100, 25);
    let short = windowed(horizon, commit);
    let top = short.v.iter().copied().fold(0.0, f64::max);
    let most = s_curve_speed_stopping_in(horizon as f64 * ds, 1500.0, 75_000.0);
    let least = s_curve_speed_stopping_in((horizon - commit) as f64 * ds, 1500.0, 75_000.0);
    eprintln!("2 mm windows: top speed {top:.3} mm/s, between {least:.3} and {most:.3}");
    assert!(
        top <= most * (1.0 + SOLVER_TOLERANCE) && top >= 0.95 * least,
        "top speed {top:.3} mm/s, stops within the window from {most:.3}, within its unkept part from {least:.3}"
    );
    assert!(
        short.time > long.time * 1.2,
        "2 mm windows {:.5} s, 8 mm windows {:.5} s",
        short.time,
        long.time
    );
}

/// Windows shorter than the stretches of a program of corners, an arc
/// and a dense curve: within every limit across the seams, above the
/// bound, and near the schedule solved whole.
#[test]
fn windows_across_corners_keep_the_limits() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(50.0, 50.0, -10.0);
    let (segments, whole) = solved(&programs::corners_arc_and_curve(), kins, start);
    let config = ScheduleConfig {
        window: Some(Window {
            horizon: 300,
            commit: 75,
        }),
        ..config()
    };
    let windowed = schedule(&segments, kins, config).unwrap();
    assert!(windowed.windows > 4, "{} windows", windowed.windows);
    let used = windowed.limit_use(kins).unwrap();
    assert!(used.slowdown() <= 1.0 + SOLVER_TOLERANCE, "{used:?}");
    let bound = lower_bound(&segments, kins, BoundConfig::default()).time;
    eprintln!(
        "in windows {:.5} s, whole {:.5} s, bound {bound:.5} s",
        windowed.time, whole.time
    );
    assert!(windowed.time >= bound);
    assert!(
        windowed.time <= 1.02 * whole.time,
        "in windows {:.5} s, whole {:.5} s",
        windowed.time,
        whole.time
    );
}

/// Followed in time and sampled every servo period, as an executor would
/// move the axes, a line's schedule cruises at the feed and accelerates
/// at the limit, as its nodes say, and away from the stops its jerk is
/// within the limit too: on a line the schedule's jerk rows are the
/// S-curve's, and the quintic between nodes keeps to them.
#[test]
fn a_schedule_followed_in_time_moves_as_its_nodes_say() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let (segments, schedule) = solved("G21 G90 G1 F6000 X22\nM2\n", kins, start);
    let followed = schedule
        .sampled(&segments, kins, 0.001, Interpolant::QuinticInTime)
        .unwrap();
    let used = followed.limits;
    eprintln!("sampled {used:?}, {:.5} s", followed.time);
    // F6000 is 100 mm/s of mill3's 150 on X; 1500 mm/s² its limit.
    assert!((used.velocity - 100.0 / 150.0).abs() < 1e-6, "{used:?}");
    assert!((used.acceleration - 1.0).abs() < 1e-3, "{used:?}");
    assert!(
        followed.jerk_in_motion > 0.99 && followed.jerk_in_motion <= 1.0 + 1e-3,
        "jerk away from the stops {}",
        followed.jerk_in_motion
    );
    // Time: no quicker than the S-curve, and within the discretisation's
    // few per cent of it, as the nodes' own time is.
    let exact = s_curve_time(12.0, 100.0, 1500.0, 75_000.0);
    assert!(
        followed.time >= exact && followed.time < 1.03 * exact,
        "followed {:.5} s, S-curve {exact:.5} s",
        followed.time
    );
}

/// Nodes spaced by speed: two per servo period at F6000 (100 mm/s, so
/// 0.05 mm apart) on a line, a rapid at mill3's 150 mm/s on X (0.075 mm),
/// and never closer than `ds`: fewer nodes, the same limits, the S-curve's
/// time within the discretisation's few per cent.
#[test]
fn nodes_spaced_by_speed_keep_the_limits() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let spaced = ScheduleConfig {
        nodes_per_period: Some(2.0),
        ..config()
    };
    for (program, top, len, spacing) in [
        ("G21 G90 G1 F6000 X22\nM2\n", 100.0, 12.0, 0.05),
        ("G21 G90 G0 X22\nM2\n", 150.0, 12.0, 0.075),
        ("G21 G90 G1 F300 X22\nM2\n", 5.0, 12.0, config().ds),
    ] {
        let (_, found) = solved_with(program, kins, start, spaced);
        let intervals = len / spacing;
        assert!(
            (found.v.len() as f64 - 1.0 - intervals).abs() <= 1.0,
            "{program}: {} nodes, {intervals} intervals of {spacing} mm",
            found.v.len()
        );
        let used = found.limit_use(kins).unwrap();
        assert!(
            used.slowdown() <= 1.0 + SOLVER_TOLERANCE,
            "{program}: {used:?}"
        );
        let exact = s_curve_time(len, top, 1500.0, 75_000.0);
        let ratio = found.time / exact;
        assert!(
            (0.995..1.03).contains(&ratio),
            "{program}: {:.5} s against the S-curve's {exact:.5} s",
            found.time
        );
    }
}

/// The first `lines` lines of stellabee1.ngc (as the bench shifts it
/// into mill3's travel) and M2; `None`, said on stderr, when the shared
/// conformance material is not checked out.
fn stellabee_head(lines: usize) -> Option<String> {
    let Some(text) = programs::stellabee() else {
        eprintln!("stellabee1.ngc not under ../shared; skipped");
        return None;
    };
    let mut head: Vec<&str> = text.lines().take(lines).collect();
    head.push("M2");
    Some(head.join("\n"))
}

/// stellabee1.ngc's first `lines` lines planned on `kins` and scheduled
/// as `base` says but with nodes two a servo period apart, at least
/// 0.01 mm; `None` without the shared conformance material.
fn two_a_period_on_stellabee(
    lines: usize,
    kins: &dyn Kinematics,
    base: ScheduleConfig,
) -> Option<(Vec<Segment>, Schedule)> {
    let head = stellabee_head(lines)?;
    let segments = planned(&head, kins, Position::ZERO);
    let spaced = ScheduleConfig {
        ds: 0.01,
        nodes_per_period: Some(2.0),
        ..base
    };
    let found = schedule(&segments, kins, spaced).unwrap();
    Some((segments, found))
}

/// Nodes spaced by speed on the dense profile stellabee1.ngc opens with
/// (its first 25 lines: short lines and blends, nodes 0.05–0.08 mm apart
/// and several servo periods each where the curves hold the speed down):
/// where the speed crests inside a half interval the jerk, √x·(…), is
/// largest between the judged points. Judged at those points alone the
/// motion read 1.009 of the jerk limit, and 1.0057 on its 1 ms samples.
#[test]
fn sparse_nodes_keep_the_jerk_where_the_speed_crests_between_them() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let Some((segments, found)) = two_a_period_on_stellabee(25, kins, config()) else {
        return;
    };
    assert_eq!(found.failed, 0, "every linear program solved");
    let used = found.limit_use(kins).unwrap();
    let followed = found
        .sampled(&segments, kins, 0.001, Interpolant::SpeedInLength)
        .unwrap();
    let (between, segment, at) = found.continuous_jerk(&segments, kins, 16).unwrap();
    eprintln!(
        "nodes {used:?}, samples {:?}, between nodes {between} (segment {segment}, {at:.4} mm)",
        followed.limits
    );
    // Where the crest of the last solution is not where its linear
    // program judged it (that of the pass before), a little over.
    assert!(
        between <= 1.001,
        "{between} of the jerk limit between nodes"
    );
    let allowed = used.slowdown().powi(3) * (1.0 + 1e-6);
    let on_samples = followed.limits;
    for value in [
        on_samples.velocity,
        on_samples.acceleration,
        on_samples.jerk,
    ] {
        assert!(value <= allowed, "{on_samples:?} on the samples");
    }
    assert!(on_samples.jerk > 0.9, "{on_samples:?}");
}

/// Nodes two a servo period apart, in windows, with a tenth of the
/// limits kept for override, as `kerf plan --follow` may solve: on
/// stellabee1.ngc's first 1400 lines the speed of one interval next to
/// a stop dipped towards rest between its nodes, the follower took it at
/// constant path acceleration, and the steps at its ends read 1.195 of
/// the jerk limit on the samples. No interval is flattened now.
#[test]
fn sparse_nodes_in_windows_never_dip_towards_rest_between_nodes() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let windowed = ScheduleConfig {
        window: Some(Window {
            horizon: 2000,
            commit: 500,
        }),
        reserve: 0.1,
        ..config()
    };
    let Some((segments, found)) = two_a_period_on_stellabee(1400, kins, windowed) else {
        return;
    };
    let followed = found
        .sampled(&segments, kins, 0.001, Interpolant::SpeedInLength)
        .unwrap();
    eprintln!(
        "samples {:?}, flattened {}",
        followed.limits, followed.flattened
    );
    assert_eq!(followed.flattened, 0);
    let on_samples = followed.limits;
    for value in [on_samples.acceleration, on_samples.jerk] {
        assert!(value <= 0.9 * (1.0 + 1e-6), "{on_samples:?} on the samples");
    }
    assert!(on_samples.velocity <= 1.0 + 1e-6, "{on_samples:?}");
}

/// A parallel machine's joints are not modelled: refused by name, not
/// scheduled as if they were axes.
#[test]
fn a_machine_with_parallel_kinematics_is_refused() {
    let machine = kerf_machines::load("oxglide-x").unwrap();
    let kins = &*machine.kinematics;
    let err = schedule(&[], kins, config()).unwrap_err();
    assert!(
        matches!(err, ScheduleError::NonTrivialKinematics { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("trivial kinematics"), "{err}");
}

/// Arcs in every plane, a helix and a rapid: every axis within its
/// limits at the nodes (the geometry is per axis, not per plane), above
/// the bound, and a dwell counted once, as standing still.
#[test]
fn arcs_in_every_plane_and_a_dwell() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(50.0, 50.0, -20.0);
    let moves = "G21 G90 G61 G1 F2400 X55\n\
                 G17 G2 X60 Y55 I0 J5 Z-19\n\
                 G18 G3 X65 Z-14 I0 K5\n\
                 G19 G2 Y60 Z-9 J5 K0\n\
                 G0 X50 Y50 Z-20\n";
    // Coarser still: these moves are long, and the test build is
    // unoptimised.
    let coarse = ScheduleConfig {
        ds: 0.05,
        passes: 3,
        ..ScheduleConfig::default()
    };
    let (segments, still) = solved_with(&format!("{moves}M2\n"), kins, start, coarse);
    let used = still.limit_use(kins).unwrap();
    assert!(used.slowdown() <= 1.0 + SOLVER_TOLERANCE, "{used:?}");
    let bound = lower_bound(&segments, kins, BoundConfig::default()).time;
    assert!(
        still.time >= bound,
        "schedule {:.5} s, bound {bound:.5} s",
        still.time
    );

    let dwelling = moves.replacen("G0 X50", "G4 P0.5\nG0 X50", 1);
    let (_, dwelt) = solved_with(&format!("{dwelling}M2\n"), kins, start, coarse);
    assert!(
        (dwelt.time - still.time - 0.5).abs() < 1e-9,
        "with a 0.5 s dwell {:.6} s, without {:.6} s",
        dwelt.time,
        still.time
    );
    assert_eq!(dwelt.dwell, 0.5);
}

/// Twenty lines of LinuxCNC's planner stress file stellabee1.ngc (lines
/// 1271–1290, G18, inches; its feed), a dense CAM profile whose fitted
/// blends turn their curvature within a few micrometres: judged only at
/// each interval's ends and middle, a schedule through them read 1.062
/// of the jerk limit on its samples.
fn stellabee_excerpt() -> (String, Position) {
    let lines = [
        "X1.4280 Z-0.1359",
        "X1.4140 Z-0.1408",
        "X1.4120 Z-0.1481",
        "X1.4100 Z-0.1487",
        "X1.4060 Z-0.1546",
        "X1.3960 Z-0.1510",
        "X1.3900 Z-0.1569",
        "X1.3820 Z-0.1575",
        "X1.3800 Z-0.1614",
        "X1.3780 Z-0.1608",
        "G2 X1.3720 Y4.8260 Z-0.1529 I-0.0095 K-0.0010",
        "G1 X1.3680",
        "X1.3640 Z-0.1556",
        "X1.3600 Z-0.1520",
        "X1.3560 Z-0.1510",
        "X1.3540 Z-0.1520",
        "X1.3480 Z-0.1687",
        "X1.3440 Z-0.1716",
        "X1.3360 Z-0.1716",
        "X1.3340 Z-0.1693",
    ];
    // Where line 1270 left the tool, in mm.
    let start = Position::xyz(1.4340 * 25.4, 4.8260 * 25.4, -0.1284 * 25.4);
    (
        format!("G20 G90 G18 F999\nG1\n{}\nM2\n", lines.join("\n")),
        start,
    )
}

/// A stretch of stellabee1.ngc (lines 8677–8689 of the file, between
/// two of the planner's stops) whose tight blends the jerk holds below
/// 1 mm/s, the speed the schedule keeps away from stops: with that floor
/// every linear program of the stretch had no solution and it stood
/// still (as did some 300 stretches of the file). The floor is lowered
/// where nothing else is found, and the motion keeps every limit on its
/// samples. (The same lines planned on their own, from rest, are solved
/// with the floor: the blends the planner makes there differ.)
#[test]
fn a_stretch_held_below_the_kept_speed_still_moves() {
    // As the benchmarks run it: shifted into mill3's travel (two lines
    // before the file's).
    let Some(text) = programs::stellabee() else {
        eprintln!("stellabee1.ngc not under ../shared; skipped");
        return;
    };
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let head: Vec<&str> = text.lines().take(8702).collect();
    let program = head.join("\n") + "\nM2\n";
    let segments = planned(&program, kins, Position::ZERO);
    // The stretch from the stop at the end of file line 8676 to the one
    // at the end of 8689 (two lines more in the program).
    let first = segments
        .iter()
        .position(|s| s.line == 8679)
        .expect("line 8677 planned");
    let last = segments
        .iter()
        .rposition(|s| s.line == 8691)
        .expect("line 8689 planned");
    assert_eq!(segments[first - 1].exit_velocity, 0.0, "a stop before");
    assert_eq!(segments[last].exit_velocity, 0.0, "a stop after");
    let part = &segments[first..=last];
    let schedule = schedule(part, kins, config()).unwrap();
    assert!(
        schedule.stranded.is_empty(),
        "stood still: {:?}",
        schedule.stranded
    );
    // The programs with the usual floor were given up on.
    assert!(
        schedule.time.is_finite() && schedule.failed > 0,
        "{}",
        schedule.failed
    );
    let followed = schedule
        .sampled(part, kins, 0.001, Interpolant::SpeedInLength)
        .unwrap();
    let on_samples = followed.limits;
    assert!(
        on_samples.velocity <= 1.0 + SOLVER_TOLERANCE
            && on_samples.acceleration <= 1.0 + SOLVER_TOLERANCE
            && on_samples.jerk <= 1.0 + SOLVER_TOLERANCE,
        "{on_samples:?}"
    );
    assert!(
        (followed.time / schedule.time - 1.0).abs() < 0.01,
        "{followed:?}"
    );
}

/// Followed by its speed as a function of arc length, the motion the
/// schedule's rows judge between nodes, a schedule through corners, an
/// arc and a dense curve, and one through a dense CAM profile, keeps
/// every axis's velocity, acceleration and jerk limit on its 1 ms
/// samples, measured as `kerf plan` measures the executor, and takes the
/// time its nodes say. (Judged at the nodes alone, by finite
/// differences, the schedules zig-zagged from node to node and read up to
/// 3.7 times the jerk limit on their samples.)
#[test]
fn a_schedule_followed_by_its_speed_in_arc_length_keeps_the_limits_on_its_samples() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let programs = [
        (
            programs::corners_arc_and_curve(),
            Position::xyz(50.0, 50.0, -5.0),
        ),
        stellabee_excerpt(),
    ];
    for (program, start) in programs {
        let (segments, schedule) = solved(&program, kins, start);
        let used = schedule.limit_use(kins).unwrap();
        let followed = schedule
            .sampled(&segments, kins, 0.001, Interpolant::SpeedInLength)
            .unwrap();
        let on_samples = followed.limits;
        eprintln!(
            "nodes {used:?}, samples {on_samples:?}, {:.5} s against {:.5} s, flattened {}",
            followed.time, schedule.time, followed.flattened
        );
        assert_eq!(followed.flattened, 0);
        // As the nodes' own use allows (the solver's tolerance), and the
        // issue's 1e-6 between the judged points.
        let allowed = used.slowdown().powi(3) * (1.0 + 1e-6);
        for (what, value) in [
            ("velocity", on_samples.velocity),
            ("acceleration", on_samples.acceleration),
            ("jerk", on_samples.jerk),
        ] {
            assert!(value <= allowed, "{what} {value} on the samples");
        }
        // The limits bind somewhere: the check is not vacuous.
        assert!(on_samples.jerk > 0.9, "{on_samples:?}");
        assert!(
            (followed.time - schedule.time).abs() < 5e-3 * schedule.time,
            "followed {:.5} s, nodes {:.5} s",
            followed.time,
            schedule.time
        );
    }
}

/// Solved as the segments arrive, window by window, the schedule hands on
/// the same intervals, to the bit, as solved with the whole program in
/// hand, hands most of them on while the program is still arriving, and
/// holds only the nodes it still reads: a program of stops, corners, an
/// arc, a dense curve and a line long enough for many windows.
#[test]
fn a_schedule_solved_as_the_segments_arrive_is_the_whole_programs() {
    use kerf_motion::schedule::ScheduleStream;
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(50.0, 50.0, -5.0);
    let program =
        programs::corners_arc_and_curve().replace("M2\n", "G1 X85 F6000\nG4 P0.2\nY56\nM2\n");
    let segments = planned(&program, kins, start);
    let window = Window {
        horizon: 100,
        commit: 50,
    };
    let config = ScheduleConfig {
        window: Some(window),
        ..config()
    };
    let whole = schedule(&segments, kins, config).unwrap();
    assert!(whole.windows > 10, "{} windows", whole.windows);
    assert!(whole.stretches >= 3, "{} stretches", whole.stretches);
    let expected = whole.intervals();

    let mut stream = ScheduleStream::new(kins, config, window).unwrap();
    let mut got = Vec::new();
    // How many intervals were handed on before the last segment came.
    let mut early = 0;
    let mut held = 0;
    for (i, segment) in segments.iter().enumerate() {
        stream.push(segment, &mut |interval| got.push(interval));
        held = held.max(stream.held_nodes());
        if i + 2 == segments.len() {
            early = got.len();
        }
    }
    eprintln!("held at most {held} of {} nodes", whole.v.len());
    // It drops the nodes it has handed on: a few windows' worth held, not
    // the program.
    assert!(
        held * 3 < whole.v.len(),
        "held {held} of {} nodes",
        whole.v.len()
    );
    stream.finish(&mut |interval| got.push(interval));
    assert_eq!(got.len(), expected.len());
    for (k, (got, expected)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(got, expected, "interval {k}");
    }
    assert!(
        early > expected.len() / 2,
        "{early} of {} intervals before the last segment",
        expected.len()
    );
    let counts = stream.counts();
    assert_eq!(
        (
            counts.windows,
            counts.failed,
            counts.window_rests,
            counts.stranded
        ),
        (
            whole.windows,
            whole.failed,
            whole.window_rests,
            whole.stranded.len()
        )
    );
}

/// Share of the acceleration and jerk limits the override tests' schedules
/// keep back.
const RESERVE: f64 = 0.1;

/// A feed hold on a schedule is a change of clock: on a line cruising at
/// 20 mm/s, the follower's rate ramps from 1 to 0 in 1/slope + slope/bend
/// seconds (the symmetric ramp of its rate limits), so the tool runs on
/// for half that time's worth of schedule, 20 mm/s × half the ramp, and
/// stops on the path; held, it does not creep; released, it ramps back
/// and ends where the schedule ends, later by the time from the hold to
/// the release (the ramps down and up each run the clock at half rate on
/// average, and are alike).
#[test]
fn a_hold_on_the_schedule_stops_on_the_path_and_resumes_there() {
    use kerf_motion::schedule::{Follower, RateLimits};
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(10.0, 10.0, -10.0);
    let config = ScheduleConfig {
        reserve: RESERVE,
        ..config()
    };
    let (segments, found) = solved_with("G21 G90 G1 F1200 X110\nM2\n", kins, start, config);
    let intervals = found.intervals();
    let limits = RateLimits::for_machine(kins, RESERVE).unwrap();
    assert!(limits.slope > 0.0 && limits.bend > 0.0, "{limits:?}");
    let ramp = 1.0 / limits.slope + limits.slope / limits.bend;
    let x_of = |s: &kerf_motion::schedule::Sample| segments[s.segment].shape.point(s.at)[0];

    let period = 0.001;
    let mut follower = Follower::with_override(period, limits);
    let mut queue = intervals.iter().copied();
    // Two seconds in: cruising at the feed.
    let mut last = None;
    for _ in 0..2000 {
        last = follower.tick(&mut queue);
    }
    let at_hold = x_of(&last.unwrap());
    follower.set_override(0.0);
    let ramp_periods = (ramp / period).ceil() as u64 + 2;
    for _ in 0..ramp_periods {
        last = follower.tick(&mut queue);
    }
    let stopped = last.unwrap();
    assert_eq!(stopped.rate, 0.0, "held after the ramp");
    let ran_on = x_of(&stopped) - at_hold;
    let expected = 20.0 * 0.5 * ramp;
    eprintln!("ramp {ramp:.4} s, ran on {ran_on:.5} mm, expected {expected:.5} mm");
    assert!(
        (ran_on - expected).abs() < 20.0 * period,
        "ran on {ran_on} mm after the hold, expected {expected} mm"
    );
    // Held: not a nanometre of creep.
    for _ in 0..500 {
        let held = follower.tick(&mut queue).unwrap();
        assert_eq!((held.segment, held.at), (stopped.segment, stopped.at));
    }
    follower.set_override(1.0);
    while let Some(sample) = follower.tick(&mut queue) {
        last = Some(sample);
    }
    // The last sample falls in the schedule's last period, where it
    // creeps into rest: a hair short of the end.
    let end = x_of(&last.unwrap());
    assert!((0.0..1e-4).contains(&(110.0 - end)), "ended at X{end}");
    // The whole schedule's time ran, and the wall clock lost the time
    // from the hold to the release on top of it (to a period either way).
    let motion: f64 = intervals.iter().map(|i| i.duration).sum();
    assert!((follower.passed_time() - motion).abs() < 1e-9 * motion);
    let wall = follower.periods() as f64 * period;
    let lost = wall - motion;
    // The ramp down runs half its time's worth of schedule, the ramp up
    // the other half: the loss is the time from the hold to the release.
    let expected_loss = (ramp_periods + 500) as f64 * period;
    assert!(
        (lost - expected_loss).abs() < 2.0 * period,
        "lost {lost:.4} s, expected {expected_loss:.4} s"
    );
}

/// Deterministic operator: a new feed override every 20–400 periods,
/// among holds, releases and values between, from a seeded generator,
/// and 100 % for good after `until` periods (so the motion ends).
fn random_operator(seed: u64, until: u64) -> impl FnMut(u64, &mut kerf_motion::schedule::Follower) {
    let mut state = seed;
    let mut next_change = 0;
    move |period, follower| {
        if period >= until {
            follower.set_override(1.0);
            return;
        }
        if period < next_change {
            return;
        }
        // xorshift64*
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        let r = state.wrapping_mul(0x2545_f491_4f6c_dd1d);
        let pick = (r >> 40) % 6;
        let factor = match pick {
            0 => 0.0,
            1 => 1.0,
            _ => ((r >> 8) & 0xffff) as f64 / 65535.0,
        };
        follower.set_override(factor);
        next_change = period + 20 + (r & 0x17f) % 381;
    }
}

/// Under an operator who turns the feed override at random, holds and
/// releases, a schedule solved with a reserve keeps every axis within
/// its limits on the follower's samples, as it does at 100 %: the rate
/// ramps fit in the reserve. Ramped faster than the reserve allows
/// (the rate limits of a reserve six times larger), the same operator
/// breaks a limit: the reserve is what keeps them.
#[test]
fn feed_override_on_the_schedule_keeps_every_limit_within_the_reserve() {
    use kerf_motion::schedule::RateLimits;
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let config = ScheduleConfig {
        reserve: RESERVE,
        ..config()
    };
    let programs = [
        (
            programs::corners_arc_and_curve().replace("F3000", "F6000"),
            Position::xyz(50.0, 50.0, -5.0),
        ),
        stellabee_excerpt(),
    ];
    let fitting = RateLimits::for_machine(kins, RESERVE).unwrap();
    let steep = RateLimits::for_machine(kins, 6.0 * RESERVE).unwrap();
    let mut broken = 0.0f64;
    for (program, start) in programs {
        let (segments, found) = solved_with(&program, kins, start, config);
        let at_full = found
            .sampled(&segments, kins, 0.001, Interpolant::SpeedInLength)
            .unwrap();
        let used = found.limit_use(kins).unwrap();
        let until = (4.0 * found.time / 0.001) as u64;
        let max = 100 * until + 100_000;
        for seed in [1u64, 7, 42] {
            let followed = found
                .followed(
                    &segments,
                    kins,
                    0.001,
                    fitting,
                    &mut random_operator(seed, until),
                    max,
                )
                .unwrap();
            let on_samples = followed.limits;
            eprintln!(
                "seed {seed}: {:.4} s at 100 %, {:.4} s overridden, {on_samples:?}",
                at_full.time,
                followed.periods as f64 * 0.001
            );
            assert!(followed.periods < max, "the motion ended");
            assert!((followed.time - at_full.time).abs() < 1e-9 * at_full.time);
            // Overridden, it takes longer than at 100 %.
            assert!(followed.periods as f64 * 0.001 > at_full.time + 0.1);
            let allowed = used.slowdown().powi(3) * (1.0 + 1e-6);
            for (what, value) in [
                ("velocity", on_samples.velocity),
                ("acceleration", on_samples.acceleration),
                ("jerk", on_samples.jerk),
            ] {
                assert!(
                    value <= allowed,
                    "seed {seed}: {what} {value} on the samples"
                );
            }
            let too_steep = found
                .followed(
                    &segments,
                    kins,
                    0.001,
                    steep,
                    &mut random_operator(seed, until),
                    max,
                )
                .unwrap()
                .limits;
            broken = broken.max(too_steep.acceleration).max(too_steep.jerk);
        }
    }
    eprintln!("ramped too steeply: {broken:.4} of a limit");
    assert!(
        broken > 1.01,
        "ramps too steep for the reserve broke no limit"
    );
}
