//! The generator of long test programs, shared by the speed benchmark
//! (`examples/bench.rs`) and the memory test (`tests/memory.rs`).

use std::io::{BufWriter, Write};
use std::path::Path;

/// Write a CAM-like program of `lines` lines to `path`.
pub fn generate(path: &Path, lines: usize) -> std::io::Result<()> {
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
