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
    let id = support::start_program(client, path);
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
        err.contains("syntax.ngc:2:12: X: Multiple x words on one line"),
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
    assert!(String::from_utf8_lossy(&out.stderr).contains("no percent sign or program end"));

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

// ---------------------------------------------------------------------------
// Machine states, motion commands and events through the real socket.

use kerf::protocol::{Event, Execution, Fields, JointRef};

/// Subscribe `client` to status at `rate_hz` (and machine events).
fn subscribe(client: &mut Client, rate_hz: f64) {
    client
        .request(&Command::Subscribe {
            rate_hz: Some(rate_hz),
            fields: Fields::Full,
            events: true,
        })
        .unwrap();
}

/// The next status event, skipping other events.
fn next_status(client: &mut Client) -> Status {
    loop {
        if let Event::Status { status } = client.next_event().unwrap() {
            return status;
        }
    }
}

/// Events until a status satisfies `pred`: the statuses seen, and the
/// reasons given by the state events among them.
fn events_until(c: &mut Client, pred: impl Fn(&Status) -> bool) -> (Vec<Status>, Vec<String>) {
    let (mut statuses, mut reasons) = (Vec::new(), Vec::new());
    loop {
        match c.next_event().unwrap() {
            Event::Status { status } => {
                let done = pred(&status);
                statuses.push(status);
                if done {
                    return (statuses, reasons);
                }
                assert!(
                    statuses.len() < MAX_STATUSES,
                    "no status satisfied the condition in {MAX_STATUSES} events; the last: {:?}",
                    statuses.last()
                );
            }
            Event::State {
                reason: Some(r), ..
            } => reasons.push(r),
            _ => {}
        }
    }
}

/// Status events until `pred` holds; returns every status seen, the last
/// one satisfying `pred`. Fails, showing the last status, if `pred` still
/// does not hold after [`MAX_STATUSES`]: a machine that never gets there
/// is a failure to read, not a test that runs forever.
fn statuses_until(client: &mut Client, pred: impl Fn(&Status) -> bool) -> Vec<Status> {
    events_until(client, pred).0
}

/// Status events a test waits through at most: 5 minutes at 200 Hz, the
/// fastest rate these tests subscribe at (the slow 1 Hz watcher only waits
/// for the machine's next state change).
const MAX_STATUSES: usize = 60_000;

fn code_of(e: ClientError) -> (ErrorCode, String) {
    match e {
        ClientError::Refused { code, message } => (code, message),
        other => panic!("expected a refusal, got {other}"),
    }
}

fn job_ended(s: &Status, id: u32) -> bool {
    s.job
        .as_ref()
        .is_some_and(|j| j.id == id && j.state != ProgramState::Running)
}

#[test]
fn the_power_up_sequence_is_enforced_with_reasons() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.client();
    let mut watcher = kerfd.client();
    watcher
        .request(&Command::Subscribe {
            rate_hz: None,
            fields: Fields::Full,
            events: true,
        })
        .unwrap();
    assert_eq!(status(&mut c).state, MachineState::Estop);
    let program = kerfd.program("p.ngc", "G0 X1\nM2\n");
    let (code, msg) = code_of(c.request(&run_cmd(&program)).unwrap_err());
    assert_eq!(code, ErrorCode::InvalidState);
    assert!(msg.contains("e-stop"), "{msg}");
    let (code, msg) = code_of(c.request(&Command::On).unwrap_err());
    assert_eq!(code, ErrorCode::InvalidState);
    assert!(msg.contains("`reset` first"), "{msg}");
    c.request(&Command::Reset).unwrap();
    assert_eq!(status(&mut c).state, MachineState::EstopReset);
    assert_eq!(
        code_of(c.request(&Command::Reset).unwrap_err()).0,
        ErrorCode::InvalidState
    );
    c.request(&Command::On).unwrap();
    assert_eq!(status(&mut c).state, MachineState::On);
    assert_eq!(
        code_of(c.request(&Command::On).unwrap_err()).1,
        "the machine is already on"
    );
    let (code, msg) = code_of(
        c.request(&Command::Mdi {
            line: "G0 X1".into(),
        })
        .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidState);
    assert_eq!(
        msg,
        "cannot run MDI: joints x, y, z are not homed; `home` first"
    );
    assert_eq!(
        code_of(c.request(&Command::Pause).unwrap_err()).0,
        ErrorCode::InvalidState
    );
    assert_eq!(
        code_of(c.request(&Command::Abort).unwrap_err()).0,
        ErrorCode::InvalidState
    );
    let id = c.request(&Command::Home { joint: None }).unwrap()["home"]
        .as_u64()
        .unwrap() as u32;
    let end = c.wait_job(id, 100.0, |_| {}).unwrap();
    assert_eq!(end.state, MachineState::Idle);
    assert_eq!(end.homed, vec![true, true, true]);
    c.request(&Command::Off).unwrap();
    c.request(&Command::On).unwrap();
    assert_eq!(
        status(&mut c).state,
        MachineState::Idle,
        "homing survives off"
    );
    c.request(&Command::Estop).unwrap();
    assert_eq!(status(&mut c).state, MachineState::Estop);

    // The watcher saw every transition, in order, with reasons.
    let mut states = Vec::new();
    while states.last() != Some(&MachineState::Estop) || states.len() < 2 {
        if let Event::State { state, reason, .. } = watcher.next_event().unwrap() {
            assert!(reason.is_some(), "a state event without a reason");
            states.push(state);
        }
    }
    assert_eq!(
        states,
        vec![
            MachineState::EstopReset,
            MachineState::On,
            MachineState::Homing,
            MachineState::Idle,
            MachineState::EstopReset,
            MachineState::Idle,
            MachineState::Estop
        ]
    );
}

#[test]
fn pause_and_resume_mid_move_keep_the_position_continuous() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program("long.ngc", "G1 X150 F3000\nM2\n");
    subscribe(&mut c, 200.0);
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    let mut seen = statuses_until(&mut c, |s| axis(s, "x") > 30.0);
    c.request(&Command::Pause).unwrap();
    seen.extend(statuses_until(&mut c, |s| {
        s.execution == Some(Execution::Paused) && s.velocity == 0.0
    }));
    let paused = seen.last().unwrap().clone();
    assert_eq!(paused.state, MachineState::Auto);
    let x_paused = axis(&paused, "x");
    assert!(
        x_paused > 30.0 && x_paused < 150.0,
        "stopped on the path: {x_paused}"
    );
    // While paused nothing moves: the next 20 statuses (0.1 s) are identical.
    for _ in 0..20 {
        let s = next_status(&mut c);
        assert_eq!(s.position, paused.position);
        assert_eq!(s.commanded, paused.commanded);
    }
    c.request(&Command::Resume).unwrap();
    seen.extend(statuses_until(&mut c, |s| job_ended(s, id)));
    let end = seen.last().unwrap();
    assert_eq!(end.program.as_ref().unwrap().state, ProgramState::Finished);
    assert!((axis(end, "x") - 150.0).abs() < 1e-9);
    // Continuity: X never goes back, Y and Z never leave the path.
    for w in seen.windows(2) {
        assert!(
            axis(&w[1], "x") >= axis(&w[0], "x"),
            "x went back from {} to {}",
            axis(&w[0], "x"),
            axis(&w[1], "x")
        );
        assert_eq!((axis(&w[1], "y"), axis(&w[1], "z")), (0.0, 0.0));
    }
    // And motion resumed from where it paused: the first sample after the
    // pause that moved starts from x_paused.
    let resumed = seen
        .iter()
        .skip_while(|s| s.execution != Some(Execution::Paused))
        .find(|s| axis(s, "x") > x_paused)
        .unwrap();
    assert!(axis(resumed, "x") > x_paused);
}

/// M0 and M1 stop the program at rest where they are and wait, whatever
/// the time, until `resume`; M1 only while the optional-stop switch is on.
/// The state event says where it stopped and what to do; `abort` from a
/// stop ends the program there.
#[test]
fn program_stops_wait_for_the_operator() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program(
        "stops.ngc",
        "G64 P0.01\nG1 X20 F3000\nM0\nG1 X40\nM1\nG1 X60\nM1\nG1 X80\nM2\n",
    );
    subscribe(&mut c, 200.0);
    assert!(status(&mut c).optional_stop, "on when the daemon starts");
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    let stopped =
        |x: f64| move |s: &Status| s.execution == Some(Execution::Paused) && axis(s, "x") == x;
    let (seen, mut reasons) = events_until(&mut c, stopped(20.0));
    let at = seen.last().unwrap().clone();
    assert_eq!(
        (at.state, at.line, at.velocity),
        (MachineState::Auto, 3, 0.0)
    );
    // It waits: 40 statuses (0.2 s) later nothing has moved.
    let waited = std::cell::Cell::new(0);
    let (seen, more) = events_until(&mut c, |_| {
        waited.set(waited.get() + 1);
        waited.get() == 40
    });
    reasons.extend(more);
    for s in &seen {
        assert_eq!(s.commanded, at.commanded);
        assert_eq!(s.execution, Some(Execution::Paused));
    }
    // The state event (which may come either side of the status that
    // first shows the stop) says where and what to do.
    assert!(
        reasons
            .iter()
            .any(|r| r.contains("program stop") && r.contains("line 3") && r.contains("resume")),
        "{reasons:?}"
    );
    c.request(&Command::Resume).unwrap();
    // The M1 at line 5 stops too: the switch is on.
    let (seen, _) = events_until(&mut c, stopped(40.0));
    assert_eq!(seen.last().unwrap().line, 5);
    assert!(
        seen.iter()
            .all(|s| axis(s, "x") >= 20.0 && axis(s, "x") <= 40.0),
        "went on from the stop to the next"
    );
    let ok = c
        .request(&Command::OptionalStop { enabled: false })
        .unwrap();
    assert_eq!(ok["enabled"], false);
    statuses_until(&mut c, |s| !s.optional_stop);
    c.request(&Command::Resume).unwrap();
    // With the switch off the M1 at line 7 (at X60) passes.
    let (seen, _) = events_until(&mut c, |s| job_ended(s, id));
    let end = seen.last().unwrap();
    assert_eq!(end.program.as_ref().unwrap().state, ProgramState::Finished);
    assert_eq!(axis(end, "x"), 80.0);
    assert!(
        seen.iter()
            .all(|s| s.line != 7 || s.execution != Some(Execution::Paused)),
        "the M1 at line 7 stopped with the switch off"
    );

    // Abort from a stop: the program ends there, aborted, and the machine
    // takes new work.
    let program = kerfd.program("abort.ngc", "G1 X10 F3000\nM0\nG1 X0\nM2\n");
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    events_until(&mut c, stopped(10.0));
    c.request(&Command::Abort).unwrap();
    let end = statuses_until(&mut c, |s| job_ended(s, id)).pop().unwrap();
    assert_eq!(end.state, MachineState::Idle);
    assert_eq!(end.execution, None);
    assert_eq!(end.program.as_ref().unwrap().state, ProgramState::Aborted);
    assert_eq!(axis(&end, "x"), 10.0);
    assert_eq!(
        code_of(c.request(&Command::Resume).unwrap_err()).0,
        ErrorCode::InvalidState
    );
}

#[test]
fn abort_stops_on_the_path_and_the_machine_takes_new_work() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program("long.ngc", "G1 X150 Y75 F3000\nG1 X0\nM2\n");
    subscribe(&mut c, 200.0);
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    statuses_until(&mut c, |s| axis(s, "x") > 20.0);
    assert_eq!(c.request(&Command::Abort).unwrap()["aborted"], id);
    let end = statuses_until(&mut c, |s| job_ended(s, id)).pop().unwrap();
    assert_eq!(end.state, MachineState::Idle);
    assert_eq!(end.job.as_ref().unwrap().state, ProgramState::Aborted);
    assert_eq!(end.program.as_ref().unwrap().state, ProgramState::Aborted);
    let (x, y) = (axis(&end, "x"), axis(&end, "y"));
    // Stopped on the programmed line y = x / 2, short of its end.
    assert!(x > 20.0 && x < 150.0, "{x}");
    assert!((y - x / 2.0).abs() < 1e-9, "left the path: ({x}, {y})");
    assert_eq!(end.velocity, 0.0);
    assert_eq!(next_status(&mut c).position, end.position, "at rest");
    c.request(&Command::Unsubscribe).unwrap();

    // The queue was flushed: an MDI move goes exactly where it says.
    let id = c
        .request(&Command::Mdi {
            line: "G0 X5 Y6".into(),
        })
        .unwrap()["mdi"]
        .as_u64()
        .unwrap() as u32;
    let end = c.wait_job(id, 100.0, |_| {}).unwrap();
    assert_eq!((axis(&end, "x"), axis(&end, "y")), (5.0, 6.0));
    assert_eq!(end.job.unwrap().state, ProgramState::Finished);
}

#[test]
fn mdi_moves_reports_errors_and_shows_operator_messages() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let mut watcher = kerfd.client();
    subscribe(&mut watcher, 1.0);
    let mdi = |c: &mut Client, line: &str| {
        let id = c
            .request(&Command::Mdi { line: line.into() })
            .map(|r| r["mdi"].as_u64().unwrap() as u32)?;
        Ok::<Status, ClientError>(c.wait_job(id, 100.0, |_| {}).unwrap())
    };
    let end = mdi(&mut c, "G0 X10 Y5 Z-2").unwrap();
    assert_eq!(
        (axis(&end, "x"), axis(&end, "y"), axis(&end, "z")),
        (10.0, 5.0, -2.0)
    );
    let (code, msg) = code_of(mdi(&mut c, "G1 X20").unwrap_err());
    assert_eq!(code, ErrorCode::ProgramError);
    assert!(msg.starts_with("MDI:1:1: G1"), "{msg}");
    let (code, msg) = code_of(mdi(&mut c, "G0 Z5").unwrap_err());
    assert_eq!(code, ErrorCode::ProgramError);
    assert!(msg.contains("axis Z"), "{msg}");
    assert_eq!(axis(&status(&mut c), "z"), -2.0, "nothing moved");

    mdi(&mut c, "(MSG, change to the 6 mm cutter) G1 X12 F600").unwrap();
    let text = loop {
        if let Event::Message { text, line } = watcher.next_event().unwrap() {
            assert_eq!(line, 1);
            break text;
        }
    };
    assert_eq!(text, "change to the 6 mm cutter");
}

#[test]
fn jogs_move_by_increments_and_continuously_until_stopped() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let jog = |axis: Option<&str>, joint: Option<JointRef>, dir: i32, distance: Option<f64>| {
        Command::Jog {
            axis: axis.map(str::to_string),
            joint,
            direction: dir,
            speed: 3000.0,
            distance,
        }
    };
    let wait = |c: &mut Client, reply: serde_json::Value| {
        let id = reply["jog"].as_u64().unwrap() as u32;
        c.wait_job(id, 100.0, |_| {}).unwrap()
    };
    let r = c.request(&jog(Some("x"), None, 1, Some(2.5))).unwrap();
    let end = wait(&mut c, r);
    assert_eq!(axis(&end, "x"), 2.5);
    let r = c
        .request(&jog(None, Some(JointRef::Name("z".into())), -1, Some(1.0)))
        .unwrap();
    assert_eq!(axis(&wait(&mut c, r), "z"), -1.0);
    let (code, msg) = code_of(
        c.request(&jog(Some("x"), None, -1, Some(10.0)))
            .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    assert!(msg.contains("axis X") && msg.contains("travel"), "{msg}");
    let (code, _) = code_of(c.request(&jog(Some("q"), None, 1, None)).unwrap_err());
    assert_eq!(code, ErrorCode::InvalidArgument);

    // Continuous: runs until jog_stop, then decelerates to rest.
    subscribe(&mut c, 200.0);
    let id = c.request(&jog(Some("y"), None, 1, None)).unwrap()["jog"]
        .as_u64()
        .unwrap() as u32;
    let moving = statuses_until(&mut c, |s| axis(s, "y") > 10.0)
        .pop()
        .unwrap();
    assert_eq!(moving.state, MachineState::Manual);
    c.request(&Command::JogStop).unwrap();
    let end = statuses_until(&mut c, |s| job_ended(s, id)).pop().unwrap();
    let y = axis(&end, "y");
    assert!(y > 10.0 && y < 200.0, "{y}");
    assert_eq!(end.state, MachineState::Idle);
    assert_eq!(next_status(&mut c).position, end.position);

    // A continuous jog stops when the client that started it disconnects.
    let mut jogger = kerfd.client();
    let id = jogger.request(&jog(Some("x"), None, 1, None)).unwrap()["jog"]
        .as_u64()
        .unwrap() as u32;
    statuses_until(&mut c, |s| axis(s, "x") > 5.0);
    drop(jogger);
    let end = statuses_until(&mut c, |s| job_ended(s, id)).pop().unwrap();
    let job = end.job.as_ref().unwrap();
    assert_eq!(job.state, ProgramState::Aborted);
    assert_eq!(
        job.error.as_deref(),
        Some("jog stopped: the client that started it disconnected")
    );
    assert!(axis(&end, "x") < 300.0);
}

#[test]
fn overrides_scale_the_feed_and_the_rapids() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let set = |c: &mut Client, feed: Option<f64>, rapid: Option<f64>| {
        c.request(&Command::Override {
            feed,
            rapid,
            spindle: None,
        })
        .unwrap();
    };
    // Out of range on purpose, so not through the schema-checking client.
    let mut raw = Client::connect(&kerfd.socket).unwrap();
    assert_eq!(
        code_of(
            raw.request(&Command::Override {
                feed: Some(250.0),
                rapid: None,
                spindle: None,
            })
            .unwrap_err()
        )
        .0,
        ErrorCode::InvalidArgument
    );
    set(&mut c, Some(50.0), Some(50.0));
    subscribe(&mut c, 200.0);
    // 6000 mm/min programmed; 100 mm of travel, ample to cruise.
    let program = kerfd.program("feeds.ngc", "G1 X100 F6000\nG0 X0\nM2\n");
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    let seen = statuses_until(&mut c, |s| axis(s, "x") > 60.0);
    let top = seen.iter().map(|s| s.velocity).fold(0.0, f64::max);
    assert_eq!(seen.last().unwrap().overrides.feed, 50.0);
    // The executor cruises just under its cap (by J·dt²/8, 0.6 mm/min here):
    // the top speed is the override times the feed within 1 mm/min.
    assert!(top <= 3000.0 + 1e-6 && top > 2999.0, "top feed {top}");
    set(&mut c, Some(120.0), None);
    let seen = statuses_until(&mut c, |s| axis(s, "x") >= 99.9);
    let top = seen.iter().map(|s| s.velocity).fold(0.0, f64::max);
    assert!(top <= 7200.0 + 1e-6 && top > 7199.0, "top feed {top}");
    // The rapid back: mill3's X allows 150 mm/s = 9000 mm/min; at 50 % the
    // cap is 4500.
    let seen = statuses_until(&mut c, |s| job_ended(s, id));
    let top = seen.iter().map(|s| s.velocity).fold(0.0, f64::max);
    assert!(top <= 4500.0 + 1e-6 && top > 4499.0, "top rapid {top}");
}

#[test]
fn run_from_a_line_and_single_block_stepping() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program("steps.ngc", "G21 G90 F3000\nG1 X10\nG1 Y10\nG1 X0\nM2\n");
    // From line 3: the modes of lines 1–2 hold (X is 10), the machine goes
    // straight to line 3's end point, then on.
    let reply = c
        .request(&Command::Run {
            path: Some(program.display().to_string()),
            line: Some(3),
        })
        .unwrap();
    let end = c
        .wait_job(reply["program"].as_u64().unwrap() as u32, 100.0, |_| {})
        .unwrap();
    assert_eq!((axis(&end, "x"), axis(&end, "y")), (0.0, 10.0));
    let p = end.program.unwrap();
    assert_eq!((p.start_line, p.state), (3, ProgramState::Finished));
    let (code, msg) = code_of(
        c.request(&Command::Run {
            path: Some(program.display().to_string()),
            line: Some(9),
        })
        .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    assert!(msg.contains("ends on line 5"), "{msg}");

    c.request(&Command::Mdi {
        line: "G0 X0 Y0".into(),
    })
    .unwrap();
    subscribe(&mut c, 200.0);
    statuses_until(&mut c, |s| {
        s.state == MachineState::Idle && axis(s, "y") == 0.0
    });
    c.request(&Command::Open {
        path: program.display().to_string(),
    })
    .unwrap();
    // Step from idle: line 2 runs, then the machine waits.
    c.request(&Command::Step).unwrap();
    let at = |s: &Status, x: f64, y: f64| {
        (axis(s, "x") - x).abs() < 1e-9 && (axis(s, "y") - y).abs() < 1e-9 && s.velocity == 0.0
    };
    let s = statuses_until(&mut c, |s| at(s, 10.0, 0.0)).pop().unwrap();
    assert_eq!(
        (s.state, s.execution),
        (MachineState::Auto, Some(Execution::Stepping))
    );
    for _ in 0..10 {
        assert_eq!(
            axis(&next_status(&mut c), "y"),
            0.0,
            "waits for the next step"
        );
    }
    c.request(&Command::Step).unwrap();
    statuses_until(&mut c, |s| at(s, 10.0, 10.0));
    c.request(&Command::Resume).unwrap();
    let end = statuses_until(&mut c, |s| s.state == MachineState::Idle)
        .pop()
        .unwrap();
    assert_eq!((axis(&end, "x"), axis(&end, "y")), (0.0, 10.0));
}

/// Single block through a loop over one line: each pass is a step, as
/// each block LinuxCNC executes is (told apart by line alone, the first
/// step ran every pass).
#[test]
fn single_block_steps_each_pass_of_a_loop() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program(
        "loop.ngc",
        "G21 G90 F3000\n#1=1\nO1 while [#1 LE 3]\nG1 X[#1*10] Y5\n#1=[#1+1]\nO1 endwhile\nM2\n",
    );
    c.request(&Command::Open {
        path: program.display().to_string(),
    })
    .unwrap();
    subscribe(&mut c, 200.0);
    let at_rest_on = |s: &Status, x: f64| {
        (axis(s, "x") - x).abs() < 1e-9 && (axis(s, "y") - 5.0).abs() < 1e-9 && s.velocity == 0.0
    };
    for x in [10.0, 20.0] {
        c.request(&Command::Step).unwrap();
        let s = statuses_until(&mut c, |s| at_rest_on(s, x)).pop().unwrap();
        assert_eq!(s.line, 4, "every pass is line 4");
        for _ in 0..10 {
            let s = next_status(&mut c);
            assert_eq!(axis(&s, "x"), x, "waits for the next step");
            assert_eq!(s.execution, Some(Execution::Stepping));
        }
    }
    // The third pass, then the program ends (M2 moves nothing).
    c.request(&Command::Step).unwrap();
    let end = statuses_until(&mut c, |s| s.state == MachineState::Idle)
        .pop()
        .unwrap();
    assert_eq!(axis(&end, "x"), 30.0);
}

/// mill3 with a following-error limit on joint x and a simulated jam of
/// that joint at 20 mm.
fn jamming_machine(kerfd_dir: &std::path::Path) -> std::path::PathBuf {
    let mill3 = kerf_machines::EMBEDDED[0].1;
    let text = mill3.replacen(
        "name = \"x\"\naxis = \"x\"",
        "name = \"x\"\naxis = \"x\"\nfollowing_error = 0.5",
        1,
    ) + "\n[hal.sim.jam]\njoint = 0\nat = 20.0\n";
    assert!(text.contains("following_error"));
    let path = kerfd_dir.join("jamming.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_following_error_faults_the_machine_and_every_client_hears_why() {
    let dir = std::sync::Arc::new(tempfile::tempdir().unwrap());
    let machine = jamming_machine(dir.path());
    let kerfd = Kerfd::start_in(dir, &["--machine", machine.to_str().unwrap()], &[]);
    let mut c = kerfd.ready_client();
    let mut watchers: Vec<Client> = (0..3).map(|_| kerfd.client()).collect();
    for (i, w) in watchers.iter_mut().enumerate() {
        // Different kinds of subscription all carry the machine events.
        w.request(&Command::Subscribe {
            rate_hz: [None, Some(5.0), Some(50.0)][i],
            fields: [Fields::Full, Fields::Changed, Fields::Full][i],
            events: true,
        })
        .unwrap();
    }
    let program = kerfd.program("crash.ngc", "G1 X50 F1200\nM2\n");
    let id = c.request(&run_cmd(&program)).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    for w in &mut watchers {
        let reason = loop {
            if let Event::State {
                state: MachineState::Fault,
                previous,
                reason,
                ..
            } = w.next_event().unwrap()
            {
                assert_eq!(previous, MachineState::Auto);
                break reason.unwrap();
            }
        };
        assert!(
            reason.starts_with("following error: joint x is ") && reason.contains("limit 0.5"),
            "{reason}"
        );
    }
    let s = status(&mut c);
    assert_eq!(s.state, MachineState::Fault);
    assert!(s.fault.as_deref().unwrap().contains("following error"));
    // The jammed joint stopped at 20 mm.
    assert_eq!(s.joints[0], 20.0);
    let (code, msg) = code_of(
        c.request(&Command::Mdi {
            line: "G0 Y1".into(),
        })
        .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::Fault);
    assert!(msg.contains("`reset`"), "{msg}");
    // The program ends failed once its queue is discarded.
    let end = c.wait_job(id, 100.0, |_| {}).unwrap();
    let p = end.program.unwrap();
    assert_eq!(p.state, ProgramState::Failed);
    assert!(p
        .error
        .unwrap()
        .starts_with("stopped by fault: following error"));
    // Only the operator clears it; then the machine is off until `on`.
    c.request(&Command::Reset).unwrap();
    assert_eq!(status(&mut c).state, MachineState::EstopReset);
    c.request(&Command::On).unwrap();
    let id = c
        .request(&Command::Mdi {
            line: "G0 Y10".into(),
        })
        .unwrap()["mdi"]
        .as_u64()
        .unwrap() as u32;
    let end = c.wait_job(id, 100.0, |_| {}).unwrap();
    assert_eq!(end.state, MachineState::Idle);
    assert_eq!(axis(&end, "y"), 10.0);
}

#[test]
fn every_command_and_event_matches_the_schema() {
    // Every line of this test goes through the schema-checking client;
    // at the end, each command's result and each event kind must have been
    // checked at least once.
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.client();
    let mut w = kerfd.client();
    w.request(&Command::Subscribe {
        rate_hz: Some(50.0),
        fields: Fields::Changed,
        events: true,
    })
    .unwrap();
    c.request(&Command::Hello).unwrap();
    c.request(&Command::Auth {
        token: "any".into(),
    })
    .unwrap();
    c.request(&Command::Estop).unwrap();
    support::ready(&mut c);
    c.request(&Command::Off).unwrap();
    c.request(&Command::On).unwrap();
    let set = |m: serde_json::Value| m.as_object().unwrap().clone();
    c.request(&Command::SetOffset {
        system: "g59.3".into(),
        values: set(serde_json::json!({"x": 1.5, "Z": -2})),
    })
    .unwrap();
    c.request(&Command::Offsets).unwrap();
    c.request(&Command::SetTool {
        tool: 4,
        pocket: Some(7),
        offsets: Some(set(serde_json::json!({"z": 33.0}))),
        diameter: Some(6.0),
        comment: Some("6 mm end mill".into()),
    })
    .unwrap();
    c.request(&Command::Tools).unwrap();
    c.request(&Command::RemoveTool { tool: 4 }).unwrap();
    c.request(&Command::Override {
        feed: Some(100.0),
        rapid: None,
        spindle: Some(80.0),
    })
    .unwrap();
    let id = c
        .request(&Command::Jog {
            axis: Some("x".into()),
            joint: None,
            direction: 1,
            speed: 600.0,
            distance: None,
        })
        .unwrap()["jog"]
        .as_u64()
        .unwrap() as u32;
    c.request(&Command::JogStop).unwrap();
    c.wait_job(id, 100.0, |_| {}).unwrap();
    let program = kerfd.program(
        "all.ngc",
        "G21 G90\n(MSG, starting)\nG1 X40 F1200\nG1 Y10\nM2\n",
    );
    c.request(&Command::Open {
        path: program.display().to_string(),
    })
    .unwrap();
    let id = c
        .request(&Command::Run {
            path: None,
            line: None,
        })
        .unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    c.request(&Command::Pause).unwrap();
    c.request(&Command::Step).unwrap();
    c.request(&Command::Resume).unwrap();
    c.request(&Command::OptionalStop { enabled: true }).unwrap();
    c.request(&Command::Abort).unwrap();
    c.wait_job(id, 100.0, |_| {}).unwrap();
    let id = c.request(&Command::Step).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    c.request(&Command::Abort).unwrap();
    c.wait_job(id, 100.0, |_| {}).unwrap();
    let id = c
        .request(&Command::Mdi {
            line: "G0 X1".into(),
        })
        .unwrap()["mdi"]
        .as_u64()
        .unwrap() as u32;
    c.wait_job(id, 100.0, |_| {}).unwrap();
    let mut events = std::collections::BTreeSet::new();
    while !["state", "program", "message", "changes"]
        .iter()
        .all(|e| events.contains(*e))
    {
        let e = serde_json::to_value(w.next_event().unwrap()).unwrap();
        events.insert(e["event"].as_str().unwrap().to_string());
    }
    w.request(&Command::Unsubscribe).unwrap();
    c.request(&Command::Status).unwrap();
    // Force control needs a machine with a force controller.
    let cutter = Kerfd::start(&[
        "--machine",
        concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml"),
    ]);
    let mut f = cutter.client();
    let on = f
        .request(&Command::ForceControl {
            enabled: true,
            target_n: Some(250.0),
        })
        .unwrap();
    assert_eq!(on["target_n"], 250.0);
    f.request(&Command::ForceControl {
        enabled: false,
        target_n: None,
    })
    .unwrap();

    let seen = support::schema().seen.lock().unwrap().clone();
    for cmd in kerf::protocol::COMMANDS {
        assert!(
            seen.contains(&format!("result_{cmd}")),
            "no `{cmd}` reply was checked against the schema"
        );
    }
    for e in ["state", "program", "message", "changes", "status"] {
        assert!(
            seen.contains(&format!("event_{e}")),
            "no `{e}` event checked"
        );
    }
}

#[test]
fn the_cli_drives_the_machine_and_prints_for_people_and_scripts() {
    let kerfd = Kerfd::start(&[]);
    let socket = kerfd.socket.to_str().unwrap().to_string();
    let kerf = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_kerf"))
            .args(["--socket", &socket])
            .args(args)
            .stdin(std::process::Stdio::null())
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).to_string(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    // `watch` on a pipe prints one line per change; start it first so it
    // sees the machine come up.
    let mut watch = std::process::Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(["--socket", &socket, "watch", "--rate", "50"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut watched = BufReader::new(watch.stdout.take().unwrap());
    let mut first = String::new();
    watched.read_line(&mut first).unwrap();
    assert!(first.starts_with("estop  line 0"), "{first}");

    for cmd in ["reset", "on", "home"] {
        let (code, _, err) = kerf(&[cmd]);
        assert_eq!(code, Some(0), "{cmd}: {err}");
    }
    let (code, out, err) = kerf(&["mdi", "G0 X10 Y5"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.starts_with("idle  X   10.0000  Y    5.0000"), "{out}");
    let (code, out, _) = kerf(&["jog", "y", "-", "--distance", "2", "--speed", "1200"]);
    assert_eq!(code, Some(0));
    assert!(out.contains("Y    3.0000"), "{out}");
    let (code, _, err) = kerf(&["mdi", "G0 Z5"]);
    assert_eq!(code, Some(1));
    assert!(err.contains("axis Z"), "{err}");
    let (code, out, _) = kerf(&["override", "feed", "120"]);
    assert_eq!((code, out.trim()), (Some(0), "feed override 120 %"));
    let (code, out, _) = kerf(&["--json", "status"]);
    assert_eq!(code, Some(0));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    support::schema().check("status", &v);
    assert_eq!(v["overrides"]["feed"], 120.0);
    assert_eq!(v["position"]["y"], 3.0);

    let (code, _, _) = kerf(&["offsets", "set", "G55", "x=1.25", "z=-3"]);
    assert_eq!(code, Some(0));
    let (_, out, _) = kerf(&["offsets"]);
    assert!(
        out.lines()
            .any(|l| l.starts_with(" G55    X    1.2500  Y    0.0000  Z   -3.0000")),
        "{out}"
    );
    let (code, _, err) = kerf(&["offsets", "set", "G60", "x=1"]);
    assert_eq!(code, Some(1));
    assert!(err.contains("G54 … G59.3"), "{err}");
    let (code, _, _) = kerf(&[
        "tools",
        "set",
        "3",
        "z=42.5",
        "--diameter",
        "3",
        "--comment",
        "drill",
    ]);
    assert_eq!(code, Some(0));
    let (_, out, _) = kerf(&["--json", "tools"]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["tools"][0]["offsets"]["z"], 42.5);
    assert_eq!(v["tools"][0]["comment"], "drill");
    let (_, out, _) = kerf(&["tools"]);
    assert!(
        out.starts_with("T3    P3    X    0.0000  Y    0.0000  Z   42.5000  D3.0000  drill"),
        "{out}"
    );

    let (code, out, _) = kerf(&["estop"]);
    assert_eq!((code, out.trim()), (Some(0), "e-stop"));
    // The watcher followed along and saw the e-stop.
    let mut line = String::new();
    while !line.starts_with("state estop") {
        line.clear();
        watched.read_line(&mut line).unwrap();
    }
    assert!(line.contains("e-stop"), "{line}");
    watch.kill().unwrap();
    watch.wait().unwrap();
}

fn mdi_to_end(c: &mut Client, line: &str) -> Status {
    let id = c
        .request(&Command::Mdi { line: line.into() })
        .unwrap_or_else(|e| panic!("mdi {line:?}: {e}"))["mdi"]
        .as_u64()
        .unwrap() as u32;
    c.wait_job(id, 100.0, |_| {}).unwrap()
}

#[test]
fn work_offsets_move_mdi_and_programs_and_their_changes_persist() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let mut values = serde_json::Map::new();
    values.insert("x".into(), serde_json::json!(7.5));
    c.request(&Command::SetOffset {
        system: "G54".into(),
        values,
    })
    .unwrap();
    let end = mdi_to_end(&mut c, "G54 G0 X10");
    assert_eq!(axis(&end, "x"), 17.5, "X10 in G54 is machine X 10 + 7.5");

    mdi_to_end(&mut c, "G10 L2 P1 X5");
    let offsets = c.request(&Command::Offsets).unwrap();
    assert_eq!(offsets["systems"]["G54"]["x"], 5.0, "{offsets}");
    let end = mdi_to_end(&mut c, "G0 X1");
    assert_eq!(axis(&end, "x"), 6.0, "the new offset applies at once");
    // A refused line (Z5 is beyond the travel) changes no parameter.
    assert!(c
        .request(&Command::Mdi {
            line: "G55 G0 Z5".into()
        })
        .is_err());
    let offsets = c.request(&Command::Offsets).unwrap();
    assert_eq!(offsets["active"], "G54", "{offsets}");

    // A program's G10 L2 and G28.1 come back too.
    let program = kerfd.program("g10.ngc", "G10 L2 P2 Y-3\nG0 X2\nG28.1\nM2\n");
    let end = run_to_end(&mut c, &program);
    assert_eq!(axis(&end, "x"), 7.0);
    let offsets = c.request(&Command::Offsets).unwrap();
    assert_eq!(offsets["systems"]["G55"]["y"], -3.0, "{offsets}");
    assert_eq!(offsets["g28"]["x"], 7.0, "{offsets}");

    // So do tool table entries (G10 L1), into tool.tbl.
    c.request(&Command::SetTool {
        tool: 3,
        pocket: None,
        offsets: None,
        diameter: None,
        comment: Some("probe".into()),
    })
    .unwrap();
    mdi_to_end(&mut c, "G10 L1 P3 Z12.5 R3");
    let tools = c.request(&Command::Tools).unwrap();
    let t3 = &tools["tools"][0];
    assert_eq!(
        (&t3["offsets"]["z"], &t3["diameter"], &t3["comment"]),
        (
            &serde_json::json!(12.5),
            &serde_json::json!(6.0),
            &serde_json::json!("probe")
        ),
        "{tools}"
    );

    let dir = kerfd.dir.clone();
    drop(c);
    drop(kerfd);
    let kerfd = Kerfd::start_in(dir, &[], &[]);
    let mut c = kerfd.ready_client();
    let offsets = c.request(&Command::Offsets).unwrap();
    assert_eq!(offsets["systems"]["G54"]["x"], 5.0, "{offsets}");
    assert_eq!(offsets["systems"]["G55"]["y"], -3.0, "{offsets}");
    let end = mdi_to_end(&mut c, "G0 X0");
    assert_eq!(
        axis(&end, "x"),
        5.0,
        "the kept offset applies after a restart"
    );
}

#[test]
fn mdi_keeps_the_modal_state_until_a_run_or_reset() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let x0 = axis(&status(&mut c), "x");
    mdi_to_end(&mut c, "G91");
    mdi_to_end(&mut c, "G0 X1");
    let end = mdi_to_end(&mut c, "G0 X1");
    assert_eq!(axis(&end, "x"), x0 + 2.0, "G91 held for both moves");

    // Units, the feed rate, G1 and the coordinate system carry over too.
    let mut values = serde_json::Map::new();
    values.insert("y".into(), serde_json::json!(2.0));
    c.request(&Command::SetOffset {
        system: "G55".into(),
        values,
    })
    .unwrap();
    mdi_to_end(&mut c, "G90 G20 G55");
    mdi_to_end(&mut c, "G1 F100 X0.5");
    let end = mdi_to_end(&mut c, "Y1");
    assert!((axis(&end, "x") - 12.7).abs() < 1e-9, "{end:?}");
    assert!((axis(&end, "y") - 27.4).abs() < 1e-9, "{end:?}");
    let offsets = c.request(&Command::Offsets).unwrap();
    assert_eq!(offsets["active"], "G55", "{offsets}");

    // A reset starts afresh (mm, absolute); the coordinate system is a
    // parameter and stays, as in LinuxCNC.
    c.request(&Command::Estop).unwrap();
    support::ready(&mut c);
    let end = mdi_to_end(&mut c, "G0 X3");
    assert_eq!(axis(&end, "x"), 3.0);
}

#[test]
fn the_spindle_override_is_set_shown_and_checked() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    assert_eq!(status(&mut c).overrides.spindle, 100.0);
    let reply = c
        .request(&Command::Override {
            feed: None,
            rapid: None,
            spindle: Some(80.0),
        })
        .unwrap();
    assert_eq!(reply["spindle"], 80.0);
    let seen = loop {
        let s = status(&mut c);
        if s.overrides.spindle != 100.0 {
            break s;
        }
    };
    assert_eq!(seen.overrides.spindle, 80.0);
    assert_eq!(seen.overrides.feed, 100.0, "the feed override is untouched");
    // Out of range on purpose, so not through the schema-checking client.
    let mut raw = Client::connect(&kerfd.socket).unwrap();
    let (code, msg) = code_of(
        raw.request(&Command::Override {
            feed: None,
            rapid: None,
            spindle: Some(201.0),
        })
        .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    assert!(msg.contains("spindle override 201"), "{msg}");

    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args([
            "--socket",
            kerfd.socket.to_str().unwrap(),
            "override",
            "spindle",
            "50",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let seen = loop {
        let s = status(&mut c);
        if s.overrides.spindle != 80.0 {
            break s;
        }
    };
    assert_eq!(seen.overrides.spindle, 50.0);
}

#[test]
fn the_tool_m6_loads_stays_in_the_spindle_for_later_lines() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let mut offsets = serde_json::Map::new();
    offsets.insert("z".into(), serde_json::json!(-1.5));
    c.request(&Command::SetTool {
        tool: 2,
        pocket: None,
        offsets: Some(offsets),
        diameter: None,
        comment: None,
    })
    .unwrap();
    mdi_to_end(&mut c, "T2 M6");
    let end = mdi_to_end(&mut c, "G43 G0 Z0");
    assert_eq!(axis(&end, "z"), -1.5, "G43 takes tool 2's length");
    // A program starts with it loaded too.
    let program = kerfd.program("g43.ngc", "G43\nG0 Z-0.25\nM2\n");
    let end = run_to_end(&mut c, &program);
    assert_eq!(axis(&end, "z"), -1.75);
    mdi_to_end(&mut c, "G49 G0 Z0");
    assert_eq!(axis(&status(&mut c), "z"), 0.0, "G49 cancels it");
}
