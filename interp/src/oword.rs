//! O-word control flow: subroutines (O… sub/endsub/call/return, M98/M99),
//! if/elseif/else, while, do-while, repeat, break and continue.
//!
//! Like LinuxCNC, the interpreter remembers where each label's line is
//! (file and byte offset) and seeks there to loop or call; it skips lines
//! it must not execute by reading on until the matching label. Only labels
//! are kept in memory, never program text.

use crate::block::{CallType, OType, SUB_PARAMS};
use crate::error::{bail, chk, Fault, R};
use crate::interp::{ExecStatus, Interp, Label, MAX_CALL_LEVELS};

/// LinuxCNC words its duplicate-label error two ways (loops and `if`).
#[derive(Clone, Copy)]
enum LabelWording {
    DefinedIn,
    AlreadyDefined,
}

impl Interp<'_> {
    /// The current block's label, which must have been seen.
    fn defined_label(&self) -> R<Label> {
        self.find_label()
            .cloned()
            .ok_or_else(|| self.undefined_label())
    }

    fn line_text(&self) -> String {
        String::from_utf8_lossy(&self.raw).into_owned()
    }

    /// At the opening line of a loop or `if`: remember the label the first
    /// time; on a later pass the label must be this very line (a second
    /// block with the same label is an error). With `after_do`, a label
    /// left by a `do` is the loop's own.
    fn enter_control_label(&mut self, after_do: bool, wording: LabelWording) -> R {
        let Some(op) = self.find_label() else {
            return self.control_save_offset();
        };
        let defined = op.sequence_number.wrapping_add(1);
        if (after_do && op.kind == OType::Do) || self.sequence_number == defined {
            return Ok(());
        }
        match wording {
            LabelWording::DefinedIn => bail!(
                "{}: duplicate O-word label: '{}' - defined in line {}",
                self.sequence_number,
                self.line_text(),
                defined
            ),
            LabelWording::AlreadyDefined => bail!(
                "{}: duplicate O-word label - already defined in line {}: '{}'",
                self.sequence_number,
                defined,
                self.line_text()
            ),
        }
    }

    /// Remember the current block's label and where its line is.
    pub(crate) fn control_save_offset(&mut self) -> R {
        let name = self.block.o_name.clone();
        if let Some(op) = self.labels.get(&name) {
            let file = self.files[op.file].name.clone();
            if self.sequence_number.wrapping_sub(1) == op.sequence_number {
                bail!(
                    "File:{} line:{} sub: o|{}| found in illegal location",
                    self.files[self.cur_file].name,
                    self.sequence_number,
                    name
                );
            }
            bail!(
                "File:{} line:{} redefining sub: o|{}| already defined in file:{}",
                self.files[self.cur_file].name,
                self.sequence_number,
                name,
                file
            );
        }
        self.labels.insert(
            name,
            Label {
                kind: self.block.o_type,
                file: self.cur_file,
                offset: self.block.offset,
                sequence_number: self.sequence_number.wrapping_sub(1),
                repeat_count: -1,
            },
        );
        Ok(())
    }

    /// Go back to a label's line, or search forward (in this file or a
    /// subroutine file) for a subroutine not seen yet.
    fn control_back_to(&mut self) -> R {
        let name = self.block.o_name.clone();
        if let Some(op) = self.labels.get(&name).cloned() {
            self.seek_to(op.file, op.offset)?;
            self.sequence_number = op.sequence_number;
            return Ok(());
        }
        if let Some(path) = self.find_ngc_file(&name) {
            let file = self.open_file(&path)?;
            self.seek_to(file, 0)?;
            self.sequence_number = 0;
        }
        self.skipping_o = Some(name.clone());
        self.skipping_to_sub = Some(name);
        self.skipping_start = self.sequence_number;
        Ok(())
    }

    fn enter_context(&mut self) -> R {
        chk!(
            self.call_level + 1 >= MAX_CALL_LEVELS,
            "Too many subroutine levels"
        );
        self.call_level += 1;
        let name = self.block.o_name.clone();
        let call_type = self.block.call_type;
        let frame = &mut self.contexts[self.call_level];
        frame.named.clear();
        frame.sub_name = Some(name);
        frame.call_type = call_type;
        frame.m98_loop_counter = -1;
        frame.saved = None;
        frame.restore_on_return = false;
        frame.remap_frame = call_type == CallType::Remap;
        Ok(())
    }

    /// Leave the current subroutine level, restoring M73-saved modes.
    fn leave_context(&mut self, restore: bool) -> R {
        chk!(self.call_level < 1, "Bug: call stack underrun");
        let level = self.call_level;
        self.contexts[level].named.clear();
        self.contexts[level].sub_name = None;
        self.call_level -= 1;
        let frame = &self.contexts[level];
        if restore && frame.restore_on_return && frame.saved.is_some() {
            self.restore_settings(level)?;
        }
        Ok(())
    }

    /// Enter a subroutine: pass arguments in #1–#30 and go to its label.
    pub(crate) fn execute_call(&mut self, call_type: CallType) -> R {
        let level = self.call_level;
        // Where to come back to (also after an error in the call).
        let pos = self.tell();
        let file = self.cur_file;
        let seq = self.sequence_number;
        {
            let prev = &mut self.contexts[level - 1];
            prev.position = pos;
            prev.file = file;
            prev.sequence_number = seq;
        }
        if call_type == CallType::Remap {
            self.remap_add_parameters()?;
        }
        self.skipping_o = None;
        if call_type != CallType::M98Sub {
            for i in 0..SUB_PARAMS {
                self.contexts[level - 1].saved_params[i] = self.params[i + 1];
                self.params[i + 1] = self.block.params.get(i).copied().unwrap_or(0.0);
            }
        }
        if self.cfg.oword_n_args {
            self.add_named_param("n_args", true)?;
            self.store_named_param("n_args", self.block.params.len() as f64, true)?;
        }
        if self.block.o_type == OType::M98 && self.block.has(b'l') {
            let l = self.block.l();
            let offset = self.block.offset;
            let prev = &mut self.contexts[level - 1];
            if prev.m98_loop_counter == -1 {
                prev.m98_loop_counter = l;
            }
            prev.m98_loop_counter -= 1;
            if prev.m98_loop_counter > 0 {
                prev.position = offset;
                prev.sequence_number = prev.sequence_number.saturating_sub(1);
            } else {
                prev.m98_loop_counter = -1;
            }
        }
        // M98 with L0 calls nothing (LinuxCNC then goes on with the next line).
        if self.block.o_type == OType::M98 && self.block.l() == 0 {
            return Ok(());
        }
        if let Err(e) = self.control_back_to() {
            self.call_level -= 1;
            return Err(e);
        }
        Ok(())
    }

    /// Leave a subroutine (endsub, return, M99) or end a definition.
    fn execute_return(&mut self, call_type: CallType) -> R<ExecStatus> {
        if self.skipping_o.is_some() && self.block.o_type == OType::EndSub {
            self.skipping_o = None;
        }
        if self.call_level != 0 {
            let level = self.call_level;
            let remap_frame = self.contexts[level].remap_frame;
            if call_type != CallType::M98Sub {
                for i in 0..SUB_PARAMS {
                    self.params[i + 1] = self.contexts[level - 1].saved_params[i];
                }
            }
            let (file, pos, seq) = {
                let p = &self.contexts[level - 1];
                (p.file, p.position, p.sequence_number)
            };
            self.seek_to(file, pos)?;
            self.sequence_number = seq;
            self.leave_context(true)?;
            self.sub_name = self.contexts[self.call_level].sub_name.clone();
            if remap_frame {
                return self.remap_finished();
            }
        } else if self.block.o_type == OType::EndSub {
            chk!(!self.defining_sub, "Not in subroutine definition");
            self.skipping_o = None;
            self.defining_sub = false;
            self.sub_name = None;
        }
        Ok(ExecStatus::Ok)
    }

    fn find_label(&self) -> Option<&Label> {
        self.labels.get(&self.block.o_name)
    }

    fn undefined_label(&self) -> Fault {
        Fault::new(format!(
            "{}: undefined O-word label: '{}'",
            self.sequence_number,
            self.line_text()
        ))
    }

    fn no_matching(&self, op: &Label, what: &str) -> Fault {
        Fault::new(format!(
            "{}: no matching {what} label: '{}' (found '{}' in line {})",
            self.sequence_number,
            self.line_text(),
            otype_name(op.kind),
            op.sequence_number + 1
        ))
    }

    /// Execute an O-word line (LinuxCNC's `convert_control_functions`).
    pub(crate) fn convert_control_functions(&mut self) -> R<ExecStatus> {
        self.fault_word = Some((crate::interp::WordName::O, self.block.o_col));
        if self
            .skipping_o
            .as_deref()
            .is_some_and(|s| s != self.block.o_name)
        {
            return Ok(ExecStatus::Ok);
        }
        if self.skipping_to_sub.is_some() && !matches!(self.block.o_type, OType::Sub | OType::Bare)
        {
            return Ok(ExecStatus::Ok);
        }
        match self.block.o_type {
            OType::None => {}
            OType::Sub | OType::Bare => {
                let frame_type = self.contexts[self.call_level].call_type;
                chk!(
                    self.block.o_type == OType::Bare
                        && frame_type != CallType::M98Sub
                        && frame_type != CallType::None,
                    "Fanuc 'O....' subroutine must be called with 'M98'"
                );
                chk!(
                    self.block.o_type == OType::Sub
                        && !matches!(
                            frame_type,
                            CallType::NgcSub | CallType::Remap | CallType::None
                        ),
                    "'O.... sub' subroutine must be called with 'O.... call'"
                );
                if self.skipping_o.is_some() {
                    self.control_save_offset()?;
                    self.skipping_o = None;
                }
                self.skipping_to_sub = None;
                if self.block.o_type == OType::Bare {
                    return Ok(ExecStatus::Ok);
                }
                // A sub line inside a called sub's body that is not the sub
                // itself is a definition nested in another.
                chk!(
                    self.call_level != 0
                        && self.contexts[self.call_level].sub_name.as_deref()
                            != Some(self.block.o_name.as_str()),
                    "Nested subroutine definition"
                );
                if self.call_level == 0 {
                    chk!(self.defining_sub, "Nested subroutine definition");
                    self.control_save_offset()?;
                    self.skipping_o = Some(self.block.o_name.clone());
                    self.skipping_start = self.sequence_number;
                    self.defining_sub = true;
                    self.sub_name = Some(self.block.o_name.clone());
                }
            }
            OType::EndSub | OType::Return | OType::M99 => {
                chk!(
                    self.block.o_type == OType::M99 && self.call_level == 0,
                    "Bug:  Reached convert_control_functions() from M99 in main program"
                );
                if self.call_level == 0 && self.sub_name.is_none() {
                    bail!(
                        "{}: not in a subroutine definition: '{}'",
                        self.sequence_number,
                        self.line_text()
                    );
                }
                let frame_type = self.contexts[self.call_level].call_type;
                chk!(
                    frame_type == CallType::M98Sub && self.block.o_type != OType::M99,
                    "Fanuc 'O....' subroutine definition must end with 'M99'"
                );
                chk!(
                    frame_type == CallType::NgcSub
                        && !matches!(self.block.o_type, OType::EndSub | OType::Return),
                    "'O.... endsub' or 'O.... return' must follow 'O.... sub' subroutine definition"
                );
                return self.execute_return(frame_type);
            }
            OType::Call | OType::M98 => {
                self.enter_context()?;
                let call_type = self.contexts[self.call_level].call_type;
                self.execute_call(call_type)?;
            }
            OType::Do => {
                self.skipping_o = None;
                if self.find_label().is_none() {
                    self.control_save_offset()?;
                }
            }
            OType::Repeat => {
                self.enter_control_label(false, LabelWording::DefinedIn)?;
                self.skipping_o = None;
                let name = self.block.o_name.clone();
                let test = self.test_value;
                let seq = self.sequence_number;
                let mut skip = false;
                if let Some(op) = self.labels.get_mut(&name) {
                    if op.kind == OType::Repeat {
                        if op.repeat_count == -1 {
                            op.repeat_count = crate::block::round_to_int(test);
                        }
                        if op.repeat_count > 0 {
                            op.repeat_count -= 1;
                        } else {
                            op.repeat_count = -1;
                            skip = true;
                        }
                    }
                }
                if skip {
                    self.skipping_o = Some(name);
                    self.skipping_start = seq;
                }
            }
            OType::While => {
                // The `while` that closes a `do` shares the do's label.
                self.enter_control_label(true, LabelWording::DefinedIn)?;
                self.skipping_o = None;
                let kind = self.find_label().map(|op| op.kind);
                if kind == Some(OType::While) {
                    if self.test_value == 0.0 {
                        self.skipping_o = Some(self.block.o_name.clone());
                        self.skipping_start = self.sequence_number;
                    }
                } else if self.test_value != 0.0 && !self.doing_break {
                    // The `while` that closes a `do`: loop back.
                    self.control_back_to()?;
                } else {
                    self.doing_break = false;
                }
            }
            OType::If => {
                self.enter_control_label(false, LabelWording::AlreadyDefined)?;
                if self.test_value != 0.0 {
                    self.skipping_o = None;
                    self.executed_if = true;
                } else {
                    self.skipping_o = Some(self.block.o_name.clone());
                    self.skipping_start = self.sequence_number;
                    self.executed_if = false;
                }
            }
            OType::ElseIf => {
                let op = self.defined_label()?;
                if op.kind != OType::If {
                    return Err(self.no_matching(&op, "'if'"));
                }
                if self
                    .skipping_o
                    .as_deref()
                    .is_some_and(|s| s != self.block.o_name)
                {
                    return Ok(ExecStatus::Ok);
                }
                if self.executed_if {
                    self.skipping_o = Some(self.block.o_name.clone());
                    self.skipping_start = self.sequence_number;
                    return Ok(ExecStatus::Ok);
                }
                if self.test_value != 0.0 {
                    self.skipping_o = None;
                    self.executed_if = true;
                }
            }
            OType::Else => {
                let op = self.defined_label()?;
                if op.kind != OType::If {
                    return Err(self.no_matching(&op, "'if'"));
                }
                if self.executed_if {
                    self.skipping_o = Some(self.block.o_name.clone());
                    self.skipping_start = self.sequence_number;
                    return Ok(ExecStatus::Ok);
                }
                if self.skipping_o.as_deref() == Some(self.block.o_name.as_str()) {
                    self.executed_if = true;
                    self.skipping_o = None;
                }
            }
            OType::EndIf => {
                let op = self.defined_label()?;
                if op.kind != OType::If {
                    return Err(self.no_matching(&op, ""));
                }
                self.skipping_o = None;
                self.executed_if = true;
            }
            OType::Break => {
                let op = self.defined_label()?;
                if op.kind != OType::While && op.kind != OType::Do {
                    return Err(self.no_matching(&op, "while/do"));
                }
                self.skipping_o = Some(self.block.o_name.clone());
                self.skipping_start = self.sequence_number;
                self.doing_break = true;
            }
            OType::Continue => {
                let op = self.defined_label()?;
                if op.kind != OType::While && op.kind != OType::Do {
                    return Err(self.no_matching(&op, "while/do"));
                }
                if self.skipping_o.as_deref() == Some(self.block.o_name.as_str()) {
                    return Ok(ExecStatus::Ok);
                }
                self.skipping_o = Some(self.block.o_name.clone());
                self.skipping_start = self.sequence_number;
                self.doing_continue = true;
            }
            OType::EndRepeat | OType::EndWhile => {
                let op = self.defined_label()?;
                if (self.block.o_type == OType::EndRepeat && op.kind != OType::Repeat)
                    || (self.block.o_type == OType::EndWhile && op.kind != OType::While)
                {
                    return Err(self.no_matching(&op, ""));
                }
                if self.skipping_o.as_deref() == Some(self.block.o_name.as_str()) {
                    self.skipping_o = None;
                    if self.doing_continue {
                        self.doing_continue = false;
                        self.control_back_to()?;
                    }
                } else {
                    self.control_back_to()?;
                }
            }
        }
        Ok(ExecStatus::Ok)
    }
}

/// LinuxCNC's name for an O-word kind in messages (`sub`, `while`, …).
fn otype_name(t: OType) -> &'static str {
    match t {
        OType::None => "none",
        OType::Sub => "sub",
        OType::EndSub => "endsub",
        OType::Call => "call",
        OType::Do => "do",
        OType::While => "while",
        OType::If => "if",
        OType::ElseIf => "elseif",
        OType::Else => "else",
        OType::EndIf => "endif",
        OType::Break => "break",
        OType::Continue => "continue",
        OType::EndWhile => "endwhile",
        OType::Return => "return",
        OType::Repeat => "repeat",
        OType::EndRepeat => "endrepeat",
        OType::M98 => "98",
        OType::M99 => "99",
        OType::Bare => "",
    }
}
