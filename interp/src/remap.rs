//! Remapped codes: G-, M-, T-, S- and F-codes replaced by NGC subroutines
//! (`[RS274NGC] REMAP=`), following LinuxCNC's remap semantics.
//!
//! A block holding remapped codes runs in phases, in LinuxCNC's order of
//! execution: everything up to the first remapped code runs, then the
//! code's subroutine is called; when it returns, the block carries on to
//! the next remapped code, and so on. Steps already done are remembered so
//! each runs once. Inside a remap subroutine the code it replaces has its
//! built-in meaning (so an M6 remap can call M6).

use crate::block::{step, Block, CallType, OType};
use crate::error::{chk, Fault, R};
use crate::interp::{ExecStatus, Interp};

/// Most remapped blocks that may be nested.
const MAX_NESTED_REMAPS: usize = 10;

impl Interp<'_> {
    /// The remap for code `letter` `number` (M number, G×10; 0 for T S F).
    pub(crate) fn remap_for(&self, letter: char, number: i32) -> Option<usize> {
        if self.cfg.remaps.is_empty() || number < 0 {
            return None;
        }
        self.cfg.remaps.iter().position(|r| {
            r.letter == letter && (r.number == number || matches!(letter, 't' | 's' | 'f'))
        })
    }

    /// True if the remap for this code is running in an outer block.
    fn remap_in_progress(&self, letter: char, number: i32) -> bool {
        match self.remap_for(letter, number) {
            Some(r) => self
                .remap_blocks
                .iter()
                .any(|b| b.executing_remap == Some(r)),
            None => false,
        }
    }

    /// Note which steps of a freshly parsed block are remapped.
    pub(crate) fn find_remappings(&mut self, b: &mut Block) {
        if self.cfg.remaps.is_empty() {
            return;
        }
        let mut steps: Vec<u32> = Vec::new();
        for (letter, s) in [
            ('f', step::SET_FEED_RATE),
            ('s', step::SET_SPINDLE_SPEED),
            ('t', step::PREPARE),
        ] {
            if b.has(letter as u8)
                && self.remap_for(letter, 0).is_some()
                && !self.remap_in_progress(letter, 0)
            {
                steps.push(s);
            }
        }
        let user = |s: &Self, group: usize| {
            let m = b.m_modes[group];
            m != -1 && s.remap_for('m', m).is_some()
        };
        if user(self, 5) {
            let m = b.m_modes[5];
            if !((62..=68).contains(&m) && self.remap_in_progress('m', m)) {
                steps.push(step::M_5);
            }
        }
        if user(self, 6) {
            let m = b.m_modes[6];
            if !((m == 6 || m == 61) && self.remap_in_progress('m', m)) {
                steps.push(step::M_6);
            }
        }
        for (group, s) in [
            (7, step::M_7),
            (8, step::M_8),
            (9, step::M_9),
            (10, step::M_10),
        ] {
            if user(self, group) {
                steps.push(s);
            }
        }
        let mode = b.g_modes[crate::block::gm::MOTION];
        if (mode != -1 && self.remap_for('g', mode).is_some())
            || (b.motion_to_be != -1 && self.remap_for('g', b.motion_to_be).is_some())
        {
            steps.push(step::MOTION);
        }
        if user(self, 4) {
            let m = b.m_modes[4];
            if !(matches!(m, 0 | 1 | 60) && self.remap_in_progress('m', m)) {
                steps.push(step::MGROUP4);
            }
        }
        steps.sort_unstable();
        steps.dedup();
        b.remappings = steps;
    }

    /// Start the subroutine of a remapped code found in the controlling
    /// block `b`: prepare an `O<name> call` in the executing block.
    pub(crate) fn convert_remapped_code(
        &mut self,
        b: &mut Block,
        phase: u32,
        letter: char,
        number: i32,
    ) -> R<ExecStatus> {
        let r = self
            .remap_for(letter, number)
            .ok_or_else(|| Fault::new("BUG: convert_remapped_code: no remapping"))?;
        b.executing_remap = Some(r);
        b.phase = phase;
        let remap = self.cfg.remaps[r].clone();
        let mut call = Block {
            o_type: OType::Call,
            o_name: remap.ngc.clone(),
            call_type: CallType::Remap,
            line_number: self.sequence_number,
            ..Block::default()
        };
        if remap.argspec.as_deref().is_some_and(|a| a.contains('@')) {
            // Positional arguments, rounded to four places as LinuxCNC
            // passes them through text.
            let args = self.remap_arguments(b, r)?;
            for (_, v) in args {
                let rounded: f64 = format!("{v:.4}").parse().unwrap_or(v);
                call.params.push(rounded);
            }
        }
        self.line_text_override = Some(format!("O <{}> call ", remap.ngc));
        *self.block = call;
        Ok(ExecStatus::Remap)
    }

    /// The words a remap's argspec asks for, in argspec order, checking
    /// the required ones are there.
    fn remap_arguments(&self, b: &Block, r: usize) -> R<Vec<(String, f64)>> {
        let remap = &self.cfg.remaps[r];
        let spec = remap.argspec.clone().unwrap_or_default();
        let mut required = String::new();
        let mut optional = String::new();
        for c in spec.chars() {
            if c.is_ascii_uppercase() && !required.contains(c.to_ascii_lowercase()) {
                required.push(c.to_ascii_lowercase());
            }
            if c.is_ascii_lowercase() && !optional.contains(c) {
                optional.push(c);
            }
            if ">^Nn".contains(c) && !required.contains(c) {
                required.push(c);
            }
        }
        let mut args = Vec::new();
        let mut missing = Vec::new();
        for c in spec.chars() {
            let l = c.to_ascii_lowercase();
            if !l.is_ascii_lowercase() || l == 'n' || l == 'o' || l == 'g' || l == 'm' {
                continue;
            }
            match b.get(l as u8) {
                Some(v) => {
                    if required.contains(l) || optional.contains(l) {
                        args.push((l.to_string(), v));
                    }
                }
                None => {
                    if required.contains(l) {
                        missing.push(l.to_ascii_uppercase());
                    }
                }
            }
        }
        let mut tail = String::new();
        if !missing.is_empty() {
            tail.push_str(" missing: ");
            tail.push_str(
                &missing
                    .iter()
                    .map(|c| c.to_string())
                    .collect::<Vec<_>>()
                    .join(","),
            );
        }
        let mut errored = !missing.is_empty();
        if required.contains('n') || required.contains('N') {
            args.push(("n".into(), b.line_number as f64));
        }
        if required.contains('>') {
            if self.feed_rate > 0.0 {
                args.push(("f".into(), self.feed_rate));
            } else {
                tail.push_str("F>0,");
                errored = true;
            }
        }
        if required.contains('^') {
            if self.speed > 0.0 {
                args.push(("s".into(), self.speed));
            } else {
                tail.push_str("S>0,");
                errored = true;
            }
        }
        chk!(errored, "user-defined {}:{}", remap.name, tail);
        Ok(args)
    }

    /// In a remap subroutine's frame, define its argspec words as local
    /// named parameters (unless they are passed by position).
    pub(crate) fn remap_add_parameters(&mut self) -> R {
        let Some(cb) = self.remap_blocks.last() else {
            return Ok(());
        };
        let Some(r) = cb.executing_remap else {
            return Ok(());
        };
        let spec = self.cfg.remaps[r].argspec.clone();
        if spec.as_deref().is_none_or(|s| s.contains('@')) {
            return Ok(());
        }
        let cb = cb.clone();
        for (name, v) in self.remap_arguments(&cb, r)? {
            self.add_named_param(&name, false)?;
            self.store_named_param(&name, v, false)?;
        }
        Ok(())
    }

    /// Execute a block that holds remapped codes.
    pub(crate) fn execute_remapped_block(&mut self) -> R<ExecStatus> {
        chk!(
            self.remap_blocks.len() + 1 >= MAX_NESTED_REMAPS,
            "maximum nesting of remapped blocks exceeded"
        );
        let mut cb = (*self.block).clone();
        cb.breadcrumbs = 0;
        cb.executing_remap = None;
        cb.line_number = self.sequence_number;
        cb.phase = cb.remappings.first().copied().unwrap_or(0);
        self.remap_blocks.push(cb);
        self.sequence_number = 0;
        self.continue_controlling_block()
    }

    /// Run the controlling block on from where it stopped: to its next
    /// remapped code (whose subroutine is then started) or to its end.
    fn continue_controlling_block(&mut self) -> R<ExecStatus> {
        let Some(mut cb) = self.remap_blocks.pop() else {
            return Err(Fault::new("BUG: no controlling block"));
        };
        let status = self.execute_block(&mut cb);
        let saved_line = cb.line_number;
        self.remap_blocks.push(cb);
        match status? {
            ExecStatus::Remap => self.convert_control_functions(),
            other => {
                if other != ExecStatus::Exit {
                    self.remap_blocks.pop();
                    self.sequence_number = saved_line;
                }
                Ok(other)
            }
        }
    }

    /// A remap subroutine returned: go on with its block.
    pub(crate) fn remap_finished(&mut self) -> R<ExecStatus> {
        let Some(cb) = self.remap_blocks.last_mut() else {
            return Err(Fault::new(
                "BUG: remap_finished without a controlling block",
            ));
        };
        let phase = cb.phase;
        cb.remappings.retain(|&s| s != phase);
        if let Some(&next) = cb.remappings.first() {
            cb.phase = next;
        }
        self.continue_controlling_block()
    }
}
