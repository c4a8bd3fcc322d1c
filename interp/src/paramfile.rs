//! The persistent parameter file (LinuxCNC's `.var` format): one
//! `NUMBER<TAB>VALUE` pair per line, in increasing order.
//!
//! The interpreter keeps #5161–#5390 (G28/G30 homes, G92 offsets, the nine
//! work coordinate systems and their rotations) across runs. [`save`] writes
//! them atomically: a temporary file is written and flushed to disk, the old
//! file is kept as `FILE.bak`, and the new one is renamed into place, so a
//! power loss leaves either the old or the new file, never half of one.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Number of numbered parameters (#0 to #5601).
pub const PARAMETER_COUNT: usize = 5602;

/// The parameters that a parameter file must hold and that are saved.
pub fn persistent_parameters() -> impl Iterator<Item = usize> {
    let homes = (5161..=5169).chain(5181..=5189);
    let g92 = 5210..=5219;
    // Each system k (1 = G54 … 9 = G59.3) has X…W offsets then its rotation
    // at 5200 + 20k + 1 … 5200 + 20k + 10.
    let systems = (1..=9).flat_map(|k| {
        let base = 5200 + 20 * k;
        base + 1..=base + 10
    });
    homes.chain(g92).chain(std::iter::once(5220)).chain(systems)
}

/// An error reading or writing the parameter file.
#[derive(Debug)]
pub struct ParamFileError(pub String);

impl std::fmt::Display for ParamFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ParamFileError {}

/// Parse parameter file text into `(number, value)` pairs, checking LinuxCNC's
/// rules: numbers in 1..5601 and in increasing order. Lines that are not a
/// number followed by a value are ignored (they are comments).
pub fn parse(text: &str) -> Result<Vec<(usize, f64)>, ParamFileError> {
    let mut out: Vec<(usize, f64)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        let (Some(a), Some(b)) = (it.next(), it.next()) else {
            continue;
        };
        let (Ok(number), Some(value)) = (a.parse::<i64>(), crate::ini::leading_number(b)) else {
            continue;
        };
        if number <= 0 || number >= PARAMETER_COUNT as i64 {
            return Err(ParamFileError(format!(
                "line {}: Parameter number out of range",
                n + 1
            )));
        }
        let number = number as usize;
        if out.last().is_some_and(|&(last, _)| last >= number) {
            return Err(ParamFileError(format!(
                "line {}: Parameter file out of order",
                n + 1
            )));
        }
        out.push((number, value));
    }
    Ok(out)
}

/// Read a parameter file. A missing file reads as empty (every parameter 0),
/// as in LinuxCNC.
pub fn load(path: &Path) -> Result<Vec<(usize, f64)>, ParamFileError> {
    match fs::read_to_string(path) {
        Ok(text) => parse(&text).map_err(|e| ParamFileError(format!("{}: {e}", path.display()))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(e) => Err(ParamFileError(format!(
            "Unable to open parameter file: '{}': {e}",
            path.display()
        ))),
    }
}

/// The text of a parameter file holding `values` (all parameters, indexed
/// by number): every persistent parameter, plus any other parameter the old
/// file listed, in LinuxCNC's `%d\t%f` form.
pub fn format(values: &[f64], old: &[(usize, f64)]) -> String {
    let mut numbers: Vec<usize> = persistent_parameters().collect();
    numbers.extend(old.iter().map(|&(n, _)| n));
    numbers.sort_unstable();
    numbers.dedup();
    let mut out = String::new();
    for n in numbers {
        let v = values.get(n).copied().unwrap_or(0.0);
        out.push_str(&format!("{n}\t{v:.6}\n"));
    }
    out
}

/// Write `values` to the parameter file at `path` atomically, keeping the
/// previous file as `path.bak`.
pub fn save(path: &Path, values: &[f64]) -> Result<(), ParamFileError> {
    let err = |what: &str, e: std::io::Error| {
        ParamFileError(format!(
            "cannot {what} parameter file {}: {e}",
            path.display()
        ))
    };
    let old = load(path).unwrap_or_default();
    let text = format(values, &old);
    let tmp = sibling(path, ".new");
    {
        let mut f = fs::File::create(&tmp).map_err(|e| err("create", e))?;
        f.write_all(text.as_bytes()).map_err(|e| err("write", e))?;
        f.sync_all().map_err(|e| err("flush", e))?;
    }
    if path.exists() {
        let bak = sibling(path, ".bak");
        let _ = fs::remove_file(&bak);
        fs::hard_link(path, &bak)
            .or_else(|_| fs::copy(path, &bak).map(|_| ()))
            .map_err(|e| err("back up", e))?;
    }
    fs::rename(&tmp, path).map_err(|e| err("replace", e))?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Ok(d) = fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(suffix);
    PathBuf::from(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn persistent_set_is_homes_g92_and_nine_systems() {
        let all: Vec<usize> = persistent_parameters().collect();
        assert_eq!(all.len(), 9 + 9 + 10 + 1 + 9 * 10);
        assert!(all.contains(&5161) && all.contains(&5189) && all.contains(&5210));
        assert!(all.contains(&5221) && all.contains(&5230) && all.contains(&5390));
        assert!(!all.contains(&5231) && !all.contains(&5170));
    }

    #[test]
    fn order_and_range_are_checked() {
        assert!(parse("5221 1.0\n5220 1\n").is_err());
        assert!(parse("9999 1\n").is_err());
        let ok = parse("5220\t1.000000\n5221 2.5 comment\nnot a line\n").unwrap();
        assert_eq!(ok, vec![(5220, 1.0), (5221, 2.5)]);
    }

    #[test]
    fn save_is_atomic_and_keeps_a_backup() {
        let dir = std::env::temp_dir().join(format!("kerf-var-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("test.var");
        fs::write(&path, "5220\t1.000000\n5221\t7.000000\n").unwrap();
        let mut values = vec![0.0; PARAMETER_COUNT];
        values[5220] = 2.0;
        values[5221] = 3.25;
        save(&path, &values).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains("5221\t3.250000\n"), "{text}");
        assert!(text.contains("5220\t2.000000\n"));
        assert_eq!(
            fs::read_to_string(dir.join("test.var.bak")).unwrap(),
            "5220\t1.000000\n5221\t7.000000\n"
        );
        assert!(!dir.join("test.var.new").exists());
        fs::remove_dir_all(&dir).unwrap();
    }
}
