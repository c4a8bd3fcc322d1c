//! How close third-order planning could come to the lower bound: for each
//! program, the executor's cycle time, the time-optimal lower bound of
//! `kerf_motion::bound` (the figure the `motion` bench divides by) and a
//! jerk-limited schedule of `kerf_motion::schedule` along the same planned
//! path. The optimum lies between the bound and the schedule, so
//! `schedule / bound` is the most a planner that shapes the speed inside
//! each segment may still have to give away against the bound, and
//! `executor / schedule` the least such a planner would gain.
//!
//! Run: `cargo bench --bench schedule` (about four minutes on this project's
//! 2-core VM), or with `-- LINES PASSES` for the first LINES lines of
//! stellabee1.ngc (default 2000; `-- 200000` for the whole file) and
//! PASSES linear programs per stretch (default 6). `-- LINES PASSES
//! HORIZON [COMMIT]` solves the stretches in windows of HORIZON nodes,
//! keeping COMMIT of each (default a quarter), as a planner that runs
//! ahead of the motion must (`kerf_motion::schedule::Window`); about
//! 100 s at `2000 6 2000 500`. A fifth number N spaces each segment's
//! nodes by its top speed, N per servo period
//! (`ScheduleConfig::nodes_per_period`; HORIZON 0 for no windows).
//! `--reserve R` solves with the share R of every acceleration and jerk
//! limit kept back for feed override on the follower
//! (`ScheduleConfig::reserve`); the limit use columns still read the
//! machine's whole limits.

#[path = "programs.rs"]
mod programs;

use std::time::Instant;

use kerf_interp::{Interpreter, Position};
use kerf_motion::bound::{lower_bound, BoundConfig};
use kerf_motion::offline::{self, plan_program, RunConfig};
use kerf_motion::schedule::{schedule, Follower, Interpolant, Interval, ScheduleConfig, Window};
use kerf_motion::{Kinematics, PathMode, PlannerConfig};

/// One program's row, its schedule solved as `solve` says (the command's
/// numbers) at the planner's servo period.
fn row(name: &str, program: &str, kins: &dyn Kinematics, solve: ScheduleConfig) {
    let planner = PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        ..PlannerConfig::default()
    };
    let run = || Interpreter::from_text(program, name, Position::ZERO);
    let executor = offline::run(
        run(),
        kins,
        Position::ZERO,
        RunConfig {
            planner,
            record: 0,
            follow: None,
        },
    )
    .expect("benchmark programs run")
    .cycle_time;
    let segments =
        plan_program(run(), kins, Position::ZERO, planner, 1).expect("benchmark programs plan");
    let bound = lower_bound(&segments, kins, BoundConfig::for_planner(&planner)).time;
    let t0 = Instant::now();
    let config = ScheduleConfig {
        period: planner.period,
        ..solve
    };
    let found = schedule(&segments, kins, config).expect("mill3 has trivial kinematics");
    let wall = t0.elapsed().as_secs_f64();
    // Before the slow measures below, so that a long run that fails in
    // them has said this much.
    for &(first, last, nodes) in found.stranded.iter().take(20) {
        eprintln!(
            "{name}: stranded: {nodes} nodes from segment {first} (line {}) to {last} (line {})",
            segments[first].line, segments[last].line
        );
    }
    let used = found.limit_use(kins).expect("mill3 has trivial kinematics");
    let time = found.scaled_time(&used);
    let follow = |between| {
        found
            .sampled(&segments, kins, planner.period, between)
            .expect("mill3 has trivial kinematics")
    };
    let followed = follow(Interpolant::QuinticInTime);
    let by_length = follow(Interpolant::SpeedInLength);
    let (continuous, _, _) = found
        .continuous_jerk(&segments, kins, 16)
        .expect("mill3 has trivial kinematics");
    let tick = follower_tick_cost(&found.intervals(), planner.period);
    println!(
        "{name:<30} {executor:>10.3} s {bound:>10.3} s {time:>10.3} s {:>7.3} {:>8.3} {:>9.3}  {:>5.3} {:>6.3} {:>6.3} {:>9} {:>6} {:>3} {:>6} {wall:>7.1} s  {:>5.3} {:>5.3} {:>6.3} {:>6.3}  {:>10.3} s {:>5.3} {:>5.3} {:>6.3} {:>6.3} {:>4} {:>6.3}  {tick}",
        executor / bound,
        time / bound,
        executor / time,
        used.velocity,
        used.acceleration,
        used.jerk,
        found.v.len(),
        found.stretches,
        found.failed,
        format!("{}/{}", found.windows, found.window_rests),
        followed.limits.velocity,
        followed.limits.acceleration,
        followed.limits.jerk,
        followed.jerk_in_motion,
        by_length.time,
        by_length.limits.velocity,
        by_length.limits.acceleration,
        by_length.limits.jerk,
        by_length.jerk_in_motion,
        by_length.flattened,
        continuous,
    );
}

/// Median, 99th percentile and largest wall time of a `Follower` tick
/// over `intervals` at `period`, µs, as a table cell.
fn follower_tick_cost(intervals: &[Interval], period: f64) -> String {
    let motion: f64 = intervals.iter().map(|i| i.duration).sum();
    if !motion.is_finite() {
        // A stretch that stands still: the follower would wait there for
        // ever (and the loop below with it).
        return "-".into();
    }
    let mut times: Vec<f64> = Vec::with_capacity((motion / period) as usize + 2);
    let mut follower = Follower::new(period);
    let mut queue = intervals.iter().copied();
    loop {
        let t0 = Instant::now();
        let sample = follower.tick(&mut queue);
        let took = t0.elapsed().as_secs_f64() * 1e6;
        if sample.is_none() {
            break;
        }
        times.push(took);
    }
    if times.is_empty() {
        return "-".into();
    }
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    format!("{:.2}/{:.2}/{:.1}", at(0.5), at(0.99), at(1.0))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let reserve = match args.iter().position(|a| a == "--reserve") {
        Some(k) => match args.get(k + 1).and_then(|r| r.parse::<f64>().ok()) {
            Some(r) if (0.0..1.0).contains(&r) => r,
            _ => {
                eprintln!("--reserve takes a share of the limits, at least 0 and below 1");
                std::process::exit(2);
            }
        },
        None => 0.0,
    };
    let numbers: Vec<usize> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let lines = numbers.first().copied().unwrap_or(2000);
    let passes = numbers.get(1).copied().unwrap_or(6);
    let window = match (numbers.get(2), numbers.get(3)) {
        (Some(&horizon), Some(&commit)) if horizon > 0 => Some(Window { horizon, commit }),
        (Some(&horizon), None) if horizon > 0 => Some(Window {
            horizon,
            commit: horizon / 4,
        }),
        _ => None,
    };
    let nodes_per_period = numbers.get(4).map(|&n| n as f64);
    let solve = ScheduleConfig {
        passes,
        window,
        nodes_per_period,
        reserve,
        ..ScheduleConfig::default()
    };
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let nodes = match nodes_per_period {
        None => "every 0.01 mm".to_string(),
        Some(n) => {
            format!("{n} per servo period at each segment's top speed, at least 0.01 mm apart")
        }
    };
    let solved = match window {
        None => format!("{passes} passes per stretch, each stretch whole"),
        Some(w) => format!(
            "{passes} passes per window of {} nodes, {} kept of each",
            w.horizon, w.commit
        ),
    };
    let kept = if reserve > 0.0 {
        format!(
            ", {:.0} % of acceleration and jerk kept for override",
            100.0 * reserve
        )
    } else {
        String::new()
    };
    println!("machine mill3, G64 P0.01, servo period 1 ms, schedule nodes {nodes}, {solved}{kept}");
    println!(
        "{:<30} {:>12} {:>12} {:>12} {:>7} {:>8} {:>9}  {:>5} {:>6} {:>6} {:>9} {:>6} {:>3} {:>6} {:>9}  {:>5} {:>5} {:>6} {:>6}  {:>12} {:>5} {:>5} {:>6} {:>6} {:>4} {:>6}  tick µs med/p99/max",
        "program",
        "executor",
        "bound",
        "schedule",
        "ex/bd",
        "sch/bd",
        "ex/sch",
        "v",
        "a",
        "j",
        "nodes",
        "stops",
        "bad",
        "win",
        "solve",
        "v@T",
        "a@T",
        "j@T",
        "moving",
        "by length",
        "v@T",
        "a@T",
        "j@T",
        "moving",
        "flat",
        "cont j"
    );
    row(
        "circle R20, 0.05 mm chords",
        &programs::circle_small_segments(),
        kins,
        solve,
    );
    row(
        "zig-zag pocket 60x40",
        &programs::zigzag_pocket(),
        kins,
        solve,
    );
    match programs::stellabee() {
        Some(text) => {
            let mut head: Vec<&str> = text.lines().take(lines).collect();
            head.push("M2");
            row(
                &format!("stellabee1.ngc, {lines} lines"),
                &head.join("\n"),
                kins,
                solve,
            );
        }
        None => println!("stellabee1.ngc: ../shared/conformance not found, skipped"),
    }
    println!();
    println!(
        "v a j: largest axis velocity, acceleration and jerk use of the schedule at its nodes"
    );
    println!("(schedule times are slowed by any excess, the solver's tolerance, up to 1e-5)");
    println!("stops: stretches between stops, each its own linear programs; bad: programs the solver gave up on;");
    println!("win: windows solved / windows with no solution, followed by the one before to rest (0/0: each stretch whole)");
    println!("v@T a@T j@T: the same, on the schedule followed in time and sampled every servo period (Schedule::sampled),");
    println!("  first a quintic in time between nodes, then (by length: its motion time) the speed as a function of arc");
    println!("  length that the schedule's rows judge (Interpolant::SpeedInLength); moving: the jerk away from stops;");
    println!("  flat: intervals followed at constant acceleration where that speed would dip towards rest;");
    println!("  cont j: the jerk of that motion itself, between the samples (Schedule::continuous_jerk, 33 points an interval);");
    println!("tick: wall time of one schedule::Follower tick through the schedule's intervals (the executor's share of");
    println!("  third-order planning; positions on the path not included), this machine's clock, reported, not a bound");
}
