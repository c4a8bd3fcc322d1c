//! Status and pins across two processes over iceoryx2: this test exports,
//! `kerf-shm` (a separate process) watches and drives inputs. Every wait
//! is on a value arriving, bounded by a deadline.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use kerf_io::pins::{PinBank, PinConfig};
use kerf_io::shm::{state, ShmExport, StatusFrame};

fn spawn(args: &[&str], stdin: bool) -> (Child, Receiver<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_kerf-shm"))
        .args(args)
        .stdin(if stdin { Stdio::piped() } else { Stdio::null() })
        .stdout(Stdio::piped())
        .spawn()
        .expect("start kerf-shm");
    let out = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines() {
            if tx.send(line.unwrap()).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

fn frame(tick: u64) -> StatusFrame {
    let mut f = StatusFrame {
        tick,
        joint_count: 3,
        state: state::RUNNING,
        line: 7,
        ..Default::default()
    };
    for j in 0..3 {
        f.position[j] = tick as f64 * 0.125 + j as f64;
    }
    f
}

#[test]
fn another_process_sees_status_and_outputs_and_drives_inputs() {
    let instance = format!("kerf-test-{}", std::process::id());
    let pins = PinConfig {
        digital_out: vec!["coolant".into(), "clamp".into()],
        digital_in: vec!["door".into()],
        analog_out: vec!["power".into()],
        analog_in: vec!["volts".into()],
    };
    let mut export = ShmExport::start(&instance, &pins).expect("services");
    let mut bank = PinBank::new(&pins);
    bank.set_digital(0, true).unwrap();
    bank.set_analog(0, 0.25).unwrap();

    // The watcher prints status frames and pin values until it has seen
    // three frames and both pins.
    let (mut watcher, lines) = spawn(
        &[
            "watch", &instance, "--pin", "coolant", "--pin", "power", "--frames", "3",
        ],
        false,
    );
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut tick = 0;
    loop {
        assert!(Instant::now() < deadline, "watcher saw only {got:?}");
        tick += 1;
        export.exchange(&frame(tick), &mut bank);
        match lines.recv_timeout(Duration::from_millis(2)) {
            Ok(l) => got.push(l),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    assert!(watcher.wait().unwrap().success());
    assert!(got.contains(&"pin coolant 1".to_string()), "{got:?}");
    assert!(got.contains(&"pin power 0.25".to_string()), "{got:?}");
    let statuses: Vec<&String> = got.iter().filter(|l| l.starts_with("status")).collect();
    assert!(statuses.len() >= 3, "{got:?}");
    let mut last = 0;
    for s in statuses {
        // status tick=T state=2 line=7 fault=0 pos=a,b,c
        let t: u64 = s.split_whitespace().nth(1).unwrap()[5..].parse().unwrap();
        assert!(t > last && t <= tick, "{s}");
        last = t;
        let f = frame(t);
        let want = format!(
            "status tick={t} state=2 line=7 fault=0 pos={},{},{}",
            f.position[0], f.position[1], f.position[2]
        );
        assert_eq!(s, &want);
    }

    // Another process drives the inputs; the bank sees them.
    let (mut door, door_out) = spawn(&["set", &instance, "door", "1"], true);
    let (mut volts, volts_out) = spawn(&["set", &instance, "volts", "3.5"], true);
    for rx in [&door_out, &volts_out] {
        assert_eq!(rx.recv_timeout(Duration::from_secs(20)).unwrap(), "set");
    }
    assert!(!bank.digital_in(0).unwrap());
    let deadline = Instant::now() + Duration::from_secs(20);
    while !(bank.digital_in(0).unwrap() && bank.analog_in(0).unwrap() == 3.5) {
        assert!(Instant::now() < deadline, "inputs never arrived: {bank:?}");
        tick += 1;
        export.exchange(&frame(tick), &mut bank);
        std::thread::yield_now();
    }
    drop(door.stdin.take());
    drop(volts.stdin.take());
    assert!(door.wait().unwrap().success());
    assert!(volts.wait().unwrap().success());
    assert!(!export.failed());
    assert!(export.published() > 0);
}
