//! Reading canon text back into canon commands.
//!
//! LinuxCNC can run a saved listing of canonical calls instead of G-code
//! (its `canterp` interpreter plugin): one call per line, as `rs274`
//! prints them, optionally with the counter and N columns in front. This
//! module reads such a listing and yields the [`Canon`] commands it
//! describes, so a recorded stream can be replayed through kerf, and the
//! text format round-trips: commands → [`crate::linuxcnc`] text → commands.
//!
//! Coordinates in the text are program coordinates in the units the
//! listing last set (`USE_LENGTH_UNITS`), relative to the offsets it last
//! set (`SET_G5X_OFFSET`, `SET_G92_OFFSET`, `SET_XY_ROTATION`,
//! `USE_TOOL_LENGTH_OFFSET`); they are converted to machine coordinates as
//! the interpreter converts its own. Moves may give six axes (rs274) or
//! nine (canterp). `ON_RESET` and `SET_FEED_REFERENCE`, which describe
//! rs274's session rather than the program, are skipped; any other call
//! kerf has no command for is an error naming it.

use std::io::BufRead;
use std::sync::Arc;

use nom::bytes::complete::{take_while, take_while1};
use nom::character::complete::{char, digit1, space0, space1};
use nom::combinator::opt;
use nom::sequence::{pair, terminated};
use nom::IResult;

use crate::canon::{Canon, CanonCmd, Plane, Position, Source, Units};
use crate::emit::CanonState;
use crate::error::InterpError;

/// An iterator over the commands of a canon text listing.
pub struct CanonText<R> {
    reader: R,
    file: Arc<str>,
    line: u32,
    text: String,
    state: CanonState,
    done: bool,
}

/// Read the canon text listing `reader` (named `file` in sources and
/// errors).
pub fn read_canon_text<R: BufRead>(reader: R, file: impl Into<Arc<str>>) -> CanonText<R> {
    CanonText {
        reader,
        file: file.into(),
        line: 0,
        text: String::new(),
        state: CanonState::default(),
        done: false,
    }
}

/// The call on a line: its name and the text between its parentheses.
fn call(i: &str) -> IResult<&str, (&str, &str)> {
    // Optional counter and N column, as rs274 prints them.
    let (i, _) = space0(i)?;
    let (i, _) = opt(terminated(digit1, space1))(i)?;
    let (i, _) = opt(terminated(
        pair(
            char('N'),
            take_while(|c: char| c == '.' || c.is_ascii_digit()),
        ),
        space1,
    ))(i)?;
    let (i, name) =
        take_while1(|c: char| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')(i)?;
    let (i, _) = char('(')(i)?;
    let close = i.rfind(')').ok_or(nom::Err::Error(nom::error::Error::new(
        i,
        nom::error::ErrorKind::Char,
    )))?;
    Ok((&i[close + 1..], (name, &i[..close])))
}

/// The numbers of an argument list (separated by commas or blanks).
fn numbers(args: &str) -> Result<Vec<f64>, String> {
    args.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|a| !a.is_empty())
        .map(|a| a.parse().map_err(|_| format!("bad number {a:?}")))
        .collect()
}

/// A quoted argument (`COMMENT("…")`), or the bare text.
fn quoted(args: &str) -> String {
    let t = args.trim();
    match (t.find('"'), t.rfind('"')) {
        (Some(a), Some(b)) if b > a => t[a + 1..b].to_string(),
        _ => t.to_string(),
    }
}

impl<R: BufRead> CanonText<R> {
    fn error(&self, column: u32, word: Option<&str>, message: String) -> InterpError {
        InterpError {
            file: self.file.clone(),
            line: self.line.max(1),
            column,
            word: word.map(str::to_string),
            message,
            line_text: self.text.trim_end().to_string(),
        }
    }

    /// Program-unit axis values (6 or 9) as a full program position.
    fn program_position(&self, v: &[f64]) -> Result<[f64; 9], String> {
        if v.len() != 6 && v.len() != 9 {
            return Err(format!("expected 6 or 9 coordinates, found {}", v.len()));
        }
        let mut p = [0.0; 9];
        p[..v.len()].copy_from_slice(v);
        Ok(p)
    }

    /// Lengths in program units (angles as they are) to mm.
    fn offset(&self, v: &[f64]) -> Position {
        let mut p = [0.0; 9];
        p[..v.len().min(9)].copy_from_slice(&v[..v.len().min(9)]);
        Position::from_array(self.state.offset_to_mm(p))
    }

    fn command(&mut self, name: &str, args: &str) -> Result<Option<CanonCmd>, String> {
        use CanonCmd::*;
        let n = || numbers(args);
        let mm = |s: &Self, v: f64| v * s.state.units.mm_per_unit();
        let spindle = |v: &[f64]| v.first().map(|&s| s as u32).unwrap_or(0);
        Ok(Some(match name {
            "ON_RESET" | "SET_FEED_REFERENCE" => return Ok(None),
            "USE_LENGTH_UNITS" => {
                let units = match args.trim() {
                    "CANON_UNITS_MM" => Units::Mm,
                    "CANON_UNITS_INCHES" => Units::Inch,
                    other => return Err(format!("unknown units {other}")),
                };
                self.state.units = units;
                UseLengthUnits(units)
            }
            "SET_G5X_OFFSET" => {
                let v = n()?;
                let (index, rest) = v.split_first().ok_or("missing coordinate system")?;
                let offset = self.offset(rest);
                self.state.g5x = offset.to_array();
                SetG5xOffset {
                    index: *index as u8,
                    offset,
                }
            }
            "SET_G92_OFFSET" => {
                let offset = self.offset(&n()?);
                self.state.g92 = offset.to_array();
                SetG92Offset { offset }
            }
            "SET_XY_ROTATION" => {
                let degrees = *n()?.first().ok_or("missing angle")?;
                self.state.rotation = degrees;
                SetXYRotation { degrees }
            }
            "USE_TOOL_LENGTH_OFFSET" => {
                let v = n()?;
                // canterp gives only Z; rs274 prints all nine.
                let v = if v.len() == 1 {
                    vec![0.0, 0.0, v[0]]
                } else {
                    v
                };
                let offset = self.offset(&v);
                self.state.tool = offset.to_array();
                UseToolLengthOffset { offset }
            }
            "SELECT_PLANE" => {
                let plane = match args.trim() {
                    "CANON_PLANE_XY" => Plane::XY,
                    "CANON_PLANE_YZ" => Plane::YZ,
                    "CANON_PLANE_XZ" => Plane::XZ,
                    "CANON_PLANE_UV" => Plane::UV,
                    "CANON_PLANE_VW" => Plane::VW,
                    "CANON_PLANE_UW" => Plane::UW,
                    other => return Err(format!("unknown plane {other}")),
                };
                self.state.plane = plane;
                SelectPlane(plane)
            }
            "SET_FEED_RATE" => SetFeedRate {
                mm_per_min: mm(self, *n()?.first().ok_or("missing feed rate")?),
            },
            "STRAIGHT_TRAVERSE" => StraightTraverse {
                end: self.state.to_machine(self.program_position(&n()?)?),
            },
            "STRAIGHT_FEED" => StraightFeed {
                end: self.state.to_machine(self.program_position(&n()?)?),
            },
            "ARC_FEED" => {
                // first end, second end, first centre, second centre,
                // rotation, normal end, A B C (U V W).
                let v = n()?;
                if v.len() != 9 && v.len() != 12 {
                    return Err(format!("expected 9 or 12 arguments, found {}", v.len()));
                }
                let plane = self.state.plane;
                let [fa, sa, na] = plane.axes().map(|a| a.index());
                let mut end = [0.0; 9];
                end[3..3 + v.len() - 6].copy_from_slice(&v[6..]);
                end[fa] = v[0];
                end[sa] = v[1];
                end[na] = v[5];
                let mut centre = end;
                centre[fa] = v[2];
                centre[sa] = v[3];
                let c = self.state.to_machine(centre).to_array();
                ArcFeed {
                    end: self.state.to_machine(end),
                    center: [c[fa], c[sa]],
                    plane,
                    turns: v[4] as i32,
                }
            }
            "DWELL" => Dwell {
                seconds: *n()?.first().ok_or("missing time")?,
            },
            "COMMENT" => Comment(quoted(args)),
            "MESSAGE" => Message(quoted(args)),
            "MIST_ON" => MistOn,
            "MIST_OFF" => MistOff,
            "FLOOD_ON" => FloodOn,
            "FLOOD_OFF" => FloodOff,
            "ENABLE_FEED_OVERRIDE" => EnableFeedOverride,
            "DISABLE_FEED_OVERRIDE" => DisableFeedOverride,
            "SELECT_TOOL" => {
                let t = *n()?.first().ok_or("missing tool")? as i32;
                SelectTool { tool: t, pocket: t }
            }
            "CHANGE_TOOL" => {
                let t = n()?.first().map(|&t| t as i32).unwrap_or(0);
                ChangeTool { tool: t, pocket: t }
            }
            "SET_SPINDLE_SPEED" => {
                let v = n()?;
                match v.as_slice() {
                    [rpm] => SetSpindleSpeed {
                        spindle: 0,
                        rpm: *rpm,
                    },
                    [s, rpm] => SetSpindleSpeed {
                        spindle: *s as u32,
                        rpm: *rpm,
                    },
                    _ => return Err("expected a speed".into()),
                }
            }
            "START_SPINDLE_CLOCKWISE" => StartSpindleClockwise {
                spindle: spindle(&n()?),
            },
            "START_SPINDLE_COUNTERCLOCKWISE" => StartSpindleCounterclockwise {
                spindle: spindle(&n()?),
            },
            "STOP_SPINDLE_TURNING" => StopSpindleTurning {
                spindle: spindle(&n()?),
            },
            "SET_FEED_MODE" => {
                let v = n()?;
                SetFeedMode {
                    spindle: spindle(&v),
                    per_revolution: v.get(1).is_some_and(|&m| m != 0.0),
                }
            }
            "SET_MOTION_CONTROL_MODE" => {
                let mut parts = args.split(',');
                let mode = parts.next().unwrap_or("").trim();
                let tolerance = parts.next().map(numbers).transpose()?;
                let tolerance = mm(
                    self,
                    tolerance.and_then(|t| t.first().copied()).unwrap_or(0.0),
                );
                SetMotionControlMode(match mode {
                    "CANON_EXACT_STOP" => crate::canon::MotionMode::ExactStop,
                    "CANON_EXACT_PATH" => crate::canon::MotionMode::ExactPath,
                    "CANON_CONTINUOUS" => crate::canon::MotionMode::Continuous { tolerance },
                    other => return Err(format!("unknown motion mode {other}")),
                })
            }
            "SET_NAIVECAM_TOLERANCE" => SetNaivecamTolerance {
                tolerance: mm(self, *n()?.first().ok_or("missing tolerance")?),
            },
            "SET_SPINDLE_MODE" => {
                let v = n()?;
                SetSpindleMode {
                    spindle: spindle(&v),
                    css_max_rpm: v.get(1).copied().unwrap_or(0.0),
                }
            }
            "START_SPEED_FEED_SYNC" | "START_SPEED_FEED_SYNCH" => {
                let v = n()?;
                StartSpeedFeedSync {
                    spindle: 0,
                    mm_per_rev: mm(self, *v.first().ok_or("missing pitch")?),
                    velocity_mode: v.get(1).is_some_and(|&m| m != 0.0),
                }
            }
            "STOP_SPEED_FEED_SYNCH" => StopSpeedFeedSync,
            "CHANGE_TOOL_NUMBER" => ChangeToolNumber {
                tool: *n()?.first().ok_or("missing tool")? as i32,
            },
            "ENABLE_SPEED_OVERRIDE" => EnableSpeedOverride {
                spindle: spindle(&n()?),
            },
            "DISABLE_SPEED_OVERRIDE" => DisableSpeedOverride {
                spindle: spindle(&n()?),
            },
            "PROGRAM_STOP" => ProgramStop,
            "OPTIONAL_PROGRAM_STOP" => OptionalProgramStop,
            "PROGRAM_END" => ProgramEnd,
            _ => return Err(format!("the canon call {name} is not supported")),
        }))
    }
}

impl<R: BufRead> Iterator for CanonText<R> {
    type Item = Result<Canon, InterpError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.text.clear();
            match self.reader.read_line(&mut self.text) {
                Ok(0) => {
                    self.done = true;
                    return None;
                }
                Ok(_) => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(self.error(1, None, format!("cannot read: {e}"))));
                }
            }
            self.line += 1;
            let line = self.text.trim_end().to_string();
            if line.trim().is_empty() {
                continue;
            }
            let (name, args) = match call(&line) {
                Ok((_, c)) => c,
                Err(_) => {
                    self.done = true;
                    return Some(Err(self.error(1, None, "not a canon call".into())));
                }
            };
            let column = line.find(name).map(|c| c as u32 + 1).unwrap_or(1);
            match self.command(name, args) {
                Ok(None) => continue,
                Ok(Some(cmd)) => {
                    return Some(Ok(Canon {
                        source: Source::new(self.file.clone(), self.line),
                        cmd,
                    }))
                }
                Err(message) => {
                    self.done = true;
                    let name = name.to_string();
                    return Some(Err(self.error(column, Some(&name), message)));
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_both_rs274_and_canterp_forms() {
        let text = "    1 N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)\n\
                    N....  STRAIGHT_TRAVERSE(1.0000, 0.0000, -.1, 0., 0., 0., 0., 0., 0.)\n\
                    SET_FEED_RATE(10)\n\
                    ARC_FEED(2.0, 0.0, 1.5, 0.0, -1, -0.1, 0, 0, 0)\n\
                    ON_RESET()\n\
                    COMMENT(\"done (really)\")\n";
        let cmds: Vec<CanonCmd> = read_canon_text(text.as_bytes(), "t.canon")
            .map(|c| c.unwrap().cmd)
            .collect();
        assert_eq!(cmds[0], CanonCmd::UseLengthUnits(Units::Inch));
        // Inches to machine mm.
        assert_eq!(
            cmds[1],
            CanonCmd::StraightTraverse {
                end: Position::xyz(25.4, 0.0, -2.54)
            }
        );
        assert_eq!(cmds[2], CanonCmd::SetFeedRate { mm_per_min: 254.0 });
        match &cmds[3] {
            CanonCmd::ArcFeed {
                end, center, turns, ..
            } => {
                assert!((end.x - 50.8).abs() < 1e-12 && (end.z + 2.54).abs() < 1e-12);
                assert!((center[0] - 38.1).abs() < 1e-12 && center[1].abs() < 1e-12);
                assert_eq!(*turns, -1);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(cmds[4], CanonCmd::Comment("done (really)".into()));
        assert_eq!(cmds.len(), 5);
    }

    #[test]
    fn unknown_calls_are_errors_naming_them() {
        let mut it = read_canon_text("CLAMP_AXIS(CANON_AXIS_X)\n".as_bytes(), "t.canon");
        let e = it.next().unwrap().unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.canon:1:1: CLAMP_AXIS: the canon call CLAMP_AXIS is not supported"
        );
        assert!(it.next().is_none());
    }

    /// Commands printed as rs274 text and read back print the same text.
    #[test]
    fn rs274_text_round_trips() {
        use crate::linuxcnc::{run_rs274, Rs274Formatter, Rs274Options};
        use crate::{Config, Interpreter, Offline};
        let program = "G20 G17 G90 G64 P0.01\nS1000 M3 M8\nG10 L2 P1 X1 Y2\nG92 X0.5\n\
                       G0 X1 Y1 Z0.1\nG1 Z-0.1 F20\nG2 X2 Y1 I0.5 J0 Z-0.2\nG3 X1 Y1 R0.5\n\
                       G4 P0.5 (pause)\nG21 G1 X10 Y10\nG61.1 G95 F0.1 G1 X11\nM5 M9\nM2\n";
        let interp = Interpreter::with_source(
            Box::new(std::io::Cursor::new(program.as_bytes().to_vec())),
            "p.ngc",
            None,
            Config::rs274(),
            Box::new(Offline::default()),
        );
        let units = Config::rs274().user_units_per_mm;
        let first = run_rs274(
            interp,
            Rs274Options {
                ini_given: false,
                user_units_per_mm: units,
                max_commands: None,
            },
        )
        .stdout;
        let mut fmt = Rs274Formatter::new(units);
        fmt.skip_start_up();
        let mut second = String::new();
        for c in read_canon_text(first.as_bytes(), "p.canon") {
            fmt.write(&c.unwrap(), &mut second);
        }
        let calls = |t: &str| -> Vec<String> {
            t.lines()
                .map(|l| {
                    l.trim_start()
                        .splitn(3, ' ')
                        .nth(2)
                        .unwrap_or("")
                        .trim()
                        .to_string()
                })
                .filter(|c| c != "ON_RESET()" && !c.starts_with("SET_FEED_REFERENCE"))
                .collect()
        };
        assert_eq!(calls(&second), calls(&first));
        assert!(calls(&first).len() > 20);
    }
}
