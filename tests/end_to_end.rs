//! End to end through the real daemon binary and its socket, in simulation.

mod support;

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;

use kerf::client::{Client, ClientError};
use kerf::protocol::{Command, ErrorCode, MachineState, ProgramState, Status};
use support::{axis, status, Kerfd};

fn run_cmd(path: &std::path::Path) -> Command {
    Command::Run {
        path: Some(path.display().to_string()),
        line: None,
    }
}

/// Run a program and follow status events until it is no longer running.
fn run_to_end(client: &mut Client, path: &std::path::Path) -> Status {
    let reply = client.request(&run_cmd(path)).unwrap();
    let id = reply["program"].as_u64().unwrap() as u32;
    client.wait_job(id, 50.0, |_| {}).unwrap()
}

#[test]
fn inch_and_incremental_program_ends_at_the_computed_position() {
    let kerfd = Kerfd::start(&[]);
    let program = kerfd.program(
        "inch.ngc",
        "(G20 and G91 through the whole stack)\n\
         G21 G90 G0 X10 Y10 Z-5\n\
         G20 G91\n\
         G1 X1 Y0.5 F40\n\
         G1 Z-0.25\n\
         G0 X-0.5 Y1\n\
         G21 G90 G1 X12.5 F600\n\
         G91 G1 Y0.25\n\
         M2\n",
    );
    // Independent expectation: 1 in = 25.4 mm.
    // X: 10 + 25.4 - 12.7 = 22.7, then absolute 12.5.
    // Y: 10 + 12.7 + 25.4 = 48.1, then + 0.25 mm = 48.35.
    // Z: -5 - 6.35 = -11.35.
    let mut client = kerfd.ready_client();
    let end = run_to_end(&mut client, &program);
    let p = end.program.as_ref().unwrap();
    assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);
    assert_eq!(end.state, MachineState::Idle);
    // 1 µm: the executor ends every segment exactly on its end point; the
    // only error is floating-point rounding of the inch conversion.
    for (key, want) in [("x", 12.5), ("y", 48.35), ("z", -11.35)] {
        let got = axis(&end, key);
        assert!((got - want).abs() < 1e-3, "{key}: got {got}, want {want}");
    }
    let again = status(&mut client);
    assert_eq!(again.state, MachineState::Idle);
    assert_eq!(again.line, 9, "the program ended on line 9 (M2)");
}

#[test]
fn a_program_outside_the_travel_is_refused_and_nothing_moves() {
    let kerfd = Kerfd::start(&[]);
    let mut client = kerfd.ready_client();
    let ok = kerfd.program("ok.ngc", "G0 X5 Y6 Z-7\nM2\n");
    run_to_end(&mut client, &ok);
    let before = status(&mut client);

    let bad = kerfd.program("bad.ngc", "G0 X20\nG1 Y10 F100\nG1 Z-150\nM2\n");
    let err = client.request(&run_cmd(&bad)).unwrap_err();
    match err {
        ClientError::Refused { code, message } => {
            assert_eq!(code, ErrorCode::ProgramError);
            assert!(message.contains("bad.ngc:3"), "{message}");
            assert!(message.contains("axis Z"), "{message}");
        }
        other => panic!("expected a refusal, got {other}"),
    }
    let after = status(&mut client);
    assert_eq!(after.position, before.position);
    assert_eq!(after.state, MachineState::Idle);

    let syntax = kerfd.program("syntax.ngc", "G0 X1\nG1 X2 F100 X3\nM2\n");
    let err = client.request(&run_cmd(&syntax)).unwrap_err().to_string();
    assert!(
        err.contains("syntax.ngc:2:12: X: axis word repeated"),
        "{err}"
    );
}

#[test]
fn garbage_gets_an_error_and_the_connection_stays_usable() {
    let kerfd = Kerfd::start(&[]);
    let mut stream = UnixStream::connect(&kerfd.socket).unwrap();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut long = vec![b'x'; (1 << 20) + 10];
    long.push(b'\n');
    stream.write_all(b"\xff\xfe garbage\n").unwrap();
    stream.write_all(&long).unwrap();
    stream
        .write_all(b"{\"id\": 7, \"cmd\": \"launch\"}\n")
        .unwrap();
    stream
        .write_all(b"{\"id\": 8, \"cmd\": \"hello\"}\n")
        .unwrap();
    let mut replies = Vec::new();
    for _ in 0..4 {
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        support::schema().check_server_line(&line, Some("hello"));
        replies.push(serde_json::from_str::<serde_json::Value>(&line).unwrap());
    }
    assert_eq!(replies[0]["error"]["code"], "parse_error");
    assert_eq!(replies[1]["error"]["code"], "line_too_long");
    assert_eq!(replies[2]["id"], 7);
    assert_eq!(replies[2]["error"]["code"], "unknown_command");
    assert_eq!(replies[3]["id"], 8);
    assert_eq!(replies[3]["ok"]["machine"], "mill3");
}

#[test]
fn the_cli_runs_a_program_and_reports_status() {
    let kerfd = Kerfd::start(&[]);
    let program = kerfd.program("cli.ngc", "G21 G90\nG1 X3 Y4 F3000\nM30\n");
    let kerf = env!("CARGO_BIN_EXE_kerf");
    let cli = |args: &[&str]| {
        std::process::Command::new(kerf)
            .args(args)
            .args(["--socket", kerfd.socket.to_str().unwrap()])
            .output()
            .unwrap()
    };
    // A fresh daemon is in e-stop: `kerf run` says what to do.
    let out = cli(&["run", program.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("e-stop") && err.contains("`reset`"), "{err}");
    for step in [["reset"], ["on"], ["home"]] {
        let out = cli(&step);
        assert!(
            out.status.success(),
            "{step:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let out = std::process::Command::new(kerf)
        .args([
            "run",
            program.to_str().unwrap(),
            "--socket",
            kerfd.socket.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("program finished"));

    let out = std::process::Command::new(kerf)
        .args([
            "--socket",
            kerfd.socket.to_str().unwrap(),
            "status",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["state"], "idle");
    assert!((json["position"]["x"].as_f64().unwrap() - 3.0).abs() < 1e-9);
    assert!((json["position"]["y"].as_f64().unwrap() - 4.0).abs() < 1e-9);

    let bad = kerfd.program("bad.ngc", "G1 X3 F100\n");
    let out = std::process::Command::new(kerf)
        .args([
            "run",
            bad.to_str().unwrap(),
            "--socket",
            kerfd.socket.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no program end"));

    let out = std::process::Command::new(kerf)
        .args([
            "status",
            "--socket",
            kerfd.dir.path().join("none.sock").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("is kerfd running?"));
}

#[test]
fn a_second_daemon_on_the_same_socket_is_refused() {
    let kerfd = Kerfd::start(&[]);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kerfd"))
        .args(["--socket", kerfd.socket.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("already listening"));
}
