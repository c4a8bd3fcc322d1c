//! `kerf status`: print the machine state, current line and position.

use std::path::Path;

use super::{fmt_position, Failure};
use crate::client::Client;
use crate::protocol::{Command, Status};

/// Print one status snapshot, human-readable or as JSON.
pub fn status(socket: &Path, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let value = client.request(&Command::Status)?;
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&value).expect("JSON value")
        );
        return Ok(());
    }
    let status: Status =
        serde_json::from_value(value).map_err(|e| Failure::new(format!("bad status: {e}")))?;
    println!("machine   {}", status.machine);
    println!(
        "state     {}",
        serde_json::to_value(status.state)
            .expect("enum")
            .as_str()
            .unwrap_or("?")
    );
    println!("line      {}", status.line);
    println!("position  {}", fmt_position(&status));
    if let Some(p) = &status.program {
        let state = serde_json::to_value(p.state).expect("enum");
        println!(
            "program   #{} {} ({})",
            p.id,
            p.file,
            state.as_str().unwrap_or("?")
        );
        if let Some(e) = &p.error {
            println!("error     {e}");
        }
    }
    if let Some(f) = &status.fault {
        println!("fault     {f}");
    }
    println!(
        "servo     {} µs, {} ticks, {} overruns",
        status.servo.period_us, status.servo.ticks, status.servo.overruns
    );
    Ok(())
}
