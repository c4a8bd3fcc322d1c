//! A reader for LinuxCNC INI files, enough for the settings the interpreter
//! takes from them (`[RS274NGC]`, `[EMCIO]`, `[TRAJ]`, `[AXIS_*]`) and for
//! `#<_ini[section]name>` parameters.

use std::collections::HashMap;

/// The sections and entries of an INI file. Keys keep every value given,
/// in order, because some (REMAP) may repeat.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Ini {
    sections: HashMap<String, Vec<(String, String)>>,
}

impl Ini {
    /// Parse INI text: `[SECTION]` headers, `KEY = VALUE` lines, and `#` or
    /// `;` comment lines. Section and key names compare exactly.
    pub fn parse(text: &str) -> Ini {
        let mut ini = Ini::default();
        let mut section = String::new();
        for raw in text.lines() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
                continue;
            }
            if let Some(rest) = line.strip_prefix('[') {
                if let Some(end) = rest.find(']') {
                    section = rest[..end].trim().to_string();
                    continue;
                }
            }
            if let Some(eq) = line.find('=') {
                let key = line[..eq].trim().to_string();
                let value = line[eq + 1..].trim().to_string();
                ini.sections
                    .entry(section.clone())
                    .or_default()
                    .push((key, value));
            }
        }
        ini
    }

    /// The first value of `key` in `section`.
    pub fn get<'a>(&'a self, section: &str, key: &'a str) -> Option<&'a str> {
        self.all(section, key).next()
    }

    /// Every value of `key` in `section`, in file order.
    pub fn all<'a>(&'a self, section: &str, key: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.sections
            .get(section)
            .into_iter()
            .flat_map(move |entries| {
                entries
                    .iter()
                    .filter(move |(k, _)| k == key)
                    .map(|(_, v)| v.as_str())
            })
    }

    /// A boolean entry: `1`, `true`, `yes`, `on` (any case) are true; `0`,
    /// `false`, `no`, `off` false; anything else or absent gives `None`.
    pub fn get_bool(&self, section: &str, key: &str) -> Option<bool> {
        let v = self.get(section, key)?.to_ascii_lowercase();
        match v.as_str() {
            "1" | "true" | "yes" | "on" => Some(true),
            "0" | "false" | "no" | "off" => Some(false),
            _ => None,
        }
    }

    /// A numeric entry (the leading number of the value, like `strtod`).
    pub fn get_f64(&self, section: &str, key: &str) -> Option<f64> {
        leading_number(self.get(section, key)?)
    }
}

/// The longest prefix of `s` that parses as a decimal number, as C's
/// `strtod` reads it (sign, digits, point, exponent).
pub(crate) fn leading_number(s: &str) -> Option<f64> {
    let s = s.trim_start();
    let b = s.as_bytes();
    let mut i = 0;
    if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
        i += 1;
    }
    let digits_start = i;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    if i < b.len() && b[i] == b'.' {
        i += 1;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
    }
    if i == digits_start || (i == digits_start + 1 && b[digits_start] == b'.') {
        return None;
    }
    let mut end = i;
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        let mut j = i + 1;
        if j < b.len() && (b[j] == b'+' || b[j] == b'-') {
            j += 1;
        }
        let exp_start = j;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        if j > exp_start {
            end = j;
        }
    }
    s[..end].parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_keys_and_repeats() {
        let ini = Ini::parse(
            "# comment\n[RS274NGC]\nSUBROUTINE_PATH = subs:more\nREMAP=M400 ngc=a\nREMAP=M401 ngc=b\n[A]\nVALUE= 2.5\n",
        );
        assert_eq!(ini.get("RS274NGC", "SUBROUTINE_PATH"), Some("subs:more"));
        let remaps: Vec<_> = ini.all("RS274NGC", "REMAP").collect();
        assert_eq!(remaps, vec!["M400 ngc=a", "M401 ngc=b"]);
        assert_eq!(ini.get_f64("A", "VALUE"), Some(2.5));
        assert_eq!(ini.get("A", "NONE"), None);
    }

    #[test]
    fn strtod_prefix() {
        assert_eq!(leading_number("42.0 deg"), Some(42.0));
        assert_eq!(leading_number("-1e3x"), Some(-1000.0));
        assert_eq!(leading_number("1e"), Some(1.0));
        assert_eq!(leading_number("."), None);
        assert_eq!(leading_number("abc"), None);
    }
}
