//! The streaming interpreter: reads one block at a time and yields canon.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::Path;
use std::sync::Arc;

use crate::canon::{Axis, Canon, CanonCmd, Position, Source, Units};
use crate::error::InterpError;
use crate::lex::{Block, Lexer, Word};

/// Modal motion mode (group 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Motion {
    Rapid,
    Feed,
}

/// The interpreter's modal state between blocks.
#[derive(Clone, Debug)]
struct Modal {
    motion: Option<Motion>,
    units: Units,
    incremental: bool,
    /// Active feed rate in mm/min.
    feed: f64,
    /// Current tool position in machine coordinates.
    position: Position,
}

/// An RS274NGC interpreter over one program, yielding [`Canon`] commands.
///
/// It pulls lines from the reader only as the consumer asks for commands, so
/// a program of any length is interpreted in constant memory. After an error
/// it yields that error once and then ends.
pub struct Interpreter<R> {
    reader: R,
    file: Arc<str>,
    line: u32,
    text: String,
    lexer: Lexer,
    block: Block,
    modal: Modal,
    pending: VecDeque<Canon>,
    /// The program opened with a `%` line, so a second `%` ends it.
    percent_opened: bool,
    any_block: bool,
    done: bool,
}

impl Interpreter<BufReader<File>> {
    /// Open a program file; `start` is the machine's current position.
    pub fn open(path: &Path, start: Position) -> io::Result<Self> {
        let file = File::open(path)?;
        Ok(Interpreter::new(
            BufReader::with_capacity(64 * 1024, file),
            path.display().to_string(),
            start,
        ))
    }
}

impl<R: BufRead> Interpreter<R> {
    /// Interpret a program read from `reader`, naming it `file` in sources and
    /// errors; `start` is the machine's current position.
    pub fn new(reader: R, file: impl Into<Arc<str>>, start: Position) -> Self {
        Interpreter {
            reader,
            file: file.into(),
            line: 0,
            text: String::new(),
            lexer: Lexer::default(),
            block: Block::default(),
            modal: Modal {
                motion: None,
                units: Units::Mm,
                incremental: false,
                feed: 0.0,
                position: start,
            },
            pending: VecDeque::new(),
            percent_opened: false,
            any_block: false,
            done: false,
        }
    }

    /// The tool position after the commands yielded so far were interpreted.
    pub fn position(&self) -> Position {
        self.modal.position
    }

    fn error(&self, column: u32, word: Option<String>, message: impl Into<String>) -> InterpError {
        InterpError {
            file: self.file.clone(),
            line: self.line,
            column,
            word,
            message: message.into(),
        }
    }

    fn word_error(&self, w: &Word, message: impl Into<String>) -> InterpError {
        self.error(w.column, Some(word_name(w)), message)
    }

    fn emit(&mut self, cmd: CanonCmd) {
        self.pending.push_back(Canon {
            source: Source {
                file: self.file.clone(),
                line: self.line,
            },
            cmd,
        });
    }

    /// Read and execute the next line. Returns false at end of input.
    fn step(&mut self) -> Result<bool, InterpError> {
        self.text.clear();
        let n = self
            .reader
            .read_line(&mut self.text)
            .map_err(|e| self.error(1, None, format!("cannot read program: {e}")))?;
        if n == 0 {
            return Ok(false);
        }
        self.line += 1;
        let text = std::mem::take(&mut self.text);
        let mut block = std::mem::take(&mut self.block);
        let lexed = self
            .lexer
            .lex(text.trim_end_matches(['\n', '\r']), &mut block);
        self.text = text;
        let result = match lexed {
            Ok(()) => self.execute(&block),
            Err(e) => Err(self.error(e.column, None, e.message)),
        };
        self.block = block;
        result.map(|_| true)
    }

    fn execute(&mut self, block: &Block) -> Result<(), InterpError> {
        if block.percent {
            if !self.any_block {
                self.percent_opened = true;
                self.any_block = true;
                return Ok(());
            }
            if self.percent_opened {
                self.emit(CanonCmd::ProgramEnd);
                self.done = true;
                return Ok(());
            }
            return Err(self.error(1, None, "'%' may only open a program and close it"));
        }
        if block.words.is_empty() && block.comments.is_empty() {
            return Ok(());
        }
        self.any_block = true;
        if block.deleted {
            return Ok(());
        }

        // Sort the block's words into modal groups, rejecting repeats and conflicts.
        let mut motion: Option<(Motion, &Word)> = None;
        let mut units: Option<(Units, &Word)> = None;
        let mut distance: Option<(bool, &Word)> = None;
        let mut dwell: Option<&Word> = None;
        let mut stop: Option<&Word> = None;
        let mut feed: Option<&Word> = None;
        let mut p_word: Option<&Word> = None;
        let mut axes: [Option<&Word>; 9] = [None; 9];
        for w in &block.words {
            match w.letter {
                'G' => {
                    let code = (w.value * 10.0).round() as i64;
                    if (w.value * 10.0 - code as f64).abs() > 1e-6 {
                        return Err(self.word_error(w, "G-codes have at most one decimal place"));
                    }
                    let conflict = match code {
                        0 | 10 => motion
                            .replace((
                                if code == 0 {
                                    Motion::Rapid
                                } else {
                                    Motion::Feed
                                },
                                w,
                            ))
                            .is_some(),
                        40 => dwell.replace(w).is_some(),
                        200 | 210 => units
                            .replace((if code == 200 { Units::Inch } else { Units::Mm }, w))
                            .is_some(),
                        900 | 910 => distance.replace((code == 910, w)).is_some(),
                        _ => {
                            return Err(self.word_error(w, "this G-code is not supported yet"));
                        }
                    };
                    if conflict {
                        return Err(self
                            .word_error(w, "two G-codes from the same modal group in one block"));
                    }
                }
                'M' => {
                    let code = w.value.round() as i64;
                    if (w.value - code as f64).abs() > 1e-6 || !(code == 2 || code == 30) {
                        return Err(self.word_error(w, "this M-code is not supported yet"));
                    }
                    if stop.replace(w).is_some() {
                        return Err(self
                            .word_error(w, "two M-codes from the same modal group in one block"));
                    }
                }
                'N' => {}
                'F' | 'P' => {
                    let slot = if w.letter == 'F' {
                        &mut feed
                    } else {
                        &mut p_word
                    };
                    if slot.replace(w).is_some() {
                        return Err(self.word_error(w, "word repeated in one block"));
                    }
                }
                c => match Axis::from_letter(c) {
                    Some(axis) => {
                        if axes[axis.index()].replace(w).is_some() {
                            return Err(self.word_error(w, "axis word repeated in one block"));
                        }
                    }
                    None => return Err(self.word_error(w, "this word is not supported yet")),
                },
            }
        }

        // LinuxCNC's order of execution: comments, feed, dwell, units,
        // distance mode, motion, stop. Values in the block are read in the
        // units in force after this block's G20/G21.
        for c in &block.comments {
            let t = c.text.trim_start();
            if t.len() >= 4 && t[..4].eq_ignore_ascii_case("MSG,") {
                self.emit(CanonCmd::Message(t[4..].to_string()));
            } else {
                self.emit(CanonCmd::Comment(c.text.clone()));
            }
        }
        let new_units = units.map(|(u, _)| u).unwrap_or(self.modal.units);
        let scale = new_units.mm_per_unit();
        if let Some(w) = feed {
            if w.value < 0.0 {
                return Err(self.word_error(w, "negative feed rate"));
            }
            self.modal.feed = w.value * scale;
            self.emit(CanonCmd::SetFeedRate {
                mm_per_min: self.modal.feed,
            });
        }
        if let Some(w) = dwell {
            let Some(p) = p_word else {
                return Err(self.word_error(w, "dwell time missing: give G4 a P word in seconds"));
            };
            if p.value < 0.0 {
                return Err(self.word_error(p, "negative dwell time"));
            }
            self.emit(CanonCmd::Dwell { seconds: p.value });
        } else if let Some(p) = p_word {
            return Err(self.word_error(p, "P word with no G-code that uses it"));
        }
        if let Some((u, _)) = units {
            self.modal.units = u;
            self.emit(CanonCmd::UseLengthUnits(u));
        }
        if let Some((incremental, _)) = distance {
            self.modal.incremental = incremental;
        }
        if let Some((m, _)) = motion {
            self.modal.motion = Some(m);
        }

        if let Some(first_axis) = axes.iter().flatten().next() {
            let Some(mode) = self.modal.motion else {
                return Err(self.word_error(
                    first_axis,
                    "axis word with no motion mode: program G0 or G1 first",
                ));
            };
            if mode == Motion::Feed && self.modal.feed <= 0.0 {
                let at = motion.map(|(_, w)| w).unwrap_or(first_axis);
                return Err(
                    self.word_error(at, "cannot feed with a zero feed rate: program an F word")
                );
            }
            let mut end = self.modal.position.to_array();
            for (i, w) in axes.iter().enumerate() {
                if let Some(w) = w {
                    let value = if Axis::ALL[i].is_rotary() {
                        w.value
                    } else {
                        w.value * scale
                    };
                    end[i] = if self.modal.incremental {
                        end[i] + value
                    } else {
                        value
                    };
                }
            }
            let end = Position::from_array(end);
            self.modal.position = end;
            self.emit(match mode {
                Motion::Rapid => CanonCmd::StraightTraverse { end },
                Motion::Feed => CanonCmd::StraightFeed { end },
            });
        }

        if stop.is_some() {
            self.emit(CanonCmd::ProgramEnd);
            self.done = true;
        }
        Ok(())
    }
}

/// The canonical spelling of a word's code for error messages: `G1`, `M30`, `X`.
fn word_name(w: &Word) -> String {
    match w.letter {
        'G' | 'M' => {
            if w.value.fract() == 0.0 {
                format!("{}{}", w.letter, w.value as i64)
            } else {
                format!("{}{}", w.letter, w.value)
            }
        }
        c => c.to_string(),
    }
}

impl<R: BufRead> Iterator for Interpreter<R> {
    type Item = Result<Canon, InterpError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(c) = self.pending.pop_front() {
                return Some(Ok(c));
            }
            if self.done {
                return None;
            }
            match self.step() {
                Ok(true) => {}
                Ok(false) => {
                    self.done = true;
                    return Some(Err(self.error(
                        1,
                        None,
                        "file ended with no program end: add M2 or M30 (or close with '%')",
                    )));
                }
                Err(e) => {
                    self.done = true;
                    self.pending.clear();
                    return Some(Err(e));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(text: &str) -> Result<Vec<CanonCmd>, InterpError> {
        Interpreter::new(text.as_bytes(), "t.ngc", Position::ZERO)
            .map(|r| r.map(|c| c.cmd))
            .collect()
    }

    fn ends(cmds: &[CanonCmd]) -> Vec<Position> {
        cmds.iter()
            .filter_map(|c| match c {
                CanonCmd::StraightTraverse { end } | CanonCmd::StraightFeed { end } => Some(*end),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn inch_and_incremental_moves_accumulate_in_mm() {
        let cmds = run("G21 G90 G0 X10 Y20\nG20 G91 G1 X1 Z-0.5 F10\nX1\nM2\n").unwrap();
        let e = ends(&cmds);
        assert_eq!(e[0], Position::xyz(10.0, 20.0, 0.0));
        assert_eq!(e[1], Position::xyz(10.0 + 25.4, 20.0, -12.7));
        assert_eq!(e[2], Position::xyz(10.0 + 50.8, 20.0, -12.7));
        assert!(cmds.contains(&CanonCmd::SetFeedRate { mm_per_min: 254.0 }));
        assert_eq!(cmds.last(), Some(&CanonCmd::ProgramEnd));
    }

    #[test]
    fn sources_carry_file_and_line() {
        let all: Vec<Canon> =
            Interpreter::new("(a)\n\nG0 X1\nM30\n".as_bytes(), "p.ngc", Position::ZERO)
                .collect::<Result<_, _>>()
                .unwrap();
        let mv = all
            .iter()
            .find(|c| matches!(c.cmd, CanonCmd::StraightTraverse { .. }))
            .unwrap();
        assert_eq!(mv.source.to_string(), "p.ngc:3");
    }

    #[test]
    fn errors_locate_the_word() {
        let e = run("G0 X1\nG1 X2\nM2\n").unwrap_err();
        assert_eq!((e.line, e.column), (2, 1));
        assert!(e.message.contains("zero feed rate"), "{e}");
        let e = run("G0 G1 X1\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.ngc:1:4: G1: two G-codes from the same modal group in one block"
        );
        let e = run("G1 F100 X1 X2\n").unwrap_err();
        assert_eq!(e.column, 12);
        let e = run("X1\n").unwrap_err();
        assert!(e.message.contains("no motion mode"));
        let e = run("G0 X1\n").unwrap_err();
        assert!(e.message.contains("no program end"));
    }

    #[test]
    fn stops_after_the_first_error() {
        let out: Vec<_> =
            Interpreter::new("G0 X1\nG7\nG0 X2\nM2\n".as_bytes(), "t.ngc", Position::ZERO)
                .collect();
        assert_eq!(out.len(), 2);
        assert!(out[1].is_err());
    }

    #[test]
    fn percent_delimited_program_and_block_delete() {
        let cmds = run("%\n/G0 X5\nG0 X1\n%\nG0 X9\n").unwrap();
        assert_eq!(ends(&cmds), vec![Position::xyz(1.0, 0.0, 0.0)]);
        assert_eq!(cmds.last(), Some(&CanonCmd::ProgramEnd));
    }
}
