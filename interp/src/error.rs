//! Interpreter errors: every one names where (file, line, column) and why.

use std::fmt;
use std::sync::Arc;

/// An error in a G-code program, located to the word at fault.
///
/// Displays as `file:line:column: WORD: message`, e.g.
/// `demo.ngc:12:7: G2: Radius to end of arc differs from radius to start`.
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
    /// What is wrong, in LinuxCNC's wording where LinuxCNC has one.
    pub message: String,
    /// The text of the offending line, as read.
    pub line_text: String,
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

/// An error before it is placed in a file: the message and, when known, the
/// word at fault and its column.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Fault {
    pub message: String,
    pub word: Option<String>,
    pub column: Option<u32>,
}

impl Fault {
    /// A fault with only a message; the interpreter fills in the word it was
    /// executing.
    pub fn new(message: impl Into<String>) -> Fault {
        Fault {
            message: message.into(),
            word: None,
            column: None,
        }
    }

    /// A fault at a column, with no word.
    pub fn at(column: u32, message: impl Into<String>) -> Fault {
        Fault {
            message: message.into(),
            word: None,
            column: Some(column),
        }
    }
}

impl Fault {
    /// Place a fault that arose while reading the value of a word: name
    /// that word, and its column unless the fault has a closer one.
    pub fn in_word(mut self, word: impl FnOnce() -> String, column: u32) -> Fault {
        if self.word.is_none() {
            self.word = Some(word());
        }
        if self.column.is_none() {
            self.column = Some(column);
        }
        self
    }
}

/// Result of interpreter internals.
pub(crate) type R<T = ()> = Result<T, Fault>;

/// Return a [`Fault`] with a formatted message.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::Fault::new(format!($($arg)*)))
    };
}

/// Return a [`Fault`] if the condition (a description of what is wrong) holds.
macro_rules! chk {
    ($bad:expr, $($arg:tt)*) => {
        {
            let bad: bool = $bad;
            if bad {
                return Err($crate::error::Fault::new(format!($($arg)*)));
            }
        }
    };
}

pub(crate) use {bail, chk};
