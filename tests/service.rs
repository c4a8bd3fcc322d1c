//! kerfd as a service: configuration, TCP with a bearer token, persistence
//! across kill -9, SIGTERM during motion, and systemd notifications.

mod support;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::os::unix::net::{UnixDatagram, UnixStream};
use std::sync::Arc;

use kerf::protocol::{Command, MachineState};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use serde_json::{json, Value};
use support::{axis, Kerfd};

fn kerfd_output(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_kerfd"))
        .args(args)
        .env_remove("NOTIFY_SOCKET")
        .output()
        .unwrap()
}

#[test]
fn configuration_errors_name_the_file_the_key_and_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("kerf.toml");
    let socket = dir.path().join("s.sock");
    let socket = socket.to_str().unwrap();
    let cases = [
        (
            "[servo]\nperiod_us = 5\n",
            "key `servo.period_us`: 5 µs is out of range",
        ),
        (
            "[tcp]\nlisten = \"0.0.0.0:7477\"\n",
            "key `tcp.listen`: 0.0.0.0:7477 is reachable",
        ),
        (
            "[socket]\ngroup = \"no-such-group-kerf\"\n",
            "socket group \"no-such-group-kerf\" does not exist",
        ),
        ("machine = \"nosuch\"\n", "unknown machine \"nosuch\""),
        ("[servo]\nperiod = 1000\n", "unknown field `period`"),
    ];
    for (text, want) in cases {
        std::fs::write(&config, text).unwrap();
        let out = kerfd_output(&[
            "--config",
            config.to_str().unwrap(),
            "--socket",
            socket,
            "--state-dir",
            dir.path().join("state").to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{text}: started anyway");
        assert!(err.contains(want), "{text}: {err}");
        if !want.contains("group") && !want.contains("machine") {
            assert!(err.contains(config.to_str().unwrap()), "{text}: {err}");
        }
    }
    // A state directory that cannot be created is named.
    let out = kerfd_output(&["--socket", socket, "--state-dir", "/proc/kerf-state"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("state directory /proc/kerf-state"));
}

fn tcp_request(stream: &mut TcpStream, reader: &mut BufReader<TcpStream>, request: Value) -> Value {
    let mut line = request.to_string();
    line.push('\n');
    stream.write_all(line.as_bytes()).unwrap();
    let mut reply = String::new();
    reader.read_line(&mut reply).unwrap();
    support::schema().check_server_line(&reply, request["cmd"].as_str());
    serde_json::from_str(&reply).unwrap()
}

#[test]
fn tcp_clients_must_present_the_token() {
    let dir = Arc::new(tempfile::tempdir().unwrap());
    let config = dir.path().join("kerf.toml");
    std::fs::write(
        &config,
        "[tcp]\nlisten = \"127.0.0.1:0\"\ntoken = \"correct-horse-battery-staple\"\n",
    )
    .unwrap();
    let kerfd = Kerfd::start_in(dir.clone(), &["--config", config.to_str().unwrap()], &[]);
    let address = kerfd
        .startup_log
        .lines()
        .find(|l| l.contains("listening on TCP"))
        .and_then(|l| l.split("address=").nth(1))
        .and_then(|a| a.split_whitespace().next())
        .expect("kerfd logs its TCP address")
        .to_string();
    let mut stream = TcpStream::connect(&address).unwrap();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let hello = tcp_request(&mut stream, &mut reader, json!({"id": 1, "cmd": "hello"}));
    assert_eq!(hello["ok"]["auth_required"], true);
    let r = tcp_request(&mut stream, &mut reader, json!({"id": 2, "cmd": "status"}));
    assert_eq!(r["error"]["code"], "unauthorized");
    let r = tcp_request(
        &mut stream,
        &mut reader,
        json!({"id": 3, "cmd": "auth", "token": "correct-horse-battery-stapler"}),
    );
    assert_eq!(r["error"]["code"], "unauthorized");
    let r = tcp_request(
        &mut stream,
        &mut reader,
        json!({"id": 4, "cmd": "auth", "token": "correct-horse-battery-staple"}),
    );
    assert_eq!(r["ok"], json!({}));
    let r = tcp_request(&mut stream, &mut reader, json!({"id": 5, "cmd": "status"}));
    assert_eq!(r["ok"]["state"], "estop");
    // The Unix socket needs no token: its file permissions guard it.
    let mut unix = kerfd.client();
    assert_eq!(
        unix.request(&Command::Hello).unwrap()["auth_required"],
        false
    );
}

/// Pipeline `count` offset and tool writes; kill -9 kerfd right after the
/// `kill_after`-th acknowledgement. Returns the highest acknowledged value
/// written to G54 X and to tool 1's Z.
fn write_until_killed(kerfd: &mut Kerfd, base: u64, count: u64, kill_after: u64) -> (u64, u64) {
    let stream = UnixStream::connect(&kerfd.socket).unwrap();
    let mut writer = stream.try_clone().unwrap();
    let sender = std::thread::spawn(move || {
        for i in base..base + count {
            let request = if i % 2 == 0 {
                json!({"id": i, "cmd": "set_offset", "system": "G54", "values": {"x": i}})
            } else {
                json!({"id": i, "cmd": "set_tool", "tool": 1, "offsets": {"z": i}})
            };
            if writer.write_all(format!("{request}\n").as_bytes()).is_err() {
                break; // kerfd is gone
            }
        }
    });
    let mut reader = BufReader::new(stream);
    let (mut acked_offset, mut acked_tool) = (0, 0);
    let mut acks = 0;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 {
            break;
        }
        let reply: Value = serde_json::from_str(&line).unwrap();
        assert!(reply.get("ok").is_some(), "{line}");
        let i = reply["id"].as_u64().unwrap();
        if i.is_multiple_of(2) {
            acked_offset = i;
        } else {
            acked_tool = i;
        }
        acks += 1;
        if acks == kill_after {
            // Mid-stream: the next writes are in flight.
            kerfd.child.kill().unwrap();
            kerfd.child.wait().unwrap();
        }
    }
    sender.join().unwrap();
    (acked_offset, acked_tool)
}

#[test]
fn kill_9_at_any_moment_loses_no_acknowledged_offset_or_tool() {
    let dir = Arc::new(tempfile::tempdir().unwrap());
    // Seeded so a failure can be replayed; the kill lands wherever the
    // daemon is at that ack, mid-write or not.
    let mut rng = fastrand::Rng::with_seed(0x6b65_7266);
    let mut floor = (0, 0);
    for round in 0..4u64 {
        let mut kerfd = Kerfd::start_in(dir.clone(), &[], &[]);
        // What the previous round acknowledged is still there.
        let mut c = kerfd.client();
        let offsets = c.request(&Command::Offsets).unwrap();
        let x = offsets["systems"]["G54"]["x"].as_f64().unwrap() as u64;
        let tools = c.request(&Command::Tools).unwrap();
        let z = tools["tools"]
            .as_array()
            .unwrap()
            .first()
            .map(|t| t["offsets"]["z"].as_f64().unwrap() as u64)
            .unwrap_or(0);
        assert!(
            x >= floor.0 && z >= floor.1,
            "round {round}: acknowledged G54 X {} and tool Z {} but found {x} and {z}",
            floor.0,
            floor.1
        );
        drop(c);
        let base = 1000 * (round + 1);
        let kill_after = rng.u64(5..150);
        floor = write_until_killed(&mut kerfd, base, 400, kill_after);
        assert!(floor.0 >= base && floor.1 >= base, "acks were counted");
    }
    // Files on disk are whole and parse; the backup too.
    let state = dir.path().join("state");
    for f in ["kerf.var", "tool.tbl", "kerf.var.bak", "tool.tbl.bak"] {
        assert!(state.join(f).exists(), "{f} missing");
    }
    kerf::state::Store::open(&state).expect("the state directory loads");
}

#[test]
fn sigterm_stops_motion_persists_and_exits_cleanly() {
    let mut kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    c.request(&Command::SetOffset {
        system: "G55".into(),
        values: json!({"y": 12.5}).as_object().unwrap().clone(),
    })
    .unwrap();
    let program = kerfd.program("long.ngc", "G1 X250 F6000\nM2\n");
    c.request(&Command::Run {
        path: Some(program.display().to_string()),
        line: None,
    })
    .unwrap();
    c.request(&Command::Subscribe {
        rate_hz: Some(100.0),
        fields: kerf::protocol::Fields::Full,
        events: false,
    })
    .unwrap();
    loop {
        if let kerf::protocol::Event::Status { status } = c.next_event().unwrap() {
            if axis(&status, "x") > 20.0 {
                break;
            }
        }
    }
    kill(Pid::from_raw(kerfd.child.id() as i32), Signal::SIGTERM).unwrap();
    let stopped = kerfd.wait_log("motion stopped on the path");
    assert!(stopped.contains("state written"), "{stopped}");
    let status = kerfd.child.wait().unwrap();
    assert!(status.success(), "exit status {status}");
    assert!(!kerfd.socket.exists(), "the socket file is removed");
    let var = std::fs::read_to_string(kerfd.dir.path().join("state/kerf.var")).unwrap();
    assert!(var.contains("5242\t12.500000"), "G55 Y persisted:\n{var}");
}

#[test]
fn systemd_hears_ready_watchdog_status_and_stopping() {
    let dir = Arc::new(tempfile::tempdir().unwrap());
    let notify_path = dir.path().join("notify.sock");
    let notify = UnixDatagram::bind(&notify_path).unwrap();
    let mut kerfd = Kerfd::start_in(
        dir.clone(),
        &[],
        &[
            ("NOTIFY_SOCKET", notify_path.to_str().unwrap()),
            // 100 ms: kerfd pings every 50 ms.
            ("WATCHDOG_USEC", "100000"),
        ],
    );
    let mut buf = [0u8; 4096];
    let mut recv = || {
        let n = notify.recv(&mut buf).unwrap();
        String::from_utf8_lossy(&buf[..n]).to_string()
    };
    let first = recv();
    assert!(first.contains("READY=1\n"), "{first}");
    assert!(first.contains("STATUS=machine mill3"), "{first}");
    let mut pings = 0;
    while pings < 3 {
        let m = recv();
        if m == "WATCHDOG=1\n" {
            pings += 1;
        }
    }
    let mut c = kerfd.client();
    assert_eq!(c.status().unwrap().state, MachineState::Estop);
    // State changes update the status line.
    c.request(&Command::Reset).unwrap();
    loop {
        let m = recv();
        if m.starts_with("STATUS=") {
            assert_eq!(m, "STATUS=estop_reset: e-stop reset\n");
            break;
        }
    }
    kill(Pid::from_raw(kerfd.child.id() as i32), Signal::SIGTERM).unwrap();
    loop {
        let m = recv();
        if m.contains("STOPPING=1") {
            assert!(m.contains("STATUS=stopping"), "{m}");
            break;
        }
    }
    assert!(kerfd.child.wait().unwrap().success());
}
