//! Persistent machine state: the parameter file and the tool table.
//!
//! Both live in the state directory (`--state-dir`) in LinuxCNC's formats,
//! so an integrator can read, diff and hand-edit them, and carry them over:
//!
//! * `kerf.var`: numbered RS274NGC parameters, one `NUMBER<TAB>VALUE` per
//!   line — 5161–5169 G28 position, 5181–5189 G30 position, 5210 G92 on,
//!   5211–5219 G92 offset, 5220 active coordinate system (1 = G54 …
//!   9 = G59.3), 5221–5229 G54 … 5381–5389 G59.3 (20 apart). Axes in the
//!   order X Y Z A B C U V W.
//! * `tool.tbl`: one tool per line, `T1 P1 Z10.5 D6 ;comment`.
//!
//! The API deals in plain values ([`Parameters`], [`Tool`]) so the
//! interpreter can later take and give them without knowing about files.
//!
//! Every write is atomic and durable before it returns: the new text goes
//! to a temporary file that is fsynced, the previous file is kept as
//! `NAME.bak`, the temporary file is renamed over the real one, and the
//! directory is fsynced. A crash at any moment leaves either the old or the
//! new file whole, and a change that was acknowledged (the write returned)
//! is never lost.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Names of the nine work coordinate systems, index 0 = G54 (parameter 5221).
pub const COORDINATE_SYSTEMS: [&str; 9] = [
    "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3",
];

/// Axis letters in parameter order.
pub const AXES: [char; 9] = ['X', 'Y', 'Z', 'A', 'B', 'C', 'U', 'V', 'W'];

/// File name of the parameter file in the state directory.
pub const PARAMETER_FILE: &str = "kerf.var";
/// File name of the tool table in the state directory.
pub const TOOL_FILE: &str = "tool.tbl";

/// The persistent parameters: mm for linear axes, degrees for rotary ones,
/// in the order of [`AXES`].
#[derive(Clone, Debug, PartialEq)]
pub struct Parameters {
    /// Work offsets of G54 … G59.3, by [`COORDINATE_SYSTEMS`] index.
    pub work_offsets: [[f64; 9]; 9],
    /// Active coordinate system, index into [`COORDINATE_SYSTEMS`].
    pub active_system: usize,
    /// G92 offset.
    pub g92: [f64; 9],
    /// G92 offset applied.
    pub g92_active: bool,
    /// Position stored for G28.
    pub g28: [f64; 9],
    /// Position stored for G30.
    pub g30: [f64; 9],
}

impl Default for Parameters {
    fn default() -> Self {
        Parameters {
            work_offsets: [[0.0; 9]; 9],
            active_system: 0,
            g92: [0.0; 9],
            g92_active: false,
            g28: [0.0; 9],
            g30: [0.0; 9],
        }
    }
}

impl Parameters {
    /// The parameters as RS274NGC numbered parameters.
    pub fn to_numbered(&self) -> BTreeMap<u32, f64> {
        let mut m = BTreeMap::new();
        let mut put = |base: u32, v: &[f64; 9]| {
            for (i, x) in v.iter().enumerate() {
                m.insert(base + i as u32, *x);
            }
        };
        put(5161, &self.g28);
        put(5181, &self.g30);
        put(5211, &self.g92);
        for (k, offsets) in self.work_offsets.iter().enumerate() {
            put(5221 + 20 * k as u32, offsets);
        }
        m.insert(5210, if self.g92_active { 1.0 } else { 0.0 });
        m.insert(5220, (self.active_system + 1) as f64);
        m
    }

    /// Parameters from numbered parameters; numbers it does not know are
    /// ignored (a LinuxCNC var file holds more), missing ones stay zero.
    pub fn from_numbered(m: &BTreeMap<u32, f64>) -> Result<Parameters, String> {
        let mut p = Parameters::default();
        let get = |base: u32, v: &mut [f64; 9]| {
            for (i, x) in v.iter_mut().enumerate() {
                if let Some(value) = m.get(&(base + i as u32)) {
                    *x = *value;
                }
            }
        };
        get(5161, &mut p.g28);
        get(5181, &mut p.g30);
        get(5211, &mut p.g92);
        for (k, offsets) in p.work_offsets.iter_mut().enumerate() {
            get(5221 + 20 * k as u32, offsets);
        }
        p.g92_active = m.get(&5210).is_some_and(|v| *v != 0.0);
        if let Some(&v) = m.get(&5220) {
            if !(1.0..=9.0).contains(&v) || v.fract() != 0.0 {
                return Err(format!(
                    "parameter 5220 (coordinate system) is {v}, not 1 to 9"
                ));
            }
            p.active_system = v as usize - 1;
        }
        Ok(p)
    }

    /// The text of the parameter file.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        for (n, v) in self.to_numbered() {
            s.push_str(&format!("{n}\t{v:.6}\n"));
        }
        s
    }

    /// Parse the text of a parameter file; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Parameters, String> {
        let mut m = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let mut words = line.split_whitespace();
            let (Some(n), Some(v)) = (words.next(), words.next()) else {
                return Err(format!(
                    "{origin}:{}: expected `NUMBER VALUE`, got {line:?}",
                    i + 1
                ));
            };
            let n: u32 = n
                .parse()
                .map_err(|_| format!("{origin}:{}: {n:?} is not a parameter number", i + 1))?;
            let v: f64 = v
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| format!("{origin}:{}: {v:?} is not a number", i + 1))?;
            m.insert(n, v);
        }
        Parameters::from_numbered(&m).map_err(|e| format!("{origin}: {e}"))
    }
}

/// One tool table entry. Offsets in mm (degrees for rotary axes).
#[derive(Clone, Debug, PartialEq)]
pub struct Tool {
    /// Tool number (T word), 1 or more.
    pub number: u32,
    /// Pocket number (P word).
    pub pocket: u32,
    /// Tool offsets per axis in [`AXES`] order; Z is the tool length.
    pub offsets: [f64; 9],
    /// Diameter, mm.
    pub diameter: f64,
    /// Free text after `;`.
    pub comment: String,
}

impl Tool {
    /// A tool with zero offsets in the pocket of its own number.
    pub fn new(number: u32) -> Tool {
        Tool {
            number,
            pocket: number,
            offsets: [0.0; 9],
            diameter: 0.0,
            comment: String::new(),
        }
    }

    fn to_line(&self) -> String {
        let mut s = format!("T{} P{}", self.number, self.pocket);
        for (axis, v) in AXES.iter().zip(&self.offsets) {
            if *v != 0.0 {
                s.push_str(&format!(" {axis}{v:.6}"));
            }
        }
        if self.diameter != 0.0 {
            s.push_str(&format!(" D{:.6}", self.diameter));
        }
        if !self.comment.is_empty() {
            s.push_str(&format!(" ;{}", self.comment));
        }
        s
    }
}

/// The tool table, by tool number.
pub type ToolTable = BTreeMap<u32, Tool>;

/// The text of a tool table file.
pub fn tools_to_text(tools: &ToolTable) -> String {
    tools.values().map(|t| t.to_line() + "\n").collect()
}

/// Parse a tool table in LinuxCNC's format; `origin` names it in errors.
/// Words LinuxCNC has and kerf does not use yet (I J Q) are accepted and
/// dropped.
pub fn parse_tools(text: &str, origin: &str) -> Result<ToolTable, String> {
    let mut tools = ToolTable::new();
    for (i, raw) in text.lines().enumerate() {
        let at = |m: String| format!("{origin}:{}: {m}", i + 1);
        let (body, comment) = match raw.find(';') {
            Some(k) => (&raw[..k], raw[k + 1..].trim().to_string()),
            None => (raw, String::new()),
        };
        if body.trim().is_empty() {
            continue;
        }
        let mut tool: Option<Tool> = None;
        let mut pocket = None;
        let mut offsets = [0.0; 9];
        let mut diameter = 0.0;
        for word in body.split_whitespace() {
            let mut chars = word.chars();
            let Some(letter) = chars.next().map(|c| c.to_ascii_uppercase()) else {
                continue;
            };
            let value: f64 = chars
                .as_str()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| at(format!("{word:?} is not a letter and a number")))?;
            match letter {
                'T' | 'P' if value < 0.0 || value.fract() != 0.0 => {
                    return Err(at(format!("{word}: must be a whole number")));
                }
                'T' if value < 1.0 => return Err(at("tool numbers start at 1".into())),
                'T' => tool = Some(Tool::new(value as u32)),
                'P' => pocket = Some(value as u32),
                'D' => diameter = value,
                'I' | 'J' | 'Q' => {}
                c => match AXES.iter().position(|a| *a == c) {
                    Some(k) => offsets[k] = value,
                    None => return Err(at(format!("{word}: unknown word {c}"))),
                },
            }
        }
        let mut tool = tool.ok_or_else(|| at("no T word".into()))?;
        if let Some(p) = pocket {
            tool.pocket = p;
        }
        tool.offsets = offsets;
        tool.diameter = diameter;
        tool.comment = comment;
        if tools.insert(tool.number, tool).is_some() {
            return Err(at("tool listed twice".into()));
        }
    }
    Ok(tools)
}

/// Why the state directory could not be used.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("state directory {dir}: {source}")]
    Dir {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("{0}")]
    Corrupt(String),
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// The state directory with the parameters and tool table it holds.
#[derive(Debug)]
pub struct Store {
    dir: PathBuf,
    parameters: Parameters,
    tools: ToolTable,
}

impl Store {
    /// Open (creating) the state directory and load its files. A file that
    /// is missing starts empty; one that cannot be parsed is replaced by its
    /// backup if that parses (with a warning), else it is an error.
    pub fn open(dir: &Path) -> Result<Store, StateError> {
        std::fs::create_dir_all(dir).map_err(|source| StateError::Dir {
            dir: dir.to_path_buf(),
            source,
        })?;
        let parameters = load(&dir.join(PARAMETER_FILE), Parameters::parse)?.unwrap_or_default();
        let tools = load(&dir.join(TOOL_FILE), parse_tools)?.unwrap_or_default();
        Ok(Store {
            dir: dir.to_path_buf(),
            parameters,
            tools,
        })
    }

    /// The state directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The parameters in force.
    pub fn parameters(&self) -> &Parameters {
        &self.parameters
    }

    /// The tool table.
    pub fn tools(&self) -> &ToolTable {
        &self.tools
    }

    /// Replace the parameters; durable when this returns Ok. On error the
    /// old values stay in force.
    pub fn set_parameters(&mut self, p: Parameters) -> Result<(), StateError> {
        write_atomic(&self.dir.join(PARAMETER_FILE), p.to_text().as_bytes())?;
        self.parameters = p;
        Ok(())
    }

    /// Replace the tool table; durable when this returns Ok. On error the
    /// old table stays in force.
    pub fn set_tools(&mut self, tools: ToolTable) -> Result<(), StateError> {
        write_atomic(&self.dir.join(TOOL_FILE), tools_to_text(&tools).as_bytes())?;
        self.tools = tools;
        Ok(())
    }

    /// Write both files again (at shutdown, so they carry the latest format).
    pub fn flush(&self) -> Result<(), StateError> {
        write_atomic(
            &self.dir.join(PARAMETER_FILE),
            self.parameters.to_text().as_bytes(),
        )?;
        write_atomic(
            &self.dir.join(TOOL_FILE),
            tools_to_text(&self.tools).as_bytes(),
        )
    }
}

fn backup_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".bak");
    PathBuf::from(s)
}

fn load<T>(
    path: &Path,
    parse: impl Fn(&str, &str) -> Result<T, String>,
) -> Result<Option<T>, StateError> {
    let read = |p: &Path| -> Result<Option<T>, String> {
        match std::fs::read_to_string(p) {
            Ok(text) => parse(&text, &p.display().to_string()).map(Some),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(format!("cannot read {}: {e}", p.display())),
        }
    };
    match read(path) {
        Ok(v) => Ok(v),
        Err(e) => {
            let bak = backup_path(path);
            match read(&bak) {
                Ok(Some(v)) => {
                    tracing::warn!("{e}; using the backup {}", bak.display());
                    Ok(Some(v))
                }
                _ => Err(StateError::Corrupt(e)),
            }
        }
    }
}

/// Replace `path` with `bytes` atomically and durably, keeping the old file
/// as `PATH.bak`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), StateError> {
    let err = |source| StateError::Write {
        path: path.to_path_buf(),
        source,
    };
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    {
        let mut f = File::create(&tmp).map_err(err)?;
        f.write_all(bytes).map_err(err)?;
        f.sync_all().map_err(err)?;
    }
    if path.exists() {
        // The backup is a second name for the old file, swapped in by a
        // rename so `NAME.bak` too is always whole.
        let mut bak_tmp = backup_path(path).into_os_string();
        bak_tmp.push(".tmp");
        let bak_tmp = PathBuf::from(bak_tmp);
        let _ = std::fs::remove_file(&bak_tmp);
        std::fs::hard_link(path, &bak_tmp).map_err(err)?;
        std::fs::rename(&bak_tmp, backup_path(path)).map_err(err)?;
    }
    std::fs::rename(&tmp, path).map_err(err)?;
    File::open(dir).and_then(|d| d.sync_all()).map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_use_linuxcnc_numbers() {
        let mut p = Parameters::default();
        p.work_offsets[0][0] = 10.0; // G54 X
        p.work_offsets[8][2] = -3.5; // G59.3 Z
        p.g92[1] = 2.0;
        p.g92_active = true;
        p.g28[2] = -1.0;
        p.g30[0] = 7.0;
        p.active_system = 1;
        let m = p.to_numbered();
        // Independent expectation: LinuxCNC's parameter table.
        assert_eq!(m[&5221], 10.0);
        assert_eq!(m[&5383], -3.5);
        assert_eq!(m[&5212], 2.0);
        assert_eq!(m[&5210], 1.0);
        assert_eq!(m[&5163], -1.0);
        assert_eq!(m[&5181], 7.0);
        assert_eq!(m[&5220], 2.0);
        assert_eq!(Parameters::parse(&p.to_text(), "v").unwrap(), p);
    }

    #[test]
    fn bad_parameter_files_name_the_line() {
        let e = Parameters::parse("5221 1.0\n5222 x\n", "k.var").unwrap_err();
        assert_eq!(e, "k.var:2: \"x\" is not a number");
        let e = Parameters::parse("5220 12\n", "k.var").unwrap_err();
        assert!(e.contains("5220"), "{e}");
    }

    #[test]
    fn tool_table_round_trips_linuxcnc_lines() {
        let text = "T1 P1 Z10.5 D6 ;6 mm end mill\n; a comment line\nT7 P3 X0.1 Z-2 I10 Q1\n";
        let tools = parse_tools(text, "tool.tbl").unwrap();
        assert_eq!(tools[&1].offsets[2], 10.5);
        assert_eq!(tools[&1].diameter, 6.0);
        assert_eq!(tools[&1].comment, "6 mm end mill");
        assert_eq!(tools[&7].pocket, 3);
        assert_eq!(tools[&7].offsets[0], 0.1);
        assert_eq!(parse_tools(&tools_to_text(&tools), "t").unwrap(), tools);
        let e = parse_tools("T1 Z1\nT2 Zq\n", "tool.tbl").unwrap_err();
        assert_eq!(e, "tool.tbl:2: \"Zq\" is not a letter and a number");
        let e = parse_tools("T1\nT1\n", "tool.tbl").unwrap_err();
        assert_eq!(e, "tool.tbl:2: tool listed twice");
    }

    #[test]
    fn writes_replace_atomically_and_keep_a_backup() {
        let dir = tempfile::tempdir().unwrap();
        let mut store = Store::open(dir.path()).unwrap();
        let mut p = Parameters::default();
        p.work_offsets[0][0] = 1.0;
        store.set_parameters(p.clone()).unwrap();
        p.work_offsets[0][0] = 2.0;
        store.set_parameters(p.clone()).unwrap();
        let path = dir.path().join(PARAMETER_FILE);
        let bak = backup_path(&path);
        assert!(std::fs::read_to_string(&path)
            .unwrap()
            .contains("5221\t2.000000"));
        assert!(std::fs::read_to_string(&bak)
            .unwrap()
            .contains("5221\t1.000000"));
        assert!(!dir.path().join("kerf.var.tmp").exists());

        // A damaged file falls back to the backup.
        std::fs::write(&path, "5221 garbage\n").unwrap();
        let again = Store::open(dir.path()).unwrap();
        assert_eq!(again.parameters().work_offsets[0][0], 1.0);
        // Both damaged: an error naming the file.
        std::fs::write(&bak, "nonsense\n").unwrap();
        let e = Store::open(dir.path()).unwrap_err().to_string();
        assert!(e.contains("kerf.var:1"), "{e}");
    }
}
