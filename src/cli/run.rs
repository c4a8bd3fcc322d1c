//! `kerf run`: run a program on kerfd and follow it to its end.

use std::io::{IsTerminal, Write};
use std::path::Path;

use super::{fmt_position, print_json, Failure, FAILED};
use crate::client::Client;
use crate::protocol::{Command, Execution, ProgramState};

/// Send `file` to kerfd (from line `from`), show progress, and fail if the
/// program fails. With `json`, print only the final status as JSON.
pub fn run(socket: &Path, file: &Path, from: Option<u32>, json: bool) -> Result<(), Failure> {
    let path = std::fs::canonicalize(file)
        .map_err(|e| Failure::new(format!("{}: {e}", file.display())))?;
    let mut client = Client::connect(socket)?;
    let reply = client.request(&Command::Run {
        path: Some(path.display().to_string()),
        line: from,
    })?;
    let id = reply["program"]
        .as_u64()
        .ok_or_else(|| Failure::new(format!("bad run reply: {reply}")))? as u32;
    let tty = std::io::stdout().is_terminal() && !json;
    let mut last = (u32::MAX, false);
    let started = std::time::Instant::now();
    let end = client.wait_job(id, 10.0, |status| {
        let Some(program) = status.program.as_ref().filter(|p| p.id == id) else {
            return;
        };
        // Paused: a feed hold, or a program stop (M0, M1) that waits for
        // the operator, who may be at another terminal.
        let paused = status.execution == Some(Execution::Paused);
        if json || (status.line, paused) == last {
            return;
        }
        last = (status.line, paused);
        let text = format!(
            "line {:>6}/{}  {}{}",
            status.line,
            program.lines,
            fmt_position(status),
            if paused {
                "  paused: `kerf resume` goes on"
            } else {
                ""
            }
        );
        if tty {
            print!("\r{text}");
            let _ = std::io::stdout().flush();
        } else {
            println!("{text}");
        }
    })?;
    if tty {
        println!();
    }
    if json {
        print_json(&serde_json::to_value(&end).expect("status serialises"));
    }
    let program = end.program.as_ref().filter(|p| p.id == id);
    match program.map(|p| (p.state, p.error.clone())) {
        Some((ProgramState::Finished, _)) => {
            if !json {
                println!(
                    "program finished in {:.1} s",
                    started.elapsed().as_secs_f64()
                );
            }
            Ok(())
        }
        Some((state, error)) => Err(Failure(
            FAILED,
            format!(
                "program {}: {}",
                super::name(&state),
                error.as_deref().unwrap_or("no reason given")
            ),
        )),
        None => Err(Failure::new("the program's status was lost")),
    }
}
