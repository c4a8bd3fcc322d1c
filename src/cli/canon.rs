//! `kerf canon`: interpret a program offline and print its canon stream.

use std::io::Write;
use std::path::Path;

use kerf_interp::{Interpreter, Position};

use super::Failure;

/// Print the canon commands of `file`, one per line with its source.
pub fn canon(file: &Path) -> Result<(), Failure> {
    let interp = Interpreter::open(file, Position::ZERO)
        .map_err(|e| Failure::new(format!("{}: {e}", file.display())))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for item in interp {
        match item {
            Ok(c) => {
                if writeln!(out, "{c}").is_err() {
                    return Ok(());
                }
            }
            Err(e) => {
                let _ = out.flush();
                return Err(Failure::new(e.to_string()));
            }
        }
    }
    Ok(())
}
