//! `kerf status`: print the machine state, current line and position.

use std::path::Path;

use super::{fmt_position, fmt_state, name, print_json, Failure};
use crate::client::Client;
use crate::protocol::Command;

/// Print one status snapshot, human-readable or as JSON; with `latency`
/// the servo thread's timing figures too.
pub fn status(socket: &Path, json: bool, latency: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    if json {
        print_json(&client.request(&Command::Status)?);
        return Ok(());
    }
    let status = client.status()?;
    println!("machine   {}", status.machine);
    println!("state     {}", fmt_state(&status));
    let unhomed = status.homed.iter().filter(|h| !**h).count();
    if unhomed > 0 {
        println!(
            "homed     {} of {} joints",
            status.homed.len() - unhomed,
            status.homed.len()
        );
    }
    println!("line      {}", status.line);
    println!("position  {}", fmt_position(&status));
    println!(
        "speed     {:.1} mm/min   feed override {:.0} %   rapid override {:.0} %   \
         spindle override {:.0} %",
        status.velocity, status.overrides.feed, status.overrides.rapid, status.overrides.spindle
    );
    if let Some(p) = &status.program {
        println!("program   #{} {} ({})", p.id, p.file, name(&p.state));
        if let Some(e) = &p.error {
            println!("error     {e}");
        }
    }
    if let Some(f) = &status.fault {
        println!("fault     {f}");
    }
    let fe = status
        .following_error
        .iter()
        .map(|e| format!("{e:.4}"))
        .collect::<Vec<_>>()
        .join("  ");
    println!("follow    {fe} (mm, commanded − measured)");
    if let Some(f) = &status.force {
        match f.target_n {
            Some(t) => println!(
                "force     {:.1} N, target {t:.1} N, feed override {:.0} %",
                f.force_n,
                f.feed_override * 100.0
            ),
            None => println!("force     {:.1} N, control off", f.force_n),
        }
    }
    let s = &status.servo;
    println!(
        "servo     {} µs, {} ticks, {} overruns, {} clock, {} guard takeovers",
        s.period_us, s.ticks, s.overruns, s.clock, s.guard_takeovers
    );
    if latency {
        let l = &s.latency;
        if l.samples == 0 {
            println!("latency   not measured (virtual clock, or no tick yet)");
        } else {
            println!(
                "latency   min {:.1}  median {:.1}  p99 {:.1}  p99.9 {:.1}  max {:.1} µs ({} wake-ups)",
                l.min_us, l.median_us, l.p99_us, l.p999_us, l.max_us, l.samples
            );
        }
        println!(
            "realtime  SCHED_FIFO {}, memory locked {}, CPU {}",
            yes(s.sched_fifo),
            yes(s.memory_locked),
            s.cpu.map_or("any".to_string(), |c| c.to_string())
        );
    }
    Ok(())
}

fn yes(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}

/// `kerf force on [TARGET] | off`.
pub fn force(socket: &Path, enabled: bool, target_n: Option<f64>) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let reply = client.request(&Command::ForceControl { enabled, target_n })?;
    match reply.get("target_n").and_then(|t| t.as_f64()) {
        Some(t) if enabled => println!("force control on, target {t:.1} N"),
        _ => println!("force control off"),
    }
    Ok(())
}
