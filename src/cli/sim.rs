//! `kerf sim`: run a program on the simulated machine on a virtual clock
//! and report following, contour and force figures.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use serde_json::{json, Value};

use super::{open_program, Failure};
use crate::simulate::{self, SimOptions, SimReport};
use crate::svg::{Chart, Series};

/// `kerf sim FILE --machine NAME [--plot OUT] [--json]`.
pub fn sim(
    file: &Path,
    machine: &str,
    tool_table: Option<&Path>,
    options: SimOptions,
    plot: Option<&Path>,
    json_out: bool,
) -> Result<(), Failure> {
    let machine = kerf_machines::load(machine).map_err(|e| Failure::new(e.to_string()))?;
    let program = open_program(file, machine.home(), tool_table)?;
    let options = SimOptions {
        record: plot.is_some(),
        ..options
    };
    let report = simulate::simulate(program, &machine, &options)
        .map_err(|e| Failure::new(format!("{}: {e:#}", file.display())))?;
    if let Some(out) = plot {
        write_plot(out, &report).map_err(|e| Failure::new(format!("{}: {e}", out.display())))?;
    }
    let text = if json_out {
        format!("{}\n", to_json(&report))
    } else {
        summary(&machine.description.name, &report)
    };
    // A reader that stops early (`| head`) is not an error.
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(Failure::new(format!("cannot write the report: {e}")))
        }
        _ => Ok(()),
    }
}

/// The report as a person reads it.
fn summary(machine: &str, report: &SimReport) -> String {
    let mut out = String::new();
    // Writing into a String cannot fail.
    macro_rules! putln {
        ($($arg:tt)*) => {{ let _ = writeln!(out, $($arg)*); }};
    }
    macro_rules! put {
        ($($arg:tt)*) => {{ let _ = write!(out, $($arg)*); }};
    }
    putln!("machine              {}", machine);
    putln!("cycle time           {:.3} s", report.cycle_time);
    putln!("max following error  {:.6} mm", report.max_following_error);
    putln!("max contour error    {:.6} mm", report.max_contour_error);
    for j in &report.joints {
        putln!(
            "  joint {:<6} max {:.6} mm  rms {:.6} mm",
            j.name,
            j.max_following_error,
            j.rms_following_error
        );
    }
    if let Some(c) = &report.cutting {
        putln!(
            "max cutting force    {:.1} N ({:.3} s cutting)",
            c.max_force,
            c.cutting_time
        );
        for ch in &c.changes {
            put!(
                "  depth {:.2} → {:.2} mm at {:.3} s: force {:.1} → {:.1} N",
                ch.depth_from,
                ch.depth_to,
                ch.time,
                ch.force_before,
                ch.force_after
            );
            match ch.settle {
                Some(s) => putln!(", settled in {s:.3} s"),
                None if report.force.is_some() && ch.depth_to > 0.0 => {
                    putln!(", did not settle")
                }
                None => putln!(),
            }
        }
    }
    if let Some(f) = &report.force {
        putln!(
            "force control        target {:.1} N, max {:.1} N, rms error after settling {}, settle {}",
            f.target,
            f.max,
            f.rms_error_pct.map_or("-".into(), |e| format!("{e:.2} %")),
            f.settle.map_or("never".into(), |s| format!("{s:.3} s")),
        );
    }
    let t = &report.tick_time;
    putln!(
        "tick compute         median {:.1} µs, p99 {:.1} µs, max {:.1} µs ({} ticks)",
        t.median_ns as f64 / 1000.0,
        t.p99_ns as f64 / 1000.0,
        t.max_ns as f64 / 1000.0,
        report.ticks
    );
    out
}

/// The report as JSON: the keys `kerf sim --json` promises, and more.
pub fn to_json(report: &SimReport) -> Value {
    let joints: Vec<Value> = report
        .joints
        .iter()
        .map(|j| {
            json!({"name": j.name, "max_following_error_mm": j.max_following_error,
                   "rms_following_error_mm": j.rms_following_error})
        })
        .collect();
    let cutting = report.cutting.as_ref().map(|c| {
        json!({
            "max_force_n": c.max_force,
            "cutting_time_s": c.cutting_time,
            "depth_changes": c.changes.iter().map(|ch| json!({
                "time_s": ch.time, "depth_from_mm": ch.depth_from, "depth_to_mm": ch.depth_to,
                "force_before_n": ch.force_before, "force_after_n": ch.force_after,
                "settle_s": ch.settle,
            })).collect::<Vec<_>>(),
        })
    });
    // With force control, the force and override of every controller step
    // (one spindle revolution), as parallel arrays.
    let force = report.force.map(|f| {
        let steps = &report.forces;
        json!({"target_n": f.target, "max_n": f.max, "rms_error_pct": f.rms_error_pct,
        "settle_s": f.settle,
        "trace": {
            "time_s": steps.iter().map(|s| s.time).collect::<Vec<_>>(),
            "force_n": steps.iter().map(|s| s.force).collect::<Vec<_>>(),
            "estimated_n": steps.iter().map(|s| s.estimated).collect::<Vec<_>>(),
            "feed_override": steps.iter().map(|s| s.feed_override).collect::<Vec<_>>(),
        }})
    });
    let us = |ns: u64| ns as f64 / 1000.0;
    let t = &report.tick_time;
    json!({
        "cycle_time_s": report.cycle_time,
        "max_following_error_mm": report.max_following_error,
        "max_contour_error_mm": report.max_contour_error,
        "force": force,
        "joints": joints,
        "cutting": cutting,
        "ticks": report.ticks,
        "tick_compute_us": {"median": us(t.median_ns), "p99": us(t.p99_ns), "max": us(t.max_ns)},
    })
}

/// Every `k`-th item, about `n` in all, and the last.
fn thin<T: Copy>(items: &[T], n: usize) -> Vec<T> {
    let step = (items.len() / n.max(1)).max(1);
    let mut out: Vec<T> = items.iter().step_by(step).copied().collect();
    if let Some(last) = items.last() {
        out.push(*last);
    }
    out
}

fn write_plot(out: &Path, report: &SimReport) -> std::io::Result<()> {
    let trace = thin(&report.trace, 4000);
    let mut charts = vec![
        Chart::xy_path(
            "Tool path (XY): programmed and simulated",
            &report.programmed,
            "simulated",
            trace.iter().map(|p| (p.actual[0], p.actual[1])).collect(),
        ),
        Chart {
            title: "Following error against time".into(),
            x_label: "t, s".into(),
            y_label: "mm".into(),
            equal_aspect: false,
            series: report
                .joints
                .iter()
                .enumerate()
                .map(|(j, f)| {
                    Series::new(
                        &f.name,
                        trace
                            .iter()
                            .map(|p| (p.time, p.following_error[j]))
                            .collect(),
                    )
                })
                .collect(),
        },
        Chart {
            title: "Commanded feed against time".into(),
            x_label: "t, s".into(),
            y_label: "mm/min".into(),
            equal_aspect: false,
            series: vec![Series::new(
                "path feed",
                trace.iter().map(|p| (p.time, p.velocity * 60.0)).collect(),
            )],
        },
    ];
    if !report.forces.is_empty() {
        let f = &report.forces;
        let mut series = vec![
            Series::new(
                "force (process)",
                f.iter().map(|s| (s.time, s.force)).collect(),
            ),
            Series::new(
                "force (from spindle current)",
                f.iter().map(|s| (s.time, s.estimated)).collect(),
            ),
        ];
        if let Some(force) = &report.force {
            let (a, b) = (f[0].time, f[f.len() - 1].time);
            series.push(Series::new(
                "target",
                vec![(a, force.target), (b, force.target)],
            ));
        }
        charts.push(Chart {
            title: "Cutting force per spindle revolution".into(),
            x_label: "t, s".into(),
            y_label: "N".into(),
            equal_aspect: false,
            series,
        });
        charts.push(Chart {
            title: "Force controller's feed override".into(),
            x_label: "t, s".into(),
            y_label: "%".into(),
            equal_aspect: false,
            series: vec![Series::new(
                "override",
                f.iter()
                    .map(|s| (s.time, s.feed_override * 100.0))
                    .collect(),
            )],
        });
    }
    std::fs::write(out, crate::svg::page(&charts))
}
