//! `kerf sim` through the real binary: the JSON it promises, the plot, and
//! clear errors for bad input.

use std::process::Command;

use serde_json::Value;

fn kerf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(args)
        .output()
        .unwrap()
}

fn json(out: &std::process::Output) -> Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

const ALUMINIUM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");
const CUT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.ngc");

#[test]
fn json_reports_following_and_contour_error_and_null_force_without_control() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("line.ngc");
    std::fs::write(&p, "G21 G90\nG1 X20 Y20 F1000\nM2\n").unwrap();
    let svg = dir.path().join("out.svg");
    let out = kerf(&[
        "sim",
        p.to_str().unwrap(),
        "--no-feedforward",
        "--json",
        "--plot",
        svg.to_str().unwrap(),
    ]);
    let j = json(&out);
    // A diagonal at 1000 mm/min: each joint moves at v/√2, so each lags
    // by v/(√2·K·kp) = 0.4648/√2 = 0.3287 mm in the steady part.
    let lag = 0.4648 / 2f64.sqrt();
    let fe = j["max_following_error_mm"].as_f64().unwrap();
    assert!((fe - lag).abs() < 0.003, "{fe}");
    assert!(j["max_contour_error_mm"].as_f64().unwrap() < 1e-6);
    assert!(j["cycle_time_s"].as_f64().unwrap() > 28.28 / (1000.0 / 60.0));
    assert!(j["force"].is_null());
    assert!(j["cutting"].is_null());
    assert_eq!(j["joints"].as_array().unwrap().len(), 3);
    let plot = std::fs::read_to_string(&svg).unwrap();
    assert!(plot.contains("Following error against time"), "plot");
}

/// The contour error at the end is measured against the program's last
/// move: until 2026-11-26 the last sample was measured against line 1's
/// moves alone, and a program starting with a rapid there reported its
/// distance from that rapid (10 mm here).
#[test]
fn the_contour_error_at_the_end_is_measured_against_the_last_move() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("end.ngc");
    std::fs::write(&p, "G0 X150 Y100 Z-10\nG1 X160 F600\nM2\n").unwrap();
    let j = json(&kerf(&["sim", p.to_str().unwrap(), "--json"]));
    // The corner blend stays within G64's default 0.01 mm; the servo
    // with feedforward follows it to well under a micrometre more.
    let contour = j["max_contour_error_mm"].as_f64().unwrap();
    assert!(contour < 0.011, "max contour error {contour} mm");
}

/// A loop runs one source line for every pass: the contour error is
/// measured against the moves the commanded segment spans, not against
/// moves picked by source line (which compared a pass with an earlier one,
/// tens of millimetres away, until 2026-11-27).
#[test]
fn the_contour_error_in_a_loop_is_measured_against_each_pass() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("holes.ngc");
    std::fs::write(
        &p,
        "G21 G90 G64 P0.05\nG0 Z-1\n#1=0\nO1 while [#1 LT 360]\n\
         G0 X[150+40*COS[#1]] Y[100+40*SIN[#1]] Z-1\nG1 Z-6 F600\nG0 Z-1\n\
         #1=[#1+45]\nO1 endwhile\nG0 Z0\nM2\n",
    )
    .unwrap();
    let j = json(&kerf(&["sim", p.to_str().unwrap(), "--json"]));
    // The corners' blends stay within P = 0.05 mm, and the servo with
    // feedforward follows them to well under a micrometre more.
    let contour = j["max_contour_error_mm"].as_f64().unwrap();
    assert!(contour < 0.051, "max contour error {contour} mm");
}

#[test]
fn json_reports_force_figures_with_control() {
    let out = kerf(&[
        "sim",
        CUT,
        "--machine",
        ALUMINIUM,
        "--force",
        "250",
        "--json",
    ]);
    let j = json(&out);
    let f = &j["force"];
    assert_eq!(f["target_n"], 250.0);
    for key in ["max_n", "rms_error_pct", "settle_s"] {
        assert!(f[key].as_f64().is_some(), "{key}: {f}");
    }
    // Force and override against time, one entry per spindle revolution
    // (60 ms at 1000 rpm).
    let trace = &f["trace"];
    let times = trace["time_s"].as_array().unwrap();
    let cycle = j["cycle_time_s"].as_f64().unwrap();
    assert_eq!(times.len(), (cycle / 0.060) as usize, "{cycle}");
    for key in ["force_n", "estimated_n", "feed_override"] {
        assert_eq!(trace[key].as_array().unwrap().len(), times.len(), "{key}");
    }
    let changes = j["cutting"]["depth_changes"].as_array().unwrap();
    assert_eq!(
        changes.len(),
        3,
        "into the stock, up the step, out: {changes:?}"
    );
}

#[test]
fn bad_input_is_named() {
    let out = kerf(&["sim", CUT, "--machine", ALUMINIUM, "--force", "0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--force"));

    let out = kerf(&["sim", "/nonexistent/x.ngc"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/x.ngc"));

    // A cutting process on a machine whose joints are not X, Y and Z.
    let ox = kerf_machines::EMBEDDED
        .iter()
        .find(|(n, _)| *n == "oxglide-x")
        .unwrap()
        .1
        .replace(
            "[hal]\nbackend = \"sim\"",
            "[hal]\nbackend = \"sim\"\n[hal.sim.cutting]\nstock_top = 0.0",
        );
    let dir = tempfile::tempdir().unwrap();
    let machine = dir.path().join("ox-cut.toml");
    std::fs::write(&machine, ox).unwrap();
    let p = dir.path().join("p.ngc");
    std::fs::write(&p, "G1 X20 F1000\nM2\n").unwrap();
    let out = kerf(&[
        "sim",
        p.to_str().unwrap(),
        "--machine",
        machine.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("hal.sim.cutting.joints") && err.contains("does not drive axis X"),
        "{err}"
    );

    // A following-error fault stops the run and says which joint: X lags
    // 0.46 mm at 1000 mm/min without feedforward.
    let tight = std::fs::read_to_string(ALUMINIUM).unwrap().replacen(
        "following_error = 1.0",
        "following_error = 0.01",
        1,
    );
    let machine = dir.path().join("tight.toml");
    std::fs::write(&machine, tight).unwrap();
    let out = kerf(&[
        "sim",
        p.to_str().unwrap(),
        "--machine",
        machine.to_str().unwrap(),
        "--no-feedforward",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("joint 0 following error"), "{err}");
}
