//! kerf: the controller daemon `kerfd` and the `kerf` client, wired from
//! the interpreter, motion, machines and io crates.
//!
//! * [`servo`]: the servo tick (executor → kinematics → HAL) and the thread
//!   that paces it.
//! * [`daemon`]: the command socket and the jobs that move the machine.
//! * [`machine`]: the machine state machine (e-stop, on, homed, auto, …).
//! * [`state`]: the persistent parameter file and tool table.
//! * [`config`]: the daemon's configuration file.
//! * [`systemd`]: readiness, watchdog and journal logging.
//! * [`protocol`]: the socket's message types.
//! * [`client`]: a blocking client for the `kerf` command.
//! * [`cli`]: the `kerf` command's subcommands.

pub mod cli;
pub mod client;
pub mod config;
pub mod daemon;
pub mod latency;
pub mod machine;
pub mod paths;
pub mod protocol;
pub mod seqlock;
pub mod servo;
pub mod simulate;
pub mod state;
pub mod svg;
pub mod systemd;
