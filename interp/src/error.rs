//! Interpreter errors: every one names where (file, line, column) and why.

use std::fmt;
use std::sync::Arc;

/// An error in a G-code program, located to the word at fault.
///
/// Displays as `file:line:column: WORD: message`, e.g.
/// `demo.ngc:12:7: G2: radius too small to reach the end point`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InterpError {
    /// Program file name as given to the interpreter.
    pub file: Arc<str>,
    /// 1-based line number.
    pub line: u32,
    /// 1-based column of the word at fault (of the line start if none).
    pub column: u32,
    /// The word at fault as written in canonical form (`G2`, `X`, `F`), if any.
    pub word: Option<String>,
    /// What is wrong, and where possible what to do about it.
    pub message: String,
}

impl fmt::Display for InterpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file, self.line, self.column)?;
        if let Some(word) = &self.word {
            write!(f, "{word}: ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for InterpError {}
