//! The tool table, read from LinuxCNC's `.tbl` format.
//!
//! Each line describes one tool with blank-separated words: `T` tool number,
//! `P` pocket, `X Y Z A B C U V W` offsets, `D` diameter, `I` front angle,
//! `J` back angle, `Q` orientation; text after `;` is a comment. Values are
//! in the machine's user units (see [`crate::Config::user_units_per_mm`]).
//!
//! Entry 0 holds the tool in the spindle. On a non-random tool changer the
//! tools fill entries 1, 2, … in file order; on a random changer the entry
//! is the pocket number.

use crate::canon::{Position, ToolData};

/// The tool table: entry 0 is the spindle, the rest are the loaded tools.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolTable {
    entries: Vec<ToolData>,
    random: bool,
}

/// A tool table line that could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ToolTableError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong with it.
    pub message: String,
}

impl std::fmt::Display for ToolTableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl ToolTable {
    /// An empty table (no tools; nothing in the spindle).
    pub fn new(random_toolchanger: bool) -> ToolTable {
        ToolTable {
            entries: vec![ToolData::default()],
            random: random_toolchanger,
        }
    }

    /// Parse a tool table. Lines that cannot be read are reported with their
    /// number; LinuxCNC skips them, so callers may choose to warn and go on
    /// with [`ToolTable::parse_lenient`].
    pub fn parse(text: &str, random_toolchanger: bool) -> Result<ToolTable, ToolTableError> {
        let (table, errors) = Self::parse_lenient(text, random_toolchanger);
        match errors.into_iter().next() {
            Some(e) => Err(e),
            None => Ok(table),
        }
    }

    /// Parse a tool table, skipping unreadable lines and returning them.
    pub fn parse_lenient(text: &str, random_toolchanger: bool) -> (ToolTable, Vec<ToolTableError>) {
        let mut table = ToolTable::new(random_toolchanger);
        let mut errors = Vec::new();
        let mut next_index = 1usize;
        for (n, raw) in text.lines().enumerate() {
            if raw.starts_with(';') {
                continue;
            }
            let body = raw.split(';').next().unwrap_or("");
            if body.trim_end_matches(['\r', '\n']).len() <= 1 {
                continue;
            }
            match Self::read_entry(body, random_toolchanger, &mut next_index) {
                Ok((index, data)) => {
                    table.put(index, data);
                    if !random_toolchanger && table.entries[0].tool == data.tool {
                        table.entries[0] = data;
                    }
                }
                Err(message) => errors.push(ToolTableError {
                    line: n + 1,
                    message,
                }),
            }
        }
        (table, errors)
    }

    fn read_entry(
        body: &str,
        random: bool,
        next_index: &mut usize,
    ) -> Result<(usize, ToolData), String> {
        let mut data = ToolData::default();
        let mut index = 0usize;
        for token in body.split(' ').filter(|t| !t.is_empty()) {
            let token = token.trim_end_matches(['\r', '\n', '\t']);
            if token.is_empty() {
                continue;
            }
            let letter = token.as_bytes()[0].to_ascii_uppercase();
            // A token starting with a non-ASCII character is no word.
            let Some(rest) = token.get(1..) else {
                return Err(format!("unknown word {token:?}"));
            };
            let real = || {
                crate::ini::leading_number(rest).ok_or_else(|| format!("bad number in {token:?}"))
            };
            let int = || -> Result<i32, String> {
                leading_int(rest).ok_or_else(|| format!("bad whole number in {token:?}"))
            };
            match letter {
                b'T' => data.tool = int()?,
                b'P' => {
                    let pocket = int()?;
                    data.pocket = pocket;
                    index = if random {
                        usize::try_from(pocket).map_err(|_| format!("bad pocket {pocket}"))?
                    } else {
                        let i = *next_index;
                        *next_index += 1;
                        i
                    };
                }
                b'D' => data.diameter = real()?,
                b'X' => data.offset.x = real()?,
                b'Y' => data.offset.y = real()?,
                b'Z' => data.offset.z = real()?,
                b'A' => data.offset.a = real()?,
                b'B' => data.offset.b = real()?,
                b'C' => data.offset.c = real()?,
                b'U' => data.offset.u = real()?,
                b'V' => data.offset.v = real()?,
                b'W' => data.offset.w = real()?,
                b'I' => data.front_angle = real()?,
                b'J' => data.back_angle = real()?,
                b'Q' => data.orientation = int()?,
                _ => return Err(format!("unknown word {token:?}")),
            }
        }
        if index >= 1000 {
            return Err(format!(
                "pocket index {index} is beyond the table's 1000 entries"
            ));
        }
        Ok((index, data))
    }

    /// True for a random tool changer (tools move between pockets).
    pub fn random_toolchanger(&self) -> bool {
        self.random
    }

    /// The entry at `index` (0 is the spindle); empty if beyond the table.
    pub fn get(&self, index: usize) -> ToolData {
        self.entries.get(index).copied().unwrap_or_default()
    }

    /// Replace the entry at `index`, growing the table if needed.
    pub fn put(&mut self, index: usize, data: ToolData) {
        if index >= self.entries.len() {
            self.entries.resize(index + 1, ToolData::default());
        }
        self.entries[index] = data;
    }

    /// Number of entries, the spindle included.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True if the table holds only the (empty) spindle entry.
    pub fn is_empty(&self) -> bool {
        self.entries.len() <= 1
    }

    /// The index of tool `tool`, as LinuxCNC finds it: tool 0 is entry 0 on
    /// a non-random changer; otherwise the first entry after the spindle
    /// with that number (the spindle if it is the only one).
    pub fn find(&self, tool: i32) -> Option<usize> {
        if tool == -1 {
            return None;
        }
        if !self.random && tool == 0 {
            return Some(0);
        }
        let mut found = None;
        for (i, e) in self.entries.iter().enumerate() {
            if e.tool == tool {
                found = Some(i);
                if i != 0 {
                    break;
                }
            }
        }
        found
    }

    /// Format the table in `.tbl` form (entries after the spindle, zeros
    /// left out), as LinuxCNC saves it.
    pub fn to_text(&self) -> String {
        let start = if self.random { 0 } else { 1 };
        let mut out = String::new();
        for e in self.entries.iter().skip(start) {
            if e.tool == -1 {
                continue;
            }
            out.push_str(&format!("T{} P{}", e.tool, e.pocket));
            let p: Position = e.offset;
            for (letter, v) in "XYZABCUVW".chars().zip(p.to_array()) {
                if v != 0.0 {
                    out.push_str(&format!(" {letter}{v:+.6}"));
                }
            }
            if e.diameter != 0.0 {
                out.push_str(&format!(" D{:+.6}", e.diameter));
            }
            if e.front_angle != 0.0 {
                out.push_str(&format!(" I{:+.6}", e.front_angle));
            }
            if e.back_angle != 0.0 {
                out.push_str(&format!(" J{:+.6}", e.back_angle));
            }
            if e.orientation != 0 {
                out.push_str(&format!(" Q{}", e.orientation));
            }
            out.push('\n');
        }
        out
    }
}

fn leading_int(s: &str) -> Option<i32> {
    let s = s.trim_start();
    let end = s
        .char_indices()
        .find(|&(i, c)| !(c.is_ascii_digit() || (i == 0 && (c == '+' || c == '-'))))
        .map(|(i, _)| i)
        .unwrap_or(s.len());
    s[..end].parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonrandom_tools_fill_entries_in_file_order() {
        let t = ToolTable::parse(
            "T3 P7 Z1.5 D0.25 ;small\n; comment line\nT1 P1 X-0.5 Z2 Q2 I10 J20\n",
            false,
        )
        .unwrap();
        assert_eq!(t.get(1).tool, 3);
        assert_eq!(t.get(1).pocket, 7);
        assert_eq!(t.get(1).offset.z, 1.5);
        assert_eq!(t.get(1).diameter, 0.25);
        assert_eq!(t.get(2).tool, 1);
        assert_eq!(t.get(2).orientation, 2);
        assert_eq!(t.get(2).front_angle, 10.0);
        assert_eq!(t.find(1), Some(2));
        assert_eq!(t.find(0), Some(0));
        assert_eq!(t.find(9), None);
    }

    #[test]
    fn random_changer_uses_pocket_numbers() {
        let t = ToolTable::parse("T5 P4 Z1\n", true).unwrap();
        assert_eq!(t.get(4).tool, 5);
        assert_eq!(t.find(5), Some(4));
        assert_eq!(t.find(0), None);
    }

    #[test]
    fn bad_words_are_reported_with_their_line() {
        let e = ToolTable::parse("T1 P1\nT2 P2 Zfoo\n", false).unwrap_err();
        assert_eq!(e.line, 2);
    }
}
