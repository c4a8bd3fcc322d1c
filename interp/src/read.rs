//! Reading a line: folding it, then parsing words, parameters and
//! expressions into a [`Block`].
//!
//! As in LinuxCNC, values are evaluated while the line is read, with the
//! parameter values in force before the line; assignments on the line are
//! collected and applied only when it executes, so every read in a block
//! happens before any of its writes.

use crate::block::{g, g_group, gm, is_cycle, m_group, Block, CallType, OType, SUB_PARAMS};
use crate::error::{chk, Fault, R};
use crate::interp::{Interp, Side};
use crate::lex::{self, Func, Op};

/// LinuxCNC's operator precedence (higher binds tighter).
fn precedence(op: Op) -> u8 {
    match op {
        Op::RightBracket => 1,
        Op::And | Op::Xor | Op::Or => 2,
        Op::Lt | Op::Eq | Op::Ne | Op::Le | Op::Ge | Op::Gt => 3,
        Op::Minus | Op::Plus => 4,
        Op::DividedBy | Op::Modulo | Op::Times => 5,
        Op::Power => 6,
    }
}

/// Two numbers are equal for EQ and NE if they differ by less than this.
const TOLERANCE_EQUAL: f64 = 0.0001;

fn binary(left: f64, op: Op, right: f64) -> R<f64> {
    Ok(match op {
        Op::DividedBy => {
            chk!(right == 0.0, "Attempt to divide by zero");
            left / right
        }
        Op::Modulo => {
            let mut v = left % right;
            if v < 0.0 {
                v += right.abs();
            }
            v
        }
        Op::Power => {
            chk!(
                left < 0.0 && right.floor() != right,
                "Attempt to raise negative to non integer power"
            );
            left.powf(right)
        }
        Op::Times => left * right,
        Op::And => bool_f(left != 0.0 && right != 0.0),
        Op::Xor => bool_f((left == 0.0) != (right == 0.0)),
        Op::Minus => left - right,
        Op::Or => bool_f(left != 0.0 || right != 0.0),
        Op::Plus => left + right,
        Op::Lt => bool_f(left < right),
        Op::Eq => bool_f((left - right).abs() < TOLERANCE_EQUAL),
        Op::Ne => bool_f((left - right).abs() >= TOLERANCE_EQUAL),
        Op::Le => bool_f(left <= right),
        Op::Ge => bool_f(left >= right),
        Op::Gt => bool_f(left > right),
        Op::RightBracket => left,
    })
}

fn bool_f(b: bool) -> f64 {
    if b {
        1.0
    } else {
        0.0
    }
}

fn unary(v: f64, f: Func) -> R<f64> {
    Ok(match f {
        Func::Abs => v.abs(),
        Func::Acos => {
            chk!(!(-1.0..=1.0).contains(&v), "Argument to acos out of range");
            crate::ld::degrees(v.acos())
        }
        Func::Asin => {
            chk!(!(-1.0..=1.0).contains(&v), "Argument to asin out of range");
            crate::ld::degrees(v.asin())
        }
        Func::Cos => crate::ld::cos_deg(v),
        Func::Exp => v.exp(),
        Func::Fix => v.floor(),
        Func::Fup => v.ceil(),
        Func::Ln => {
            chk!(v <= 0.0, "Zero or negative argument to ln");
            v.ln()
        }
        Func::Round => {
            let r = v + if v < 0.0 { -0.5 } else { 0.5 };
            (r as i64) as f64
        }
        Func::Sin => crate::ld::sin_deg(v),
        Func::Sqrt => {
            chk!(v < 0.0, "Negative argument to sqrt");
            v.sqrt()
        }
        Func::Tan => crate::ld::tan_deg(v),
        Func::Exists | Func::Atan => v,
    })
}

impl Interp<'_> {
    /// The folded line's byte at `i`, or 0 past its end (C string style).
    #[inline]
    fn ch(&self, i: usize) -> u8 {
        self.line.get(i).copied().unwrap_or(0)
    }

    /// Source column of folded byte `i`.
    fn col_at(&self, i: usize) -> u32 {
        self.cols
            .get(i)
            .copied()
            .unwrap_or_else(|| self.cols.last().map(|c| c + 1).unwrap_or(1))
    }

    fn fault_at(&self, i: usize, message: impl Into<String>) -> Fault {
        Fault::at(self.col_at(i), message)
    }

    /// Fold the raw line: lower case, no blanks, tabs or CRs outside
    /// comments; comments and `;` remarks kept as written.
    pub(crate) fn close_and_downcase(&mut self) -> R {
        self.line.clear();
        self.cols.clear();
        let raw = &self.raw;
        self.line.reserve(raw.len());
        self.cols.reserve(raw.len());
        let mut col: u32 = 0;
        let mut i = 0;
        while i < raw.len() {
            let c = raw[i];
            i += 1;
            // Columns count characters: UTF-8 continuation bytes belong to
            // the character before them (a stray one at the start still
            // takes column 1).
            if c & 0xC0 != 0x80 || col == 0 {
                col += 1;
            }
            match c {
                b' ' | b'\t' | b'\r' => {}
                b';' => {
                    // A remark: the rest of the line as written.
                    self.line.push(c);
                    self.cols.push(col);
                    for &c in &raw[i..] {
                        if c & 0xC0 != 0x80 {
                            col += 1;
                        }
                        self.line.push(c);
                        self.cols.push(col);
                    }
                    return Ok(());
                }
                b'(' => {
                    // A comment, as written, up to its `)`.
                    self.line.push(c);
                    self.cols.push(col);
                    loop {
                        let Some(&c) = raw.get(i) else {
                            return Err(Fault::new("Unclosed comment found"));
                        };
                        i += 1;
                        if c & 0xC0 != 0x80 {
                            col += 1;
                        }
                        self.line.push(c);
                        self.cols.push(col);
                        match c {
                            b')' => break,
                            b'(' => return Err(Fault::at(col, "Nested comment found")),
                            _ => {}
                        }
                    }
                }
                _ => {
                    self.line.push(c.to_ascii_lowercase());
                    self.cols.push(col);
                }
            }
        }
        Ok(())
    }

    /// Parse the folded line into `block`.
    pub(crate) fn parse_line(&mut self, block: &mut Block) -> R {
        block.clear();
        self.read_items(block)?;
        if self.skipping_o.is_none() {
            self.enhance_block(block)?;
            self.check_items(block)?;
            self.find_remappings(block);
        }
        Ok(())
    }

    fn read_items(&mut self, block: &mut Block) -> R {
        let length = self.line.len();
        let mut counter = 0usize;
        if self.ch(counter) == b'/' {
            counter += 1;
        }
        if self.ch(counter) == b'n' {
            self.read_n_number(&mut counter, block)?;
        }
        let mut m_number = -1;
        if self.ch(counter) == b'm' {
            let mut c = counter + 1;
            if let Ok(v) = self.read_integer_value(&mut c) {
                m_number = v;
            }
        }
        if self.ch(counter) == b'o' || m_number == 98 || (m_number == 99 && self.call_level > 0) {
            self.read_o(&mut counter, block)?;
            if self.skipping_o.is_some() {
                return Ok(());
            }
            while counter < length {
                match self.ch(counter) {
                    b';' => counter = length,
                    b'(' => self.read_comment(&mut counter, block)?,
                    _ => return Err(self.fault_at(counter, "Unexpected character after O-word")),
                }
            }
            return Ok(());
        }
        if self.skipping_o.is_some() {
            return Ok(());
        }
        while counter < length {
            self.read_one_item(&mut counter, block)?;
        }
        Ok(())
    }

    fn read_one_item(&mut self, counter: &mut usize, block: &mut Block) -> R {
        let letter = self.ch(*counter);
        let bad = |s: &Self| {
            let message = if letter.is_ascii_graphic() {
                format!("Bad character '{}' used", letter as char)
            } else {
                format!("Bad character '\\{letter:03o}' used")
            };
            Err(s.fault_at(*counter, message))
        };
        match letter {
            b'#' => self.read_parameter_setting(counter, block),
            b'$' => {
                let col = self.col_at(*counter);
                *counter += 1;
                chk!(
                    block.dollar.is_some(),
                    "Multiple spindle choice ($) words on one line"
                );
                let v = self.read_real_value(counter)?;
                block.dollar = Some(v);
                let _ = col;
                Ok(())
            }
            b'(' => self.read_comment(counter, block),
            b';' => {
                *counter = self.line.len();
                Ok(())
            }
            b'@' => {
                *counter += 1;
                block.radius = Some(self.read_real_value(counter)?);
                Ok(())
            }
            b'^' => {
                *counter += 1;
                block.theta = Some(self.read_real_value(counter)?);
                Ok(())
            }
            b'g' => self.read_g(counter, block),
            b'm' => self.read_m(counter, block),
            b'x' | b'y' | b'z' | b'a' | b'b' | b'c' | b'u' | b'v' | b'w' => {
                let axis = b"xyzabcuvw".iter().position(|&l| l == letter).unwrap_or(0);
                if !self.cfg.axes[axis] {
                    return bad(self);
                }
                self.read_real_word(counter, block, letter)
            }
            b'd' | b'e' | b'i' | b'j' | b'k' | b'r' | b'f' | b's' | b'p' | b'q' => {
                self.read_real_word(counter, block, letter)
            }
            b'h' | b'l' | b't' => self.read_integer_word(counter, block, letter),
            _ => bad(self),
        }
    }

    /// A word with a real value (axes, D E F I J K P Q R S).
    fn read_real_word(&mut self, counter: &mut usize, block: &mut Block, letter: u8) -> R {
        let col = self.col_at(*counter);
        let start = *counter;
        *counter += 1;
        if block.has(letter) {
            let message = if matches!(letter, b'u' | b'v' | b'w') {
                format!(
                    "Multiple {} words on one line",
                    letter.to_ascii_uppercase() as char
                )
            } else {
                format!("Multiple {} words on one line", letter as char)
            };
            return Err(Fault {
                message,
                word: Some((letter.to_ascii_uppercase() as char).to_string()),
                column: Some(self.col_at(start)),
            });
        }
        let word = || (letter.to_ascii_uppercase() as char).to_string();
        let mut value = self
            .read_real_value(counter)
            .map_err(|f| f.in_word(word, col))?;
        let negative = match letter {
            b'f' => Some("Negative f word used"),
            b's' => Some("Negative spindle speed used"),
            _ => None,
        };
        if let Some(message) = negative.filter(|_| value < 0.0) {
            return Err(Fault::new(message).in_word(word, col));
        }
        if letter == b'x' && self.lathe_diameter_mode {
            value /= 2.0;
        }
        block.set(letter, value);
        block.cols[(letter - b'a') as usize] = col;
        Ok(())
    }

    /// A word with a whole-number value (H L T).
    fn read_integer_word(&mut self, counter: &mut usize, block: &mut Block, letter: u8) -> R {
        let col = self.col_at(*counter);
        let start = *counter;
        *counter += 1;
        if block.has(letter) {
            return Err(Fault {
                message: format!("Multiple {} words on one line", letter as char),
                word: Some((letter.to_ascii_uppercase() as char).to_string()),
                column: Some(self.col_at(start)),
            });
        }
        let word = || (letter.to_ascii_uppercase() as char).to_string();
        let value = self
            .read_integer_value(counter)
            .map_err(|f| f.in_word(word, col))?;
        let negative = match letter {
            b'h' => (value < -1).then_some("Negative h word used"),
            b'l' => (value < 0).then_some("Negative l word used"),
            b't' => (value < 0).then_some("Negative tool id (tool not found)"),
            _ => None,
        };
        if let Some(message) = negative {
            return Err(Fault::new(message).in_word(word, col));
        }
        block.set(letter, value as f64);
        block.cols[(letter - b'a') as usize] = col;
        Ok(())
    }

    fn read_comment(&mut self, counter: &mut usize, block: &mut Block) -> R {
        // The line was folded, so every `(` has its `)`.
        let rest = &self.line[*counter..];
        let (after, body) =
            lex::comment(rest).map_err(|_| self.fault_at(*counter, "Unclosed comment found"))?;
        block.comment = Some(String::from_utf8_lossy(body).into_owned());
        *counter += rest.len() - after.len();
        Ok(())
    }

    fn read_g(&mut self, counter: &mut usize, block: &mut Block) -> R {
        let col = self.col_at(*counter);
        *counter += 1;
        let read = self
            .read_real_value(counter)
            .map_err(|f| f.in_word(|| "G".into(), col))?
            * 10.0;
        let mut value = read.floor() as i64;
        if read - value as f64 > 0.999 {
            value = read.ceil() as i64;
        } else if read - value as f64 > 0.001 {
            return Err(Fault::at(col, "G-code out of range"));
        }
        if value > 999 {
            return Err(Fault::at(col, "G-code out of range"));
        }
        if value < 0 {
            return Err(Fault::at(col, "Negative g code used"));
        }
        let value = value as i32;
        let two = || Fault {
            message: "Two g codes used from same modal group".into(),
            word: Some(crate::interp::gcode_name(value)),
            column: Some(col),
        };
        if let Some(r) = self.remap_for('g', value) {
            let mode = self.cfg.remaps[r].modal_group as usize;
            if block.g_modes[mode] != -1 {
                return Err(two());
            }
            block.g_modes[mode] = value;
            block.g_cols[mode] = col;
            return Ok(());
        }
        let Some(mode) = g_group(value) else {
            return Err(Fault {
                message: "Unknown g code used".into(),
                word: Some(crate::interp::gcode_name(value)),
                column: Some(col),
            });
        };
        if value == g::G80 && block.g_modes[mode] != -1 {
            return Ok(());
        }
        if block.g_modes[mode] != g::G80 && block.g_modes[mode] != -1 {
            return Err(two());
        }
        block.g_modes[mode] = value;
        block.g_cols[mode] = col;
        Ok(())
    }

    fn read_m(&mut self, counter: &mut usize, block: &mut Block) -> R {
        let col = self.col_at(*counter);
        *counter += 1;
        let value = self
            .read_integer_value(counter)
            .map_err(|f| f.in_word(|| "M".into(), col))?;
        let at = |message: String| Fault {
            message,
            word: Some(format!("M{value}")),
            column: Some(col),
        };
        if value < 0 {
            return Err(at("Negative m code used".into()));
        }
        let mode = if let Some(r) = self.remap_for('m', value) {
            self.cfg.remaps[r].modal_group as usize
        } else {
            if value > 199 {
                return Err(at(format!("M-code greater than 199: M{value}")));
            }
            match m_group(value) {
                Some(m) => m,
                None => return Err(at(format!("Unknown m code used: M{value}"))),
            }
        };
        if block.m_modes[mode] != -1 {
            return Err(at("Two m codes used from same modal group".into()));
        }
        block.m_modes[mode] = value;
        block.m_cols[mode] = col;
        block.m_count += 1;
        if (100..200).contains(&value) {
            block.user_m = true;
        }
        Ok(())
    }

    fn read_n_number(&mut self, counter: &mut usize, block: &mut Block) -> R {
        *counter += 1;
        let value = self.read_integer_unsigned(counter)?;
        block.n_number = Some(value);
        if self.ch(*counter) == b'.' {
            *counter += 1;
            self.read_integer_unsigned(counter)?;
        }
        Ok(())
    }

    fn read_integer_unsigned(&mut self, counter: &mut usize) -> R<i64> {
        let start = *counter;
        let (_, digits) = lex::unsigned_integer(&self.line[start..])
            .map_err(|_| self.fault_at(start, "Bad format unsigned integer"))?;
        let v = digits.iter().fold(0i64, |v, &d| {
            v.saturating_mul(10).saturating_add((d - b'0') as i64)
        });
        *counter = start + digits.len();
        Ok(v.min(i32::MAX as i64))
    }

    /// A value that must be a whole number (within 0.0001).
    pub(crate) fn read_integer_value(&mut self, counter: &mut usize) -> R<i32> {
        let start = *counter;
        let v = self.read_real_value(counter)?;
        let mut n = v.floor();
        if v - n > 0.9999 {
            n = v.ceil();
        } else if v - n > 0.0001 {
            return Err(self.fault_at(start, "Non integer value for integer"));
        }
        chk!(
            !(i32::MIN as f64..=i32::MAX as f64).contains(&n),
            "Non integer value for integer"
        );
        Ok(n as i32)
    }

    /// A real value: a number, a parameter, an expression in brackets, a
    /// function, or a sign before any of those.
    ///
    /// Values nest (brackets, functions, signs, `##` indirection), each
    /// level a recursive call; the depth is bounded so that a hostile line
    /// gets an error rather than exhausting the stack.
    pub(crate) fn read_real_value(&mut self, counter: &mut usize) -> R<f64> {
        const MAX_NESTING: u32 = 100;
        if self.value_depth >= MAX_NESTING {
            return Err(self.fault_at(*counter, "Expression nested too deeply"));
        }
        self.value_depth += 1;
        let v = self.read_real_value_nested(counter);
        self.value_depth -= 1;
        v
    }

    fn read_real_value_nested(&mut self, counter: &mut usize) -> R<f64> {
        let c = self.ch(*counter);
        if c == 0 {
            return Err(self.fault_at(*counter, "No characters found in reading real value"));
        }
        let c1 = self.ch(*counter + 1);
        let v = if c == b'[' {
            self.read_real_expression(counter)?
        } else if c == b'#' {
            self.read_parameter(counter, false)?
        } else if c == b'+' && c1 != 0 && !c1.is_ascii_digit() && c1 != b'.' {
            *counter += 1;
            self.read_real_value(counter)?
        } else if c == b'-' && c1 != 0 && !c1.is_ascii_digit() && c1 != b'.' {
            *counter += 1;
            -self.read_real_value(counter)?
        } else if c.is_ascii_lowercase() {
            self.read_unary(counter)?
        } else {
            self.read_real_number(counter)?
        };
        chk!(v.is_nan(), "Calculation resulted in 'not a number'");
        chk!(v.is_infinite(), "Calculation resulted in 'infinity'");
        Ok(v)
    }

    /// A number: optional signs, then digits and a point, read as C++'s
    /// stream extraction reads them.
    fn read_real_number(&mut self, counter: &mut usize) -> R<f64> {
        let start = *counter;
        // LinuxCNC takes the run of signs, digits and points, then asks the
        // converter to read all of it: one sign and one decimal.
        let span = match lex::number_span(&self.line[start..]) {
            Ok((_, span)) => span,
            Err(_) => &[],
        };
        let shown = || String::from_utf8_lossy(span).into_owned();
        let (rest, (negative, body)) = lex::signed_decimal(span).map_err(|_| {
            self.fault_at(
                start,
                format!(
                    "bad number format (conversion failed) parsing '{}'",
                    shown()
                ),
            )
        })?;
        if !rest.is_empty() {
            return Err(self.fault_at(
                start,
                format!(
                    "bad number format (trailing characters) parsing '{}'",
                    shown()
                ),
            ));
        }
        let v = fast_parse(body);
        *counter = start + span.len();
        Ok(if negative { -v } else { v })
    }

    fn read_real_expression(&mut self, counter: &mut usize) -> R<f64> {
        const MAX_STACK: usize = 7;
        let mut values = [0.0f64; MAX_STACK + 1];
        let mut ops = [Op::RightBracket; MAX_STACK + 1];
        *counter += 1;
        values[0] = self.read_real_value(counter)?;
        ops[0] = self.read_operation(counter)?;
        let mut si = 1usize;
        while ops[0] != Op::RightBracket {
            values[si] = self.read_real_value(counter)?;
            ops[si] = self.read_operation(counter)?;
            if precedence(ops[si]) > precedence(ops[si - 1]) {
                si += 1;
                chk!(si > MAX_STACK, "Expression too deeply nested");
            } else {
                while precedence(ops[si]) <= precedence(ops[si - 1]) {
                    values[si - 1] = binary(values[si - 1], ops[si - 1], values[si])?;
                    ops[si - 1] = ops[si];
                    if si > 1 && precedence(ops[si - 1]) <= precedence(ops[si - 2]) {
                        si -= 1;
                    } else {
                        break;
                    }
                }
            }
        }
        Ok(values[0])
    }

    fn read_operation(&mut self, counter: &mut usize) -> R<Op> {
        let at = *counter;
        let rest = &self.line[at..];
        if let Ok((after, op)) = lex::operation(rest) {
            *counter += rest.len() - after.len();
            return Ok(op);
        }
        let message = match self.ch(at) {
            0 => "Unclosed expression",
            b'a' => "Unknown operation name starting with a",
            b'm' => "Unknown operation name starting with m",
            b'x' => "Unknown operation name starting with x",
            b'o' => "Unknown operation name starting with o",
            b'e' => "Unknown operation name starting with e",
            b'n' => "Unknown operation name starting with n",
            b'g' => "Unknown operation name starting with g",
            b'l' => "Unknown operation name starting with l",
            _ => "Unknown operation",
        };
        Err(self.fault_at(at, message))
    }

    fn read_unary(&mut self, counter: &mut usize) -> R<f64> {
        let at = *counter;
        let rest = &self.line[at..];
        let func = match lex::function(rest) {
            Ok((after, func)) => {
                *counter += rest.len() - after.len();
                func
            }
            Err(_) => {
                let c = self.ch(at);
                let message = if b"acefflrst".contains(&c) {
                    format!("Unknown word starting with {}", c as char)
                } else {
                    "Unknown word where unary operation could be".to_string()
                };
                return Err(self.fault_at(at, message));
            }
        };
        if self.ch(*counter) != b'[' {
            return Err(self.fault_at(*counter, "Left bracket missing after unary operation name"));
        }
        if func == Func::Exists {
            *counter += 1;
            if self.ch(*counter) != b'#' {
                return Err(self.fault_at(*counter, "Expected # reading parameter"));
            }
            let v = self.read_parameter(counter, true)?;
            if self.ch(*counter) != b']' {
                return Err(self.fault_at(*counter, "Expected ] reading bracketed parameter"));
            }
            *counter += 1;
            return Ok(v);
        }
        let v = self.read_real_expression(counter)?;
        if func == Func::Atan {
            if self.ch(*counter) != b'/' {
                return Err(self.fault_at(*counter, "Slash missing after first atan argument"));
            }
            *counter += 1;
            if self.ch(*counter) != b'[' {
                return Err(self.fault_at(*counter, "Left bracket missing after slash with atan"));
            }
            let v2 = self.read_real_expression(counter)?;
            return Ok(crate::ld::degrees(v.atan2(v2)));
        }
        unary(v, func)
    }

    /// `#n`, `##n`, `#[expr]` or `#<name>`. With `check_exists`, the result
    /// is 1 if the parameter exists and 0 if not.
    fn read_parameter(&mut self, counter: &mut usize, check_exists: bool) -> R<f64> {
        *counter += 1;
        if self.ch(*counter) == b'<' {
            let name = self.read_name(counter)?;
            let found = self.find_named_param(&name)?;
            if check_exists {
                return Ok(bool_f(found.is_some()));
            }
            return match found {
                Some(v) => Ok(v),
                None if self.defining_sub => Ok(0.0),
                None => Err(Fault::new(format!("Named parameter #<{name}> not defined"))),
            };
        }
        let start = *counter;
        let index = self.read_integer_value(counter)?;
        if check_exists {
            return Ok(bool_f(
                (1..crate::paramfile::PARAMETER_COUNT as i32).contains(&index),
            ));
        }
        if !(1..crate::paramfile::PARAMETER_COUNT as i32).contains(&index) {
            return Err(self.fault_at(start, "Parameter number out of range"));
        }
        chk!(
            (5420..=5428).contains(&index) && self.cutter_comp_side != Side::Off,
            "Cannot read current position with cutter radius compensation on"
        );
        Ok(self.params[index as usize])
    }

    /// `<name>`: the characters up to `>`.
    fn read_name(&mut self, counter: &mut usize) -> R<String> {
        let start = *counter;
        let rest = &self.line[start..];
        let (after, name) = lex::bracketed_name(rest)
            .map_err(|_| self.fault_at(start, "Named parameter not terminated"))?;
        *counter += rest.len() - after.len();
        Ok(String::from_utf8_lossy(name).into_owned())
    }

    fn read_parameter_setting(&mut self, counter: &mut usize, block: &mut Block) -> R {
        let col = self.col_at(*counter);
        *counter += 1;
        if self.ch(*counter) == b'<' {
            let name = self.read_name(counter)?;
            let word = || format!("#<{name}>");
            self.add_named_param(&name, false)
                .map_err(|f| f.in_word(word, col))?;
            if self.ch(*counter) != b'=' {
                return Err(self.fault_at(*counter, "Equal sign missing in parameter setting"));
            }
            *counter += 1;
            let value = self
                .read_real_value(counter)
                .map_err(|f| f.in_word(word, col))?;
            block.assign_named.push((name, value));
            return Ok(());
        }
        let start = *counter;
        let index = self.read_integer_value(counter)?;
        if !(1..crate::paramfile::PARAMETER_COUNT as i32).contains(&index) {
            return Err(self.fault_at(start, "Parameter number out of range"));
        }
        if (5400..=5413).contains(&index) || (5420..=5428).contains(&index) {
            return Err(self.fault_at(start, "Parameter is readonly"));
        }
        if self.ch(*counter) != b'=' {
            return Err(self.fault_at(*counter, "Equal sign missing in parameter setting"));
        }
        *counter += 1;
        let value = self
            .read_real_value(counter)
            .map_err(|f| f.in_word(|| format!("#{index}"), col))?;
        block.assign_numbered.push((index as usize, value));
        Ok(())
    }

    /// The label of an O-word line and what it does.
    fn read_o(&mut self, counter: &mut usize, block: &mut Block) -> R {
        block.o_col = self.col_at(*counter);
        let mut name;
        if self.ch(*counter) == b'm' {
            let mut n = *counter + 1;
            let number = self.read_integer_value(&mut n)?;
            if number == 98 {
                chk!(
                    self.cfg.disable_fanuc_style_sub,
                    "DISABLE_FANUC_STYLE_SUB set in INI file, but found m98"
                );
                block.o_type = OType::M98;
                *counter += 3;
                while *counter < self.line.len() {
                    self.read_one_item(counter, block)?;
                }
                chk!(!block.has(b'p'), "Found 'm98' code with no P-word");
                let p = block.p();
                let mut n = p.floor();
                if p - n > 0.9999 {
                    n = p.ceil();
                } else {
                    chk!(p - n > 0.0001, "Non integer value for integer");
                }
                name = format!("{}", n as i64);
            } else {
                chk!(
                    self.cfg.disable_fanuc_style_sub,
                    "DISABLE_FANUC_STYLE_SUB set in INI file, but found m99"
                );
                chk!(
                    self.defining_sub,
                    "Found 'M99' instead of 'O endsub' after 'O sub'"
                );
                block.o_type = OType::M99;
                *counter += 3;
                name = self.contexts[self.call_level]
                    .sub_name
                    .clone()
                    .unwrap_or_default();
            }
        } else {
            *counter += 1;
            if self.ch(*counter) == b'<' {
                name = self.read_name(counter)?;
            } else {
                let v = self.read_integer_value(counter)?;
                name = v.to_string();
            }
            let rest = &self.line[*counter..];
            block.o_type = match lex::o_keyword(rest) {
                Ok((after, kind)) => {
                    *counter += rest.len() - after.len();
                    kind
                }
                Err(_) => OType::None,
            };
            if block.o_type == OType::None {
                let c = self.ch(*counter);
                if c == b'(' || c == b';' || c == 0 {
                    chk!(
                        self.cfg.disable_fanuc_style_sub,
                        "DISABLE_FANUC_STYLE_SUB disabled in INI file, but found bare O-word"
                    );
                    block.o_type = OType::Bare;
                }
            }
        }
        match block.o_type {
            OType::Sub
            | OType::Bare
            | OType::EndSub
            | OType::Call
            | OType::M98
            | OType::Return
            | OType::M99 => {}
            _ => {
                let sub = if self.call_level > 0 {
                    self.contexts[self.call_level]
                        .sub_name
                        .clone()
                        .unwrap_or_default()
                } else if self.defining_sub {
                    self.sub_name.clone().unwrap_or_default()
                } else {
                    String::new()
                };
                name = format!("{sub}#{name}");
            }
        }
        block.o_name = name;
        match block.o_type {
            OType::Sub | OType::Bare => {
                chk!(self.defining_sub, "Nested subroutine definition");
            }
            OType::EndSub | OType::Return | OType::M99 => {
                // Searching forward for a called sub must not run past the
                // end of the sub that called it.
                if let Some(wanted) = &self.skipping_to_sub {
                    if self.call_level >= 2
                        && self.contexts[self.call_level - 1].sub_name.as_deref()
                            == Some(block.o_name.as_str())
                    {
                        return Err(Fault::new(format!(
                            "Failed to find sub 'O{wanted}' before the end of sub 'O{}'",
                            block.o_name
                        )));
                    }
                }
                if self
                    .skipping_o
                    .as_deref()
                    .is_some_and(|s| s != block.o_name)
                {
                    return Ok(());
                }
                if block.o_type != OType::M99 && self.ch(*counter) == b'[' {
                    self.return_value = self.read_real_expression(counter)?;
                    self.value_returned = true;
                } else {
                    self.return_value = 0.0;
                    self.value_returned = false;
                }
            }
            _ if self.defining_sub => block.o_type = OType::None,
            OType::Call => {
                if self.skipping_o.is_some() {
                    block.o_type = OType::None;
                    return Ok(());
                }
                block.call_type = CallType::NgcSub;
                block.params.clear();
                while matches!(self.ch(*counter), b'[' | b'(') {
                    if self.ch(*counter) == b'(' {
                        self.read_comment(counter, block)?;
                        continue;
                    }
                    chk!(
                        block.params.len() >= SUB_PARAMS,
                        "Too many subroutine parameters"
                    );
                    let v = self.read_real_expression(counter)?;
                    block.params.push(v);
                }
            }
            OType::M98 => {
                block.params.clear();
                block.call_type = CallType::M98Sub;
            }
            OType::While | OType::Repeat | OType::If | OType::ElseIf => {
                if self
                    .skipping_o
                    .as_deref()
                    .is_some_and(|s| s != block.o_name)
                {
                    return Ok(());
                }
                let word = match block.o_type {
                    OType::While => "while",
                    OType::Repeat => "repeat",
                    OType::If => "if",
                    _ => "elseif",
                };
                if self.ch(*counter) != b'[' {
                    return Err(
                        self.fault_at(*counter, format!("Left bracket missing after '{word}'"))
                    );
                }
                self.test_value = self.read_real_expression(counter)?;
            }
            OType::None => {
                return Err(Fault::at(block.o_col, "Unknown control command in o word"));
            }
            _ => {}
        }
        Ok(())
    }

    /// Work out the motion this block will do and check that axis words
    /// have a use (LinuxCNC's `enhance_block`).
    fn enhance_block(&mut self, block: &mut Block) -> R {
        let polar = block.radius.is_some() || block.theta.is_some();
        if polar {
            chk!(
                !self.cfg.axes[0] || !self.cfg.axes[1],
                "Cannot use polar coordinate on a machine lacking X or Y axes"
            );
            chk!(
                self.plane != crate::canon::Plane::XY,
                "Cannot use polar coordinate except in G17 plane"
            );
            chk!(
                block.has(b'x'),
                "Cannot specify both polar coordinate and X word"
            );
            chk!(
                block.has(b'y'),
                "Cannot specify both polar coordinate and Y word"
            );
        }
        let axis_flag = block.any_axis();
        let ijk_flag = block.has(b'i') || block.has(b'j') || block.has(b'k');
        let mode0 = block.g_modes[gm::MODAL_0];
        let mode1 = block.g_modes[gm::MOTION];
        let covets = matches!(mode0, g::G10 | g::G28 | g::G30 | g::G52 | g::G92);
        if mode1 != -1 {
            if mode1 == g::G80 {
                chk!(
                    (polar || axis_flag) && !covets,
                    "Cannot use axis values with g80"
                );
                check_offset_words(mode0, polar, axis_flag)?;
            } else {
                chk!(covets, "Cannot use two g codes that both use axis values");
                chk!(
                    !axis_flag
                        && !polar
                        && !matches!(
                            mode1,
                            g::G0
                                | g::G1
                                | g::G2
                                | g::G3
                                | g::G5_2
                                | g::G70
                                | g::G71
                                | g::G71_1
                                | g::G71_2
                                | g::G72
                                | g::G72_1
                                | g::G72_2
                        )
                        && self.remap_for('g', mode1).is_none(),
                    "All axes missing with motion code"
                );
            }
            block.motion_to_be = mode1;
        } else if covets {
            check_offset_words(mode0, polar, axis_flag)?;
        } else if axis_flag || polar {
            let tlo = block.g_modes[gm::TOOL_LENGTH_OFFSET];
            chk!(
                (self.motion_mode == -1 || self.motion_mode == g::G80)
                    && tlo != g::G43_1
                    && tlo != g::G43_2,
                "Cannot use axis values without a g code that uses them"
            );
            if tlo != g::G43_1 {
                block.motion_to_be = self.motion_mode;
            }
        } else if ijk_flag && (self.motion_mode == g::G2 || self.motion_mode == g::G3) {
            block.motion_to_be = self.motion_mode;
        }
        chk!(
            polar && block.motion_to_be == -1,
            "Polar coordinates can only be used for motion"
        );
        Ok(())
    }

    fn check_items(&mut self, block: &Block) -> R {
        self.check_g_codes(block)?;
        chk!(block.m_count > 4, "Too many m codes on line");
        self.check_other_codes(block)
    }

    fn check_g_codes(&mut self, block: &Block) -> R {
        let mode0 = block.g_modes[gm::MODAL_0];
        let mode1 = block.g_modes[gm::MOTION];
        match mode0 {
            -1 => {}
            g::G4 => {
                chk!(!block.has(b'p'), "Dwell time missing with g4");
                chk!(
                    mode1 == g::G2 || mode1 == g::G3,
                    "G4 not allowed with G2 or G3 because they both use P"
                );
            }
            g::G10 => {
                let p = block.p();
                let p_int = if p >= 0.0 {
                    (p + 0.5) as i32
                } else {
                    (p - 0.5) as i32
                };
                let l = block.l();
                chk!(
                    !matches!(l, 0 | 1 | 2 | 10 | 11 | 20),
                    "Line with G10 does not have L0, L1, L10, L11, L2, or L20"
                );
                chk!(
                    (p + 0.0001) - p_int as f64 > 0.0002,
                    "P value not an integer with G10"
                );
                chk!(
                    (l == 2 || l == 20) && !(0..=9).contains(&p_int),
                    "P value out of range (0-9) with G10 L{l}"
                );
                chk!(
                    (l == 1 || l == 10 || l == 11) && p_int < 1,
                    "P value out of range with G10 L{l}"
                );
            }
            g::G5_3 => {
                chk!(
                    mode1 != g::G5_2 && mode1 != -1,
                    "Between G5.2 and G5.3 codes, only additional G5.2 codes are allowed."
                );
            }
            g::G53 => {
                chk!(
                    block.motion_to_be != g::G0 && block.motion_to_be != g::G1,
                    "Must use g0 or g1 with g53"
                );
                let dist = block.g_modes[gm::DISTANCE_MODE];
                chk!(
                    dist == g::G91
                        || (dist != g::G90
                            && self.distance_mode == crate::interp::Distance::Incremental),
                    "Cannot use g53 incremental"
                );
            }
            _ => {}
        }
        Ok(())
    }

    fn check_other_codes(&mut self, block: &Block) -> R {
        let motion = block.motion_to_be;
        if self.remap_for('g', motion).is_some() {
            return Ok(());
        }
        if (4..=10).any(|grp| {
            let m = block.m_modes[grp];
            m != -1 && self.remap_for('m', m).is_some()
        }) {
            return Ok(());
        }
        let cycle = is_cycle(motion);
        chk!(block.has(b'a') && cycle, "Cannot put an a in canned cycle");
        chk!(block.has(b'b') && cycle, "Cannot put a b in canned cycle");
        chk!(block.has(b'c') && cycle, "Cannot put a c in canned cycle");
        let g7x = matches!(
            motion,
            g::G70 | g::G71 | g::G71_1 | g::G71_2 | g::G72 | g::G72_1 | g::G72_2
        );
        let comp = block.g_modes[gm::CUTTER_COMP];
        if block.has(b'd') {
            chk!(
                !matches!(comp, g::G41 | g::G42 | g::G41_1 | g::G42_1)
                    && !g7x
                    && block.g_modes[gm::SPINDLE_MODE] != g::G96,
                "D word with no G41, G41.1, G42, G42.1, G71, G71.1, G71.2 or G96 to use it"
            );
        }
        if block.dollar.is_some() {
            chk!(
                !matches!(motion, g::G76 | g::G33 | g::G33_1 | g::G95 | g::G96 | g::G97)
                    && !matches!(block.m_modes[7], 3 | 4 | 5 | 19)
                    && block.m_modes[9] != 51
                    && !block.has(b's'),
                "$ (spindle selection) word with no M3, M4, M5, M19, M51, G33, G33.1, G76, G95, G96 or G97 to use it"
            );
        }
        if block.has(b'e') {
            chk!(
                !matches!(motion, g::G76 | g::G33 | g::G33_1 | g::G70)
                    && !matches!(block.m_modes[5], 66..=68),
                "E word with no G70, G76, M66, M67 or M68 to use it"
            );
        }
        if block.has(b'h') {
            let tlo = block.g_modes[gm::TOOL_LENGTH_OFFSET];
            chk!(
                tlo != g::G43 && motion != g::G76 && tlo != g::G43_2,
                "H word with no G43 or G76 to use it"
            );
        }
        let mode0 = block.g_modes[gm::MODAL_0];
        if block.has(b'i') {
            chk!(
                !matches!(
                    motion,
                    g::G2 | g::G3 | g::G5 | g::G5_1 | g::G76 | g::G87 | g::G33_1
                ) && !g7x
                    && mode0 != g::G10,
                "I word with no G2, G3, G5, G5.1, G10, G33.1, G76, or G87 to use it"
            );
        }
        if block.has(b'j') {
            chk!(
                !matches!(motion, g::G2 | g::G3 | g::G5 | g::G5_1 | g::G76 | g::G87)
                    && mode0 != g::G10,
                "J word with no G2, G3, G5, G5.1, G10, G76 or G87 to use it"
            );
        }
        if block.has(b'k') {
            chk!(
                !matches!(motion, g::G2 | g::G3 | g::G33 | g::G33_1 | g::G76 | g::G87),
                "K word with no G2, G3, G33, G33.1, G76, or G87 to use it"
            );
        }
        if block.has(b'l') {
            chk!(
                !(g::G81..=g::G89).contains(&motion)
                    && !matches!(motion, g::G76 | g::G5_2 | g::G73)
                    && mode0 != g::G10
                    && !matches!(comp, g::G41 | g::G41_1 | g::G42 | g::G42_1)
                    && block.m_modes[5] != 66
                    && block.o_type != OType::M98,
                "L word with no G10, cutter compensation, canned cycle, digital/analog input, M98 or NURBS code"
            );
        }
        if block.has(b'p') {
            chk!(
                !matches!(mode0, g::G10 | g::G4)
                    && block.g_modes[gm::CONTROL_MODE] != g::G64
                    && !matches!(
                        motion,
                        g::G76
                            | g::G82
                            | g::G86
                            | g::G88
                            | g::G89
                            | g::G5
                            | g::G5_2
                            | g::G70
                            | g::G2
                            | g::G3
                            | g::G74
                            | g::G84
                    )
                    && !matches!(block.m_modes[9], 50..=53)
                    && !matches!(block.m_modes[5], 62..=66)
                    && block.m_modes[7] != 19
                    && !block.user_m
                    && block.o_type != OType::M98,
                "P word with no G2 G3 G4 G10 G64 G5 G5.2 G76 G82 G86 G88 G89 or M50 M51 M52 M53 M62 M63 M64 M65 M66 M98 or user M code to use it"
            );
            let p = block.p();
            let p_value = crate::block::round_to_int(p);
            chk!(
                (motion == g::G2 || motion == g::G3 || block.m_modes[7] == 19)
                    && (p_value as f64 - p).abs() > 0.001,
                "P value not an integer with M19 G2 or G3"
            );
            chk!(
                block.m_modes[7] == 19 && !(0..=2).contains(&p_value),
                "P value must be 0,1,or 2 with M19"
            );
            chk!(
                (motion == g::G2 || motion == g::G3) && p_value < 1,
                "P value should be 1 or greater with G2 or G3"
            );
        }
        if block.has(b'q') {
            chk!(
                !matches!(motion, g::G83 | g::G73 | g::G5 | g::G76 | g::G70)
                    && !g7x
                    && !block.user_m
                    && !matches!(block.m_modes[5], 66..=68)
                    && mode0 != g::G10
                    && block.m_modes[6] != 61
                    && block.g_modes[gm::CONTROL_MODE] != g::G64
                    && block.m_modes[7] != 19,
                "Q word with no G5, G10, G64, G73, G76, G83, M19, M66, M67, M68 or user M code that uses it"
            );
        }
        if block.has(b'r') {
            chk!(
                block.g_modes[gm::CONTROL_MODE] == g::G64 && block.m_modes[7] == 19,
                "R word is ambiguous on a line with both G64 and M19 - use separate lines"
            );
            chk!(
                !matches!(motion, g::G2 | g::G3 | g::G76 | g::G73 | g::G74)
                    && block.g_modes[gm::CONTROL_MODE] != g::G64
                    && !g7x
                    && !(g::G81..=g::G89).contains(&motion)
                    && !matches!(comp, g::G41_1 | g::G42_1)
                    && mode0 != g::G10
                    && block.m_modes[7] != 19,
                "R word with no g code that uses it"
            );
            let r = block.or(b'r', 0.0);
            chk!(
                block.m_modes[7] == 19 && !(0.0..=360.0).contains(&r),
                "R value must be within 0..360 with M19"
            );
        }
        if !block.has(b's') {
            chk!(
                block.g_modes[gm::SPINDLE_MODE] == g::G96,
                "S word missing with G96"
            );
        }
        if motion == g::G33 || motion == g::G33_1 {
            chk!(!block.has(b'k'), "K word missing with g33/g33.1");
            chk!(block.has(b'f'), "F word used with a g33/g33.1");
        }
        if motion == g::G76 {
            chk!(!block.has(b'p'), "P word missing with G76");
            chk!(
                !block.has(b'i') || !block.has(b'j') || !block.has(b'k'),
                "I J or K words missing with G76"
            );
        }
        Ok(())
    }
}

/// G52 and G92 need axis words, and plain ones.
fn check_offset_words(mode0: i32, polar: bool, axis_flag: bool) -> R {
    chk!(
        polar && mode0 == g::G92,
        "Polar coordinates can only be used for motion"
    );
    chk!(
        !axis_flag && (mode0 == g::G52 || mode0 == g::G92),
        "All axes missing with g52 or g92"
    );
    Ok(())
}

/// Parse an unsigned decimal number of digits and at most one point.
/// Short ones (the common case) are assembled exactly from integers;
/// longer ones go through the standard library's correctly rounded parser.
fn fast_parse(b: &[u8]) -> f64 {
    if b.len() <= 15 {
        let mut mantissa: u64 = 0;
        let mut frac_digits: i32 = 0;
        let mut seen_point = false;
        for &c in b {
            if c == b'.' {
                seen_point = true;
            } else {
                mantissa = mantissa * 10 + (c - b'0') as u64;
                if seen_point {
                    frac_digits += 1;
                }
            }
        }
        // Integers below 2^53 divided by an exact power of ten round once,
        // which is exactly what a correctly rounded parse gives.
        const POW10: [f64; 16] = [
            1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
        ];
        return mantissa as f64 / POW10[frac_digits as usize];
    }
    std::str::from_utf8(b)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::fast_parse;

    #[test]
    fn fast_parse_matches_the_standard_parser() {
        for s in [
            "0",
            "1",
            "1.",
            ".5",
            "12.345",
            "0.1",
            "123456789.012345",
            "99999.99999",
            "0.0001",
        ] {
            assert_eq!(fast_parse(s.as_bytes()), s.parse::<f64>().unwrap(), "{s}");
        }
        assert_eq!(fast_parse(b"3.14159265358979323846"), std::f64::consts::PI);
    }
}
