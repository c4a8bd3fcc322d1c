//! Memory stays flat with program length.
//!
//! Interprets a generated 1,000,000-line program (no loops) and compares
//! the process's resident memory after the first 100,000 lines with its
//! peak at the end: the interpreter reads one line at a time and keeps no
//! per-line state, so the growth must be small and independent of length.
//! (This file holds one test so that the process measures nothing else.)
//!
//! The 10,000,000-line check of the whole CLI is a command, documented in
//! `docs/gcode.md`:
//!
//! ```text
//! cargo run --release -p kerf-interp --example bench 10000000 --keep /tmp/10m.ngc
//! /usr/bin/time -v target/release/kerf canon /tmp/10m.ngc > /dev/null
//! ```

#[path = "support/generate.rs"]
mod generate;

use kerf_interp::{Config, Interpreter, Offline};

/// A field of /proc/self/status in kB (Linux only).
fn status_kb(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status.lines().find_map(|l| {
        let rest = l.strip_prefix(field)?.strip_prefix(':')?;
        rest.trim().trim_end_matches("kB").trim().parse().ok()
    })
}

#[test]
fn resident_memory_does_not_grow_with_program_length() {
    if status_kb("VmRSS").is_none() {
        println!("skipped: /proc/self/status is not available on this system");
        return;
    }
    let path = std::env::temp_dir().join(format!("kerf-memory-{}.ngc", std::process::id()));
    const LINES: usize = 1_000_000;
    generate::generate(&path, LINES).unwrap();
    let interp =
        Interpreter::open_with(&path, Config::default(), Box::new(Offline::default())).unwrap();
    let mut early = 0;
    let mut commands = 0usize;
    for c in interp {
        let c = c.unwrap_or_else(|e| panic!("{e}"));
        commands += 1;
        if early == 0 && c.source.line >= 100_000 {
            early = status_kb("VmRSS").unwrap();
        }
    }
    let peak = status_kb("VmHWM").unwrap();
    std::fs::remove_file(&path).unwrap();
    println!(
        "{LINES} lines, {commands} commands: resident {early} kB after 100,000 lines, peak {peak} kB"
    );
    assert!(commands > LINES / 2, "the program should produce its moves");
    // 900,000 more lines may not add more than 2 MB (allocator slack).
    assert!(
        peak <= early + 2048,
        "memory grew from {early} kB to {peak} kB over the program"
    );
}
