//! The executor following a jerk-limited schedule where one is ready
//! (`Executor::tick_following`, run offline by `offline::run` with
//! `RunConfig::follow`): against the schedule's own time, the machine's
//! limits and the program's tolerance, under feed hold, single block and
//! overrides.

#[path = "../benches/programs.rs"]
mod programs;

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, plan_program, FollowConfig, Report, RunConfig};
use kerf_motion::schedule::{schedule, RateLimits, ScheduleConfig};
use kerf_motion::{Executor, Kinematics, PathMode, PlannerConfig};

/// Corners and an arc blended, a dense curve, a dwell, a rapid and a
/// line into an exact stop, from (50, 50): stretches of schedule between
/// stops, and markers between them for the executor.
fn program() -> String {
    programs::corners_arc_and_curve().replace(
        "G61 G1 X50 Y50\n",
        "G4 P0.1\nG0 X80 Y40\nG1 F2000 X90\nG61 G1 X50 Y50\n",
    )
}

fn start() -> Position {
    Position::xyz(50.0, 50.0, -5.0)
}

fn planner() -> PlannerConfig {
    PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        ..PlannerConfig::default()
    }
}

/// Coarse enough for the unoptimised test build: nodes every 0.02 mm.
fn follow() -> FollowConfig {
    FollowConfig {
        schedule: ScheduleConfig {
            ds: 0.02,
            ..FollowConfig::default().schedule
        },
        ..FollowConfig::default()
    }
}

fn run(follow: Option<FollowConfig>, operate: impl FnMut(&mut Executor, f64)) -> Report {
    let machine = kerf_machines::load("mill3").unwrap();
    offline::run_operated(
        Interpreter::from_text(program(), "follow.ngc", start()),
        &*machine.kinematics,
        start(),
        RunConfig {
            planner: planner(),
            record: 0,
            follow,
        },
        operate,
    )
    .unwrap()
}

/// The whole-program schedule's motion time (its intervals, as a
/// follower runs them) and its stretches, solved apart from the run.
fn schedule_time(kins: &dyn Kinematics) -> (f64, usize) {
    let config = follow();
    let segments = plan_program(
        Interpreter::from_text(program(), "follow.ngc", start()),
        kins,
        start(),
        planner(),
        1,
    )
    .unwrap();
    let found = schedule(
        &segments,
        kins,
        ScheduleConfig {
            window: Some(config.window),
            ..config.schedule
        },
    )
    .unwrap();
    let motion: f64 = found.intervals().iter().map(|i| i.duration).sum();
    (motion, found.stretches)
}

/// The run without an operator, and a time (on the servo grid) early in
/// its longest stretch followed, which lasts longer than `ramp`: a ramp
/// to rest started there ends inside it.
fn early_in_longest_stretch(ramp: f64) -> (Report, f64) {
    let mut spans: Vec<(f64, f64)> = Vec::new();
    let plain = run(Some(follow()), |ex, t| {
        match (ex.is_following(), spans.last_mut()) {
            (true, Some(span)) if span.1 < 0.0 => {}
            (true, _) => spans.push((t, -1.0)),
            (false, Some(span)) if span.1 < 0.0 => span.1 = t,
            (false, _) => {}
        }
    });
    let longest = spans
        .iter()
        .copied()
        .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)))
        .unwrap();
    eprintln!("stretches followed (s): {spans:?}");
    assert!(longest.1 - longest.0 > ramp, "{longest:?}");
    (plain, ((longest.0 + 0.02) * 1000.0).round() / 1000.0)
}

fn within_limits_and_tolerance(report: &Report, what: &str) {
    assert!(
        report.max_limit_ratio() <= 1.0 + 1e-6,
        "{what}: limit use {}",
        report.max_limit_ratio()
    );
    assert_eq!(report.over_tolerance, 0.0, "{what}: left the tolerance");
}

/// Following, the run takes the schedule's time (each stretch's
/// intervals back to back, the dwell, and at most a couple of periods a
/// stretch where a stretch's end falls inside a period and the markers
/// take theirs), takes every stretch, beats the executor's own profiles
/// on the dense curve, and keeps every limit and the tolerance.
#[test]
fn the_executor_follows_the_schedule_and_keeps_every_limit() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let own = run(None, |_, _| {});
    let followed = run(Some(follow()), |_, _| {});
    let (motion, stretches) = schedule_time(kins);
    eprintln!(
        "own profiles {:.4} s, following {:.4} s, schedule {motion:.4} s + 0.1 s dwell, {} of {stretches} stretches followed",
        own.cycle_time, followed.cycle_time, followed.stretches_followed
    );
    within_limits_and_tolerance(&own, "own profiles");
    within_limits_and_tolerance(&followed, "following");
    assert_eq!(followed.stretches_followed, stretches as u64);
    let period = planner().period;
    let expected = motion + 0.1;
    assert!(
        (followed.cycle_time - expected).abs() <= (2 * stretches + 4) as f64 * period,
        "ran {:.4} s, the schedule {expected:.4} s",
        followed.cycle_time
    );
    assert!(
        followed.cycle_time < own.cycle_time,
        "following {:.4} s, own profiles {:.4} s",
        followed.cycle_time,
        own.cycle_time
    );
}

/// A feed hold while following slows along the path within the reserve
/// (the limits and the tolerance hold throughout), stands still until
/// released, and resumes on the schedule: the run is longer by the time
/// from the hold to the release, the ramps down and up costing half
/// their time each.
#[test]
fn a_hold_while_following_stops_on_the_path_and_resumes() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let hold_time = RateLimits::for_machine(kins, follow().schedule.reserve)
        .unwrap()
        .hold_time();
    let (plain, hold_at) = early_in_longest_stretch(hold_time);
    let release_at = hold_at + hold_time + 0.5;
    let mut held_still = Vec::new();
    let mut following_at_hold = false;
    let held = run(Some(follow()), |ex, t| {
        if (t - hold_at).abs() < 1e-9 {
            following_at_hold = ex.is_following();
            ex.set_hold(true);
        }
        if t > hold_at + hold_time + 0.01 && t < release_at - 0.01 {
            held_still.push((ex.position(), ex.velocity(), ex.is_following()));
        }
        if t >= release_at && ex.is_held() {
            ex.set_hold(false);
        }
    });
    assert!(following_at_hold, "the hold came while following");
    within_limits_and_tolerance(&held, "held");
    assert!(!held_still.is_empty());
    let (at, ..) = held_still[0];
    for &(p, v, following) in &held_still {
        assert_eq!(p, at, "crept while held");
        assert_eq!(v, 0.0);
        assert!(following, "a hold stays on the schedule");
    }
    let lost = held.cycle_time - plain.cycle_time;
    let period = planner().period;
    eprintln!("hold ramp {hold_time:.4} s, lost {lost:.4} s");
    assert!(
        (lost - (release_at - hold_at)).abs() <= 3.0 * period,
        "lost {lost:.4} s, held {:.4} s",
        release_at - hold_at
    );
    assert_eq!(held.stretches_followed, plain.stretches_followed);
}

/// Single block switched on while following stops the tool along the
/// path, as a hold does, and hands it back to the executor's own
/// profiles once at rest, mid-stretch; they stop at the end of the line
/// and wait for a step. Switched off, the run ends, taking the schedule
/// again at the next stretch. Limits and tolerance hold throughout.
#[test]
fn single_block_leaves_the_schedule_at_rest() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let hold_time = RateLimits::for_machine(kins, follow().schedule.reserve)
        .unwrap()
        .hold_time();
    let (plain, on_at) = early_in_longest_stretch(hold_time);
    let off_at = on_at + hold_time + 1.0;
    let mut left_at_rest = None;
    let mut waited = false;
    let report = run(Some(follow()), |ex, t| {
        if (t - on_at).abs() < 1e-9 {
            assert!(ex.is_following());
            ex.set_single_block(true);
        }
        if t > on_at && left_at_rest.is_none() && !ex.is_following() {
            left_at_rest = Some((t, ex.velocity()));
        }
        if t >= off_at && !ex.is_following() && !waited {
            waited = ex.velocity() == 0.0;
            ex.set_single_block(false);
        }
    });
    within_limits_and_tolerance(&report, "single block");
    let (t, v) = left_at_rest.expect("left the schedule");
    let period = planner().period;
    eprintln!(
        "left the schedule {:.4} s after single block, ramp {hold_time:.4} s",
        t - on_at
    );
    assert_eq!(v, 0.0, "left at rest");
    // At the end of the ramp to rest, not at the stretch's end.
    assert!(
        (t - on_at - hold_time).abs() <= 2.0 * period,
        "left {:.4} s after single block, the ramp takes {hold_time:.4} s",
        t - on_at
    );
    assert!(waited, "waited for a step");
    // The stretches after the single-block stop were taken again.
    assert_eq!(report.stretches_followed, plain.stretches_followed);
}

/// Above 100 % the schedule has no room: the executor keeps its own
/// profiles, which honour the override, and runs exactly as it does
/// without a schedule.
#[test]
fn above_full_override_the_executor_keeps_its_own_profiles() {
    let faster = |ex: &mut Executor, t: f64| {
        if t == 0.0 {
            ex.set_feed_override(1.5);
        }
    };
    let own = run(None, faster);
    let followed = run(Some(follow()), faster);
    assert_eq!(followed.stretches_followed, 0);
    assert_eq!(followed.cycle_time, own.cycle_time);
    within_limits_and_tolerance(&followed, "150 %");
}

/// A machine whose joints are not its axes has no schedule: the run says
/// so instead of running without one.
#[test]
fn a_parallel_machine_cannot_follow_a_schedule() {
    let machine = kerf_machines::load("oxglide-x").unwrap();
    let home = machine.home();
    let err = offline::run(
        Interpreter::from_text("G21 G91 G1 F600 X1\nM2\n", "p.ngc", home),
        &*machine.kinematics,
        home,
        RunConfig {
            planner: PlannerConfig::default(),
            record: 0,
            follow: Some(follow()),
        },
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(text.contains("trivial kinematics"), "{text}");
}
