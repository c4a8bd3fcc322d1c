//! `kerf plan` and `kerf check`: plan a program offline for a machine.

use std::io::Write;
use std::path::Path;

use kerf_motion::offline::{self, FollowConfig, LimitUse, Report, RunConfig};
use kerf_motion::schedule::ScheduleConfig;
use kerf_motion::{Planner, PlannerConfig};
use serde_json::json;

use super::{open_program, Failure};
use crate::svg::{Chart, Series};

fn load(machine: &str) -> Result<kerf_machines::Machine, Failure> {
    kerf_machines::load(machine).map_err(|e| Failure::new(e.to_string()))
}

/// `kerf check`: interpret the whole program and check every move against
/// the machine's travel, reach and joint strokes. Lists every violation.
pub fn check(
    file: &Path,
    machine: &str,
    tool_table: Option<&Path>,
    json_out: bool,
) -> Result<(), Failure> {
    let machine = load(machine)?;
    let kins = &*machine.kinematics;
    let home = machine.home();
    let mut planner = Planner::new(kins, home, PlannerConfig::default());
    let mut problems = Vec::new();
    let mut moves = 0usize;
    for canon in open_program(file, home, tool_table)? {
        match canon {
            Err(e) => {
                problems.push(e.to_string());
                break;
            }
            Ok(c) => {
                if let Err(e) = planner.plan(&c) {
                    problems.push(e.to_string());
                }
                while planner.next_segment().is_some() {
                    moves += 1;
                }
            }
        }
    }
    if json_out {
        println!(
            "{}",
            json!({"ok": problems.is_empty(), "segments": moves, "violations": problems})
        );
    } else if problems.is_empty() {
        println!(
            "{}: ok ({moves} segments within the limits of {})",
            file.display(),
            machine.description.name
        );
    } else {
        for p in &problems {
            println!("{p}");
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(Failure::new(format!("{} violation(s)", problems.len())))
    }
}

/// `kerf plan --segments`: list the planned segments with their limits,
/// to see what holds a program back.
pub fn segments(
    file: &Path,
    machine: &str,
    tool_table: Option<&Path>,
    period: f64,
) -> Result<(), Failure> {
    let machine = load(machine)?;
    let kins = &*machine.kinematics;
    let home = machine.home();
    let config = PlannerConfig {
        period,
        ..PlannerConfig::default()
    };
    let mut planner = Planner::new(kins, home, config);
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut print = |seg: Option<kerf_motion::Segment>| -> std::io::Result<()> {
        let Some(seg) = seg else {
            return writeln!(
                out,
                "{:>6} {:<6} {:>10} {:>10} {:>10} {:>11} {:>12} {:>10}",
                "line", "kind", "length", "feed", "v max", "a max", "j max", "exit"
            );
        };
        let kind = match (seg.kind, seg.shape) {
            (kerf_motion::SegmentKind::Dwell { .. }, _) => "dwell",
            (kerf_motion::SegmentKind::Output(_), _) => "output",
            (_, kerf_motion::path::Shape::Blend(_)) => "blend",
            (_, kerf_motion::path::Shape::Arc(_)) => "arc",
            (kerf_motion::SegmentKind::Rapid, _) => "rapid",
            _ => "line",
        };
        writeln!(
            out,
            "{:>6} {:<6} {:>10.4} {:>10.1} {:>10.1} {:>11.1} {:>12.0} {:>10.1}",
            seg.line,
            kind,
            seg.length,
            seg.feed * 60.0,
            seg.max_velocity * 60.0,
            seg.max_acceleration,
            seg.max_jerk,
            seg.exit_velocity * 60.0
        )
    };
    // A closed pipe (`| head`) ends the listing quietly.
    if print(None).is_err() {
        return Ok(());
    }
    for canon in open_program(file, home, tool_table)? {
        let canon = canon.map_err(|e| Failure::new(e.to_string()))?;
        planner
            .plan(&canon)
            .map_err(|e| Failure::new(e.to_string()))?;
        while let Some(seg) = planner.next_segment() {
            if print(Some(seg)).is_err() {
                return Ok(());
            }
        }
    }
    planner.finish();
    while let Some(seg) = planner.next_segment() {
        if print(Some(seg)).is_err() {
            return Ok(());
        }
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
/// `kerf plan`: plan and execute the program on a virtual clock, print
/// cycle time, largest path deviation and limit use, and optionally plot.
pub fn plan(
    file: &Path,
    machine: &str,
    tool_table: Option<&Path>,
    plot: Option<&Path>,
    json_out: bool,
    trapezoidal: bool,
    follow: Option<f64>,
    period: f64,
) -> Result<(), Failure> {
    let machine = load(machine)?;
    let kins = &*machine.kinematics;
    // The reserve is checked where the schedule is made
    // (`ScheduleError::Reserve`), before anything runs.
    let follow = follow.map(|reserve| {
        let default = FollowConfig::default();
        FollowConfig {
            schedule: ScheduleConfig {
                reserve,
                ..default.schedule
            },
            ..default
        }
    });
    let config = RunConfig {
        planner: PlannerConfig {
            jerk_limited: !trapezoidal,
            period,
            ..PlannerConfig::default()
        },
        record: if plot.is_some() { 2000 } else { 0 },
        follow,
    };
    let home = machine.home();
    let report = offline::run(open_program(file, home, tool_table)?, kins, home, config)
        .map_err(|e| Failure::new(e.to_string()))?;
    if let Some(out) = plot {
        let names: Vec<String> = kins.joints().iter().map(|j| j.name.clone()).collect();
        write_plot(out, &report, &names)
            .map_err(|e| Failure::new(format!("{}: {e}", out.display())))?;
    }
    if json_out {
        let uses = |v: &[LimitUse]| {
            v.iter()
                .map(|u| {
                    json!({"name": u.name, "velocity": u.velocity.ratio, "acceleration": u.acceleration.ratio, "jerk": u.jerk.ratio})
                })
                .collect::<Vec<_>>()
        };
        println!(
            "{}",
            json!({
                "cycle_time_s": report.cycle_time,
                "max_deviation_mm": report.max_deviation,
                "max_deviation_allowed_mm": report.max_deviation_allowed,
                "over_tolerance_mm": report.over_tolerance,
                "max_limit_ratio": report.max_limit_ratio(),
                "segments": report.segments,
                "guard_takeovers": report.guard_takeovers,
                "stretches_followed": report.stretches_followed,
                "axes": uses(&report.axes),
                "joints": uses(&report.joints),
            })
        );
        return Ok(());
    }
    // A closed pipe (`| head`) ends the output quietly.
    let _ = print_report(&machine.description.name, period, &report);
    Ok(())
}

/// Deviation beyond the program's tolerance that is rounding, not a path
/// leaving it, mm: positions along the path carry about 1e-13 mm of it.
const TOLERANCE_ROUNDING: f64 = 1e-9;

/// What the program allowed where the deviation was largest, in words.
fn allowance(allowed: f64) -> String {
    if allowed == 0.0 {
        "exact path there".to_string()
    } else if allowed.is_finite() {
        format!("P + Q = {allowed:.6} mm there")
    } else {
        "G64 without a limit there".to_string()
    }
}

fn print_report(machine: &str, period: f64, report: &Report) -> std::io::Result<()> {
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    writeln!(out, "machine          {machine}")?;
    writeln!(out, "servo period     {:.0} µs", period * 1e6)?;
    writeln!(out, "cycle time       {:.3} s", report.cycle_time)?;
    writeln!(out, "segments         {}", report.segments)?;
    writeln!(
        out,
        "max deviation    {:.6} mm (line {} at {:.3} s; {})",
        report.max_deviation,
        report.max_deviation_at.1,
        report.max_deviation_at.0,
        allowance(report.max_deviation_allowed)
    )?;
    if report.over_tolerance > TOLERANCE_ROUNDING {
        writeln!(
            out,
            "over tolerance   {:.6} mm (line {} at {:.3} s)",
            report.over_tolerance, report.over_tolerance_at.1, report.over_tolerance_at.0
        )?;
    }
    writeln!(out, "max limit use    {:.6}", report.max_limit_ratio())?;
    writeln!(out, "guard takeovers  {}", report.guard_takeovers)?;
    if report.stretches_followed > 0 {
        writeln!(
            out,
            "schedule         {} stretches followed",
            report.stretches_followed
        )?;
    }
    writeln!(out)?;
    writeln!(
        out,
        "{:<8} {:>10} {:>10} {:>10}   worst at",
        "", "velocity", "accel", "jerk"
    )?;
    for (kind, list) in [("axis", &report.axes), ("joint", &report.joints)] {
        for u in list.iter() {
            let worst = [u.velocity, u.acceleration, u.jerk]
                .into_iter()
                .max_by(|a, b| a.ratio.total_cmp(&b.ratio))
                .unwrap_or_default();
            writeln!(
                out,
                "{:<8} {:>10.4} {:>10.4} {:>10.4}   line {} at {:.3} s",
                format!("{kind} {}", u.name),
                u.velocity.ratio,
                u.acceleration.ratio,
                u.jerk.ratio,
                worst.line,
                worst.time
            )?;
        }
    }
    Ok(())
}

fn write_plot(out: &Path, report: &Report, joint_names: &[String]) -> std::io::Result<()> {
    let pts = &report.points;
    let time: Vec<f64> = pts.iter().map(|p| p.time).collect();
    let path = Chart::xy_path(
        "Tool path (XY): programmed and planned",
        &report.programmed,
        "planned",
        pts.iter().map(|p| (p.position.x, p.position.y)).collect(),
    );
    let tool = Chart {
        title: "Tool tip against time".into(),
        x_label: "t, s".into(),
        y_label: "mm".into(),
        equal_aspect: false,
        series: ["X", "Y", "Z"]
            .iter()
            .enumerate()
            .map(|(i, n)| {
                Series::new(
                    n,
                    time.iter()
                        .zip(pts)
                        .map(|(t, p)| (*t, p.position.to_array()[i]))
                        .collect(),
                )
            })
            .collect(),
    };
    let joints = Chart {
        title: "Joint positions against time".into(),
        x_label: "t, s".into(),
        y_label: "joint units".into(),
        equal_aspect: false,
        series: joint_names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                Series::new(
                    n,
                    time.iter()
                        .zip(pts)
                        .map(|(t, p)| (*t, p.joints[i]))
                        .collect(),
                )
            })
            .collect(),
    };
    let feed = Chart {
        title: "Feed against time".into(),
        x_label: "t, s".into(),
        y_label: "mm/min".into(),
        equal_aspect: false,
        series: vec![Series::new(
            "path feed",
            time.iter()
                .zip(pts)
                .map(|(t, p)| (*t, p.velocity * 60.0))
                .collect(),
        )],
    };
    std::fs::write(out, crate::svg::page(&[path, tool, joints, feed]))
}
