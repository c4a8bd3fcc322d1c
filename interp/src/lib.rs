//! kerf-interp: the RS274NGC interpreter, in LinuxCNC's dialect.
//!
//! Text goes in, [`Canon`] commands come out. The interpreter is pure: no
//! threads or clocks, and it learns about the machine only through its
//! [`Config`] and the queries of an [`Environment`]. It streams:
//! [`Interpreter`] is an iterator that reads one line at a time as the
//! consumer asks for commands, so memory stays flat however long the
//! program is (O-word loops and calls seek back in the file).
//!
//! Every canon command carries its [`Source`] (file, line, N word), and
//! every error names file, line, column and the word at fault. The
//! [`linuxcnc`] module prints the stream in the text format of LinuxCNC's
//! stand-alone interpreter `rs274`.
//!
//! Inside, a line is read as LinuxCNC reads it: folded (lower case, blanks
//! dropped outside comments), then walked word by word, with its tokens
//! (numbers, operators, function names, O-word keywords, `<names>`)
//! recognised by nom parsers and its values evaluated as they are read.
//! Blocks then execute in LinuxCNC's order, and a small canon layer turns
//! program coordinates into machine coordinates. The language is described
//! in `docs/gcode.md`.

// Positions are parallel arrays indexed by axis (X..W); index loops over
// them read more plainly than zipped iterators.
#![allow(clippy::needless_range_loop)]
#![warn(missing_docs)]

mod block;
pub mod canon;
pub mod canontext;
mod comp;
pub mod config;
mod cycles;
mod emit;
pub mod error;
mod exec;
mod g7x;
pub mod ini;
mod interp;
mod ld;
mod lex;
pub mod linuxcnc;
mod motion;
mod oword;
pub mod paramfile;
mod params;
mod read;
mod remap;
pub mod tools;

pub use canon::{
    Axis, BlockNumber, Canon, CanonCmd, MotionMode, OrientDirection, Plane, Position, ProbeKind,
    Source, ToolData, Units,
};
pub use config::{Config, Environment, Offline, ProbeOutcome, Remap};
pub use error::InterpError;
pub use interp::{Ending, Interpreter, ProgramSource};
pub use tools::ToolTable;
