//! Robustness of the command socket: many subscribers, garbage, huge
//! lines, slow and vanished clients, while a program runs. Nothing here
//! may stop the program or the other clients; the servo tick's overruns
//! are counted and printed (not asserted: they depend on the machine's load).

mod support;

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use kerf::client::Client;
use kerf::protocol::{Command, ProgramState, ServoStatus};
use serde_json::Value;
use support::Kerfd;

const CLIENTS: usize = 100;
const RATE_HZ: f64 = 100.0;

/// Run `program` to its end, watched by `c`; the servo figures before and after.
fn run_and_measure(c: &mut Client, program: &std::path::Path) -> (ServoStatus, ServoStatus) {
    let before = c.status().unwrap().servo;
    let id = support::start_program(c, program);
    let end = c.wait_job(id, 20.0, |_| {}).unwrap();
    assert_eq!(end.program.unwrap().state, ProgramState::Finished);
    (before, end.servo)
}

fn report(label: &str, before: &ServoStatus, after: &ServoStatus) -> u64 {
    let overruns = after.overruns - before.overruns;
    // The latency figures cover the daemon's whole run so far.
    let l = &after.latency;
    eprintln!(
        "{label}: {} ticks, {overruns} overruns; wake-up lateness so far: median {:.0} µs, \
         p99 {:.0} µs, p99.9 {:.0} µs, max {:.0} µs",
        after.ticks - before.ticks,
        l.median_us,
        l.p99_us,
        l.p999_us,
        l.max_us
    );
    overruns
}

#[test]
fn a_hundred_subscribers_garbage_and_bad_clients_do_not_disturb_a_program() {
    let kerfd = Kerfd::start(&[]);
    let mut c = kerfd.ready_client();
    let program = kerfd.program("load.ngc", "G1 X150 F6000\nG1 Y100\nG0 X0 Y0\nM2\n");
    // The same program with no other client, for comparison.
    let (b0, a0) = run_and_measure(&mut c, &program);
    report("servo, no other clients", &b0, &a0);

    let stop = Arc::new(AtomicBool::new(false));
    let mut subscribers = Vec::new();
    for i in 0..CLIENTS {
        let stream = UnixStream::connect(&kerfd.socket).unwrap();
        let stop = stop.clone();
        subscribers.push(std::thread::spawn(move || {
            let mut writer = stream.try_clone().unwrap();
            let fields = if i % 2 == 0 { "full" } else { "changed" };
            writeln!(
                writer,
                r#"{{"id": {i}, "cmd": "subscribe", "rate_hz": {RATE_HZ}, "fields": "{fields}"}}"#
            )
            .unwrap();
            let mut reader = BufReader::new(stream);
            let mut events = 0u64;
            let mut line = String::new();
            while !stop.load(Ordering::Relaxed) {
                line.clear();
                if reader.read_line(&mut line).unwrap() == 0 {
                    panic!("client {i}: kerfd closed the connection");
                }
                // Check a sample of the traffic against the schema (all of
                // it would load the machine more than the daemon does).
                if events.is_multiple_of(50) {
                    support::schema().check_server_line(&line, Some("subscribe"));
                }
                let v: Value = serde_json::from_str(&line).unwrap();
                if v.get("event").is_some() {
                    events += 1;
                }
            }
            events
        }));
    }
    // A client that subscribes as fast as allowed and never reads.
    let mut slow = UnixStream::connect(&kerfd.socket).unwrap();
    writeln!(slow, r#"{{"id": 1, "cmd": "subscribe", "rate_hz": 1000}}"#).unwrap();
    // Clients that subscribe and vanish.
    for _ in 0..10 {
        let mut gone = UnixStream::connect(&kerfd.socket).unwrap();
        writeln!(gone, r#"{{"id": 1, "cmd": "subscribe", "rate_hz": 1000}}"#).unwrap();
    }
    // A client that sends garbage, then 3 MiB without a newline, then a
    // good request on the same connection.
    let garbage = std::thread::spawn({
        let socket = kerfd.socket.clone();
        move || {
            let stream = UnixStream::connect(&socket).unwrap();
            let mut w = stream.try_clone().unwrap();
            w.write_all(b"{\"id\": 1, \"cmd\": \n\x00\x01garbage\n")
                .unwrap();
            w.write_all(&vec![b'{'; 3 << 20]).unwrap();
            w.write_all(b"\n{\"id\": 9, \"cmd\": \"hello\"}\n").unwrap();
            let mut r = BufReader::new(stream);
            let codes: Vec<Value> = (0..4)
                .map(|_| {
                    let mut line = String::new();
                    r.read_line(&mut line).unwrap();
                    support::schema().check_server_line(&line, Some("hello"));
                    serde_json::from_str(&line).unwrap()
                })
                .collect();
            codes
        }
    });
    // The program is started by a client that hangs up at once: it runs on.
    let id = support::start_program(&mut kerfd.client(), &program);
    let before = c.status().unwrap().servo;
    let end = c.wait_job(id, 20.0, |_| {}).unwrap();
    let p = end.program.as_ref().unwrap();
    assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);
    let overruns = report(
        &format!("servo, {CLIENTS} clients at {RATE_HZ} Hz plus bad clients"),
        &before,
        &end.servo,
    );
    stop.store(true, Ordering::Relaxed);
    let counts: Vec<u64> = subscribers.into_iter().map(|t| t.join().unwrap()).collect();
    let least = *counts.iter().min().unwrap();
    let total: u64 = counts.iter().sum();
    eprintln!(
        "events delivered: {total} to {CLIENTS} clients, the least served got {least}; overruns {overruns}"
    );
    assert!(least > 0, "a subscriber got no events at all");

    let replies = garbage.join().unwrap();
    assert_eq!(replies[0]["error"]["code"], "parse_error");
    assert_eq!(replies[1]["error"]["code"], "parse_error");
    assert_eq!(replies[2]["error"]["code"], "line_too_long");
    assert_eq!(replies[3]["id"], 9);
    assert_eq!(replies[3]["ok"]["server"], "kerfd");

    // The slow client never read, and kerfd still answers everyone.
    assert!(c.request(&Command::Hello).is_ok());
    drop(slow);
}
