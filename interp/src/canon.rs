//! The canonical machining commands: the narrow, printable boundary between
//! the interpreter and motion.
//!
//! All positions are absolute machine coordinates: millimetres for linear
//! axes, degrees for rotary axes, whatever units and offsets the program used.

use std::fmt;
use std::sync::Arc;

/// One machine axis, in the RS274NGC order X Y Z A B C U V W.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Axis {
    X,
    Y,
    Z,
    A,
    B,
    C,
    U,
    V,
    W,
}

impl Axis {
    /// Every axis, in canonical order (the index order of [`Position::to_array`]).
    pub const ALL: [Axis; 9] = [
        Axis::X,
        Axis::Y,
        Axis::Z,
        Axis::A,
        Axis::B,
        Axis::C,
        Axis::U,
        Axis::V,
        Axis::W,
    ];

    /// Index of this axis in [`Axis::ALL`] and [`Position::to_array`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The upper-case G-code letter of this axis.
    pub fn letter(self) -> char {
        b"XYZABCUVW"[self.index()] as char
    }

    /// Parse an axis letter, either case.
    pub fn from_letter(c: char) -> Option<Axis> {
        let i = "XYZABCUVW".find(c.to_ascii_uppercase())?;
        Some(Axis::ALL[i])
    }

    /// True for A, B and C, whose positions are in degrees.
    pub fn is_rotary(self) -> bool {
        matches!(self, Axis::A | Axis::B | Axis::C)
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.letter())
    }
}

/// A tool position in machine coordinates: mm for X Y Z U V W, degrees for A B C.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Position {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub u: f64,
    pub v: f64,
    pub w: f64,
}

impl Position {
    /// The machine origin.
    pub const ZERO: Position = Position {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        a: 0.0,
        b: 0.0,
        c: 0.0,
        u: 0.0,
        v: 0.0,
        w: 0.0,
    };

    /// Position from X Y Z only, other axes at zero.
    pub fn xyz(x: f64, y: f64, z: f64) -> Position {
        Position {
            x,
            y,
            z,
            ..Position::ZERO
        }
    }

    /// The coordinates in [`Axis::ALL`] order.
    pub fn to_array(&self) -> [f64; 9] {
        [
            self.x, self.y, self.z, self.a, self.b, self.c, self.u, self.v, self.w,
        ]
    }

    /// Build from coordinates in [`Axis::ALL`] order.
    pub fn from_array(p: [f64; 9]) -> Position {
        Position {
            x: p[0],
            y: p[1],
            z: p[2],
            a: p[3],
            b: p[4],
            c: p[5],
            u: p[6],
            v: p[7],
            w: p[8],
        }
    }

    /// The coordinate of one axis.
    pub fn get(&self, axis: Axis) -> f64 {
        self.to_array()[axis.index()]
    }

    /// Set the coordinate of one axis.
    pub fn set(&mut self, axis: Axis, value: f64) {
        let mut p = self.to_array();
        p[axis.index()] = value;
        *self = Position::from_array(p);
    }
}

/// Length units a program is written in (G20 inches, G21 millimetres).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    Mm,
    Inch,
}

impl Units {
    /// Millimetres per program unit.
    pub fn mm_per_unit(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Inch => 25.4,
        }
    }
}

/// Where a canon command came from: the program file and its 1-based line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Source {
    pub file: Arc<str>,
    pub line: u32,
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.file, self.line)
    }
}

/// One canonical machining command with the source line that produced it.
#[derive(Clone, Debug, PartialEq)]
pub struct Canon {
    pub source: Source,
    pub cmd: CanonCmd,
}

/// A canonical machining command.
///
/// Moves carry absolute machine coordinates (see [`Position`]); feed rates
/// are in mm/min like the F word, converted from inches when G20 is active.
#[derive(Clone, Debug, PartialEq)]
pub enum CanonCmd {
    /// The program switched length units (G20/G21). Informational: every
    /// coordinate in the stream is already in mm.
    UseLengthUnits(Units),
    /// Feed rate for following feed moves, mm/min (or deg/min for pure rotary moves).
    SetFeedRate { mm_per_min: f64 },
    /// Rapid move (G0) in a straight line to `end`.
    StraightTraverse { end: Position },
    /// Feed move (G1) in a straight line to `end` at the current feed rate.
    StraightFeed { end: Position },
    /// Dwell (G4) for a time in seconds.
    Dwell { seconds: f64 },
    /// A plain comment `( ... )` or `; ...`.
    Comment(String),
    /// An operator message `(MSG, ...)`.
    Message(String),
    /// Program end (M2, M30 or the closing `%`).
    ProgramEnd,
}

fn fmt_pos(f: &mut fmt::Formatter<'_>, p: &Position) -> fmt::Result {
    write!(f, "X{:.4} Y{:.4} Z{:.4}", p.x, p.y, p.z)?;
    for axis in &Axis::ALL[3..] {
        let v = p.get(*axis);
        if v != 0.0 {
            write!(f, " {}{:.4}", axis.letter(), v)?;
        }
    }
    Ok(())
}

impl fmt::Display for CanonCmd {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CanonCmd::UseLengthUnits(Units::Mm) => write!(f, "units mm"),
            CanonCmd::UseLengthUnits(Units::Inch) => write!(f, "units inch"),
            CanonCmd::SetFeedRate { mm_per_min } => write!(f, "feed {mm_per_min:.4} mm/min"),
            CanonCmd::StraightTraverse { end } => {
                write!(f, "rapid ")?;
                fmt_pos(f, end)
            }
            CanonCmd::StraightFeed { end } => {
                write!(f, "line ")?;
                fmt_pos(f, end)
            }
            CanonCmd::Dwell { seconds } => write!(f, "dwell {seconds:.4} s"),
            CanonCmd::Comment(text) => write!(f, "comment {text:?}"),
            CanonCmd::Message(text) => write!(f, "message {text:?}"),
            CanonCmd::ProgramEnd => write!(f, "program end"),
        }
    }
}

impl fmt::Display for Canon {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.source, self.cmd)
    }
}
