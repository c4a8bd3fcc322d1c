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
//! LINES defaults to 1,000,000. The program comes from the generator in
//! `interp/tests/support/generate.rs` (shared with the memory test):
//! CAM-like output with rapids, feeds, arcs in centre and radius format,
//! feed changes, comments and an occasional parameter expression, ending
//! with M2.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use kerf_interp::{Config, Interpreter, Offline};

#[path = "../tests/support/generate.rs"]
mod generate;
use generate::generate;

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
