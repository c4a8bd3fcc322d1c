//! The `kerf` command's subcommands, one module each.
//!
//! Each subcommand is a function returning `Result<(), Failure>`; `main` in
//! `src/bin/kerf.rs` only parses arguments and dispatches.

pub mod canon;
pub mod kins;
pub mod plan;
pub mod run;
pub mod sim;
pub mod status;
pub mod workspace;

use crate::client::ClientError;
use crate::protocol::Status;

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

/// The position of a status as `X   1.0000  Y   2.0000 ...`.
pub fn fmt_position(status: &Status) -> String {
    status
        .position
        .iter()
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
