//! Executing a block in LinuxCNC's order: comment, spindle mode, feed mode,
//! feed rate, spindle speed, tool selection, M-codes (I/O, tool change,
//! spindle, coolant, overrides, user codes), G-codes (dwell, plane, units,
//! lathe mode, cutter compensation, tool length offset, coordinate system,
//! path control, distance modes, retract mode, G10/G28/G30/G52/G92, motion)
//! and last the stopping M-codes.

use crate::block::{g, gm, round_to_int, step, Block};
use crate::canon::{CanonCmd, MotionMode, OrientDirection, Plane, Units};
use crate::emit::rotate;
use crate::error::{bail, chk, Fault, R};
use crate::interp::{
    gcode_name, Distance, ExecStatus, FeedMode, Interp, Retract, SavedModes, Side, Turning,
    WordName, A, C, X, Y, Z,
};

/// kerf's built-in M-code: cutting-force control on (`M170 P`*newtons*).
const M_FORCE_ON: i32 = 170;
/// kerf's built-in M-code: cutting-force control off.
const M_FORCE_OFF: i32 = 171;

/// Inch per mm, for unit changes.
const INCH_PER_MM: f64 = 1.0 / 25.4;

impl Block {
    /// True the first time a step runs in this block (remapped blocks run
    /// in several phases; each step must run once).
    pub(crate) fn once(&mut self, s: u32) -> bool {
        let bit = 1u64 << s;
        if self.breadcrumbs & bit != 0 {
            false
        } else {
            self.breadcrumbs |= bit;
            true
        }
    }

    /// True if step `s` of this block is remapped.
    pub(crate) fn remapped(&self, s: u32) -> bool {
        self.remappings.contains(&s)
    }
}

impl Interp<'_> {
    fn point_g(&mut self, b: &Block, group: usize) {
        let code = b.g_modes[group];
        if code >= 0 {
            self.fault_word = Some((WordName::G(code), b.g_cols[group]));
        }
    }

    fn point_m(&mut self, b: &Block, group: usize) {
        let code = b.m_modes[group];
        if code >= 0 {
            self.fault_word = Some((WordName::M(code), b.m_cols[group]));
        }
    }

    fn point_word(&mut self, b: &Block, letter: u8) {
        if b.has(letter) {
            self.fault_word = Some((WordName::Letter(letter), b.col(letter)));
        }
    }

    /// Run a parsed block. Returns `Exit` at program end.
    pub(crate) fn execute_block(&mut self, b: &mut Block) -> R<ExecStatus> {
        // An empty `()` is no comment at all (LinuxCNC tests the first
        // character of the stored text).
        if b.comment.as_deref().is_some_and(|c| !c.is_empty()) && b.once(step::COMMENT) {
            let text = b.comment.clone().unwrap_or_default();
            self.convert_comment(&text, true)?;
        }
        if b.g_modes[gm::SPINDLE_MODE] != -1 && b.once(step::SPINDLE_MODE) {
            self.point_g(b, gm::SPINDLE_MODE);
            self.convert_spindle_mode(b)?;
        }
        if b.g_modes[gm::FEED_MODE] != -1 && b.once(step::FEED_MODE) {
            self.point_g(b, gm::FEED_MODE);
            self.convert_feed_mode(b.g_modes[gm::FEED_MODE]);
        }
        if let Some(f) = b.get(b'f') {
            if self.feed_mode != FeedMode::InverseTime && b.once(step::SET_FEED_RATE) {
                if b.remapped(step::SET_FEED_RATE) {
                    return self.convert_remapped_code(b, step::SET_FEED_RATE, 'f', 0);
                }
                self.feed_rate = f;
                self.enqueue(CanonCmd::SetFeedRate {
                    mm_per_min: self.len_mm(f),
                });
            }
        }
        if let Some(s) = b.get(b's') {
            if b.once(step::SET_SPINDLE_SPEED) {
                if b.remapped(step::SET_SPINDLE_SPEED) {
                    return self.convert_remapped_code(b, step::SET_SPINDLE_SPEED, 's', 0);
                }
                self.point_word(b, b's');
                self.speed = s;
                self.enqueue(CanonCmd::SetSpindleSpeed { spindle: 0, rpm: s });
            }
        }
        if b.has(b't') && b.once(step::PREPARE) {
            if b.remapped(step::PREPARE) {
                return self.convert_remapped_code(b, step::PREPARE, 't', 0);
            }
            self.point_word(b, b't');
            self.convert_tool_select(b)?;
        }
        if let Some(status) = self.convert_m(b)? {
            return Ok(status);
        }
        if let Some(status) = self.convert_g(b)? {
            return Ok(status);
        }
        if b.m_modes[4] != -1 && b.once(step::MGROUP4) {
            self.point_m(b, 4);
            if b.remapped(step::MGROUP4) {
                return self.convert_remapped_code(b, step::MGROUP4, 'm', b.m_modes[4]);
            }
            return self.convert_stop(b);
        }
        Ok(ExecStatus::Ok)
    }

    // ------------------------------------------------------------------
    // comments

    /// A comment: operator messages, debug output, logging, abort, or a
    /// plain comment.
    pub(crate) fn convert_comment(&mut self, comment: &str, enqueue: bool) -> R {
        let start = comment.len() - comment.trim_start().len();
        let body = &comment[start..];
        let lc = body.to_ascii_lowercase();
        let after = |prefix: &str| &body[prefix.len()..];
        if lc.starts_with("msg,") {
            self.emit(CanonCmd::Message(after("msg,").to_string()));
        } else if lc.starts_with("debug,") {
            let text = self.convert_param_comment(after("debug,"))?;
            if self.params[5599] > 0.0 {
                self.emit(CanonCmd::Message(text));
            }
        } else if lc.starts_with("print,") {
            let text = self.convert_param_comment(after("print,"))?;
            self.emit(CanonCmd::Print(text));
        } else if lc.starts_with("log,") {
            let text = self.convert_param_comment(after("log,"))?;
            self.emit(CanonCmd::Log(text));
        } else if lc.starts_with("logopen,") {
            self.emit(CanonCmd::LogOpen(after("logopen,").to_string()));
        } else if lc.starts_with("logappend,") {
            self.emit(CanonCmd::LogAppend(after("logappend,").to_string()));
        } else if lc.starts_with("py,") || lc.starts_with("pyrun,") || lc.starts_with("pyreload") {
            bail!("Python comments (PY, PYRUN, PYRELOAD) are not supported");
        } else if lc.starts_with("abort,") {
            let text = self.convert_param_comment(after("abort,"))?;
            return Err(Fault::new(text));
        } else if lc == "logclose" {
            self.emit(CanonCmd::LogClose);
        } else if enqueue {
            self.enqueue(CanonCmd::Comment(body.to_string()));
        }
        Ok(())
    }

    /// Substitute `#n` and `#<name>` in a comment, formatted with `%d`,
    /// `%f` or `%.Nf` if one was given before them (default six places).
    fn convert_param_comment(&mut self, text: &str) -> R<String> {
        let c = text.as_bytes();
        let mut out = String::with_capacity(text.len() + 16);
        let mut decimals: usize = 6;
        let mut i = 0;
        while i < c.len() {
            match c[i] {
                b'%' => {
                    i += 1;
                    match c.get(i) {
                        Some(b'd') => {
                            i += 1;
                            decimals = 0;
                        }
                        Some(b'f') => {
                            i += 1;
                            decimals = 4;
                        }
                        Some(b'.') => {
                            i += 1;
                            if c.get(i).is_some_and(|d| d.is_ascii_digit()) {
                                if c.get(i + 1) == Some(&b'f') {
                                    decimals = (c[i] - b'0') as usize;
                                    i += 2;
                                } else {
                                    out.push('.');
                                }
                            } else {
                                out.push('.');
                            }
                        }
                        _ => out.push('%'),
                    }
                }
                b'#' => {
                    i += 1;
                    chk!(i >= c.len(), "Named parameter not terminated");
                    let value = if c[i].is_ascii_digit() {
                        let s = i;
                        while i < c.len() && c[i].is_ascii_digit() {
                            i += 1;
                        }
                        let n: usize = text[s..i].parse().unwrap_or(usize::MAX);
                        self.params.get(n).copied()
                    } else if c[i] == b'<' {
                        i += 1;
                        chk!(i >= c.len(), "Named parameter not terminated");
                        let mut name = String::new();
                        while i < c.len() && c[i] != b')' && c[i] != b'>' {
                            if !c[i].is_ascii_whitespace() {
                                name.push(if self.cfg.no_downcase_oword {
                                    c[i] as char
                                } else {
                                    c[i].to_ascii_lowercase() as char
                                });
                            }
                            i += 1;
                        }
                        chk!(
                            i >= c.len() || c[i] != b'>',
                            "Named parameter not terminated"
                        );
                        i += 1;
                        self.find_named_param(&name).ok().flatten()
                    } else {
                        out.push('#');
                        continue;
                    };
                    match value {
                        Some(v) => {
                            let v = if (v - 0.0).abs() < 0.0001 { 0.0 } else { v };
                            out.push_str(&format!("{v:.decimals$}"));
                        }
                        None => out.push_str("######"),
                    }
                }
                _ => {
                    let s = i;
                    while i < c.len() && c[i] != b'%' && c[i] != b'#' {
                        i += 1;
                    }
                    out.push_str(&text[s..i]);
                }
            }
        }
        Ok(out)
    }

    // ------------------------------------------------------------------
    // feed, speed, spindle modes, tools

    fn convert_spindle_mode(&mut self, b: &Block) -> R {
        if b.g_modes[gm::SPINDLE_MODE] == g::G97 {
            self.css_mode = false;
            self.enqueue(CanonCmd::SetSpindleMode {
                spindle: 0,
                css_max_rpm: 0.0,
            });
        } else {
            self.css_mode = true;
            let max = b.get(b'd').map(f64::abs).unwrap_or(1e30);
            self.enqueue(CanonCmd::SetSpindleMode {
                spindle: 0,
                css_max_rpm: max,
            });
        }
        Ok(())
    }

    fn convert_feed_mode(&mut self, code: i32) {
        match code {
            g::G93 => {
                self.enqueue_debug_comment("interpreter: feed mode set to inverse time");
                self.feed_mode = FeedMode::InverseTime;
                self.enqueue(CanonCmd::SetFeedMode {
                    spindle: 0,
                    per_revolution: false,
                });
            }
            g::G94 => {
                self.enqueue_debug_comment("interpreter: feed mode set to units per minute");
                self.feed_mode = FeedMode::UnitsPerMinute;
                self.enqueue(CanonCmd::SetFeedMode {
                    spindle: 0,
                    per_revolution: false,
                });
                self.feed_rate = 0.0;
                self.enqueue(CanonCmd::SetFeedRate { mm_per_min: 0.0 });
            }
            _ => {
                self.enqueue_debug_comment("interpreter: feed mode set to units per revolution");
                self.feed_mode = FeedMode::UnitsPerRevolution;
                self.enqueue(CanonCmd::SetFeedMode {
                    spindle: self.active_spindle,
                    per_revolution: true,
                });
                self.feed_rate = 0.0;
                self.enqueue(CanonCmd::SetFeedRate { mm_per_min: 0.0 });
            }
        }
    }

    /// The comments LinuxCNC's interpreter gives about mode changes (it is
    /// built with them on; they show in its output).
    pub(crate) fn enqueue_debug_comment(&mut self, text: &str) {
        self.enqueue(CanonCmd::Comment(text.to_string()));
    }

    /// The tool table index of tool `tool`.
    pub(crate) fn find_tool_index(&self, tool: i32) -> R<usize> {
        self.tools
            .find(tool)
            .ok_or_else(|| Fault::new(format!("Requested tool {tool} not found in the tool table")))
    }

    fn convert_tool_select(&mut self, b: &Block) -> R {
        let t = b.or(b't', 0.0) as i32;
        let idx = self.find_tool_index(t)?;
        self.emit(CanonCmd::SelectTool {
            tool: t,
            pocket: self.tools.get(idx).pocket,
        });
        self.selected_pocket = idx as i32;
        self.selected_tool = t;
        Ok(())
    }

    pub(crate) fn convert_tool_change(&mut self) -> R {
        chk!(self.selected_pocket < 0, "Txx missing for M6");
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot change tools with cutter radius compensation on"
        );
        self.emit(CanonCmd::StartChange);
        if !self.cfg.tool_change_with_spindle_on {
            self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
            self.spindle_turning = Turning::Stopped;
        }
        if self.cfg.tool_change_quill_up {
            let rel = self.find_relative([0.0; 9]);
            self.emit(CanonCmd::Comment("AXIS,hide".into()));
            let mut p = self.cur;
            p[Z] = rel[Z];
            self.canon_straight_traverse(p);
            self.emit(CanonCmd::Comment("AXIS,show".into()));
            self.cur[Z] = rel[Z];
        }
        if self.cfg.tool_change_at_g30 {
            let home = self.home_params(5181);
            let end = self.find_relative(home);
            self.emit(CanonCmd::Comment("AXIS,hide".into()));
            self.canon_straight_traverse(end);
            self.emit(CanonCmd::Comment("AXIS,show".into()));
            self.cur = end;
        }
        let idx = self.selected_pocket.max(0) as usize;
        let data = self.tools.get(idx);
        self.emit(CanonCmd::ChangeTool {
            tool: self.selected_tool,
            pocket: data.pocket,
        });
        self.current_pocket = self.selected_pocket;
        if !self.tools.random_toolchanger() {
            self.tools.put(0, data);
        } else {
            let spindle = self.tools.get(0);
            self.tools.put(0, data);
            self.tools.put(idx, spindle);
        }
        self.toolchange_flag = true;
        self.set_tool_parameters();
        Ok(())
    }

    /// The G28 (5161) or G30 (5181) home position in program units.
    fn home_params(&self, base: usize) -> [f64; 9] {
        let mut p = [0.0; 9];
        for i in 0..9 {
            p[i] = self.user_to_program(i, self.params[base + i]);
        }
        p
    }

    /// Absolute (machine-relative, program units) coordinates to the
    /// current work system: LinuxCNC's `find_relative`.
    pub(crate) fn find_relative(&self, abs: [f64; 9]) -> [f64; 9] {
        let mut r = [0.0; 9];
        let (x, y) = rotate(
            abs[X] - self.origin_offset[X] - self.tool_offset[X],
            abs[Y] - self.origin_offset[Y] - self.tool_offset[Y],
            -self.rotation_xy,
        );
        r[X] = x - self.axis_offset[X];
        r[Y] = y - self.axis_offset[Y];
        for i in 2..9 {
            r[i] = abs[i] - self.origin_offset[i] - self.axis_offset[i];
            if !(A..=C).contains(&i) {
                r[i] -= self.tool_offset[i];
            }
        }
        r
    }

    // ------------------------------------------------------------------
    // M-codes

    /// Returns `Some` if a remapped code took over the block.
    fn convert_m(&mut self, b: &mut Block) -> R<Option<ExecStatus>> {
        let m5 = b.m_modes[5];
        if m5 != -1 && b.remapped(step::M_5) && b.once(step::M_5) {
            return self.convert_remapped_code(b, step::M_5, 'm', m5).map(Some);
        }
        if m5 != -1 && b.once(step::M_5) {
            self.point_m(b, 5);
            let comp_on = self.cutter_comp_side != Side::Off;
            let p = b.get(b'p');
            let index = |v: f64| round_to_int(v).max(0) as u32;
            match m5 {
                62..=65 => {
                    let what = match m5 {
                        62 => "Cannot set motion output with cutter radius compensation on",
                        63 => "Cannot set motion digital output with cutter radius compensation on",
                        _ => {
                            "Cannot set auxiliary digital output with cutter radius compensation on"
                        }
                    };
                    chk!(comp_on, "{what}");
                    let Some(p) = p else {
                        bail!("No valid P word with M{m5}");
                    };
                    let i = index(p);
                    self.emit(match m5 {
                        62 => CanonCmd::SetMotionOutputBit { index: i },
                        63 => CanonCmd::ClearMotionOutputBit { index: i },
                        64 => CanonCmd::SetAuxOutputBit { index: i },
                        _ => CanonCmd::ClearAuxOutputBit { index: i },
                    });
                }
                66 => {
                    let e = b.get(b'e');
                    chk!(
                        p.is_some() && e.is_some(),
                        "Both digital and analog input selected"
                    );
                    let l = b.get(b'l').map(round_to_int);
                    chk!(
                        b.q() <= 0.0 && l.is_some_and(|l| l > 0),
                        "Zero timeout with wait not immediate"
                    );
                    chk!(
                        e.is_some() && l.is_some_and(|l| l != 0),
                        "Analog input with wait not immediate"
                    );
                    chk!(
                        p.is_some_and(|p| round_to_int(p) < 0)
                            || e.is_some_and(|e| round_to_int(e) < 0)
                            || (p.is_none() && e.is_none()),
                        "Invalid or missing P and E words for wait input"
                    );
                    if let Some(p) = p {
                        let mode = l.unwrap_or(0);
                        chk!(
                            !(0..=4).contains(&mode),
                            "Invalid wait type {mode} with M66"
                        );
                        let timeout = if b.q() > 0.0 { b.q() } else { 0.0 };
                        chk!(
                            comp_on,
                            "Cannot wait for digital input with cutter radius compensation on"
                        );
                        self.emit(CanonCmd::WaitInput {
                            index: index(p),
                            digital: true,
                            mode: mode as u8,
                            timeout,
                        });
                        self.input_flag = true;
                        self.input_index = index(p);
                        self.input_digital = true;
                        self.input_mode = mode as u8;
                        self.input_timeout = timeout;
                    } else if let Some(e) = e {
                        chk!(
                            comp_on,
                            "Cannot wait for analog input with cutter radius compensation on"
                        );
                        self.emit(CanonCmd::WaitInput {
                            index: index(e),
                            digital: false,
                            mode: 0,
                            timeout: 0.0,
                        });
                        self.input_flag = true;
                        self.input_index = index(e);
                        self.input_digital = false;
                        self.input_mode = 0;
                        self.input_timeout = 0.0;
                    }
                }
                67 | 68 => {
                    chk!(
                        comp_on,
                        "Cannot set {} analog output with cutter radius compensation on",
                        if m5 == 67 { "motion" } else { "auxiliary" }
                    );
                    let e = b.get(b'e');
                    chk!(
                        e.is_none() || e.is_some_and(|e| round_to_int(e) < 0),
                        "Invalid analog index with M{m5}"
                    );
                    let i = index(e.unwrap_or(0.0));
                    let value = b.q();
                    self.emit(if m5 == 67 {
                        CanonCmd::SetMotionOutputValue { index: i, value }
                    } else {
                        CanonCmd::SetAuxOutputValue { index: i, value }
                    });
                }
                _ => {}
            }
        }
        let m6 = b.m_modes[6];
        if m6 != -1 && b.once(step::M_6) {
            self.point_m(b, 6);
            let remapped = b.remapped(step::M_6);
            if remapped {
                return self.convert_remapped_code(b, step::M_6, 'm', m6).map(Some);
            }
            match m6 {
                6 => self.convert_tool_change()?,
                61 => {
                    let tool = round_to_int(b.q());
                    chk!(
                        tool < 0,
                        "Need non-negative Q-word to specify tool number with M61"
                    );
                    let idx = self.find_tool_index(tool)?;
                    self.current_pocket = idx as i32;
                    self.toolchange_flag = true;
                    self.emit(CanonCmd::ChangeToolNumber { tool });
                    let data = self.tools.get(idx);
                    self.tools.put(0, data);
                    self.set_tool_parameters();
                }
                _ => {}
            }
        }
        if self.cfg.retain_g43
            && self.tool_offset.iter().any(|&v| v != 0.0)
            && b.once(step::RETAIN_G43)
        {
            let mut g43 = Block::default();
            if self.selected_pocket > 0 {
                self.convert_tool_length_offset(g::G43, &mut g43)?;
            } else {
                self.convert_tool_length_offset(g::G49, &mut g43)?;
            }
        }
        let m7 = b.m_modes[7];
        if m7 != -1 && b.remapped(step::M_7) && b.once(step::M_7) {
            return self.convert_remapped_code(b, step::M_7, 'm', m7).map(Some);
        }
        if m7 != -1 && b.once(step::M_7) {
            self.point_m(b, 7);
            chk!(
                b.dollar.is_some_and(|d| d != 0.0 && d != -1.0),
                "Spindle ($) number out of range in M{m7} Command"
            );
            match m7 {
                3 => {
                    self.enqueue(CanonCmd::StartSpindleClockwise { spindle: 0 });
                    self.spindle_turning = Turning::Clockwise;
                }
                4 => {
                    self.enqueue(CanonCmd::StartSpindleCounterclockwise { spindle: 0 });
                    self.spindle_turning = Turning::CounterClockwise;
                }
                5 => {
                    self.spindle_turning = Turning::Stopped;
                    self.enqueue(CanonCmd::StopSpindleTurning { spindle: 0 });
                }
                19 => {
                    self.spindle_turning = Turning::Stopped;
                    if b.has(b'r') || b.has(b'p') {
                        let degrees = b
                            .get(b'r')
                            .map(|r| r + self.cfg.orient_offset)
                            .unwrap_or(self.cfg.orient_offset);
                        let direction = match b.get(b'p').map(round_to_int).unwrap_or(0) {
                            1 => OrientDirection::Clockwise,
                            2 => OrientDirection::CounterClockwise,
                            _ => OrientDirection::Either,
                        };
                        self.enqueue(CanonCmd::OrientSpindle {
                            spindle: 0,
                            degrees,
                            direction,
                        });
                    }
                    if let Some(q) = b.get(b'q') {
                        chk!(q <= 0.0, "Q word with M19 requires a value > 0");
                        self.enqueue(CanonCmd::WaitSpindleOrientComplete {
                            spindle: 0,
                            timeout: q,
                        });
                    }
                }
                70 | 73 => {
                    let saved = self.save_modes();
                    let level = self.call_level;
                    self.contexts[level].saved = Some(saved);
                    if m7 == 73 && level > 0 {
                        self.contexts[level].restore_on_return = true;
                    }
                }
                71 => {
                    let level = self.call_level;
                    self.contexts[level].saved = None;
                }
                72 => {
                    chk!(
                        self.contexts[self.call_level].saved.is_none(),
                        "Cannot restore context from invalid stack frame - missing M70/M73?"
                    );
                    self.restore_settings(self.call_level)?;
                }
                _ => {}
            }
        }
        let m8 = b.m_modes[8];
        if m8 != -1 && b.remapped(step::M_8) && b.once(step::M_8) {
            return self.convert_remapped_code(b, step::M_8, 'm', m8).map(Some);
        }
        if m8 != -1 && b.once(step::M_8) {
            match m8 {
                7 => {
                    self.enqueue(CanonCmd::MistOn);
                    self.mist = true;
                }
                8 => {
                    self.enqueue(CanonCmd::FloodOn);
                    self.flood = true;
                }
                _ => {
                    self.enqueue(CanonCmd::MistOff);
                    self.mist = false;
                    self.enqueue(CanonCmd::FloodOff);
                    self.flood = false;
                }
            }
        }
        let m9 = b.m_modes[9];
        if m9 != -1 && b.remapped(step::M_9) && b.once(step::M_9) {
            return self.convert_remapped_code(b, step::M_9, 'm', m9).map(Some);
        }
        if m9 != -1 && b.once(step::M_9) {
            self.point_m(b, 9);
            let comp_on = self.cutter_comp_side != Side::Off;
            let on = match m9 {
                48 => true,
                49 => false,
                _ => b.p() != 0.0,
            };
            chk!(
                comp_on,
                "Cannot {} overrides with cutter radius compensation on",
                if on { "enable" } else { "disable" }
            );
            match m9 {
                48 | 49 => {
                    self.emit(if on {
                        CanonCmd::EnableFeedOverride
                    } else {
                        CanonCmd::DisableFeedOverride
                    });
                    self.feed_override = on;
                    self.speed_override = on;
                    self.emit(if on {
                        CanonCmd::EnableSpeedOverride { spindle: 0 }
                    } else {
                        CanonCmd::DisableSpeedOverride { spindle: 0 }
                    });
                }
                50 => {
                    self.emit(if on {
                        CanonCmd::EnableFeedOverride
                    } else {
                        CanonCmd::DisableFeedOverride
                    });
                    self.feed_override = on;
                }
                51 => {
                    chk!(
                        b.dollar
                            .is_some_and(|d| d <= 0.0 || d >= self.cfg.spindles as f64),
                        "Invalid spindle ($) number in M51 command"
                    );
                    self.emit(if on {
                        CanonCmd::EnableSpeedOverride { spindle: 0 }
                    } else {
                        CanonCmd::DisableSpeedOverride { spindle: 0 }
                    });
                    self.speed_override = on;
                }
                52 => {
                    self.emit(if on {
                        CanonCmd::EnableAdaptiveFeed
                    } else {
                        CanonCmd::DisableAdaptiveFeed
                    });
                    self.adaptive_feed = on;
                }
                _ => {
                    self.emit(if on {
                        CanonCmd::EnableFeedHold
                    } else {
                        CanonCmd::DisableFeedHold
                    });
                    self.feed_hold = on;
                }
            }
        }
        let m10 = b.m_modes[10];
        if m10 != -1 && b.remapped(step::M_10) && b.once(step::M_10) {
            return self
                .convert_remapped_code(b, step::M_10, 'm', m10)
                .map(Some);
        }
        if (m10 == M_FORCE_ON || m10 == M_FORCE_OFF) && b.once(step::M_10) {
            // kerf's own codes: built in, so no user program is looked up.
            self.point_m(b, 10);
            let target = if m10 == M_FORCE_ON {
                let p = b.get(b'p');
                chk!(
                    !p.is_some_and(|p| p.is_finite() && p > 0.0),
                    "M170 needs P, the target cutting force in newtons, above 0 (e.g. M170 P250)"
                );
                p
            } else {
                None
            };
            self.enqueue(CanonCmd::ForceControl { target });
        } else if m10 != -1 && b.once(step::M_10) {
            self.point_m(b, 10);
            let file = format!("M{m10}");
            let exists = self.cfg.user_m_path.iter().any(|d| d.join(&file).is_file());
            chk!(!exists, "Unknown m code used: M{m10}");
            self.enqueue(CanonCmd::UserMCode {
                number: m10 as u32,
                p: b.p(),
                q: b.q(),
            });
        }
        Ok(None)
    }

    // ------------------------------------------------------------------
    // G-codes

    fn convert_g(&mut self, b: &mut Block) -> R<Option<ExecStatus>> {
        if b.g_modes[gm::MODAL_0] == g::G4 && b.once(step::DWELL) {
            self.point_g(b, gm::MODAL_0);
            let seconds = b.p();
            self.enqueue(CanonCmd::Dwell { seconds });
        }
        if b.g_modes[gm::SET_PLANE] != -1 && b.once(step::SET_PLANE) {
            self.point_g(b, gm::SET_PLANE);
            self.convert_set_plane(b.g_modes[gm::SET_PLANE])?;
        }
        if b.g_modes[gm::LENGTH_UNITS] != -1 && b.once(step::LENGTH_UNITS) {
            self.point_g(b, gm::LENGTH_UNITS);
            self.convert_length_units(b.g_modes[gm::LENGTH_UNITS]);
        }
        if b.g_modes[gm::LATHE_DIAMETER_MODE] != -1 && b.once(step::LATHE_DIAMETER_MODE) {
            self.convert_lathe_diameter_mode(b);
        }
        if b.g_modes[gm::CUTTER_COMP] != -1 && b.once(step::CUTTER_COMP) {
            self.point_g(b, gm::CUTTER_COMP);
            self.convert_cutter_compensation(b)?;
        }
        if b.g_modes[gm::TOOL_LENGTH_OFFSET] != -1 && b.once(step::TOOL_LENGTH_OFFSET) {
            self.point_g(b, gm::TOOL_LENGTH_OFFSET);
            self.convert_tool_length_offset(b.g_modes[gm::TOOL_LENGTH_OFFSET], b)?;
        }
        if b.g_modes[gm::COORD_SYSTEM] != -1 && b.once(step::COORD_SYSTEM) {
            self.point_g(b, gm::COORD_SYSTEM);
            self.convert_coordinate_system(b.g_modes[gm::COORD_SYSTEM])?;
        }
        if b.g_modes[gm::CONTROL_MODE] != -1 && b.once(step::CONTROL_MODE) {
            self.point_g(b, gm::CONTROL_MODE);
            self.convert_control_mode(b.g_modes[gm::CONTROL_MODE], b.p(), b.q(), b.get(b'r'))?;
        }
        if b.g_modes[gm::DISTANCE_MODE] != -1 && b.once(step::DISTANCE_MODE) {
            self.convert_distance_mode(b.g_modes[gm::DISTANCE_MODE]);
        }
        if b.g_modes[gm::IJK_DISTANCE_MODE] != -1 && b.once(step::IJK_DISTANCE_MODE) {
            if b.g_modes[gm::IJK_DISTANCE_MODE] == g::G90_1 {
                if self.ijk_distance_mode != Distance::Absolute {
                    self.enqueue_debug_comment(
                        "interpreter: IJK distance mode changed to absolute",
                    );
                    self.ijk_distance_mode = Distance::Absolute;
                }
            } else if self.ijk_distance_mode != Distance::Incremental {
                self.enqueue_debug_comment("interpreter: IJK distance mode changed to incremental");
                self.ijk_distance_mode = Distance::Incremental;
            }
        }
        if b.g_modes[gm::RETRACT_MODE] != -1 && b.once(step::RETRACT_MODE) {
            self.point_g(b, gm::RETRACT_MODE);
            chk!(
                self.cutter_comp_side != Side::Off,
                "Cannot change retract mode with cutter radius compensation on"
            );
            if b.g_modes[gm::RETRACT_MODE] == g::G98 {
                self.enqueue_debug_comment("interpreter: retract mode set to old_z");
                self.retract_mode = Retract::OldZ;
            } else {
                self.enqueue_debug_comment("interpreter: retract mode set to r_plane");
                self.retract_mode = Retract::RPlane;
            }
        }
        if b.g_modes[gm::MODAL_0] != -1 && b.once(step::MODAL_0) {
            self.point_g(b, gm::MODAL_0);
            self.convert_modal_0(b.g_modes[gm::MODAL_0], b)?;
        }
        if b.g_modes[gm::G92_IS_APPLIED] != -1 && b.once(step::G92_IS_APPLIED) {
            self.point_g(b, gm::G92_IS_APPLIED);
            self.convert_axis_offsets(b.g_modes[gm::G92_IS_APPLIED], b)?;
        }
        if b.motion_to_be != -1 && b.once(step::MOTION) {
            if b.g_modes[gm::MOTION] != -1 {
                self.point_g(b, gm::MOTION);
            } else {
                let first = b"xyzabcuvw".iter().find(|&&l| b.has(l)).copied();
                match first {
                    Some(l) => self.point_word(b, l),
                    None => self.fault_word = Some((WordName::G(b.motion_to_be), 1)),
                }
            }
            if self.remap_for('g', b.motion_to_be).is_some() {
                return self
                    .convert_remapped_code(b, step::MOTION, 'g', b.motion_to_be)
                    .map(Some);
            }
            self.convert_motion(b.motion_to_be, b)?;
        }
        Ok(None)
    }

    fn convert_set_plane(&mut self, code: i32) -> R {
        let comp = self.cutter_comp_side != Side::Off;
        chk!(
            comp && ((code == g::G17 && self.plane != Plane::XY)
                || (code == g::G18 && self.plane != Plane::XZ)
                || (code == g::G19 && self.plane != Plane::YZ)),
            "Cannot change planes with cutter radius comp on"
        );
        chk!(
            comp && code == g::G19,
            "Radius compensation allowed only in XY and XZ planes"
        );
        let plane = match code {
            g::G17 => Plane::XY,
            g::G18 => Plane::XZ,
            g::G19 => Plane::YZ,
            g::G17_1 => Plane::UV,
            g::G18_1 => Plane::UW,
            _ => Plane::VW,
        };
        self.canon_select_plane(plane);
        self.plane = plane;
        Ok(())
    }

    fn convert_length_units(&mut self, code: i32) {
        let units = if code == g::G20 {
            Units::Inch
        } else {
            Units::Mm
        };
        self.canon_use_length_units(units);
        if self.length_units == units {
            return;
        }
        let k = if units == Units::Inch {
            INCH_PER_MM
        } else {
            25.4
        };
        self.length_units = units;
        for i in [0, 1, 2, 6, 7, 8] {
            self.cur[i] *= k;
            self.axis_offset[i] *= k;
            self.origin_offset[i] *= k;
            self.tool_offset[i] *= k;
        }
        for p in &mut self.program {
            *p *= k;
        }
        self.comp_queue_scale(k);
        self.cutter_comp_radius *= k;
        self.feed_rate *= k;
        self.tolerance *= k;
        self.naivecam_tolerance *= k;
    }

    fn convert_lathe_diameter_mode(&mut self, b: &mut Block) {
        if b.g_modes[gm::LATHE_DIAMETER_MODE] == g::G7 {
            if !self.lathe_diameter_mode {
                if let Some(x) = b.get(b'x') {
                    b.set(b'x', x / 2.0);
                }
                if b.motion_to_be == g::G76 {
                    for l in [b'i', b'j', b'k'] {
                        if let Some(v) = b.get(l) {
                            b.set(l, v / 2.0);
                        }
                    }
                }
                self.emit(CanonCmd::Comment(
                    "interpreter: Lathe diameter mode changed to diameter".into(),
                ));
                self.lathe_diameter_mode = true;
            }
        } else if self.lathe_diameter_mode {
            if let Some(x) = b.get(b'x') {
                b.set(b'x', x * 2.0);
            }
            if b.motion_to_be == g::G76 {
                for l in [b'i', b'j', b'k'] {
                    if let Some(v) = b.get(l) {
                        b.set(l, v * 2.0);
                    }
                }
            }
            self.emit(CanonCmd::Comment(
                "interpreter: Lathe diameter mode changed to radius".into(),
            ));
            self.lathe_diameter_mode = false;
        }
    }

    pub(crate) fn convert_tool_length_offset(&mut self, code: i32, b: &mut Block) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot change tool offset with cutter radius compensation on"
        );
        let table_offset = |s: &Self, idx: usize| -> [f64; 9] {
            let o = s.tools.get(idx).offset.to_array();
            let mut r = [0.0; 9];
            for i in 0..9 {
                r[i] = s.user_to_program(i, o[i]);
            }
            r
        };
        let axes = b"xyzabcuvw";
        let new = match code {
            g::G49 => [0.0; 9],
            g::G43 => {
                let idx = if let Some(h) = b.get(b'h') {
                    let mut idx = self.find_tool_index(h as i32)?;
                    if idx == 0 && self.tools.random_toolchanger() {
                        idx = self.current_pocket.max(0) as usize;
                    }
                    idx
                } else if self.toolchange_flag {
                    self.current_pocket.max(0) as usize
                } else {
                    0
                };
                table_offset(self, idx)
            }
            g::G43_1 => {
                let mut t = self.tool_offset;
                for (i, &l) in axes.iter().enumerate() {
                    if let Some(v) = b.get(l) {
                        t[i] = v;
                    }
                }
                t
            }
            _ => {
                let has_axis = b.any_axis();
                chk!(
                    b.has(b'h') && has_axis,
                    "G43.2: Can not have both H and axis words"
                );
                chk!(
                    !b.has(b'h') && !has_axis,
                    "G43.2: No axes specified and H word missing"
                );
                let mut t = self.tool_offset;
                if let Some(h) = b.get(b'h') {
                    let idx = self.find_tool_index(h as i32)?;
                    let add = table_offset(self, idx);
                    for i in 0..9 {
                        t[i] += add[i];
                    }
                } else {
                    for (i, &l) in axes.iter().enumerate() {
                        if let Some(v) = b.get(l) {
                            t[i] += v;
                        }
                    }
                }
                t
            }
        };
        self.canon_use_tool_length_offset(new);
        let (dx, dy) = rotate(
            self.tool_offset[X] - new[X],
            self.tool_offset[Y] - new[Y],
            -self.rotation_xy,
        );
        self.cur[X] += dx;
        self.cur[Y] += dy;
        for i in 2..9 {
            self.cur[i] += self.tool_offset[i] - new[i];
        }
        self.tool_offset = new;
        Ok(())
    }

    /// The current position expressed in coordinate system `system`
    /// (1 = G54 … 9 = G59.3), with or without the tool length offset.
    fn find_current_in_system(&self, system: usize, without_tlo: bool) -> [f64; 9] {
        let p = &self.params;
        let mut r = self.cur;
        for i in 0..9 {
            r[i] += self.axis_offset[i];
        }
        let (x, y) = rotate(r[X], r[Y], self.rotation_xy);
        r[X] = x;
        r[Y] = y;
        for i in 0..9 {
            r[i] += self.origin_offset[i];
            if without_tlo {
                r[i] += self.tool_offset[i];
            }
            r[i] -= self.user_to_program(i, p[5201 + i + system * 20]);
        }
        let (x, y) = rotate(r[X], r[Y], -p[5210 + system * 20]);
        r[X] = x;
        r[Y] = y;
        if p[5210] != 0.0 {
            for i in 0..9 {
                r[i] -= self.user_to_program(i, p[5211 + i]);
            }
        }
        r
    }

    fn convert_coordinate_system(&mut self, code: i32) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot change coordinate systems with cutter radius compensation on"
        );
        let origin = match code {
            g::G54 => 1,
            g::G55 => 2,
            g::G56 => 3,
            g::G57 => 4,
            g::G58 => 5,
            g::G59 => 6,
            g::G59_1 => 7,
            g::G59_2 => 8,
            _ => 9,
        };
        if origin == self.origin_index {
            self.enqueue_debug_comment("interpreter: continuing to use same coordinate system");
            return Ok(());
        }
        self.cur = self.find_current_in_system(origin as usize, false);
        self.origin_index = origin;
        self.params[5220] = origin as f64;
        let k = 5200 + 20 * origin as usize;
        for i in 0..9 {
            self.origin_offset[i] = self.user_to_program(i, self.params[k + 1 + i]);
        }
        self.rotation_xy = self.params[k + 10];
        self.canon_set_g5x_offset(origin, self.origin_offset);
        self.canon_set_g92_offset(self.axis_offset);
        self.canon_set_xy_rotation(self.rotation_xy);
        Ok(())
    }

    fn convert_control_mode(&mut self, code: i32, p: f64, q: f64, r: Option<f64>) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot change control mode with cutter radius compensation on"
        );
        match code {
            g::G61 => {
                self.emit(CanonCmd::SetMotionControlMode(MotionMode::ExactPath));
                self.control_mode = MotionMode::ExactPath;
            }
            g::G61_1 => {
                self.emit(CanonCmd::SetMotionControlMode(MotionMode::ExactStop));
                self.control_mode = MotionMode::ExactStop;
            }
            _ => {
                if let Some(r) = r {
                    let (planner, peak_scale) = if r == 0.0 {
                        (0, -1.0)
                    } else {
                        (1, r.clamp(0.1, 1.0))
                    };
                    self.emit(CanonCmd::SetPlannerMode {
                        planner,
                        peak_scale,
                    });
                }
                let tolerance = if p >= 0.0 { p } else { 0.0 };
                self.tolerance = tolerance;
                self.control_mode = MotionMode::Continuous { tolerance };
                self.emit(CanonCmd::SetMotionControlMode(MotionMode::Continuous {
                    tolerance: self.len_mm(tolerance),
                }));
                let naivecam = if q >= 0.0 {
                    q
                } else if p >= 0.0 {
                    p
                } else {
                    0.0
                };
                self.naivecam_tolerance = naivecam;
                self.emit(CanonCmd::SetNaivecamTolerance {
                    tolerance: self.len_mm(naivecam),
                });
            }
        }
        Ok(())
    }

    fn convert_distance_mode(&mut self, code: i32) {
        if code == g::G90 {
            if self.distance_mode != Distance::Absolute {
                self.enqueue_debug_comment("interpreter: distance mode changed to absolute");
                self.distance_mode = Distance::Absolute;
            }
        } else if self.distance_mode != Distance::Incremental {
            self.enqueue_debug_comment("interpreter: distance mode changed to incremental");
            self.distance_mode = Distance::Incremental;
        }
    }

    fn convert_modal_0(&mut self, code: i32, b: &mut Block) -> R {
        match code {
            g::G10 => match b.l() {
                1 | 10 | 11 => self.convert_setup_tool(b),
                0 => {
                    let t = self.tools.get(0).tool;
                    chk!(t > 0, "G10 L0 not allowed with loaded tool <{t}>");
                    bail!("G10 L0 (reload the tool table) is not supported by the interpreter");
                }
                _ => self.convert_setup(b),
            },
            g::G28 | g::G30 => self.convert_home(code, b),
            g::G28_1 | g::G30_1 => self.convert_savehome(code),
            g::G52 | g::G92 => self.convert_axis_offsets(code, b),
            g::G5_3 => bail!("G5.3: NURBS curves (G5.2/G5.3) are not supported"),
            _ => Ok(()),
        }
    }

    fn convert_savehome(&mut self, code: i32) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot set reference point with cutter compensation in effect"
        );
        let (x, y) = rotate(
            self.cur[X] + self.axis_offset[X],
            self.cur[Y] + self.axis_offset[Y],
            self.rotation_xy,
        );
        let mut v = [0.0; 9];
        v[X] = self.program_len_to_user(x + self.tool_offset[X] + self.origin_offset[X]);
        v[Y] = self.program_len_to_user(y + self.tool_offset[Y] + self.origin_offset[Y]);
        for i in 2..9 {
            v[i] = self.program_to_user(
                i,
                self.cur[i] + self.tool_offset[i] + self.origin_offset[i] + self.axis_offset[i],
            );
            if (A..=C).contains(&i) && self.cfg.wrapped_rotary[i - A] {
                v[i] = v[i].rem_euclid(360.0);
            }
        }
        let base = if code == g::G28_1 { 5161 } else { 5181 };
        self.params[base..base + 9].copy_from_slice(&v);
        Ok(())
    }

    fn convert_home(&mut self, code: i32, b: &Block) -> R {
        let mut end = self.find_ends(b)?;
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot use G28 or G30 with cutter radius comp"
        );
        self.canon_straight_traverse(end);
        self.cur = end;
        let home = self.find_relative(self.home_params(if code == g::G28 { 5161 } else { 5181 }));
        let axes = b"xyzabcuvw";
        if b.any_axis() {
            for (i, &l) in axes.iter().enumerate() {
                if b.has(l) {
                    end[i] = home[i];
                }
            }
        } else {
            end = home;
        }
        self.canon_straight_traverse(end);
        self.cur = end;
        Ok(())
    }

    fn check_wrapped(&self, b: &Block) -> R {
        for (k, l) in [b'a', b'b', b'c'].into_iter().enumerate() {
            if let Some(v) = b.get(l) {
                chk!(
                    self.cfg.wrapped_rotary[k] && (v <= -360.0 || v >= 360.0),
                    "Invalid absolute position {v:5.2} for wrapped rotary axis {}",
                    (l as char).to_ascii_uppercase()
                );
            }
        }
        Ok(())
    }

    pub(crate) fn convert_axis_offsets(&mut self, code: i32, b: &Block) -> R {
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot change axis offsets with cutter radius comp"
        );
        self.check_wrapped(b)?;
        let axes = b"xyzabcuvw";
        match code {
            g::G52 | g::G92 => {
                self.params[5210] = 1.0;
                for (i, &l) in axes.iter().enumerate() {
                    if let Some(v) = b.get(l) {
                        if code == g::G52 {
                            self.cur[i] += self.axis_offset[i] - v;
                            self.axis_offset[i] = v;
                        } else {
                            self.axis_offset[i] = self.cur[i] + self.axis_offset[i] - v;
                            self.cur[i] = v;
                        }
                    }
                }
                self.canon_set_g92_offset(self.axis_offset);
                for i in 0..9 {
                    self.params[5211 + i] = self.program_to_user(i, self.axis_offset[i]);
                }
            }
            g::G92_1 | g::G92_2 => {
                self.params[5210] = 0.0;
                for i in 0..9 {
                    self.cur[i] += self.axis_offset[i];
                }
                self.canon_set_g92_offset([0.0; 9]);
                self.axis_offset = [0.0; 9];
                if code == g::G92_1 {
                    for i in 0..9 {
                        self.params[5211 + i] = 0.0;
                    }
                }
            }
            _ => {
                self.params[5210] = 1.0;
                for i in 0..9 {
                    let stored = self.user_to_program(i, self.params[5211 + i]);
                    self.cur[i] = self.cur[i] + self.axis_offset[i] - stored;
                    self.axis_offset[i] = stored;
                }
                self.canon_set_g92_offset(self.axis_offset);
            }
        }
        Ok(())
    }

    /// G10 L2 and L20: set a coordinate system's offsets (and rotation).
    fn convert_setup(&mut self, b: &Block) -> R {
        chk!(
            b.has(b'i') || b.has(b'j'),
            "I J words not allowed with G10 L2"
        );
        let mut p_int = (b.p() + 0.0001) as i32;
        if p_int == 0 {
            p_int = self.origin_index;
        }
        let l = b.l();
        if l == 20 {
            self.check_wrapped(b)?;
        }
        chk!(
            self.cutter_comp_side != Side::Off && p_int == self.origin_index,
            "Cannot change the active coordinate system with cutter radius compensation on"
        );
        let k = 5200 + 20 * p_int as usize;
        let cur = self.find_current_in_system(p_int as usize, false);
        let r = if let Some(r) = b.get(b'r') {
            chk!(l == 20, "R not allowed in G10 L20");
            self.params[k + 10] = r;
            r
        } else {
            self.params[k + 10]
        };
        let mut off = [0.0; 9];
        if l == 20 {
            let (ox, oy) = rotate(cur[X], cur[Y], r);
            let (x, y) = rotate(b.or(b'x', cur[X]), b.or(b'y', cur[Y]), r);
            off[X] = ox + self.user_len_to_program(self.params[k + 1]) - x;
            off[Y] = oy + self.user_len_to_program(self.params[k + 2]) - y;
            self.params[k + 1] = self.program_len_to_user(off[X]);
            self.params[k + 2] = self.program_len_to_user(off[Y]);
            if p_int == self.origin_index {
                let (x, y) = rotate(self.cur[X], self.cur[Y], self.rotation_xy);
                self.cur[X] = x;
                self.cur[Y] = y;
                self.rotation_xy = 0.0;
            }
        } else {
            for (i, l) in [b'x', b'y'].into_iter().enumerate() {
                if let Some(v) = b.get(l) {
                    off[i] = v;
                    self.params[k + 1 + i] = self.program_len_to_user(v);
                } else {
                    off[i] = self.user_len_to_program(self.params[k + 1 + i]);
                }
            }
        }
        for (i, &letter) in b"xyzabcuvw".iter().enumerate().skip(2) {
            let stored = self.user_to_program(i, self.params[k + 1 + i]);
            if let Some(mut v) = b.get(letter) {
                if l == 20 {
                    v = cur[i] + stored - v;
                }
                self.params[k + 1 + i] = self.program_to_user(i, v);
                off[i] = v;
            } else {
                off[i] = stored;
            }
        }
        if p_int == self.origin_index {
            let (x, y) = rotate(self.cur[X], self.cur[Y], self.rotation_xy);
            self.cur[X] = x;
            self.cur[Y] = y;
            for i in 0..9 {
                self.cur[i] += self.origin_offset[i];
            }
            self.origin_offset = off;
            for i in 0..9 {
                self.cur[i] -= off[i];
            }
            self.canon_set_g5x_offset(p_int, off);
            let (x, y) = rotate(self.cur[X], self.cur[Y], -r);
            self.cur[X] = x;
            self.cur[Y] = y;
            self.rotation_xy = r;
            self.canon_set_xy_rotation(r);
        } else {
            self.enqueue_debug_comment("interpreter: setting coordinate system origin");
        }
        Ok(())
    }

    /// G10 L1, L10, L11: set a tool table entry.
    fn convert_setup_tool(&mut self, b: &Block) -> R {
        let p = b.p();
        let toolno = (p + 0.5) as i32;
        let idx = self.find_tool_index(toolno)?;
        let axes = b"xyzabcuvw";
        chk!(
            !(b.any_axis() || b.has(b'r') || b.has(b'q') || b.has(b'i') || b.has(b'j')),
            "G10 L1 without offsets has no effect"
        );
        let mut data = self.tools.get(idx);
        let mut off = data.offset.to_array();
        if b.l() == 1 {
            for (i, &l) in axes.iter().enumerate() {
                if let Some(v) = b.get(l) {
                    off[i] = self.program_to_user(i, v);
                }
            }
        } else {
            let to_fixture = b.l() == 11;
            let system = if to_fixture {
                9
            } else {
                self.origin_index as usize
            };
            let mut t = self.find_current_in_system(system, true);
            if to_fixture && self.params[5210] != 0.0 {
                for i in 0..9 {
                    t[i] += self.user_to_program(i, self.params[5211 + i]);
                }
            }
            let rot = self.params[5210 + system * 20];
            match (b.get(b'x'), b.get(b'y')) {
                (Some(x), Some(y)) => {
                    let (tx, ty) = rotate(t[X] - x, t[Y] - y, rot);
                    off[X] = self.program_len_to_user(tx);
                    off[Y] = self.program_len_to_user(ty);
                }
                (Some(x), None) => {
                    let (ox, oy) = rotate(
                        self.user_len_to_program(off[X]),
                        self.user_len_to_program(off[Y]),
                        -rot,
                    );
                    let _ = ox;
                    let (ox, oy) = rotate(0.0, oy, rot);
                    let (tx, ty) = rotate(t[X] - x, 0.0, rot);
                    off[X] = self.program_len_to_user(tx + ox);
                    off[Y] = self.program_len_to_user(ty + oy);
                }
                (None, Some(y)) => {
                    let (ox, oy) = rotate(
                        self.user_len_to_program(off[X]),
                        self.user_len_to_program(off[Y]),
                        -rot,
                    );
                    let _ = oy;
                    let (ox, oy) = rotate(ox, 0.0, rot);
                    let (tx, ty) = rotate(0.0, t[Y] - y, rot);
                    off[X] = self.program_len_to_user(tx + ox);
                    off[Y] = self.program_len_to_user(ty + oy);
                }
                (None, None) => {}
            }
            for (i, &l) in axes.iter().enumerate().skip(2) {
                if let Some(v) = b.get(l) {
                    off[i] = self.program_to_user(i, t[i] - v);
                }
            }
        }
        data.offset = crate::canon::Position::from_array(off);
        if let Some(r) = b.get(b'r') {
            data.diameter = self.program_len_to_user(r) * 2.0;
        }
        if let Some(i) = b.get(b'i') {
            data.front_angle = i;
        }
        if let Some(j) = b.get(b'j') {
            data.back_angle = j;
        }
        if let Some(q) = b.get(b'q') {
            let qi = (q + 0.5) as i32;
            chk!(
                (qi as f64 - q).abs() >= 0.0001,
                "Q number in G10 is not an integer"
            );
            chk!(qi > 9, "Invalid tool orientation");
            data.orientation = qi;
        }
        self.tools.put(idx, data);
        self.emit_tool_entry(idx as i32, data);
        let random = self.tools.random_toolchanger();
        if !random && self.current_pocket == idx as i32 {
            self.tools.put(0, data);
        }
        let spindle = self.tools.get(0);
        self.params[5400] = if random {
            if spindle.tool >= 0 {
                spindle.tool as f64
            } else {
                -1.0
            }
        } else if spindle.tool > 0 {
            spindle.tool as f64
        } else {
            0.0
        };
        let o = spindle.offset.to_array();
        self.params[5401..5410].copy_from_slice(&o);
        self.params[5410] = spindle.diameter;
        self.params[5411] = spindle.front_angle;
        self.params[5412] = spindle.back_angle;
        self.params[5413] = spindle.orientation as f64;
        if !random && idx as i32 == self.current_pocket {
            self.emit_tool_entry(0, data);
        }
        Ok(())
    }

    /// A tool table entry, converted from user units to mm for the canon.
    fn emit_tool_entry(&mut self, index: i32, data: crate::canon::ToolData) {
        let k = 1.0 / self.cfg.user_units_per_mm;
        let mut o = data.offset.to_array();
        for (i, v) in o.iter_mut().enumerate() {
            if !(A..=C).contains(&i) {
                *v *= k;
            }
        }
        let mut d = data;
        d.offset = crate::canon::Position::from_array(o);
        d.diameter *= k;
        self.emit(CanonCmd::SetToolTableEntry { index, data: d });
    }

    // ------------------------------------------------------------------
    // stopping

    fn convert_stop(&mut self, b: &Block) -> R<ExecStatus> {
        self.comp_flush_all()?;
        let m = b.m_modes[4];
        match m {
            0 => self.emit(CanonCmd::ProgramStop),
            60 => {
                self.emit(CanonCmd::PalletShuttle);
                self.emit(CanonCmd::ProgramStop);
            }
            1 => self.emit(CanonCmd::OptionalProgramStop),
            2 | 30 | 99 => {
                let (x, y) = rotate(self.cur[X], self.cur[Y], self.rotation_xy);
                self.cur[X] = x;
                self.cur[Y] = y;
                for i in 0..9 {
                    self.cur[i] += self.origin_offset[i];
                }
                self.origin_index = 1;
                self.params[5220] = 1.0;
                for i in 0..9 {
                    self.origin_offset[i] = self.user_to_program(i, self.params[5221 + i]);
                }
                self.rotation_xy = self.params[5230];
                for i in 0..9 {
                    self.cur[i] -= self.origin_offset[i];
                }
                let (x, y) = rotate(self.cur[X], self.cur[Y], -self.rotation_xy);
                self.cur[X] = x;
                self.cur[Y] = y;
                self.canon_set_g5x_offset(1, self.origin_offset);
                self.canon_set_xy_rotation(self.rotation_xy);
                if self.plane != Plane::XY {
                    self.canon_select_plane(Plane::XY);
                    self.plane = Plane::XY;
                }
                self.distance_mode = Distance::Absolute;
                self.feed_mode = FeedMode::UnitsPerMinute;
                self.emit(CanonCmd::SetFeedMode {
                    spindle: 0,
                    per_revolution: false,
                });
                self.feed_rate = b.or(b'f', self.feed_rate);
                self.emit(CanonCmd::SetFeedRate { mm_per_min: 0.0 });
                if !self.feed_override {
                    self.emit(CanonCmd::EnableFeedOverride);
                    self.feed_override = true;
                }
                self.cutter_comp_side = Side::Off;
                self.cutter_comp_firstmove = true;
                self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
                self.spindle_turning = Turning::Stopped;
                self.speed_override = true;
                self.emit(CanonCmd::SetSpindleMode {
                    spindle: 0,
                    css_max_rpm: 0.0,
                });
                self.css_mode = false;
                self.motion_mode = g::G1;
                if self.mist {
                    self.emit(CanonCmd::MistOff);
                    self.mist = false;
                }
                if self.flood {
                    self.emit(CanonCmd::FloodOff);
                    self.flood = false;
                }
                if self.cfg.disable_g92_persistence {
                    for p in 5210..=5219 {
                        self.params[p] = 0.0;
                    }
                    for i in 0..9 {
                        self.cur[i] += self.axis_offset[i];
                    }
                    self.axis_offset = [0.0; 9];
                    self.canon_set_g92_offset([0.0; 9]);
                }
                if m == 30 {
                    self.emit(CanonCmd::PalletShuttle);
                }
                self.emit(CanonCmd::ProgramEnd);
                if self.percent_flag {
                    self.check_closing_percent()?;
                }
                self.unwind_call();
                return Ok(ExecStatus::Exit);
            }
            _ => {}
        }
        Ok(ExecStatus::Ok)
    }

    /// After M2/M30 in a program that opened with `%`, look for the
    /// closing `%` and note it if missing.
    fn check_closing_percent(&mut self) -> R {
        let mut line = Vec::new();
        loop {
            line.clear();
            let f = &mut self.files[self.cur_file];
            let n = std::io::BufRead::read_until(&mut f.reader, b'\n', &mut line)
                .map_err(|e| Fault::new(format!("cannot read {}: {e}", f.name)))?;
            if n == 0 {
                self.enqueue(CanonCmd::Comment(
                    "interpreter: percent sign missing from end of file".into(),
                ));
                return Ok(());
            }
            if line.trim_ascii() == b"%" {
                return Ok(());
            }
        }
    }

    // ------------------------------------------------------------------
    // M70-M73: save and restore modal state

    /// The modal state M70/M73 saves.
    fn save_modes(&self) -> SavedModes {
        SavedModes {
            g: self.active_g_codes(),
            m: self.active_m_codes(),
            settings: [
                self.sequence_number as f64,
                self.feed_rate,
                self.speed,
                self.tolerance,
                self.naivecam_tolerance,
            ],
        }
    }

    pub(crate) fn active_g_codes(&self) -> [i32; 17] {
        let mut gz = [-1; 17];
        gz[0] = self.sequence_number as i32;
        gz[1] = self.motion_mode;
        gz[3] = match self.plane {
            Plane::XY => g::G17,
            Plane::XZ => g::G18,
            Plane::YZ => g::G19,
            Plane::UV => g::G17_1,
            Plane::UW => g::G18_1,
            Plane::VW => g::G19_1,
        };
        gz[4] = match self.cutter_comp_side {
            Side::Right => g::G42,
            Side::Left => g::G41,
            Side::Off => g::G40,
        };
        gz[5] = if self.length_units == Units::Inch {
            g::G20
        } else {
            g::G21
        };
        gz[6] = if self.distance_mode == Distance::Absolute {
            g::G90
        } else {
            g::G91
        };
        gz[7] = match self.feed_mode {
            FeedMode::InverseTime => g::G93,
            FeedMode::UnitsPerMinute => g::G94,
            FeedMode::UnitsPerRevolution => g::G95,
        };
        gz[8] = if self.origin_index < 7 {
            530 + 10 * self.origin_index
        } else {
            584 + self.origin_index
        };
        gz[9] = if self.tool_offset.iter().any(|&v| v != 0.0) {
            g::G43
        } else {
            g::G49
        };
        gz[10] = if self.retract_mode == Retract::OldZ {
            g::G98
        } else {
            g::G99
        };
        gz[11] = match self.control_mode {
            MotionMode::Continuous { .. } => g::G64,
            MotionMode::ExactPath => g::G61,
            MotionMode::ExactStop => g::G61_1,
        };
        gz[13] = if self.css_mode { g::G96 } else { g::G97 };
        gz[14] = if self.ijk_distance_mode == Distance::Absolute {
            g::G90_1
        } else {
            g::G91_1
        };
        gz[15] = if self.lathe_diameter_mode {
            g::G7
        } else {
            g::G8
        };
        gz[16] = if self.params[5210] != 0.0 {
            g::G92_3
        } else {
            g::G92_2
        };
        gz
    }

    pub(crate) fn active_m_codes(&self) -> [i32; 9] {
        let mut mz = [-1; 9];
        mz[0] = self.sequence_number as i32;
        mz[2] = match self.spindle_turning {
            Turning::Stopped => 5,
            Turning::Clockwise => 3,
            Turning::CounterClockwise => 4,
        };
        mz[4] = if self.mist {
            7
        } else if self.flood {
            -1
        } else {
            9
        };
        mz[5] = if self.flood { 8 } else { -1 };
        mz[6] = match (self.feed_override, self.speed_override) {
            (true, true) => 48,
            (true, false) => 50,
            (false, true) => 51,
            (false, false) => 49,
        };
        mz[7] = if self.adaptive_feed { 52 } else { -1 };
        mz[8] = if self.feed_hold { 53 } else { -1 };
        mz
    }

    /// M72 (or return from a sub that did M73): restore the modes saved at
    /// call level `from_level` by executing the G- and M-codes that differ.
    pub(crate) fn restore_settings(&mut self, from_level: usize) -> R {
        let Some(saved) = self.contexts[from_level].saved.clone() else {
            return Ok(());
        };
        let cur_g = self.active_g_codes();
        if cur_g[5] != saved.g[5] {
            self.execute_text(&format!("G{}", saved.g[5] / 10))?;
        }
        // As LinuxCNC 2.10 does: feed, speed and the path mode are always
        // restored; other G modes and the M modes only where they differ.
        let cur_g = self.active_g_codes();
        let mut cmd = format!(" F{:.1} S{:.0}", saved.settings[1], saved.settings[2]);
        for i in [3, 4, 6, 7, 8, 9, 10, 13, 14, 15, 16] {
            let val = saved.g[i];
            if val != cur_g[i] && val != -1 {
                cmd.push(' ');
                cmd.push_str(&gcode_name(val));
            }
        }
        match saved.g[11] {
            g::G61 => cmd.push_str(" G61"),
            g::G61_1 => cmd.push_str(" G61.1"),
            _ => {
                if saved.settings[3] < 0.0 {
                    cmd.push_str(" G64");
                } else {
                    cmd.push_str(&format!(
                        " G64 P{:.6} Q{:.6}",
                        saved.settings[3],
                        saved.settings[4].max(0.0)
                    ));
                }
            }
        }
        // Each M-code goes on its own line; the first joins the G line.
        let cur_m = self.active_m_codes();
        for i in [2, 4, 5, 6, 7, 8] {
            let val = saved.m[i];
            if val != cur_m[i] && val != -1 {
                cmd.push_str(&format!("M{val}\n"));
            }
        }
        for line in cmd.split('\n') {
            if line.trim().is_empty() {
                continue;
            }
            if let Err(e) = self.execute_text(line) {
                bail!(
                    "M7x: restore_settings failed executing: '{line}': {}",
                    e.message
                );
            }
        }
        Ok(())
    }

    /// Execute one line of G-code given as text (used to restore modes),
    /// keeping the current line's identity for sources and errors.
    pub(crate) fn execute_text(&mut self, text: &str) -> R {
        let raw = std::mem::replace(&mut self.raw, text.as_bytes().to_vec());
        let line = std::mem::take(&mut self.line);
        let cols = std::mem::take(&mut self.cols);
        let length = self.line_length;
        let saved_block = std::mem::take(&mut self.block);
        let result = (|| -> R {
            self.close_and_downcase()?;
            self.line_length = self.line.len();
            let mut block = Block::default();
            self.parse_line(&mut block)?;
            for &(n, v) in &block.assign_numbered {
                self.params[n] = v;
            }
            self.execute_block(&mut block)?;
            Ok(())
        })();
        self.raw = raw;
        self.line = line;
        self.cols = cols;
        self.line_length = length;
        self.block = saved_block;
        result
    }
}
