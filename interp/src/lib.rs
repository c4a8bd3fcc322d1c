//! kerf-interp: the RS274NGC interpreter.
//!
//! Text goes in, [`Canon`] commands come out. The interpreter is pure: it has
//! no threads, clocks or knowledge of the machine beyond its starting
//! [`Position`]. It streams: [`Interpreter`] is an iterator that reads one
//! block at a time, so memory stays flat however long the program is.
//!
//! Every canon command carries its [`Source`] (file and line), and every
//! error names file, line, column and the word at fault.

pub mod canon;
pub mod error;
mod interpreter;
mod lex;

pub use canon::{Axis, Canon, CanonCmd, Position, Source, Units};
pub use error::InterpError;
pub use interpreter::Interpreter;
