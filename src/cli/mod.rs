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

/// The machine and servo period an offline tool (`check`, `plan`, `sim`,
/// `kins`, `workspace`) works on.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// Machine: embedded name or TOML file.
    pub machine: String,
    /// Servo period, µs.
    pub period_us: u32,
}

impl Target {
    /// The flags where given, else kerfd's configuration
    /// ([`Config::find`](crate::config::Config::find): `config`, else
    /// `/etc/kerf/kerf.toml` when it exists), else mill3 at 1 ms: on a
    /// deployed controller `kerf check prog.ngc` checks the machine kerfd
    /// runs, at the period it runs, not the simulated mill. Only a tool
    /// that `runs_servo` takes the period from the file. Says on stderr
    /// what the file supplied.
    pub fn resolve(
        machine: Option<String>,
        period_us: Option<u32>,
        runs_servo: bool,
        config: Option<&Path>,
    ) -> Result<Target, Failure> {
        let settled = machine.is_some() && (period_us.is_some() || !runs_servo);
        let (file, path) = if settled {
            (Default::default(), None)
        } else {
            crate::config::Config::find(config).map_err(|e| {
                Failure::new(format!(
                    "{e} (kerfd's configuration, read for the machine and servo period: fix it, or give the flags it would supply)"
                ))
            })?
        };
        let file_machine = file.machine.filter(|_| machine.is_none());
        let file_period = file
            .servo
            .period_us
            .filter(|_| runs_servo && period_us.is_none());
        if let Some(path) = path {
            let took: Vec<String> = [
                file_machine.as_ref().map(|m| format!("machine {m}")),
                file_period.map(|p| format!("servo period {p} µs")),
            ]
            .into_iter()
            .flatten()
            .collect();
            if !took.is_empty() {
                eprintln!("kerf: {} from {}", took.join(", "), path.display());
            }
        }
        Ok(Target {
            machine: machine
                .or(file_machine)
                .unwrap_or_else(|| kerf_machines::DEFAULT_MACHINE.to_string()),
            period_us: period_us.or(file_period).unwrap_or(1000),
        })
    }

    /// The servo period, s.
    pub fn period(&self) -> f64 {
        f64::from(self.period_us) * 1e-6
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
