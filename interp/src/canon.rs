//! The canonical machining commands: the narrow, printable boundary between
//! the interpreter and motion.
//!
//! All positions are absolute machine coordinates: millimetres for linear
//! axes, degrees for rotary axes, whatever units and offsets the program used.
//! Commands that describe offsets (G5x, G92, rotation, tool length) are in the
//! stream too, so that a consumer can show program coordinates or, as the
//! LinuxCNC formatter in [`crate::linuxcnc`] does, convert moves back.

use std::fmt;
use std::sync::Arc;

/// One machine axis, in the RS274NGC order X Y Z A B C U V W.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Axis {
    /// Primary linear axis X.
    X,
    /// Primary linear axis Y.
    Y,
    /// Primary linear axis Z.
    Z,
    /// Rotary axis about X.
    A,
    /// Rotary axis about Y.
    B,
    /// Rotary axis about Z.
    C,
    /// Secondary linear axis parallel to X.
    U,
    /// Secondary linear axis parallel to Y.
    V,
    /// Secondary linear axis parallel to Z.
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
    /// X, mm.
    pub x: f64,
    /// Y, mm.
    pub y: f64,
    /// Z, mm.
    pub z: f64,
    /// A, degrees.
    pub a: f64,
    /// B, degrees.
    pub b: f64,
    /// C, degrees.
    pub c: f64,
    /// U, mm.
    pub u: f64,
    /// V, mm.
    pub v: f64,
    /// W, mm.
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
    /// Millimetres (G21).
    Mm,
    /// Inches (G20).
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

/// The plane of arcs, canned cycles and cutter compensation (G17 to G19.1).
///
/// Each plane names a first, second and normal axis, in LinuxCNC's order:
/// XY (normal Z), YZ (normal X), XZ (first Z, second X, normal Y), and the
/// same for U V W.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    /// G17: X then Y, normal Z.
    XY,
    /// G19: Y then Z, normal X.
    YZ,
    /// G18: Z then X, normal Y.
    XZ,
    /// G17.1: U then V, normal W.
    UV,
    /// G19.1: V then W, normal U.
    VW,
    /// G18.1: W then U, normal V.
    UW,
}

impl Plane {
    /// The first, second and normal axis of the plane.
    pub fn axes(self) -> [Axis; 3] {
        match self {
            Plane::XY => [Axis::X, Axis::Y, Axis::Z],
            Plane::YZ => [Axis::Y, Axis::Z, Axis::X],
            Plane::XZ => [Axis::Z, Axis::X, Axis::Y],
            Plane::UV => [Axis::U, Axis::V, Axis::W],
            Plane::VW => [Axis::V, Axis::W, Axis::U],
            Plane::UW => [Axis::W, Axis::U, Axis::V],
        }
    }

    /// The G-code that selects this plane, e.g. `G18`.
    pub fn gcode(self) -> &'static str {
        match self {
            Plane::XY => "G17",
            Plane::YZ => "G19",
            Plane::XZ => "G18",
            Plane::UV => "G17.1",
            Plane::VW => "G19.1",
            Plane::UW => "G18.1",
        }
    }
}

/// Path-following mode (G61, G61.1, G64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotionMode {
    /// G61.1: stop at the end of every move.
    ExactStop,
    /// G61: follow the programmed path exactly, blending nothing.
    ExactPath,
    /// G64: blend corners, deviating from the path by at most `tolerance`
    /// mm (0 means as fast as possible).
    Continuous {
        /// Largest deviation from the programmed path, mm.
        tolerance: f64,
    },
}

/// What a straight probe (G38.2 to G38.5) does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeKind {
    /// True to move until the probe contacts (G38.2, G38.3), false to move
    /// until it loses contact (G38.4, G38.5).
    pub toward: bool,
    /// True if reaching the end without a trip is an error (G38.2, G38.4).
    pub error_if_no_trip: bool,
}

/// Spindle rotation direction, for M19 orientation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OrientDirection {
    /// Rotate whichever way is shorter (M19 P0).
    Either,
    /// Rotate clockwise (M19 P1).
    Clockwise,
    /// Rotate counter-clockwise (M19 P2).
    CounterClockwise,
}

/// One entry of the tool table, as written by G10 L1/L10/L11.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolData {
    /// Tool number (T word).
    pub tool: i32,
    /// Pocket number in the tool changer.
    pub pocket: i32,
    /// Length (and lathe X) offsets in mm, degrees for A B C.
    pub offset: Position,
    /// Cutter diameter in mm.
    pub diameter: f64,
    /// Lathe tool front angle in degrees.
    pub front_angle: f64,
    /// Lathe tool back angle in degrees.
    pub back_angle: f64,
    /// Lathe tool orientation 0 to 9.
    pub orientation: i32,
}

impl Default for ToolData {
    fn default() -> Self {
        ToolData {
            tool: -1,
            pocket: 0,
            offset: Position::ZERO,
            diameter: 0.0,
            front_angle: 0.0,
            back_angle: 0.0,
            orientation: 0,
        }
    }
}

/// The N word at the start of a block as written (`N0010` keeps its width).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockNumber {
    /// The number; digits beyond what fits in a `u32` are dropped.
    pub value: u32,
    /// How many digits were written, leading zeros included (0 for a bare `N`).
    pub digits: u8,
}

impl fmt::Display for BlockNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.digits == 0 {
            return f.write_str("N");
        }
        write!(f, "N{:0width$}", self.value, width = self.digits as usize)
    }
}

/// Where a canon command came from: the program file, its 1-based line and
/// the block's N word if the line starts with one. Line 0 marks the
/// commands the interpreter gives at start-up, before it reads any line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Source {
    /// The file name as the program was opened (or the name given to
    /// in-memory text).
    pub file: Arc<str>,
    /// 1-based line number in that file; 0 for start-up commands.
    pub line: u32,
    /// The line's N word, if it has one.
    pub block: Option<BlockNumber>,
    /// Which reading of a line this is: the lines the interpreter had read
    /// when it gave the command (0 at start-up). A loop or a subroutine
    /// called again reads one line many times; each pass has its own
    /// reading, so single block can stop after each.
    pub reading: u64,
}

impl Source {
    /// A source without an N word.
    pub fn new(file: impl Into<Arc<str>>, line: u32) -> Source {
        Source {
            file: file.into(),
            line,
            block: None,
            reading: 0,
        }
    }
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.file, self.line)
    }
}

/// One canonical machining command with the source line that produced it.
#[derive(Clone, Debug, PartialEq)]
pub struct Canon {
    /// The line that produced the command.
    pub source: Source,
    /// The command itself.
    pub cmd: CanonCmd,
}

/// A canonical machining command, in the spirit of LinuxCNC's canonical
/// machining functions.
///
/// Moves carry absolute machine coordinates (see [`Position`]): mm for X Y Z
/// U V W and degrees for A B C, with units, work offsets, G92/G52, XY
/// rotation and tool length offsets already applied. Other lengths are in mm,
/// times in seconds, feed rates in mm per minute.
#[derive(Clone, Debug, PartialEq)]
pub enum CanonCmd {
    // ---- program units and offsets (informational for motion) ----
    /// The program switched length units (G20/G21). Every coordinate in the
    /// stream is already in mm; formatters use this to print program units.
    UseLengthUnits(Units),
    /// The active work offset changed: coordinate system `index` (1 = G54 …
    /// 9 = G59.3) with its offset from machine zero in mm/degrees.
    SetG5xOffset {
        /// 1 = G54 … 9 = G59.3.
        index: u8,
        /// The system's origin in machine coordinates, mm/degrees.
        offset: Position,
    },
    /// The G92/G52 offset changed (mm/degrees; zero when not applied).
    SetG92Offset {
        /// The offset added to program coordinates, mm/degrees.
        offset: Position,
    },
    /// The rotation of the work XY plane about the work origin, degrees CCW.
    SetXYRotation {
        /// Rotation angle, degrees counter-clockwise.
        degrees: f64,
    },
    /// The tool length offset in force (G43/G43.1/G43.2/G49), mm/degrees.
    UseToolLengthOffset {
        /// The offset added to every axis, mm/degrees.
        offset: Position,
    },
    /// The plane for arcs and cycles changed (G17 to G19.1).
    SelectPlane(Plane),

    // ---- feeds and path control ----
    /// Feed rate for following feed moves: mm/min (or deg/min for pure rotary
    /// moves); mm per spindle revolution after
    /// [`CanonCmd::SetFeedMode`] with `per_revolution`.
    SetFeedRate {
        /// mm/min, deg/min, or mm/rev in per-revolution mode.
        mm_per_min: f64,
    },
    /// Feed per minute (`per_revolution` false) or per revolution of `spindle`.
    SetFeedMode {
        /// The spindle that per-revolution feed follows (0-based).
        spindle: u32,
        /// True for G95 (units per revolution), false for G93/G94.
        per_revolution: bool,
    },
    /// Path-following mode (G61, G61.1, G64 P).
    SetMotionControlMode(MotionMode),
    /// Tolerance in mm for merging collinear small moves (G64 Q).
    SetNaivecamTolerance {
        /// mm (0 disables merging).
        tolerance: f64,
    },
    /// Trajectory planner choice (G64 … R, as in LinuxCNC 2.10): planner 0
    /// is the default; planner 1 scales the peak acceleration it may use in
    /// blends by `peak_scale` (0.1 to 1).
    SetPlannerMode {
        /// Planner number (0 or 1).
        planner: u8,
        /// Factor on the peak blend acceleration (0.1 to 1).
        peak_scale: f64,
    },

    // ---- motion ----
    /// Rapid move (G0) in a straight line to `end`.
    StraightTraverse {
        /// Target, machine coordinates.
        end: Position,
    },
    /// Feed move (G1) in a straight line to `end` at the current feed rate.
    StraightFeed {
        /// Target, machine coordinates.
        end: Position,
    },
    /// Feed move along a circular arc or helix (G2/G3) from the current
    /// position to `end`.
    ///
    /// `center` holds the centre's coordinates on the plane's first and
    /// second axes (see [`Plane::axes`]); `end` also gives the helix end on
    /// the normal axis and the other axes, which move linearly. `turns` is
    /// LinuxCNC's rotation: positive counter-clockwise (G3), negative
    /// clockwise (G2) seen from the positive normal axis; its magnitude is 1
    /// plus the number of extra full turns (P word).
    ArcFeed {
        /// End of the move (arc end and helix end), machine coordinates.
        end: Position,
        /// Centre on the plane's first and second axes, machine mm.
        center: [f64; 2],
        /// The plane of the arc.
        plane: Plane,
        /// Signed turn count: sign is the direction (+ CCW), magnitude 1
        /// plus the extra full turns.
        turns: i32,
    },
    /// Probe move (G38.x) in a straight line towards `end`.
    StraightProbe {
        /// Where the probe move stops if nothing trips, machine coordinates.
        end: Position,
        /// Which of G38.2 to G38.5.
        kind: ProbeKind,
    },
    /// Rigid tapping (G33.1, G84 on a spindle with an encoder): feed to `end`
    /// synchronised with the spindle, reverse it, and return.
    RigidTap {
        /// Bottom of the hole, machine coordinates.
        end: Position,
        /// Spindle speed factor for the retract (1 = same speed).
        scale: f64,
    },
    /// Start spindle-synchronised motion: following feed moves advance
    /// `mm_per_rev` per revolution of `spindle` (G33, G76).
    StartSpeedFeedSync {
        /// The spindle to follow (0-based).
        spindle: u32,
        /// Travel per spindle revolution, mm.
        mm_per_rev: f64,
        /// True to follow spindle velocity rather than position (G95
        /// feed), false for position-locked threading.
        velocity_mode: bool,
    },
    /// End spindle-synchronised motion.
    StopSpeedFeedSync,
    /// Dwell (G4) for a time in seconds.
    Dwell {
        /// Pause length, seconds.
        seconds: f64,
    },

    // ---- spindle ----
    /// Spindle speed, revolutions per minute (or surface speed in CSS mode).
    SetSpindleSpeed {
        /// Spindle number (0-based).
        spindle: u32,
        /// Revolutions per minute, or surface speed (m/min or ft/min in
        /// program units) in CSS mode.
        rpm: f64,
    },
    /// Start the spindle clockwise (M3).
    StartSpindleClockwise {
        /// Spindle number (0-based).
        spindle: u32,
    },
    /// Start the spindle counter-clockwise (M4).
    StartSpindleCounterclockwise {
        /// Spindle number (0-based).
        spindle: u32,
    },
    /// Stop the spindle (M5).
    StopSpindleTurning {
        /// Spindle number (0-based).
        spindle: u32,
    },
    /// Constant-RPM (`css_max_rpm` 0, G97) or constant-surface-speed mode
    /// (G96) with the given maximum speed.
    SetSpindleMode {
        /// Spindle number (0-based).
        spindle: u32,
        /// Maximum RPM in CSS mode; 0 for constant RPM.
        css_max_rpm: f64,
    },
    /// Orient the spindle to an angle in degrees (M19).
    OrientSpindle {
        /// Spindle number (0-based).
        spindle: u32,
        /// Target angle, degrees.
        degrees: f64,
        /// Which way to turn to reach it.
        direction: OrientDirection,
    },
    /// Wait up to `timeout` seconds for the spindle orientation to finish.
    WaitSpindleOrientComplete {
        /// Spindle number (0-based).
        spindle: u32,
        /// Longest wait, seconds.
        timeout: f64,
    },

    // ---- tools ----
    /// Prepare tool `tool` in `pocket` for the next change (T word).
    SelectTool {
        /// Tool number.
        tool: i32,
        /// Tool table index (pocket) holding it.
        pocket: i32,
    },
    /// A tool change is about to start (M6).
    StartChange,
    /// Change to the prepared tool (M6).
    ChangeTool {
        /// Tool number going into the spindle.
        tool: i32,
        /// Its tool table index (pocket).
        pocket: i32,
    },
    /// Declare `tool` to be in the spindle without changing (M61).
    ChangeToolNumber {
        /// Tool table index of the tool now taken as loaded (LinuxCNC
        /// passes the pocket, not the tool number).
        tool: i32,
    },
    /// Write one tool table entry (G10 L1, L10, L11); `index` is the
    /// entry's place in the table.
    SetToolTableEntry {
        /// Tool table index of the entry.
        index: i32,
        /// The new entry (offsets in mm/degrees).
        data: ToolData,
    },

    // ---- coolant and overrides ----
    /// Mist coolant on (M7).
    MistOn,
    /// Mist coolant off (M9).
    MistOff,
    /// Flood coolant on (M8).
    FloodOn,
    /// Flood coolant off (M9).
    FloodOff,
    /// Allow the feed override (M48, M50 P1).
    EnableFeedOverride,
    /// Ignore the feed override (M49, M50 P0).
    DisableFeedOverride,
    /// Allow the spindle speed override (M48, M51 P1).
    EnableSpeedOverride {
        /// Spindle number (0-based).
        spindle: u32,
    },
    /// Ignore the spindle speed override (M49, M51 P0).
    DisableSpeedOverride {
        /// Spindle number (0-based).
        spindle: u32,
    },
    /// Allow adaptive feed (M52 P1).
    EnableAdaptiveFeed,
    /// Ignore adaptive feed (M52 P0).
    DisableAdaptiveFeed,
    /// Allow feed hold (M53 P1).
    EnableFeedHold,
    /// Ignore feed hold (M53 P0).
    DisableFeedHold,

    // ---- inputs and outputs ----
    /// Set digital output `index` synchronised with the next move (M62).
    SetMotionOutputBit {
        /// Output number.
        index: u32,
    },
    /// Clear digital output `index` synchronised with the next move (M63).
    ClearMotionOutputBit {
        /// Output number.
        index: u32,
    },
    /// Set analog output `index` synchronised with the next move (M67).
    SetMotionOutputValue {
        /// Output number.
        index: u32,
        /// Value to set.
        value: f64,
    },
    /// Set digital output `index` now (M64).
    SetAuxOutputBit {
        /// Output number.
        index: u32,
    },
    /// Clear digital output `index` now (M65).
    ClearAuxOutputBit {
        /// Output number.
        index: u32,
    },
    /// Set analog output `index` now (M68).
    SetAuxOutputValue {
        /// Output number.
        index: u32,
        /// Value to set.
        value: f64,
    },
    /// Wait on an input (M66): digital or analog `index`, `mode` 0 = now,
    /// 1 = rise, 2 = fall, 3 = high, 4 = low; at most `timeout` seconds.
    /// The result goes to parameter #5399 from the environment.
    WaitInput {
        /// Input number.
        index: u32,
        /// Digital (P word) or analog (E word) input.
        digital: bool,
        /// Wait mode 0 to 4 (L word).
        mode: u8,
        /// Longest wait, seconds (Q word).
        timeout: f64,
    },
    /// Cutting-force control (kerf's M170 P*force* / M171, see
    /// `docs/control.md`): on, holding `target` newtons, or off (`None`).
    /// Takes effect with the next move, in step with the motion.
    ForceControl {
        /// Target cutting force, N; `None` turns the controller off.
        target: Option<f64>,
    },
    /// Run user M-code program `M{number}` with its P and Q values (M100–M199).
    UserMCode {
        /// 100 to 199.
        number: u32,
        /// The P word (0 if absent).
        p: f64,
        /// The Q word (0 if absent).
        q: f64,
    },

    // ---- messages ----
    /// A plain comment `( ... )` or `; ...`.
    Comment(String),
    /// An operator message `(MSG, ...)` or `(DEBUG, ...)`.
    Message(String),
    /// A `(LOG, ...)` line for the log file.
    Log(String),
    /// `(LOGOPEN, file)`: start a new log file.
    LogOpen(String),
    /// `(LOGAPPEND, file)`: append to a log file.
    LogAppend(String),
    /// `(LOGCLOSE)`.
    LogClose,
    /// `(PRINT, ...)`: text for the interpreter's console.
    Print(String),

    // ---- program flow ----
    /// Pause until the operator resumes (M0).
    ProgramStop,
    /// Pause if the optional-stop switch is on (M1).
    OptionalProgramStop,
    /// Exchange pallets (M60), then pause.
    PalletShuttle,
    /// The end of motion that may be blended: wait for everything queued to
    /// finish (a closing `%`).
    Finish,
    /// Program end (M2, M30).
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

fn on_off(f: &mut fmt::Formatter<'_>, what: &str, on: bool) -> fmt::Result {
    write!(f, "{what} {}", if on { "on" } else { "off" })
}

impl fmt::Display for CanonCmd {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use CanonCmd::*;
        match self {
            UseLengthUnits(Units::Mm) => write!(f, "units mm"),
            UseLengthUnits(Units::Inch) => write!(f, "units inch"),
            SetG5xOffset { index, offset } => {
                write!(f, "work offset {index} ")?;
                fmt_pos(f, offset)
            }
            SetG92Offset { offset } => {
                write!(f, "g92 offset ")?;
                fmt_pos(f, offset)
            }
            SetXYRotation { degrees } => write!(f, "xy rotation {degrees:.4} deg"),
            UseToolLengthOffset { offset } => {
                write!(f, "tool offset ")?;
                fmt_pos(f, offset)
            }
            SelectPlane(p) => write!(f, "plane {}", p.gcode()),
            SetFeedRate { mm_per_min } => write!(f, "feed {mm_per_min:.4} mm/min"),
            SetFeedMode {
                spindle,
                per_revolution,
            } => {
                if *per_revolution {
                    write!(f, "feed per revolution of spindle {spindle}")
                } else {
                    write!(f, "feed per minute")
                }
            }
            SetMotionControlMode(MotionMode::ExactStop) => write!(f, "exact stop"),
            SetMotionControlMode(MotionMode::ExactPath) => write!(f, "exact path"),
            SetMotionControlMode(MotionMode::Continuous { tolerance }) => {
                write!(f, "blend tolerance {tolerance:.4} mm")
            }
            SetNaivecamTolerance { tolerance } => {
                write!(f, "naivecam tolerance {tolerance:.4} mm")
            }
            SetPlannerMode {
                planner,
                peak_scale,
            } => write!(f, "planner {planner} peak scale {peak_scale:.4}"),
            StraightTraverse { end } => {
                write!(f, "rapid ")?;
                fmt_pos(f, end)
            }
            StraightFeed { end } => {
                write!(f, "line ")?;
                fmt_pos(f, end)
            }
            ArcFeed {
                end,
                center,
                plane,
                turns,
            } => {
                let [a, b, _] = plane.axes();
                write!(f, "arc ")?;
                fmt_pos(f, end)?;
                write!(
                    f,
                    " centre {a}{:.4} {b}{:.4} plane {} turns {turns}",
                    center[0],
                    center[1],
                    plane.gcode()
                )
            }
            StraightProbe { end, kind } => {
                write!(f, "probe {} ", if kind.toward { "toward" } else { "away" })?;
                fmt_pos(f, end)
            }
            RigidTap { end, scale } => {
                write!(f, "rigid tap ")?;
                fmt_pos(f, end)?;
                write!(f, " scale {scale:.4}")
            }
            StartSpeedFeedSync {
                spindle,
                mm_per_rev,
                velocity_mode,
            } => write!(
                f,
                "spindle {spindle} sync {mm_per_rev:.4} mm/rev{}",
                if *velocity_mode { " (velocity)" } else { "" }
            ),
            StopSpeedFeedSync => write!(f, "spindle sync off"),
            Dwell { seconds } => write!(f, "dwell {seconds:.4} s"),
            SetSpindleSpeed { spindle, rpm } => write!(f, "spindle {spindle} speed {rpm:.4}"),
            StartSpindleClockwise { spindle } => write!(f, "spindle {spindle} cw"),
            StartSpindleCounterclockwise { spindle } => write!(f, "spindle {spindle} ccw"),
            StopSpindleTurning { spindle } => write!(f, "spindle {spindle} stop"),
            SetSpindleMode {
                spindle,
                css_max_rpm,
            } => {
                if *css_max_rpm > 0.0 {
                    write!(
                        f,
                        "spindle {spindle} constant surface speed, max {css_max_rpm:.4} rpm"
                    )
                } else {
                    write!(f, "spindle {spindle} constant rpm")
                }
            }
            OrientSpindle {
                spindle,
                degrees,
                direction,
            } => write!(f, "spindle {spindle} orient {degrees:.4} deg {direction:?}"),
            WaitSpindleOrientComplete { spindle, timeout } => {
                write!(f, "spindle {spindle} wait orient {timeout:.4} s")
            }
            SelectTool { tool, pocket } => write!(f, "select tool {tool} (pocket {pocket})"),
            StartChange => write!(f, "tool change starts"),
            ChangeTool { tool, pocket } => write!(f, "change tool {tool} (pocket {pocket})"),
            ChangeToolNumber { tool } => write!(f, "tool in spindle is {tool}"),
            SetToolTableEntry { index, data } => {
                write!(f, "tool table [{index}] T{} P{} ", data.tool, data.pocket)?;
                fmt_pos(f, &data.offset)?;
                write!(
                    f,
                    " D{:.4} front {:.4} back {:.4} orientation {}",
                    data.diameter, data.front_angle, data.back_angle, data.orientation
                )
            }
            MistOn => on_off(f, "mist", true),
            MistOff => on_off(f, "mist", false),
            FloodOn => on_off(f, "flood", true),
            FloodOff => on_off(f, "flood", false),
            EnableFeedOverride => on_off(f, "feed override", true),
            DisableFeedOverride => on_off(f, "feed override", false),
            EnableSpeedOverride { spindle } => {
                on_off(f, &format!("spindle {spindle} override"), true)
            }
            DisableSpeedOverride { spindle } => {
                on_off(f, &format!("spindle {spindle} override"), false)
            }
            EnableAdaptiveFeed => on_off(f, "adaptive feed", true),
            DisableAdaptiveFeed => on_off(f, "adaptive feed", false),
            EnableFeedHold => on_off(f, "feed hold", true),
            DisableFeedHold => on_off(f, "feed hold", false),
            SetMotionOutputBit { index } => write!(f, "output {index} on with motion"),
            ClearMotionOutputBit { index } => write!(f, "output {index} off with motion"),
            SetMotionOutputValue { index, value } => {
                write!(f, "analog output {index} = {value:.4} with motion")
            }
            SetAuxOutputBit { index } => write!(f, "output {index} on"),
            ClearAuxOutputBit { index } => write!(f, "output {index} off"),
            SetAuxOutputValue { index, value } => write!(f, "analog output {index} = {value:.4}"),
            WaitInput {
                index,
                digital,
                mode,
                timeout,
            } => write!(
                f,
                "wait {} input {index} mode {mode} timeout {timeout:.4} s",
                if *digital { "digital" } else { "analog" }
            ),
            ForceControl { target: Some(n) } => write!(f, "force control on {n:.4} N"),
            ForceControl { target: None } => write!(f, "force control off"),
            UserMCode { number, p, q } => write!(f, "user M{number} P{p} Q{q}"),
            Comment(text) => write!(f, "comment {text:?}"),
            Message(text) => write!(f, "message {text:?}"),
            Log(text) => write!(f, "log {text:?}"),
            LogOpen(text) => write!(f, "log open {text:?}"),
            LogAppend(text) => write!(f, "log append {text:?}"),
            LogClose => write!(f, "log close"),
            Print(text) => write!(f, "print {text:?}"),
            ProgramStop => write!(f, "program stop"),
            OptionalProgramStop => write!(f, "optional stop"),
            PalletShuttle => write!(f, "pallet shuttle"),
            Finish => write!(f, "finish"),
            ProgramEnd => write!(f, "program end"),
        }
    }
}

impl fmt::Display for Canon {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.source, self.cmd)
    }
}
