//! The text format of LinuxCNC's stand-alone interpreter `rs274`, so that
//! our canon stream can be compared with LinuxCNC's test corpus by `diff`.
//!
//! `rs274` prints one line per canonical call: a counter, the block's N
//! word (or `N.....`), and the call with its arguments in *program*
//! coordinates and units. Our canon stream carries machine millimetres, so
//! [`Rs274Formatter`] keeps the units and offsets the stream announces
//! (USE_LENGTH_UNITS, SET_G5X_OFFSET, SET_G92_OFFSET, SET_XY_ROTATION,
//! USE_TOOL_LENGTH_OFFSET) and converts every position back, exactly as
//! LinuxCNC's canon layer converted them forward.
//!
//! [`run_rs274`] also plays the part of `rs274`'s driver: the start-up
//! lines, `ON_RESET()` when a file is opened and closed, and the error
//! report (message, then the offending line) on stderr.

use std::fmt::Write as _;

use crate::canon::{Canon, CanonCmd, MotionMode, OrientDirection, Plane, Position, Units};
use crate::emit::CanonState;
use crate::interp::Interpreter;

/// Formats canon commands as `rs274` prints them.
#[derive(Clone, Debug)]
pub struct Rs274Formatter {
    state: CanonState,
    /// Machine user units per mm (tool table values print in these).
    user_units_per_mm: f64,
    counter: u32,
    started: bool,
}

impl Rs274Formatter {
    /// A formatter for a machine whose tool table is in `user_units_per_mm`
    /// units per mm (1/25.4 for `rs274`'s dummy machine).
    pub fn new(user_units_per_mm: f64) -> Self {
        Rs274Formatter {
            state: CanonState::default(),
            user_units_per_mm,
            counter: 0,
            started: false,
        }
    }

    fn len(&self, mm: f64) -> f64 {
        mm / self.state.units.mm_per_unit()
    }

    fn offset(&self, p: &Position) -> [f64; 9] {
        let mut v = p.to_array();
        for (i, x) in v.iter_mut().enumerate() {
            if !(3..6).contains(&i) {
                *x = self.len(*x);
            }
        }
        v
    }

    fn xyzabc(out: &mut String, p: &[f64; 9]) {
        let _ = write!(
            out,
            "{:.4}, {:.4}, {:.4}, {:.4}, {:.4}, {:.4}",
            p[0], p[1], p[2], p[3], p[4], p[5]
        );
    }

    /// The call text(s) for one command, without counter or N field.
    /// Most commands give one line; a probe gives three; some give none.
    /// Lines of `(PRINT,…)` text are marked `raw`.
    pub fn calls(&mut self, cmd: &CanonCmd, lines: &mut Vec<(bool, String)>) {
        use CanonCmd::*;
        let mut s = String::new();
        match cmd {
            UseLengthUnits(u) => {
                self.state.units = *u;
                s.push_str(match u {
                    Units::Mm => "USE_LENGTH_UNITS(CANON_UNITS_MM)",
                    Units::Inch => "USE_LENGTH_UNITS(CANON_UNITS_INCHES)",
                });
            }
            SetG5xOffset { index, offset } => {
                self.state.g5x = offset.to_array();
                let v = self.offset(offset);
                let _ = write!(s, "SET_G5X_OFFSET({index}, ");
                Self::xyzabc(&mut s, &v);
                s.push(')');
            }
            SetG92Offset { offset } => {
                self.state.g92 = offset.to_array();
                let v = self.offset(offset);
                s.push_str("SET_G92_OFFSET(");
                Self::xyzabc(&mut s, &v);
                s.push(')');
            }
            SetXYRotation { degrees } => {
                self.state.rotation = *degrees;
                let _ = write!(s, "SET_XY_ROTATION({degrees:.4})");
            }
            UseToolLengthOffset { offset } => {
                self.state.tool = offset.to_array();
                let v = self.offset(offset);
                let _ = write!(
                    s,
                    "USE_TOOL_LENGTH_OFFSET({:.4} {:.4} {:.4}, {:.4} {:.4} {:.4}, {:.4} {:.4} {:.4})",
                    v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]
                );
            }
            SelectPlane(p) => {
                self.state.plane = *p;
                let name = match p {
                    Plane::XY => "XY",
                    Plane::YZ => "YZ",
                    Plane::XZ => "XZ",
                    _ => "UNKNOWN",
                };
                let _ = write!(s, "SELECT_PLANE(CANON_PLANE_{name})");
            }
            SetFeedRate { mm_per_min } => {
                let _ = write!(s, "SET_FEED_RATE({:.4})", self.len(*mm_per_min));
            }
            SetFeedMode {
                spindle,
                per_revolution,
            } => {
                let _ = write!(s, "SET_FEED_MODE({spindle}, {})", *per_revolution as i32);
            }
            SetMotionControlMode(m) => match m {
                MotionMode::ExactStop => s.push_str("SET_MOTION_CONTROL_MODE(CANON_EXACT_STOP)"),
                MotionMode::ExactPath => s.push_str("SET_MOTION_CONTROL_MODE(CANON_EXACT_PATH)"),
                MotionMode::Continuous { tolerance } => {
                    let _ = write!(
                        s,
                        "SET_MOTION_CONTROL_MODE(CANON_CONTINUOUS, {:.6})",
                        self.len(*tolerance)
                    );
                }
            },
            SetNaivecamTolerance { tolerance } => {
                let _ = write!(s, "SET_NAIVECAM_TOLERANCE({:.4})", self.len(*tolerance));
            }
            SetPlannerMode {
                planner,
                peak_scale,
            } => {
                let _ = write!(
                    s,
                    "SET_PLANNER_MODE(type={planner}, peak_scale={peak_scale:.6})"
                );
            }
            StraightTraverse { end } => {
                let p = self.state.to_program_recovered(*end);
                s.push_str("STRAIGHT_TRAVERSE(");
                Self::xyzabc(&mut s, &p);
                s.push(')');
            }
            StraightFeed { end } => {
                let p = self.state.to_program_recovered(*end);
                s.push_str("STRAIGHT_FEED(");
                Self::xyzabc(&mut s, &p);
                s.push(')');
            }
            ArcFeed {
                end,
                center,
                plane,
                turns,
            } => {
                let [fa, sa, na] = plane.axes();
                let p = self.state.to_program_recovered(*end);
                let mut c = *end;
                c.set(fa, center[0]);
                c.set(sa, center[1]);
                let pc = self.state.to_program_recovered(c);
                let _ = write!(
                    s,
                    "ARC_FEED({:.4}, {:.4}, {:.4}, {:.4}, {turns}, {:.4}, {:.4}, {:.4}, {:.4})",
                    p[fa.index()],
                    p[sa.index()],
                    pc[fa.index()],
                    pc[sa.index()],
                    p[na.index()],
                    p[3],
                    p[4],
                    p[5]
                );
            }
            StraightProbe { end, .. } => {
                lines.push((false, "TURN_PROBE_ON()".into()));
                let p = self.state.to_program_recovered(*end);
                s.push_str("STRAIGHT_PROBE(");
                Self::xyzabc(&mut s, &p);
                s.push(')');
                lines.push((false, s));
                lines.push((false, "TURN_PROBE_OFF()".into()));
                return;
            }
            RigidTap { end, .. } => {
                let p = self.state.to_program_recovered(*end);
                let _ = write!(s, "RIGID_TAP({:.4}, {:.4}, {:.4})", p[0], p[1], p[2]);
            }
            StartSpeedFeedSync {
                mm_per_rev,
                velocity_mode,
                ..
            } => {
                let _ = write!(
                    s,
                    "START_SPEED_FEED_SYNC({:.6},{})",
                    self.len(*mm_per_rev),
                    *velocity_mode as i32
                );
            }
            StopSpeedFeedSync => s.push_str("STOP_SPEED_FEED_SYNCH()"),
            Dwell { seconds } => {
                let _ = write!(s, "DWELL({seconds:.4})");
            }
            SetSpindleSpeed { spindle, rpm } => {
                let _ = write!(s, "SET_SPINDLE_SPEED({spindle}, {rpm:.4})");
            }
            StartSpindleClockwise { spindle } => {
                let _ = write!(s, "START_SPINDLE_CLOCKWISE({spindle})");
            }
            StartSpindleCounterclockwise { spindle } => {
                let _ = write!(s, "START_SPINDLE_COUNTERCLOCKWISE({spindle})");
            }
            StopSpindleTurning { spindle } => {
                let _ = write!(s, "STOP_SPINDLE_TURNING({spindle})");
            }
            SetSpindleMode {
                spindle,
                css_max_rpm,
            } => {
                let _ = write!(s, "SET_SPINDLE_MODE({spindle} {css_max_rpm:.4})");
            }
            OrientSpindle {
                spindle,
                degrees,
                direction,
            } => {
                let mode = match direction {
                    OrientDirection::Either => 0,
                    OrientDirection::Clockwise => 1,
                    OrientDirection::CounterClockwise => 2,
                };
                let _ = write!(s, "ORIENT_SPINDLE({spindle}, {degrees:.4}, {mode})");
            }
            WaitSpindleOrientComplete { spindle, timeout } => {
                let _ = write!(s, "SPINDLE.{spindle}.WAIT_ORIENT_COMPLETE({timeout:.4})");
            }
            SelectTool { tool, .. } => {
                let _ = write!(s, "SELECT_TOOL({tool})");
            }
            // LinuxCNC 2.10's rs274 no longer prints the start of a change.
            StartChange => return,
            ChangeTool { .. } => s.push_str("CHANGE_TOOL()"),
            ChangeToolNumber { tool } => {
                let _ = write!(s, "CHANGE_TOOL_NUMBER({tool})");
            }
            SetToolTableEntry { index, data } => {
                let k = self.user_units_per_mm;
                let o = data.offset.to_array();
                let u = |i: usize| if (3..6).contains(&i) { o[i] } else { o[i] * k };
                let _ = write!(
                    s,
                    "SET_TOOL_TABLE_ENTRY({index}, {}, {:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4}, {:.4}, {:.4}, {})",
                    data.tool,
                    u(0),
                    u(1),
                    u(2),
                    u(3),
                    u(4),
                    u(5),
                    u(6),
                    u(7),
                    u(8),
                    data.front_angle,
                    data.back_angle,
                    data.orientation
                );
            }
            MistOn => s.push_str("MIST_ON()"),
            MistOff => s.push_str("MIST_OFF()"),
            FloodOn => s.push_str("FLOOD_ON()"),
            FloodOff => s.push_str("FLOOD_OFF()"),
            EnableFeedOverride => s.push_str("ENABLE_FEED_OVERRIDE()"),
            DisableFeedOverride => s.push_str("DISABLE_FEED_OVERRIDE()"),
            EnableSpeedOverride { spindle } => {
                let _ = write!(s, "ENABLE_SPEED_OVERRIDE({spindle})");
            }
            DisableSpeedOverride { spindle } => {
                let _ = write!(s, "DISABLE_SPEED_OVERRIDE({spindle})");
            }
            EnableAdaptiveFeed => s.push_str("ENABLE_ADAPTIVE_FEED()"),
            DisableAdaptiveFeed => s.push_str("DISABLE_ADAPTIVE_FEED()"),
            EnableFeedHold => s.push_str("ENABLE_FEED_HOLD()"),
            DisableFeedHold => s.push_str("DISABLE_FEED_HOLD()"),
            SetMotionOutputBit { index } => {
                let _ = write!(s, "SET_MOTION_OUTPUT_BIT({index})");
            }
            ClearMotionOutputBit { index } => {
                let _ = write!(s, "CLEAR_MOTION_OUTPUT_BIT({index})");
            }
            SetMotionOutputValue { index, value } => {
                let _ = write!(s, "SET_MOTION_OUTPUT_VALUE({index},{value:.6})");
            }
            SetAuxOutputBit { index } => {
                let _ = write!(s, "SET_AUX_OUTPUT_BIT({index})");
            }
            ClearAuxOutputBit { index } => {
                let _ = write!(s, "CLEAR_AUX_OUTPUT_BIT({index})");
            }
            SetAuxOutputValue { index, value } => {
                let _ = write!(s, "SET_AUX_OUTPUT_VALUE({index},{value:.6})");
            }
            // rs274 has no machine to wait on or run programs for.
            // rs274 has no force control: LinuxCNC would run M170/M171 as
            // user programs, which print nothing either.
            WaitInput { .. } | UserMCode { .. } | ForceControl { .. } => return,
            Comment(t) => {
                let _ = write!(s, "COMMENT(\"{t}\")");
            }
            Message(t) => {
                let _ = write!(s, "MESSAGE(\"{t}\")");
            }
            Log(t) => {
                let _ = write!(s, "LOG(\"{t}\")");
            }
            LogOpen(t) => {
                let _ = write!(s, "LOGOPEN(\"{t}\")");
            }
            LogAppend(t) => {
                let _ = write!(s, "LOGAPPEND(\"{t}\")");
            }
            LogClose => s.push_str("LOGCLOSE()"),
            Print(t) => {
                lines.push((true, t.clone()));
                return;
            }
            ProgramStop => s.push_str("PROGRAM_STOP()"),
            OptionalProgramStop => s.push_str("OPTIONAL_PROGRAM_STOP()"),
            PalletShuttle => s.push_str("PALLET_SHUTTLE()"),
            Finish => s.push_str("FINISH()"),
            ProgramEnd => s.push_str("PROGRAM_END()"),
        }
        lines.push((false, s));
    }

    /// Append the full output lines of one canon command to `out`:
    /// counter, N field, call. Before the first command from a program
    /// line, the driver's start-up lines are added.
    pub fn write(&mut self, canon: &Canon, out: &mut String) {
        if !self.started && canon.source.line > 0 {
            self.start(out);
        }
        let mut lines = Vec::with_capacity(1);
        self.calls(&canon.cmd, &mut lines);
        for (raw, text) in lines {
            if raw {
                out.push_str(&text);
                out.push('\n');
                continue;
            }
            self.counter += 1;
            let _ = write!(out, "{:5} ", self.counter);
            match canon.source.block {
                Some(n) => {
                    let label = n.to_string();
                    let _ = write!(out, "{label:<7}");
                }
                None => out.push_str("N..... "),
            }
            out.push_str(&text);
            out.push('\n');
        }
    }

    /// Print no start-up lines: for replaying a canon listing
    /// ([`crate::canontext`]), which `rs274` runs without its interpreter's
    /// session lines.
    pub fn skip_start_up(&mut self) {
        self.started = true;
    }

    /// The lines `rs274` prints after the interpreter's own start-up
    /// commands: the feed reference and the reset of opening the file.
    pub fn start(&mut self, out: &mut String) {
        if self.started {
            return;
        }
        self.started = true;
        self.counter += 1;
        let _ = writeln!(
            out,
            "{:5} N..... SET_FEED_REFERENCE(CANON_XYZ)",
            self.counter
        );
        self.on_reset(out);
    }

    /// An `ON_RESET()` line (the driver resets on open, close and exit).
    pub fn on_reset(&mut self, out: &mut String) {
        self.counter += 1;
        let _ = writeln!(out, "{:5} N..... ON_RESET()", self.counter);
    }
}

/// How `rs274` was run, for [`run_rs274`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rs274Options {
    /// An INI file was given: the driver then closes files lazily and
    /// prints one `ON_RESET()` less at the end.
    pub ini_given: bool,
    /// Machine user units per mm (1/25.4 for `rs274`'s dummy machine).
    pub user_units_per_mm: f64,
    /// Stop after this many canon commands (a guard against programs that
    /// never end); the run then counts as failed.
    pub max_commands: Option<usize>,
}

/// The outputs of an emulated `rs274` run.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Rs274Output {
    /// What `rs274` prints on stdout.
    pub stdout: String,
    /// What it prints on stderr.
    pub stderr: String,
    /// Both, interleaved as a terminal would show them (`2>&1`).
    pub merged: String,
    /// The exit status (0 or 1).
    pub status: i32,
}

/// Run an interpreter to its end as LinuxCNC's `rs274 -g` runs a file,
/// producing its stdout and stderr text. Errors are reported as `rs274`
/// reports them: the message, then the text of the offending line.
pub fn run_rs274(interp: Interpreter<'_>, options: Rs274Options) -> Rs274Output {
    let mut fmt = Rs274Formatter::new(options.user_units_per_mm);
    let mut out = Rs274Output {
        stderr: "executing\n".into(),
        merged: "executing\n".into(),
        ..Rs274Output::default()
    };
    let mut stdout = String::new();
    let mut failed = false;
    let mut interp = interp;
    for (n, item) in interp.by_ref().enumerate() {
        if options.max_commands.is_some_and(|max| n >= max) {
            let report = "stopped: too many commands (endless loop?)\n";
            out.stderr.push_str(report);
            out.merged.push_str(report);
            failed = true;
            break;
        }
        match item {
            Ok(c) => {
                stdout.clear();
                fmt.write(&c, &mut stdout);
                out.stdout.push_str(&stdout);
                out.merged.push_str(&stdout);
            }
            Err(e) => {
                stdout.clear();
                fmt.start(&mut stdout);
                out.stdout.push_str(&stdout);
                out.merged.push_str(&stdout);
                let report = format!("{}\n{}\n", e.message, e.line_text);
                out.stderr.push_str(&report);
                out.merged.push_str(&report);
                failed = true;
            }
        }
    }
    stdout.clear();
    fmt.start(&mut stdout);
    if !options.ini_given {
        fmt.on_reset(&mut stdout);
    }
    fmt.on_reset(&mut stdout);
    out.stdout.push_str(&stdout);
    out.merged.push_str(&stdout);
    // rs274 exits 0 when the program reaches its end, even if it reported
    // errors on the way (when told to continue after them).
    let ending = interp.ending();
    out.status = (failed && ending != Some(crate::interp::Ending::ProgramEnd)) as i32;
    out
}
