//! Where the cycle time goes: stellabee1.ngc (or its first LINES lines)
//! planned on mill3 under G64 P0.01, run through the executor on a
//! virtual clock, and set segment by segment beside the time-optimal
//! lower bound of `kerf_motion::bound` (the figure the `motion` bench
//! divides by).
//!
//! Run: `cargo bench --bench loss` (about 25 s), or
//! `cargo bench --bench loss -- 30000` for the first 30,000 lines. With
//! `--schedule` (and a number of lines: 2000 take about 13 s) it also sets
//! beside them the jerk-limited schedule of `kerf_motion::schedule`, a
//! motion within every limit: where the executor loses against the
//! schedule is where a better planner would gain, not only the bound.
//!
//! Each servo period counts for the segment at the front of the queue
//! when it starts; each step of the bound for the segment its middle lies
//! on. The table sums both by kind of segment, with the time each kind
//! would take at its own speed limit throughout (`at limit`): where the
//! executor is near that figure, its speed limits are what to raise, not
//! its profile. The list after it is the segments that lose the most.

#[path = "programs.rs"]
mod programs;

use std::collections::BTreeMap;

use kerf_interp::{Interpreter, Position};
use kerf_motion::bound::{lower_bound, BoundConfig};
use kerf_motion::offline::plan_program;
use kerf_motion::path::Shape;
use kerf_motion::schedule::{schedule, ScheduleConfig};
use kerf_motion::{Executor, PlannerConfig, Segment};

/// What a segment is, for the table.
fn kind(segments: &[Segment], k: usize) -> &'static str {
    let s = &segments[k];
    if !s.is_motion() {
        return "marker";
    }
    let blend = |j: usize| {
        segments
            .get(j)
            .is_some_and(|s| matches!(s.shape, Shape::Blend(_)))
    };
    match s.shape {
        Shape::Line(_) if s.exit_velocity == 0.0 => "line into a stop",
        Shape::Line(_) => "line running on",
        Shape::Arc(_) => "arc",
        Shape::Blend(_) if (k > 0 && blend(k - 1)) || blend(k + 1) => "dense-curve blend",
        Shape::Blend(_) => "corner blend",
    }
}

fn main() {
    let lines: Option<usize> = std::env::args().skip(1).find_map(|a| a.parse().ok());
    let with_schedule = std::env::args().any(|a| a == "--schedule");
    if with_schedule && lines.is_none() {
        println!(
            "--schedule needs a number of lines (the whole file, 200000, takes about ten minutes)"
        );
        return;
    }
    let Some(text) = programs::stellabee() else {
        println!("stellabee1.ngc: not found under ../shared/conformance; skipped");
        return;
    };
    let text = match lines {
        Some(n) => text.lines().take(n + 2).collect::<Vec<_>>().join("\n") + "\nM2\n",
        None => text,
    };
    let machine = kerf_machines::load("mill3").expect("mill3 is embedded");
    let kins = &*machine.kinematics;
    let config = PlannerConfig::default();
    let program = Interpreter::from_text(&text, "stellabee1.ngc", Position::ZERO);
    let segments = plan_program(program, kins, Position::ZERO, config, 1)
        .unwrap_or_else(|e| panic!("stellabee1.ngc does not plan: {e}"));

    // The executor, one servo period at a time.
    let mut executor = Executor::new(Position::ZERO);
    let mut run = vec![0.0; segments.len()];
    let mut front = 0;
    let mut periods: u64 = 0;
    loop {
        let sample = executor.tick(config.period, &segments[front..], &[]);
        run[front.min(segments.len() - 1)] += config.period;
        front += sample.consumed;
        periods += 1;
        if sample.stopped_at == Some(1) {
            break;
        }
    }
    let cycle = periods as f64 * config.period;

    // The bound, step by step, onto the segments by path position.
    let profile = lower_bound(segments.iter(), kins, BoundConfig::default());
    let mut starts = Vec::with_capacity(segments.len());
    let mut at = 0.0;
    for s in &segments {
        starts.push(at);
        if s.is_motion() && s.length > 0.0 {
            at += s.length;
        }
    }
    // Each step's time to the segment its middle lies on.
    let by_segment = |s: &[f64], step: &[f64]| {
        let mut out = vec![0.0; segments.len()];
        let mut k = 0;
        for w in 0..step.len().saturating_sub(1) {
            let middle = (s[w] + s[w + 1]) / 2.0;
            while k + 1 < segments.len() && starts[k + 1] <= middle {
                k += 1;
            }
            out[k] += step[w];
        }
        out
    };
    let bound = by_segment(&profile.s, &profile.step);
    let scheduled = with_schedule.then(|| {
        let found = schedule(&segments, kins, ScheduleConfig::default())
            .expect("mill3 has trivial kinematics");
        (found.time, by_segment(&found.s, &found.step))
    });

    println!(
        "stellabee1.ngc{} on mill3, G64 P0.01: {} segments, run {cycle:.3} s, bound {:.3} s, ratio {:.3}",
        lines.map_or(String::new(), |n| format!(" (first {n} lines)")),
        segments.len(),
        profile.time,
        cycle / profile.time,
    );
    if let Some((time, _)) = &scheduled {
        println!(
            "jerk-limited schedule {time:.3} s: run / schedule {:.3}, schedule / bound {:.3}",
            cycle / time,
            time / profile.time
        );
    }
    println!();
    println!(
        "{:<20} {:>8} {:>11} {:>11} {:>7} {:>11} {:>11} {:>11}",
        "segment", "count", "run s", "bound s", "ratio", "lost s", "at limit s", "schedule s"
    );
    // count, run, bound, at its speed limit throughout, schedule
    let mut kinds: BTreeMap<&str, (usize, f64, f64, f64, f64)> = BTreeMap::new();
    for (k, s) in segments.iter().enumerate() {
        let row = kinds.entry(kind(&segments, k)).or_default();
        row.0 += 1;
        row.1 += run[k];
        row.2 += bound[k];
        if s.is_motion() {
            row.3 += s.length / s.max_velocity.min(s.feed);
        }
        if let Some((_, steps)) = &scheduled {
            row.4 += steps[k];
        }
    }
    for (name, (count, run, bound, at_limit, scheduled_time)) in &kinds {
        let ratio = if *bound > 0.0 {
            format!("{:.3}", run / bound)
        } else {
            "-".to_string()
        };
        let scheduled_time = match scheduled {
            Some(_) => format!("{scheduled_time:.3}"),
            None => "-".to_string(),
        };
        println!(
            "{name:<20} {count:>8} {run:>11.3} {bound:>11.3} {ratio:>7} {:>11.3} {at_limit:>11.3} {scheduled_time:>11}",
            run - bound,
        );
    }
    println!();
    println!("The 10 segments that lose the most:");
    let mut order: Vec<usize> = (0..segments.len()).collect();
    order.sort_by(|&a, &b| (run[b] - bound[b]).total_cmp(&(run[a] - bound[a])));
    for &k in order.iter().take(10) {
        let s = &segments[k];
        println!(
            "  #{k} line {} {}: {:.4} mm, limits {:.2} mm/s {:.0} mm/s² {:.0} mm/s³, exit {:.2} mm/s; run {:.4} s, bound {:.4} s",
            s.line,
            kind(&segments, k),
            s.length,
            s.max_velocity,
            s.max_acceleration,
            s.max_jerk,
            s.exit_velocity,
            run[k],
            bound[k],
        );
    }
}
