//! `kerf canon`: interpret a program offline and print its canon stream,
//! in kerf's readable format or in the text format of LinuxCNC's
//! stand-alone interpreter `rs274`.

use std::io::Write;
use std::path::{Path, PathBuf};

use kerf_interp::linuxcnc::Rs274Formatter;
use kerf_interp::{Config, Interpreter, Offline};

use super::Failure;

/// Output format of `kerf canon`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Format {
    /// One command per line, `file:line: command`, positions in machine mm.
    #[default]
    Readable,
    /// `rs274`'s format: counter, N word, canonical call in program units.
    Linuxcnc,
}

/// Options of `kerf canon`.
#[derive(Clone, Debug, Default)]
pub struct CanonOptions {
    /// How to print the stream.
    pub format: Format,
    /// LinuxCNC tool table (`.tbl`).
    pub tool_table: Option<PathBuf>,
    /// Parameter file (`.var`): read at start, written back at program end.
    pub params: Option<PathBuf>,
    /// LinuxCNC INI file for `[RS274NGC]` settings (subroutine path, remaps…).
    pub ini: Option<PathBuf>,
}

/// The interpreter configuration the options describe: `rs274`'s dummy
/// machine for the LinuxCNC format, kerf's defaults otherwise.
pub fn config(options: &CanonOptions) -> Result<Config, Failure> {
    let mut cfg = match options.format {
        Format::Linuxcnc => Config::rs274(),
        Format::Readable => Config::default(),
    };
    let warn = |w: Vec<String>| {
        for w in w {
            eprintln!("kerf: warning: {w}");
        }
    };
    if let Some(ini) = &options.ini {
        warn(cfg.load_ini(ini).map_err(Failure::new)?);
    }
    if let Some(tbl) = &options.tool_table {
        warn(cfg.load_tool_table(tbl).map_err(Failure::new)?);
    }
    if let Some(params) = &options.params {
        cfg.load_parameters(params).map_err(Failure::new)?;
    }
    Ok(cfg)
}

/// Print the canon commands of `file`.
pub fn canon(file: &Path, options: &CanonOptions) -> Result<(), Failure> {
    let cfg = config(options)?;
    let user_units = cfg.user_units_per_mm;
    let env = Offline {
        parameter_file: options.params.clone(),
    };
    let interp = Interpreter::open_with(file, cfg, Box::new(env))
        .map_err(|e| Failure::new(format!("{}: {e}", file.display())))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::with_capacity(1 << 16, stdout.lock());
    let mut fmt = Rs274Formatter::new(user_units);
    let mut text = String::new();
    let mut failure = None;
    for item in interp {
        let c = match item {
            Ok(c) => c,
            Err(e) => {
                failure = Some(Failure::new(e.to_string()));
                break;
            }
        };
        let written = match options.format {
            Format::Readable => writeln!(out, "{c}"),
            Format::Linuxcnc => {
                text.clear();
                fmt.write(&c, &mut text);
                out.write_all(text.as_bytes())
            }
        };
        if written.is_err() {
            return Ok(());
        }
    }
    if options.format == Format::Linuxcnc {
        text.clear();
        fmt.start(&mut text);
        if options.ini.is_none() {
            fmt.on_reset(&mut text);
        }
        fmt.on_reset(&mut text);
        let _ = out.write_all(text.as_bytes());
    }
    let _ = out.flush();
    match failure {
        Some(f) => Err(f),
        None => Ok(()),
    }
}
