//! The `kerf` command's subcommands, one module each.
//!
//! Each subcommand is a function returning `Result<(), Failure>`; `main` in
//! `src/bin/kerf.rs` only parses arguments and dispatches. Output is for
//! people by default; with `--json` each command prints the daemon's reply
//! (or final status) as JSON for scripts.

pub mod canon;
pub mod control;
pub mod kins;
pub mod offsets;
pub mod plan;
pub mod run;
pub mod sim;
pub mod status;
pub mod watch;
pub mod workspace;

use std::path::Path;

use crate::client::{Client, ClientError};
use crate::protocol::{Command, Status};

/// Exit status for a failed command.
pub const FAILED: u8 = 1;
/// Exit status when kerfd cannot be reached (and for usage errors).
pub const CANNOT_CONNECT: u8 = 2;

/// A failed subcommand: the exit status and the message for stderr.
#[derive(Debug)]
pub struct Failure(pub u8, pub String);

impl Failure {
    /// A plain failure (exit status 1).
    pub fn new(message: impl Into<String>) -> Failure {
        Failure(FAILED, message.into())
    }
}

impl From<ClientError> for Failure {
    fn from(e: ClientError) -> Self {
        let code = if matches!(e, ClientError::Connect { .. }) {
            CANNOT_CONNECT
        } else {
            FAILED
        };
        Failure(code, e.to_string())
    }
}

/// Print a JSON value, pretty.
pub fn print_json(v: &serde_json::Value) {
    println!("{}", serde_json::to_string_pretty(v).expect("JSON value"));
}

/// Send one command; print `done` (or the reply with `json`).
pub fn simple(socket: &Path, cmd: &Command, json: bool, done: &str) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let reply = client.request(cmd)?;
    if json {
        print_json(&reply);
    } else if !done.is_empty() {
        println!("{done}");
    }
    Ok(())
}

/// The protocol name of a serialisable enum value, e.g. `estop_reset`.
pub fn name<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

/// A map of axis letters to numbers as `X   1.0000  Y   2.0000 ...`.
pub fn fmt_axes(axes: &serde_json::Map<String, serde_json::Value>) -> String {
    axes.iter()
        .map(|(axis, v)| {
            format!(
                "{}{:>10.4}",
                axis.to_uppercase(),
                v.as_f64().unwrap_or(f64::NAN)
            )
        })
        .collect::<Vec<_>>()
        .join("  ")
}

/// The position of a status as `X   1.0000  Y   2.0000 ...`.
pub fn fmt_position(status: &Status) -> String {
    fmt_axes(&status.position)
}

/// The state as shown to people: `auto (paused)`, `idle`, …
pub fn fmt_state(status: &Status) -> String {
    match status.execution {
        Some(e) => format!("{} ({})", name(&status.state), name(&e)),
        None => name(&status.state),
    }
}

/// The interpreter for `file`, read offline as `kerf canon` reads it (its
/// readable format's configuration) from `start`, with the tools of
/// `tool_table` (a LinuxCNC `.tbl` file). Without one, a program that
/// changes or measures tools stops at its first T word.
pub fn open_program(
    file: &Path,
    start: kerf_interp::Position,
    tool_table: Option<&Path>,
) -> Result<kerf_interp::Interpreter<'static>, Failure> {
    let mut cfg = canon::config(&canon::CanonOptions {
        tool_table: tool_table.map(Path::to_path_buf),
        ..Default::default()
    })?;
    cfg.start_position = start;
    kerf_interp::Interpreter::open_with(file, cfg, Box::new(kerf_interp::Offline::default()))
        .map_err(|e| Failure::new(format!("{}: {e}", file.display())))
}
