//! The servo through the real daemon: a cut with force control switched on
//! over the socket on a virtual clock, the force-control command's errors,
//! and the wake-up latency figures of a wall-clock servo.

mod support;

use kerf::client::{Client, ClientError};
use kerf::protocol::{Command, ErrorCode, Event, Execution, ProgramState, Status};
use kerf_io::sim::cutting::CuttingConfig;
use support::{axis, status, Kerfd};

const ALUMINIUM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");

/// Follow status events until `done` says so.
fn follow(client: &mut Client, mut done: impl FnMut(&Status) -> bool) -> Status {
    client
        .request(&Command::Subscribe {
            rate_hz: Some(50.0),
            fields: Default::default(),
            events: false,
        })
        .unwrap();
    loop {
        if let Event::Status { status } = client.next_event().unwrap() {
            if done(&status) {
                client.request(&Command::Unsubscribe).unwrap();
                return status;
            }
        }
    }
}

/// Follow status until program `id` no longer runs; its last status.
fn follow_to_end(client: &mut Client, id: u32) -> Status {
    follow(client, |s| {
        s.program
            .as_ref()
            .is_some_and(|p| p.id == id && p.state != ProgramState::Running)
    })
}

fn refusal(e: ClientError) -> (ErrorCode, String) {
    match e {
        ClientError::Refused { code, message } => (code, message),
        other => panic!("expected a refusal, got {other}"),
    }
}

#[test]
fn virtual_clock_cut_with_force_control_from_the_socket() {
    let kerfd = Kerfd::start(&["--virtual-clock", "--machine", ALUMINIUM]);
    let mut client = kerfd.ready_client();
    let start = status(&mut client);
    assert_eq!(start.servo.clock, "virtual");
    assert_eq!(
        start.servo.latency.samples, 0,
        "nothing to measure on a virtual clock"
    );
    let force = start.force.unwrap();
    assert!(!force.enabled && force.target_n.is_none());

    // Off → on needs a target (the machine configures none).
    let (code, message) = refusal(
        client
            .request(&Command::ForceControl {
                enabled: true,
                target_n: None,
            })
            .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    assert!(message.contains("target_n"), "{message}");
    let (code, _) = refusal(
        client
            .request(&Command::ForceControl {
                enabled: true,
                target_n: Some(-5.0),
            })
            .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    let reply = client
        .request(&Command::ForceControl {
            enabled: true,
            target_n: Some(250.0),
        })
        .unwrap();
    assert_eq!(reply["target_n"], 250.0);
    let on = follow(&mut client, |s| s.force.is_some_and(|f| f.enabled));
    assert_eq!(on.force.unwrap().target_n, Some(250.0));

    // examples/aluminium-step.ngc's slot, ended 4 mm deep inside the block
    // (at X 60; the block's step is at X 40, its far edge at X 70). Leaving
    // over the edge at full feed, the override would take one more step on
    // the revolution that straddles it, by however much of it was cut; a
    // stop in the material is held (the machine changed speed there).
    let text = "G21 G90\nG0 X0 Y50\nG0 Z-2\nG1 X60 F300\nG0 Z0\nM2\n";
    let program = kerfd.program("cut.ngc", text);
    let id = support::start_program(&mut client, &program);
    let end = follow_to_end(&mut client, id);
    let p = end.program.as_ref().unwrap();
    assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);
    // The slot ended 4 mm deep at 300 mm/min programmed; the force is
    // proportional to the feed, so holding 250 N takes the override
    // 250 N / F(300 mm/min, 4 mm), with F from the process model.
    let hal: kerf_io::HalConfig = kerf_machines::load(ALUMINIUM)
        .unwrap()
        .description
        .hal
        .try_into()
        .unwrap();
    let cut: CuttingConfig = hal.sim.cutting.unwrap();
    let want = 250.0 / cut.force(300.0 / 2000.0, 4.0, 1.0);
    let got = end.force.unwrap().feed_override;
    assert!(
        (got - want).abs() < 0.05 * want,
        "override {got}, want {want}"
    );
    // Off again: the controller lets go of the feed.
    client
        .request(&Command::ForceControl {
            enabled: false,
            target_n: None,
        })
        .unwrap();
    let off = follow(&mut client, |s| s.force.is_some_and(|f| !f.enabled));
    assert_eq!(off.force.unwrap().feed_override, 1.0);
}

#[test]
fn force_control_on_a_machine_without_a_controller_is_refused() {
    let kerfd = Kerfd::start(&["--virtual-clock"]);
    let mut client = Client::connect(&kerfd.socket).unwrap();
    assert!(status(&mut client).force.is_none());
    let (code, message) = refusal(
        client
            .request(&Command::ForceControl {
                enabled: true,
                target_n: Some(100.0),
            })
            .unwrap_err(),
    );
    assert_eq!(code, ErrorCode::InvalidArgument);
    assert!(
        message.contains("mill3 has no force controller"),
        "{message}"
    );
}

#[test]
fn wall_clock_status_reports_wake_up_latency() {
    // The figures depend on this machine's load: they are reported, and
    // only their consistency is checked here.
    let kerfd = Kerfd::start(&[]);
    let mut client = Client::connect(&kerfd.socket).unwrap();
    let s = follow(&mut client, |s| s.servo.latency.samples > 0);
    assert_eq!(s.servo.clock, "wall");
    let l = s.servo.latency;
    assert!(
        l.min_us <= l.median_us
            && l.median_us <= l.p99_us
            && l.p99_us <= l.p999_us
            && l.p999_us <= l.max_us,
        "{l:?}"
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args([
            "--socket",
            kerfd.socket.to_str().unwrap(),
            "status",
            "--latency",
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("latency   min") && text.contains("p99.9"),
        "{text}"
    );
    assert!(text.contains("realtime  SCHED_FIFO"), "{text}");
}

/// Status round trips after the servo came to rest waiting on the
/// operator: the tick count must stay put (the servo settles for at most
/// 200 ticks, then waits) however long they take.
fn assert_time_stands_still(client: &mut Client, rest: &Status, what: &str) {
    let ticks: Vec<u64> = (0..100).map(|_| status(client).servo.ticks).collect();
    assert!(
        ticks[99] <= rest.servo.ticks + 250,
        "virtual time ran on {what}: {} -> {} ticks",
        rest.servo.ticks,
        ticks[99]
    );
}

/// On a virtual clock, time stands still while motion waits on the
/// operator — at a program stop (M0), at a 0 % feed override, under feed
/// hold, between single blocks — as it does at idle: what the machine does next must not depend
/// on how long the operator took. Each time, going on finishes the program
/// where it should.
#[test]
fn virtual_time_stands_still_while_the_operator_decides() {
    let kerfd = Kerfd::start(&["--virtual-clock"]);
    let mut client = kerfd.ready_client();
    let program = kerfd.program("stop.ngc", "G21 G90\nG1 X10 F3000\nM0\nG1 X20\nM2\n");
    let id = support::start_program(&mut client, &program);
    let paused = follow(&mut client, |s| s.execution == Some(Execution::Paused));
    assert_eq!(paused.position["x"], 10.0);
    assert_time_stands_still(&mut client, &paused, "at a program stop");
    client.request(&Command::Resume).unwrap();
    let end = follow_to_end(&mut client, id);
    assert_eq!(end.program.unwrap().state, ProgramState::Finished);
    assert_eq!(end.position["x"], 20.0);

    // Feed hold, then single block. The feed override is at 0 % until
    // the hold is on: on a virtual clock the machine would otherwise
    // finish the move before a client could send `pause`.
    let program = kerfd.program("long.ngc", "G21 G90\nG1 X100 F600\nG1 Y10\nG1 Y20\nM2\n");
    let feed = |percent: f64| Command::Override {
        feed: Some(percent),
        rapid: None,
        spindle: None,
    };
    client.request(&feed(0.0)).unwrap();
    let id = support::start_program(&mut client, &program);
    let waiting = follow(&mut client, |s| {
        s.execution == Some(Execution::Running) && s.velocity == 0.0
    });
    assert_time_stands_still(&mut client, &waiting, "at a 0 % feed override");
    client.request(&Command::Pause).unwrap();
    client.request(&feed(100.0)).unwrap();
    let held = follow(&mut client, |s| {
        s.execution == Some(Execution::Paused) && s.velocity == 0.0
    });
    assert_eq!(axis(&held, "x"), 20.0, "held where the last program ended");
    assert_time_stands_still(&mut client, &held, "under feed hold");
    // `step` resumes in single-block mode: line 2 ends — where the
    // corner's blend into Y10 begins, within the default G64 tolerance of
    // X100 — and the machine waits there, showing line 3 as the next.
    client.request(&Command::Step).unwrap();
    let block = follow(&mut client, |s| axis(s, "x") > 99.9 && s.velocity == 0.0);
    assert_eq!(block.execution, Some(Execution::Stepping));
    assert_eq!((block.line, axis(&block, "y")), (3, 0.0));
    assert_time_stands_still(&mut client, &block, "between single blocks");
    client.request(&Command::Resume).unwrap();
    let end = follow_to_end(&mut client, id);
    assert_eq!(axis(&end, "y"), 20.0);
    assert_eq!(end.program.unwrap().state, ProgramState::Finished);
}

/// Single-block stepping from idle on a virtual clock, through the daemon:
/// each step runs one line and waits, with time standing still; `resume`
/// finishes the program. (`step` reaches the servo before the planner's
/// first segments; `tests/servo_control.rs` checks the servo on its own
/// with the segments arriving only after its settling ticks, which the
/// daemon here does not reliably reproduce.)
#[test]
fn stepping_from_idle_on_a_virtual_clock() {
    let kerfd = Kerfd::start(&["--virtual-clock"]);
    let mut client = kerfd.ready_client();
    let program = kerfd.program("steps.ngc", "G21 G90\nG1 X10 F3000\nG1 Y10\nG1 X0\nM2\n");
    client
        .request(&Command::Open {
            path: program.display().to_string(),
        })
        .unwrap();
    let id = client.request(&Command::Step).unwrap()["program"]
        .as_u64()
        .unwrap() as u32;
    let at =
        |s: &Status, x: f64, y: f64| axis(s, "x") == x && axis(s, "y") == y && s.velocity == 0.0;
    let first = follow(&mut client, |s| at(s, 10.0, 0.0));
    assert_eq!(first.execution, Some(Execution::Stepping));
    assert_time_stands_still(&mut client, &first, "after the first step");
    client.request(&Command::Step).unwrap();
    let second = follow(&mut client, |s| at(s, 10.0, 10.0));
    assert_time_stands_still(&mut client, &second, "after the second step");
    client.request(&Command::Resume).unwrap();
    let end = follow_to_end(&mut client, id);
    assert_eq!((axis(&end, "x"), axis(&end, "y")), (0.0, 10.0));
    assert_eq!(end.program.unwrap().state, ProgramState::Finished);
}
