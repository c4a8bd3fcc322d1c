//! `kerf status`: print the machine state, current line and position.

use std::path::Path;

use super::{fmt_position, fmt_state, name, print_json, Failure};
use crate::client::Client;
use crate::protocol::Command;

/// Print one status snapshot, human-readable or as JSON.
pub fn status(socket: &Path, json: bool) -> Result<(), Failure> {
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
        "speed     {:.1} mm/min   feed override {:.0} %   rapid override {:.0} %",
        status.velocity, status.overrides.feed, status.overrides.rapid
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
    println!(
        "servo     {} µs, {} ticks, {} overruns, latest wake-up {:.0} µs late",
        status.servo.period_us,
        status.servo.ticks,
        status.servo.overruns,
        status.servo.latency_max_us
    );
    Ok(())
}
