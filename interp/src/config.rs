//! What the interpreter is told before it starts ([`Config`]) and what it
//! asks while it runs ([`Environment`]).
//!
//! The interpreter itself touches no machine: the tool table, stored
//! parameters, search paths and INI settings come in a [`Config`]; probe
//! results, inputs and saving the parameter file go through an
//! [`Environment`]. [`Offline`] is the environment of `kerf canon`: probes
//! trip at their programmed end, inputs read their defaults, nothing is saved.

use std::path::{Path, PathBuf};

use crate::canon::{Position, ProbeKind};
use crate::ini::Ini;
use crate::tools::ToolTable;

/// A code replaced by an NGC subroutine (`[RS274NGC] REMAP=`).
#[derive(Clone, Debug, PartialEq)]
pub struct Remap {
    /// The code as written in the INI file, e.g. `M400`, `G88.1`, `T`.
    pub name: String,
    /// The letter, lower case: `m`, `g`, `t`, `s` or `f`.
    pub letter: char,
    /// The M number, or the G number times ten; 0 for T, S, F.
    pub number: i32,
    /// The modal group the code belongs to.
    pub modal_group: i32,
    /// Which words the subroutine takes (LinuxCNC's argspec), if given.
    pub argspec: Option<String>,
    /// Name of the subroutine file (without `.ngc`).
    pub ngc: String,
}

impl Remap {
    /// Parse one `REMAP=` value, e.g. `M400 modalgroup=10 argspec=PQ ngc=rm400`.
    ///
    /// Python handlers (`python=`, `prolog=`, `epilog=`) are refused: kerf
    /// runs NGC remaps only.
    pub fn parse(line: &str) -> Result<Remap, String> {
        let line = line.split('#').next().unwrap_or("");
        let mut parts = line.split_whitespace();
        let name = parts.next().ok_or("REMAP with no code")?.to_string();
        let mut modal_group = -1;
        let mut argspec = None;
        let mut ngc = None;
        for opt in parts {
            let (kw, value) = opt
                .split_once('=')
                .ok_or_else(|| format!("option '{opt}' - missing '=<value>'"))?;
            if value.is_empty() {
                return Err(format!("option '{kw}' - zero length value"));
            }
            match kw.to_ascii_lowercase().as_str() {
                "modalgroup" => modal_group = crate::ini::leading_number(value).unwrap_or(0.0) as i32,
                "argspec" => {
                    if let Some(bad) = value
                        .chars()
                        .find(|c| !(c.is_ascii_alphabetic() && *c != 'o' && *c != 'O' || ">^@".contains(*c)))
                    {
                        return Err(format!("argspec: illegal word '{bad}'"));
                    }
                    argspec = Some(value.to_string());
                }
                "ngc" => ngc = Some(value.to_string()),
                "python" | "prolog" | "epilog" => {
                    return Err(format!(
                        "{name}: {kw}= handlers need LinuxCNC's Python plugin, which kerf does not support"
                    ))
                }
                other => return Err(format!("unrecognized option '{other}'")),
            }
        }
        let ngc = ngc.ok_or_else(|| {
            format!("code '{name}' - no remap function given, use 'ngc=<basename>'")
        })?;
        let letter = name
            .chars()
            .next()
            .map(|c| c.to_ascii_lowercase())
            .ok_or("empty code")?;
        let rest = &name[letter.len_utf8()..];
        let number = match letter {
            't' | 's' | 'f' => {
                if !rest.is_empty() {
                    return Err(format!("{letter} remap - only single letter code allowed"));
                }
                0
            }
            'm' => {
                if modal_group == -1 {
                    modal_group = 10;
                }
                if !(4..=10).contains(&modal_group) {
                    return Err(format!(
                        "code '{name}' : invalid modalgroup=<int> given (currently valid: 4..10)"
                    ));
                }
                rest.parse::<i32>().map_err(|_| {
                    format!("parsing M-code: expecting integer like 'M420', got '{name}'")
                })?
            }
            'g' => {
                if modal_group == -1 {
                    modal_group = 1;
                }
                if modal_group != 1 {
                    return Err(format!("code '{name}' : invalid modalgroup=<int> given"));
                }
                let v: f64 = rest
                    .parse()
                    .map_err(|_| format!("code '{name}' : can't parse G-code"))?;
                (v * 10.0).round() as i32
            }
            _ => return Err(format!("code '{name}' cannot be remapped")),
        };
        Ok(Remap {
            name,
            letter,
            number,
            modal_group,
            argspec,
            ngc,
        })
    }
}

/// Everything the interpreter needs to know before it reads the program.
#[derive(Clone, Debug)]
pub struct Config {
    /// The tool table (entry 0 is the spindle).
    pub tool_table: ToolTable,
    /// Stored parameter values, `(number, value)`, e.g. from a parameter
    /// file; the rest start at 0.
    pub parameters: Vec<(usize, f64)>,
    /// The machine's user units (parameter file, tool table) per mm:
    /// 1 for a metric machine, 1/25.4 for an inch machine.
    pub user_units_per_mm: f64,
    /// Which axis words (X Y Z A B C U V W) the machine accepts.
    pub axes: [bool; 9],
    /// Skip lines that start with `/` (the block delete switch).
    pub block_delete: bool,
    /// Directories searched for `O<name> call` files and remap subroutines.
    pub subroutine_path: Vec<PathBuf>,
    /// Directories searched for user M-code programs `M100`–`M199`.
    pub user_m_path: Vec<PathBuf>,
    /// Codes replaced by NGC subroutines.
    pub remaps: Vec<Remap>,
    /// The INI file, for `#<_ini[section]name>` (when `ini_vars` is on).
    pub ini: Option<Ini>,
    /// Allow `#<_ini[section]name>` parameters.
    pub ini_vars: bool,
    /// Refuse M98/M99 and bare O-word subprograms.
    pub disable_fanuc_style_sub: bool,
    /// Forget the G92 offset at program end and start-up.
    pub disable_g92_persistence: bool,
    /// Keep G43 applied across tool changes.
    pub retain_g43: bool,
    /// Define `#<n_args>` in subroutines.
    pub oword_n_args: bool,
    /// Keep the case of O-word and named-parameter names.
    pub no_downcase_oword: bool,
    /// Added to the M19 R angle, degrees.
    pub orient_offset: f64,
    /// Largest difference between the start and end radius of an arc
    /// given with I J K, inches (for G20 programs).
    pub center_arc_radius_tolerance_inch: f64,
    /// The same in mm (for G21 programs).
    pub center_arc_radius_tolerance_mm: f64,
    /// Rotary axes A B C that wrap at 360°.
    pub wrapped_rotary: [bool; 3],
    /// Number of spindles.
    pub spindles: u32,
    /// Do tool changes at the G30 position.
    pub tool_change_at_g30: bool,
    /// Raise Z to machine zero before a tool change.
    pub tool_change_quill_up: bool,
    /// Leave the spindle on during a tool change.
    pub tool_change_with_spindle_on: bool,
    /// `#<_metric_machine>`: 1 metric, 0 inch, -1 unknown.
    pub metric_machine: f64,
    /// Where the machine is when the program starts, machine coordinates.
    pub start_position: Position,
    /// Tool table entry of the tool in the spindle at start (0: none).
    pub spindle_tool_index: usize,
    /// After an error, report it and go on with the next line (as
    /// `rs274 -n 0` does) instead of stopping.
    pub continue_after_error: bool,
    /// Stop with an error after reading this many lines in all (counting
    /// every pass of a loop): a guard against runaway loops for callers
    /// that cannot wait forever, such as the fuzz tests. `None`: no limit.
    pub line_limit: Option<u64>,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            tool_table: ToolTable::new(false),
            parameters: Vec::new(),
            user_units_per_mm: 1.0,
            axes: [true; 9],
            block_delete: false,
            subroutine_path: Vec::new(),
            user_m_path: Vec::new(),
            remaps: Vec::new(),
            ini: None,
            ini_vars: true,
            disable_fanuc_style_sub: false,
            disable_g92_persistence: false,
            retain_g43: false,
            oword_n_args: false,
            no_downcase_oword: false,
            orient_offset: 0.0,
            center_arc_radius_tolerance_inch: 2.0 * 0.001 * std::f64::consts::SQRT_2,
            center_arc_radius_tolerance_mm: 2.0 * 0.01 * std::f64::consts::SQRT_2,
            wrapped_rotary: [false; 3],
            spindles: 1,
            tool_change_at_g30: false,
            tool_change_quill_up: false,
            tool_change_with_spindle_on: false,
            metric_machine: 1.0,
            start_position: Position::ZERO,
            spindle_tool_index: 0,
            continue_after_error: false,
            line_limit: None,
        }
    }
}

impl Config {
    /// The dummy machine of LinuxCNC's stand-alone interpreter `rs274`: an
    /// X Y Z A B C machine whose user units (parameter file, tool table)
    /// are inches, with the tool table's entry 1 taken as loaded and the
    /// block delete switch off. `kerf canon --format linuxcnc` uses it so
    /// that outputs compare with `rs274`'s.
    pub fn rs274() -> Config {
        Config {
            user_units_per_mm: 0.03937007874016,
            axes: [true, true, true, true, true, true, false, false, false],
            spindle_tool_index: 1,
            metric_machine: -1.0,
            ..Config::default()
        }
    }

    /// Load a LinuxCNC tool table file. Lines that cannot be read are
    /// skipped (as LinuxCNC does) and returned as warnings.
    pub fn load_tool_table(&mut self, path: &Path) -> Result<Vec<String>, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read tool table {}: {e}", path.display()))?;
        let random = self.tool_table.random_toolchanger();
        let (table, errors) = ToolTable::parse_lenient(&text, random);
        self.tool_table = table;
        Ok(errors
            .into_iter()
            .map(|e| format!("{}: {e}", path.display()))
            .collect())
    }

    /// Load stored parameters from a parameter (`.var`) file; a missing
    /// file leaves every parameter at 0.
    pub fn load_parameters(&mut self, path: &Path) -> Result<(), String> {
        self.parameters = crate::paramfile::load(path).map_err(|e| e.to_string())?;
        Ok(())
    }

    /// Read a LinuxCNC INI file and apply it (see [`Config::apply_ini`]),
    /// with relative paths taken from the INI file's folder.
    pub fn load_ini(&mut self, path: &Path) -> Result<Vec<String>, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("Unable to open inifile:{}: {e}", path.display()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        Ok(self.apply_ini(&Ini::parse(&text), base))
    }

    /// Apply the interpreter settings of a LinuxCNC INI file (`[RS274NGC]`,
    /// `[EMCIO]`, `[TRAJ]`, `[AXIS_A…C]`). Relative paths are taken from
    /// `base` (the INI file's folder, as LinuxCNC runs from there).
    ///
    /// Returns the problems found (e.g. unusable REMAP lines), which
    /// LinuxCNC reports and skips.
    pub fn apply_ini(&mut self, ini: &Ini, base: &Path) -> Vec<String> {
        let mut problems = Vec::new();
        let rs = "RS274NGC";
        let flag =
            |section: &str, key: &str, default: bool| ini.get_bool(section, key).unwrap_or(default);
        self.tool_change_at_g30 = flag("EMCIO", "TOOL_CHANGE_AT_G30", false);
        self.tool_change_quill_up = flag("EMCIO", "TOOL_CHANGE_QUILL_UP", false);
        self.tool_change_with_spindle_on = flag("EMCIO", "TOOL_CHANGE_WITH_SPINDLE_ON", false);
        for (i, axis) in ["AXIS_A", "AXIS_B", "AXIS_C"].iter().enumerate() {
            self.wrapped_rotary[i] = flag(axis, "WRAPPED_ROTARY", false);
        }
        if let Some(n) = ini.get_f64("TRAJ", "SPINDLES") {
            self.spindles = (n as u32).max(1);
        }
        self.ini_vars = flag(rs, "INI_VARS", true);
        self.retain_g43 = flag(rs, "RETAIN_G43", false);
        self.oword_n_args = flag(rs, "OWORD_NARGS", false);
        self.no_downcase_oword = flag(rs, "NO_DOWNCASE_OWORD", false);
        self.orient_offset = ini.get_f64(rs, "ORIENT_OFFSET").unwrap_or(0.0);
        self.disable_g92_persistence = flag(rs, "DISABLE_G92_PERSISTENCE", false);
        self.disable_fanuc_style_sub = flag(rs, "DISABLE_FANUC_STYLE_SUB", false);
        if let Some(t) = ini.get_f64(rs, "CENTER_ARC_RADIUS_TOLERANCE_INCH") {
            self.center_arc_radius_tolerance_inch = t.max(0.00004);
        }
        if let Some(t) = ini.get_f64(rs, "CENTER_ARC_RADIUS_TOLERANCE_MM") {
            self.center_arc_radius_tolerance_mm = t.max(0.001);
        }
        if let Some(paths) = ini.get(rs, "SUBROUTINE_PATH") {
            self.subroutine_path = split_path(paths, base);
        }
        if let Some(paths) = ini.get(rs, "USER_M_PATH") {
            self.user_m_path = split_path(paths, base);
        }
        self.metric_machine = match ini.get("TRAJ", "LINEAR_UNITS") {
            Some("inch") => 0.0,
            Some(_) => 1.0,
            None => -1.0,
        };
        for line in ini.all(rs, "REMAP") {
            match Remap::parse(line) {
                Ok(r) => {
                    if self
                        .remaps
                        .iter()
                        .any(|o| o.name.eq_ignore_ascii_case(&r.name))
                    {
                        problems.push(format!("code '{}' already remapped", r.name));
                    } else {
                        self.remaps.push(r);
                    }
                }
                Err(e) => problems.push(format!("REMAP = {line}: {e}")),
            }
        }
        self.ini = Some(ini.clone());
        problems
    }
}

fn split_path(paths: &str, base: &Path) -> Vec<PathBuf> {
    paths
        .split(':')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let p = Path::new(p.trim());
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                base.join(p)
            }
        })
        .filter(|p| p.is_dir())
        .collect()
}

/// The outcome of a probe move, reported by the environment once the move
/// has run. Positions are machine coordinates (mm, degrees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeOutcome {
    /// True if the probe changed state during the move.
    pub tripped: bool,
    /// Where the probe changed state (the end point if it did not).
    pub trip_position: Position,
    /// Where the machine stopped.
    pub final_position: Position,
}

/// What the interpreter asks the machine while it runs.
///
/// Calls come only after the command they concern has been taken from the
/// interpreter (it is pull-based): the consumer must have executed a probe
/// move before it asks for the command after it.
pub trait Environment {
    /// The result of the probe move from `start` to `end` (machine coordinates).
    fn probe(&mut self, start: Position, end: Position, kind: ProbeKind) -> ProbeOutcome;

    /// The state of digital input `index` for M66 (`default` if unknown).
    fn digital_input(&mut self, index: u32, default: bool) -> bool {
        let _ = index;
        default
    }

    /// The value of analog input `index` for M66 (`default` if unknown).
    fn analog_input(&mut self, index: u32, default: f64) -> f64 {
        let _ = index;
        default
    }

    /// M66: the value of #5399 after waiting on input `index` (digital or
    /// analog) in `mode` (0 now, 1 rise, 2 fall, 3 high, 4 low) for at most
    /// `timeout` seconds: 1/0 for a digital input, the reading for an
    /// analog one, −1 on timeout. `previous` is #5399 before. A machine
    /// waits for real; by default the input is read at once
    /// ([`Environment::digital_input`], [`Environment::analog_input`]), as
    /// LinuxCNC's stand-alone interpreter does.
    fn wait_input(
        &mut self,
        index: u32,
        digital: bool,
        _mode: u8,
        _timeout: f64,
        previous: f64,
    ) -> f64 {
        if digital {
            if self.digital_input(index, previous != 0.0) {
                1.0
            } else {
                0.0
            }
        } else {
            self.analog_input(index, previous)
        }
    }

    /// Store the parameters (all of them, indexed by number) when the
    /// program ends. Only #5161–#5390 need to persist.
    fn save_parameters(&mut self, values: &[f64]) -> Result<(), String> {
        let _ = values;
        Ok(())
    }

    /// Tool changer fault and reason for #5600 and #5601.
    fn toolchanger_status(&mut self) -> (f64, f64) {
        (0.0, 0.0)
    }
}

/// The environment of offline interpretation, modelled on LinuxCNC's
/// stand-alone interpreter: a probe move reaches its programmed end, which
/// becomes the recorded probe position, and the machine backs off 0.254 mm
/// towards the start; #5070 reads 0 (not tripped), as rs274 reports, so
/// programs that loop until a probe trips behave as they do under rs274;
/// inputs read their defaults; parameters are kept only if a parameter file
/// is given.
#[derive(Clone, Debug, Default)]
pub struct Offline {
    /// Where to save the parameters at program end, if anywhere.
    pub parameter_file: Option<PathBuf>,
}

impl Environment for Offline {
    fn probe(&mut self, start: Position, end: Position, _kind: ProbeKind) -> ProbeOutcome {
        let (s, e) = (start.to_array(), end.to_array());
        let d = [s[0] - e[0], s[1] - e[1], s[2] - e[2]];
        let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let mut stop = e;
        if distance != 0.0 {
            for i in 0..3 {
                stop[i] = e[i] + 0.254 * d[i] / distance;
            }
        }
        ProbeOutcome {
            tripped: false,
            trip_position: end,
            final_position: Position::from_array(stop),
        }
    }

    fn save_parameters(&mut self, values: &[f64]) -> Result<(), String> {
        match &self.parameter_file {
            Some(path) => crate::paramfile::save(path, values).map_err(|e| e.to_string()),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remap_lines() {
        let r = Remap::parse("M400  modalgroup=5 argspec=PQ ngc=rm400").unwrap();
        assert_eq!((r.letter, r.number, r.modal_group), ('m', 400, 5));
        assert_eq!(r.argspec.as_deref(), Some("PQ"));
        let g = Remap::parse("G88.1 ngc=rg881").unwrap();
        assert_eq!((g.letter, g.number, g.modal_group), ('g', 881, 1));
        assert!(Remap::parse("M401 python=foo").is_err());
        assert!(Remap::parse("M402 modalgroup=10").is_err());
    }

    #[test]
    fn offline_probe_backs_off_towards_the_start() {
        let out = Offline::default().probe(
            Position::xyz(0.0, 0.0, 10.0),
            Position::xyz(0.0, 0.0, 0.0),
            ProbeKind {
                toward: true,
                error_if_no_trip: true,
            },
        );
        assert!(!out.tripped);
        assert_eq!(out.trip_position, Position::ZERO);
        assert!((out.final_position.z - 0.254).abs() < 1e-12);
    }
}
