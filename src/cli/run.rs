//! `kerf run`: run a program on kerfd and follow it to its end.

use std::io::{IsTerminal, Write};
use std::path::Path;

use super::{fmt_position, Failure, FAILED};
use crate::client::Client;
use crate::protocol::{Command, Event, ProgramState};

/// Send `file` to kerfd, show progress, and fail if the program fails.
pub fn run(socket: &Path, file: &Path) -> Result<(), Failure> {
    let path = std::fs::canonicalize(file)
        .map_err(|e| Failure::new(format!("{}: {e}", file.display())))?;
    let mut client = Client::connect(socket)?;
    let reply = client.request(&Command::Run {
        path: path.display().to_string(),
    })?;
    let id = reply["program"]
        .as_u64()
        .ok_or_else(|| Failure::new(format!("bad run reply: {reply}")))? as u32;
    client.request(&Command::Subscribe { rate_hz: 10.0 })?;
    let tty = std::io::stdout().is_terminal();
    let mut last_line = u32::MAX;
    let started = std::time::Instant::now();
    loop {
        let Event::Status { status } = client.next_event()?;
        let Some(program) = status.program.as_ref().filter(|p| p.id == id) else {
            continue;
        };
        let done = program.state != ProgramState::Running;
        if status.line != last_line || done {
            last_line = status.line;
            let text = format!(
                "line {:>6}/{}  {}",
                status.line,
                program.lines,
                fmt_position(&status)
            );
            if tty {
                print!("\r{text}");
                let _ = std::io::stdout().flush();
            } else {
                println!("{text}");
            }
        }
        if done {
            if tty {
                println!();
            }
            return match program.state {
                ProgramState::Finished => {
                    println!(
                        "program finished in {:.1} s",
                        started.elapsed().as_secs_f64()
                    );
                    Ok(())
                }
                _ => Err(Failure(
                    FAILED,
                    format!(
                        "program failed: {}",
                        program.error.as_deref().unwrap_or("unknown reason")
                    ),
                )),
            };
        }
    }
}
