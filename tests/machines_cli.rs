//! `kerf kins` and `kerf workspace` through the real binary, and the new
//! machines running in kerfd.
//!
//! Expected joint values come from the O-X glide paper's eqs. (7)–(8)
//! computed here; 1e-9 mm as everywhere for kinematics (JSON carries f64
//! exactly: serde_json prints the shortest representation that reads back
//! to the same number).

mod support;

use std::process::{Command, Output};

use kerf::protocol::{Command as Request, MachineState, ProgramState, Status};
use serde_json::Value;
use support::Kerfd;

const TOL: f64 = 1e-9;

fn kerf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(args)
        .output()
        .expect("run kerf")
}

fn json_of(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

/// Eqs. (7)–(8) of the O-X glide paper, l1 302, l2 432, p1 55, p2 65, d 74.
fn crossed(x: f64, z: f64) -> (f64, f64) {
    (
        x - 55.0 + (302.0_f64.powi(2) - (z + 74.0).powi(2)).sqrt(),
        x + 65.0 - (432.0_f64.powi(2) - (z - 74.0).powi(2)).sqrt(),
    )
}

#[test]
fn kins_inverse_and_forward_as_json() {
    let out = kerf(&[
        "kins",
        "--machine",
        "oxglide-x",
        "--json",
        "inverse",
        "250",
        "40",
        "-300",
    ]);
    assert!(out.status.success(), "{out:?}");
    let joints: Vec<f64> = json_of(&out)["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (s1, s2) = crossed(250.0, -300.0);
    assert!(
        (joints[0] - s1).abs() < TOL && (joints[1] - s2).abs() < TOL,
        "{joints:?}"
    );
    assert_eq!(joints[2], 40.0);

    let (a, b) = (s1.to_string(), s2.to_string());
    let out = kerf(&[
        "kins",
        "--machine",
        "oxglide-x",
        "--json",
        "forward",
        &a,
        &b,
        "40",
    ]);
    assert!(out.status.success(), "{out:?}");
    let pose = &json_of(&out)["pose"];
    assert!((pose["x"].as_f64().unwrap() - 250.0).abs() < TOL, "{pose}");
    assert!((pose["z"].as_f64().unwrap() + 300.0).abs() < TOL, "{pose}");
    assert_eq!(pose["y"].as_f64(), Some(40.0));
    assert_eq!(
        pose.as_object().unwrap().keys().collect::<Vec<_>>(),
        ["x", "y", "z"]
    );
}

#[test]
fn kins_takes_a_machine_file_and_negative_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ox.toml");
    let text = kerf_machines::EMBEDDED
        .iter()
        .find(|(n, _)| *n == "oxglide-x")
        .unwrap()
        .1;
    std::fs::write(&path, text).unwrap();
    let out = kerf(&[
        "kins",
        "--machine",
        path.to_str().unwrap(),
        "inverse",
        "250",
        "0",
        "-300",
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let (s1, _) = crossed(250.0, -300.0);
    let first: Vec<&str> = text.lines().next().unwrap().split_whitespace().collect();
    assert_eq!(first[0], "s1");
    assert!(
        (first[1].parse::<f64>().unwrap() - s1).abs() < 1e-6,
        "{text}"
    );
}

#[test]
fn kins_errors_are_json_with_a_failing_status() {
    for (args, needle) in [
        (vec!["--json", "inverse", "250", "0", "-500"], "unreachable"),
        (vec!["--json", "inverse", "250", "zero", "-300"], "\"zero\""),
        (vec!["--json", "inverse", "250", "0"], "takes 3 values"),
        (vec!["--json", "forward", "1", "2"], "takes 3 joint values"),
        (vec!["--json", "inverse", "0", "0", "-300"], "axis X"),
        (vec!["--json", "forward", "600", "100", "0"], "joint s1"),
    ] {
        let mut all = vec!["kins", "--machine", "oxglide-x"];
        all.extend(args.iter());
        let out = kerf(&all);
        assert!(!out.status.success(), "{all:?} succeeded");
        let message = json_of(&out)["error"].as_str().unwrap().to_string();
        assert!(message.contains(needle), "{all:?}: {message}");
    }
    // Without --json the message goes to stderr, naming the machine.
    let out = kerf(&["kins", "--machine", "nosuch", "inverse", "1", "2", "3"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown machine \"nosuch\""));
}

#[test]
fn workspace_prints_the_rectangle_and_draws_it() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("ox.svg");
    let out = kerf(&[
        "workspace",
        "--machine",
        "oxglide-x",
        "--plot",
        svg.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("largest inscribed rectangle"))
        .unwrap_or_else(|| panic!("{text}"));
    // "... at x LO .. HI, z LO .. HI": check the corners with the paper.
    let numbers: Vec<f64> = line
        .split([' ', ','])
        .filter_map(|w| w.parse().ok())
        .collect();
    let [w, h, _area, x0, x1, z0, z1] = numbers[..] else {
        panic!("{line}")
    };
    assert!(
        (x1 - x0 - w).abs() < 1e-3 && (z1 - z0 - h).abs() < 1e-3,
        "{line}"
    );
    for (x, z) in [(x0, z0), (x0, z1), (x1, z0), (x1, z1)] {
        // Printed to 1 µm; step that far inside before checking.
        let (x, z) = (
            x + (250.0 - x).signum() * 1e-3,
            z + (-320.0 - z).signum() * 1e-3,
        );
        let (s1, s2) = crossed(x, z);
        assert!(
            (0.0..=500.0).contains(&s1) && (0.0..=500.0).contains(&s2),
            "({x}, {z})"
        );
    }
    assert!(
        w * h > 10_000.0,
        "the paper's crossed workspace holds a far larger box: {line}"
    );
    let drawing = std::fs::read_to_string(&svg).unwrap();
    assert!(drawing.starts_with("<svg") && drawing.trim_end().ends_with("</svg>"));
    assert!(drawing.contains("largest rectangle"));
}

#[test]
fn workspace_of_a_tilting_machine_is_z_against_tilt() {
    let out = kerf(&["workspace", "--machine", "rfmt5"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    // Level, Z spans the 400 mm slider stroke exactly.
    let level: Vec<f64> = text
        .lines()
        .find(|l| l.trim_start().starts_with("0.0 "))
        .unwrap_or_else(|| panic!("{text}"))
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    assert!((level[2] - level[1] - 400.0).abs() < 0.01, "{level:?}");
    assert!(
        text.contains("reachable in every direction up to"),
        "{text}"
    );
}

fn axis(status: &Status, key: &str) -> f64 {
    status.position[key].as_f64().unwrap()
}

/// kerfd starts an O-X glide machine at its home pose (the origin is out of
/// its reach) and runs a program on it; the joints it ends with are the
/// paper's for the last programmed point.
#[test]
fn kerfd_runs_a_program_on_the_crossed_o_x_glide() {
    let kerfd = Kerfd::start(&["--machine", "oxglide-x"]);
    let mut client = kerfd.ready_client();
    let start: Status = serde_json::from_value(client.request(&Request::Status).unwrap()).unwrap();
    assert_eq!(start.machine, "oxglide-x");
    assert_eq!((axis(&start, "x"), axis(&start, "z")), (250.0, -300.0));
    let program = kerfd.program(
        "ox.ngc",
        "G21 G90\nG1 X200 Z-340 F6000\nG1 X260 Y10\nG0 Z-320\nM2\n",
    );
    let reply = client
        .request(&Request::Run {
            path: Some(program.display().to_string()),
            line: None,
        })
        .unwrap();
    let id = reply["program"].as_u64().unwrap() as u32;
    let end = client.wait_job(id, 50.0, |_| {}).unwrap();
    let p = end.program.as_ref().unwrap();
    assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);
    assert_eq!(end.state, MachineState::Idle);
    // The ideal simulated drives sit exactly on the setpoints, and the
    // executor ends on the segment's end point: only rounding remains.
    let (s1, s2) = crossed(260.0, -320.0);
    assert!((end.joints[0] - s1).abs() < 1e-6, "{:?}", end.joints);
    assert!((end.joints[1] - s2).abs() < 1e-6, "{:?}", end.joints);
    assert!((end.joints[2] - 10.0).abs() < 1e-6);
    assert!((axis(&end, "x") - 260.0).abs() < 1e-6 && (axis(&end, "z") + 320.0).abs() < 1e-6);
}
