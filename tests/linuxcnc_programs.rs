//! LinuxCNC's sample programs and trajectory-planner stress programs
//! (`../shared/conformance/linuxcnc-programs/`) through `kerf plan`, on a
//! nine-axis machine large enough for all of them: each is planned within
//! every axis limit and within P + Q of the programmed path, or refused for
//! a reason listed here.
//!
//! The suite runs the `violation_checks` programs (the ones that once made
//! LinuxCNC's own planner break a limit) at 1 ms; the whole corpus, at
//! 1 ms and at 250 µs, and the corpus moved into the workspaces of the
//! parallel machines (oxglide-x, oxglide-o, rfmt5), where joint limits
//! bind, run on demand:
//! `cargo test --release --test linuxcnc_programs -- --ignored --nocapture`
//! (about three minutes; stellabee1.ngc is left to `cargo bench --bench
//! motion`).

#[path = "support/shared.rs"]
mod shared;

#[path = "../benches/programs.rs"]
mod programs;

use std::path::{Path, PathBuf};
use std::process::Command;

use kerf_interp::{CanonCmd, MotionMode, Position};

/// Programs refused, and a part of the reason each gives: codes kerf does
/// not support, and errors LinuxCNC's `rs274` gives too.
const REFUSED: &[(&str, &str)] = &[
    ("nc_files/g76.ngc", "cutter compensation entry move"),
    ("nc_files/lathe-g76.ngc", "cutter compensation entry move"),
    (
        "nc_files/gridprobe.ngc",
        "probe move (G38.x) is not supported",
    ),
    (
        "nc_files/smartprobe.ngc",
        "probe move (G38.x) is not supported",
    ),
    ("nc_files/x-trim.ngc", "probe move (G38.x) is not supported"),
    (
        "nc_files/tool-length-probe.ngc",
        "Start point too close to probe point",
    ),
    ("nc_files/increment.ngc", "File ended with no percent sign"),
    ("nc_files/probe-hole.ngc", "File ended with no percent sign"),
    (
        "nc_files/nestedcall.ngc",
        "Unexpected character after O-word",
    ),
    (
        "nc_files/lathe_g70_71_demo.ngc",
        "G70, G71 and G72 are not supported",
    ),
    (
        "nc_files/lathe_g7x_face_boring.ngc",
        "G70, G71 and G72 are not supported",
    ),
    (
        "nc_files/lathe_g7x_quadrants.ngc",
        "G70, G71 and G72 are not supported",
    ),
    (
        "nc_files/systems.ngc",
        "G5 and G5.1 splines are not supported",
    ),
    ("nc_files/mmount.ngc", "spindle-synchronised motion"),
    ("nc_files/threading.ngc", "spindle-synchronised motion"),
    (
        "tp-stress/spindle/g33_blend.ngc",
        "spindle-synchronised motion",
    ),
    (
        "tp-stress/spindle/g33_simple.ngc",
        "spindle-synchronised motion",
    ),
    (
        "tp-stress/spindle/rigidtap_test.ngc",
        "spindle-synchronised motion",
    ),
    (
        "tp-stress/spindle/tapping.ngc",
        "spindle-synchronised motion",
    ),
    (
        "tp-stress/violation_checks/tap-discrimant-error-orig.ngc",
        "spindle-synchronised motion",
    ),
    (
        "tp-stress/arc-feed/full_xz.ngc",
        "while the XY plane is rotated",
    ),
    (
        "tp-stress/arc-feed/full_yz.ngc",
        "while the XY plane is rotated",
    ),
    (
        "tp-stress/diagnostic/bad_spirals_1.ngc",
        "Radius to end of arc differs",
    ),
    (
        "tp-stress/diagnostic/bad_spirals_comp.ngc",
        "Radius to end of arc differs",
    ),
    (
        "tp-stress/diagnostic/bad_spirals_lathe.ngc",
        "Radius to end of arc differs",
    ),
    (
        "tp-stress/diagnostic/spiral_aggressive.ngc",
        "Radius to end of arc differs",
    ),
    (
        "tp-stress/wz-tests/130207L.ngc",
        "Unknown m code used: M111",
    ),
];

/// Planned in `cargo bench --bench motion` instead (20 s in a release
/// build).
const LEFT_TO_THE_BENCH: &str = "tp-stress/performance/stellabee1.ngc";

/// The corpus machine (`benches/programs.rs`), written where the
/// command-line tools can read it.
fn machine_file(dir: &Path) -> PathBuf {
    let path = dir.join("big9.toml");
    std::fs::write(&path, programs::corpus_machine()).unwrap();
    path
}

/// The corpus, or `None` (saying the test is skipped) where the shared
/// conformance material is not checked out.
fn programs_dir() -> Option<PathBuf> {
    let found = shared::conformance_dir("linuxcnc-programs", "programs.tsv");
    if found.is_none() {
        eprintln!("skipped: ../shared/conformance/linuxcnc-programs not found");
    }
    found
}

/// The programs under `root`/`under`, as paths relative to `root`.
fn programs(root: &Path, under: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut dirs = vec![root.join(under)];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "ngc") {
                let rel = path.strip_prefix(root).unwrap();
                found.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    found.sort();
    found
}

/// The largest deviation the program allows: its largest G64 P, or the
/// planner's default tolerance (0.01 mm: blending from the start, and for
/// G64 without P), plus its largest G64 Q, in mm, read from the
/// interpreter's canon.
fn allowed_deviation(file: &Path, tools: &Path) -> f64 {
    let program = kerf::cli::open_program(file, Position::ZERO, Some(tools)).unwrap();
    let (mut p, mut q) = (0.01f64, 0.0f64);
    for canon in program {
        let Ok(canon) = canon else { break };
        match canon.cmd {
            CanonCmd::SetMotionControlMode(MotionMode::Continuous { tolerance }) => {
                p = p.max(if tolerance > 0.0 { tolerance } else { 0.01 });
            }
            CanonCmd::SetNaivecamTolerance { tolerance } => q = q.max(tolerance),
            _ => {}
        }
    }
    p + q
}

/// Plans every program of `list` at `period_us` on the nine-axis machine;
/// returns the failures, one line each, and prints what each program read.
fn plan_all(root: &Path, list: &[String], period_us: u32) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let machine = machine_file(dir.path());
    plan_on(root, list, &machine.to_string_lossy(), None, period_us).0
}

/// Plans every program of `list` on `machine` at `period_us`, moved by a
/// G54 offset of `shift` (G10 L2 P1 words) when given. Out of a shifted
/// program's travel is a refusal it may give; any other must be in
/// [`REFUSED`]. Returns the failures, one line each, and how many
/// programs were planned.
fn plan_on(
    root: &Path,
    list: &[String],
    machine: &str,
    shift: Option<&str>,
    period_us: u32,
) -> (Vec<String>, usize) {
    let mut planned = 0;
    let dir = tempfile::tempdir().unwrap();
    let tools = root.join("generic-tools.tbl");
    let mut failures = Vec::new();
    for rel in list {
        let mut file = root.join(rel);
        if let Some(shift) = shift {
            // The offset goes first, after a leading `%` line if there is one.
            let text = std::fs::read_to_string(&file).unwrap();
            let (head, body) = if text.trim_start().starts_with('%') {
                text.split_at(text.find('\n').map_or(text.len(), |n| n + 1))
            } else {
                ("", text.as_str())
            };
            let moved = format!("{head}G21 G10 L2 P1 {shift}\nG54\n{body}");
            file = dir.path().join(rel.replace('/', "_"));
            std::fs::write(&file, moved).unwrap();
        }
        let out = Command::new(env!("CARGO_BIN_EXE_kerf"))
            .arg("plan")
            .arg(&file)
            .arg("--machine")
            .arg(machine)
            .arg("--tool-table")
            .arg(&tools)
            .args(["--json", "--period-us", &period_us.to_string()])
            .current_dir(root.join(rel).parent().unwrap())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let refusal = REFUSED.iter().find(|(p, _)| p == rel);
        let out_of_travel = shift.is_some()
            && (stderr.contains("move leaves the machine's limits")
                || stderr.contains("is not on this machine"));
        match (out.status.success(), refusal) {
            (false, Some((_, why))) if stderr.contains(why) => {
                println!("{rel}: refused as expected");
                continue;
            }
            (false, None) if out_of_travel => {
                println!("{rel}: outside the machine's travel");
                continue;
            }
            (false, _) => {
                failures.push(format!("{rel}: refused: {}", stderr.trim()));
                continue;
            }
            (true, Some((_, why))) => {
                failures.push(format!("{rel}: planned, but was refused ({why})"));
                continue;
            }
            (true, None) => {}
        }
        planned += 1;
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let limit = report["max_limit_ratio"].as_f64().unwrap();
        let deviation = report["max_deviation_mm"].as_f64().unwrap();
        let over = report["over_tolerance_mm"].as_f64().unwrap();
        let allowed = allowed_deviation(&root.join(rel), &tools);
        println!(
            "{rel}: {:.3} s, deviation {deviation:.4} mm (allowed {allowed:.4}), limit use {limit:.9}",
            report["cycle_time_s"].as_f64().unwrap()
        );
        if limit > 1.0 + 1e-6 {
            failures.push(format!("{rel}: limit use {limit}"));
        }
        if over > 1e-9 {
            failures.push(format!("{rel}: {over} mm over the tolerance where it ran"));
        }
        if deviation > allowed + 1e-9 {
            failures.push(format!(
                "{rel}: deviation {deviation} mm over P + Q = {allowed} mm"
            ));
        }
    }
    (failures, planned)
}

#[test]
fn linuxcnc_violation_checks_plan_within_limits_and_tolerance() {
    let Some(root) = programs_dir() else {
        return;
    };
    let list = programs(&root, "tp-stress/violation_checks");
    assert!(list.len() >= 25, "{} programs", list.len());
    let failures = plan_all(&root, &list, 1000);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
#[ignore = "two minutes in a release build; run on demand"]
fn every_linuxcnc_program_plans_within_limits_and_tolerance() {
    let Some(root) = programs_dir() else {
        return;
    };
    let list: Vec<String> = programs(&root, "")
        .into_iter()
        .filter(|p| p != LEFT_TO_THE_BENCH)
        .collect();
    assert!(list.len() >= 220, "{} programs", list.len());
    for (refused, _) in REFUSED {
        assert!(list.iter().any(|p| p == refused), "{refused} is not there");
    }
    let mut failures = Vec::new();
    for period_us in [1000, 250] {
        failures.extend(
            plan_all(&root, &list, period_us)
                .into_iter()
                .map(|f| format!("{period_us} µs: {f}")),
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
#[ignore = "forty seconds in a release build; run on demand"]
fn linuxcnc_programs_keep_the_parallel_machines_joints_within_limits() {
    let Some(root) = programs_dir() else {
        return;
    };
    // Programs refused whatever the machine are the nine-axis test's.
    let list: Vec<String> = programs(&root, "")
        .into_iter()
        .filter(|p| p != LEFT_TO_THE_BENCH && !REFUSED.iter().any(|(r, _)| r == p))
        .collect();
    // Each machine's workspace centre (near its home), and the programs
    // that fit it when this was written: a floor, so that a shift gone
    // wrong cannot pass by refusing everything.
    let machines = [
        ("oxglide-x", "X255 Y200 Z-330", 120),
        ("oxglide-o", "X252 Y200 Z-350", 60),
        ("rfmt5", "X150 Y100 Z100", 140),
    ];
    let mut failures = Vec::new();
    for (machine, shift, floor) in machines {
        let (failed, planned) = plan_on(&root, &list, machine, Some(shift), 1000);
        failures.extend(failed.into_iter().map(|f| format!("{machine}: {f}")));
        println!("{machine}: {planned} of {} programs planned", list.len());
        if planned < floor {
            failures.push(format!("{machine}: only {planned} programs planned"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
