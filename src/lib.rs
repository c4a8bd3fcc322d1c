//! kerf: the controller daemon `kerfd` and the `kerf` client, wired from
//! the interpreter, motion, machines and io crates.
//!
//! * [`servo`]: the servo tick (executor → kinematics → HAL) and the thread
//!   that paces it.
//! * [`daemon`]: the command socket and program handling.
//! * [`protocol`]: the socket's message types.
//! * [`client`]: a blocking client for the `kerf` command.
//! * [`cli`]: the `kerf` command's subcommands.

pub mod cli;
pub mod client;
pub mod daemon;
pub mod latency;
pub mod paths;
pub mod protocol;
pub mod seqlock;
pub mod servo;
pub mod simulate;
pub mod svg;
