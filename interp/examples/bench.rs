//! Speed benchmark: interpret a generated program to canon and report
//! lines per second, beside LinuxCNC's `rs274` on the same file when it is
//! installed.
//!
//! ```text
//! cargo run --release -p kerf-interp --example bench [LINES] [--keep FILE]
//! cargo run --release -p kerf-interp --example bench -- --file FILE
//! ```
//!
//! `--keep FILE` keeps the generated program; `--file FILE` times an
//! existing program instead of generating one.
//!
//! LINES defaults to 1,000,000. The program is written by
//! [`kerf_interp`]'s test generator below: CAM-like output with rapids,
//! feeds, arcs in centre and radius format, feed changes, comments and an
//! occasional parameter expression, ending with M2.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use kerf_interp::{Config, Interpreter, Offline};

/// Write a program of `lines` lines to `path`.
fn generate(path: &Path, lines: usize) -> std::io::Result<()> {
    let mut out = BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "G21 G90 G17 G94 (generated benchmark program)")?;
    writeln!(out, "#1 = 0.5")?;
    let mut x = 0.0f64;
    let mut y = 0.0f64;
    // A deterministic pseudo-random walk (xorshift), so runs compare.
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % 10_000) as f64 / 1000.0 - 5.0
    };
    let body = lines.saturating_sub(3);
    for i in 0..body {
        let dx = next();
        let dy = next();
        match i % 16 {
            0 => writeln!(out, "G0 X{:.3} Y{:.3} Z2.000", x + dx, y + dy)?,
            1 => writeln!(out, "G1 Z-1.000 F300")?,
            2 => writeln!(out, "(pass {i})")?,
            3 => writeln!(
                out,
                "G1 X{:.3} Y{:.3} F{}",
                x + dx,
                y + dy,
                600 + i % 7 * 50
            )?,
            7 => {
                // A half circle through (x+2r, y) around (x+r, y).
                let r = dx.abs().max(0.5);
                writeln!(out, "G2 X{:.4} Y{:.4} I{:.4} J0", x + 2.0 * r, y, r)?;
                x += 2.0 * r;
                continue;
            }
            11 => {
                let r = dy.abs().max(0.5);
                writeln!(out, "G3 X{:.4} Y{:.4} R{:.4}", x, y + 2.0 * r, r)?;
                y += 2.0 * r;
                continue;
            }
            8 | 12 => writeln!(out, "G1 X{:.3} Y{:.3}", x + dx, y + dy)?,
            13 => writeln!(out, "G1 X[{:.3} + #1] Y{:.3}", x + dx, y + dy)?,
            _ => writeln!(out, "X{:.3} Y{:.3}", x + dx, y + dy)?,
        }
        x += dx;
        y += dy;
    }
    writeln!(out, "G0 Z5")?;
    writeln!(out, "M2")?;
    out.flush()
}

fn main() {
    let mut lines = 1_000_000usize;
    let mut keep: Option<PathBuf> = None;
    let mut existing: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--keep" {
            keep = args.next().map(PathBuf::from);
        } else if a == "--file" {
            existing = args.next().map(PathBuf::from);
        } else if let Ok(n) = a.parse() {
            lines = n;
        } else {
            eprintln!("usage: bench [LINES] [--keep FILE] | bench --file FILE");
            std::process::exit(2);
        }
    }
    let path = match &existing {
        Some(p) => {
            let text = std::fs::read_to_string(p).expect("cannot read the program");
            lines = text.lines().count();
            p.clone()
        }
        None => {
            let p = keep.clone().unwrap_or_else(|| {
                std::env::temp_dir().join(format!("kerf-bench-{}.ngc", std::process::id()))
            });
            generate(&p, lines).expect("cannot write the program");
            p
        }
    };

    let start = Instant::now();
    let interp = Interpreter::open_with(&path, Config::default(), Box::new(Offline::default()))
        .expect("cannot open the program");
    let mut commands = 0u64;
    for c in interp {
        c.expect("the generated program should interpret");
        commands += 1;
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "kerf-interp: {lines} lines, {commands} canon commands in {secs:.3} s = {:.0} lines/s",
        lines as f64 / secs
    );

    let mut rs274 = Command::new("rs274");
    rs274
        .arg("-g")
        .arg(&path)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .current_dir(path.parent().unwrap_or(Path::new(".")));
    let start = Instant::now();
    match rs274.status() {
        Ok(status) => {
            let secs_rs = start.elapsed().as_secs_f64();
            println!(
                "rs274 -g:    {lines} lines in {secs_rs:.3} s = {:.0} lines/s (exit {status}); kerf is {:.1}x faster",
                lines as f64 / secs_rs,
                secs_rs / secs
            );
        }
        Err(_) => {
            println!("rs274 is not installed: no comparison (Debian package linuxcnc-uspace)")
        }
    }
    if keep.is_none() && existing.is_none() {
        let _ = std::fs::remove_file(&path);
    }
}
