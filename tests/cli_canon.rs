//! `kerf canon` from the command line: both output formats, the tool table
//! and parameter file options, and error reporting.

use std::path::PathBuf;
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kerf-cli-canon-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const PROGRAM: &str = "G20 G90\nT1 M6 G43\nG0 X1 Y2 Z0\nG1 X1.5 F10\n#5161=3\nM2\n";
const TOOLS: &str = "T1 P1 Z0.5 D0.25 ;one\n";

fn kerf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(args)
        .output()
        .expect("kerf runs")
}

#[test]
fn readable_format_gives_machine_millimetres() {
    let dir = scratch("readable");
    std::fs::write(dir.join("p.ngc"), PROGRAM).unwrap();
    std::fs::write(dir.join("t.tbl"), TOOLS).unwrap();
    let out = kerf(&[
        "canon",
        "--tool-table",
        dir.join("t.tbl").to_str().unwrap(),
        dir.join("p.ngc").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    // kerf's default machine is metric, so the table's Z0.5 is 0.5 mm; the
    // program is in inches: X1 Y2 is (25.4, 50.8) mm, and Z0 with the
    // length offset is machine Z 0.5. F10 in/min is 254 mm/min.
    for want in [
        "p.ngc:3: rapid X25.4000 Y50.8000 Z0.5000",
        "p.ngc:4: feed 254.0000 mm/min",
        "p.ngc:4: line X38.1000 Y50.8000 Z0.5000",
    ] {
        assert!(
            text.lines().any(|l| l.ends_with(want)),
            "missing {want:?} in\n{text}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn linuxcnc_format_matches_rs274_and_parameters_persist() {
    let dir = scratch("linuxcnc");
    std::fs::write(dir.join("p.ngc"), PROGRAM).unwrap();
    std::fs::write(dir.join("t.tbl"), TOOLS).unwrap();
    let params = dir.join("p.var");
    let out = kerf(&[
        "canon",
        "--format",
        "linuxcnc",
        "--tool-table",
        dir.join("t.tbl").to_str().unwrap(),
        "--params",
        params.to_str().unwrap(),
        dir.join("p.ngc").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    // What LinuxCNC's rs274 prints for this program (tool-change lines as
    // LinuxCNC 2.10 prints them), counter column dropped.
    let expected = "\
N..... USE_LENGTH_UNITS(CANON_UNITS_MM)
N..... SET_G5X_OFFSET(1, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)
N..... SET_G92_OFFSET(0.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)
N..... SET_XY_ROTATION(0.0000)
N..... SET_FEED_REFERENCE(CANON_XYZ)
N..... ON_RESET()
N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)
N..... SELECT_TOOL(1)
N..... STOP_SPINDLE_TURNING(0)
N..... CHANGE_TOOL()
N..... USE_TOOL_LENGTH_OFFSET(0.0000 0.0000 0.5000, 0.0000 0.0000 0.0000, 0.0000 0.0000 0.0000)
N..... STRAIGHT_TRAVERSE(1.0000, 2.0000, 0.0000, 0.0000, 0.0000, 0.0000)
N..... SET_FEED_RATE(10.0000)
N..... STRAIGHT_FEED(1.5000, 2.0000, 0.0000, 0.0000, 0.0000, 0.0000)
N..... SET_G5X_OFFSET(1, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)
N..... SET_XY_ROTATION(0.0000)
N..... SET_FEED_MODE(0, 0)
N..... SET_FEED_RATE(0.0000)
N..... STOP_SPINDLE_TURNING(0)
N..... SET_SPINDLE_MODE(0 0.0000)
N..... PROGRAM_END()
N..... ON_RESET()
N..... ON_RESET()
";
    let text = String::from_utf8(out.stdout).unwrap();
    let got: String = text
        .lines()
        .map(|l| format!("{}\n", l.trim_start().split_once(' ').unwrap().1))
        .collect();
    assert_eq!(got, expected);
    // The counter counts from 1.
    assert!(text.starts_with("    1 N....."), "{text}");
    // #5161 was set by the program and saved at M2 (rs274 machine units).
    let saved = std::fs::read_to_string(&params).unwrap();
    assert!(
        saved
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>() == ["5161", "3.000000"]),
        "{saved}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn errors_name_file_line_column_and_word_and_fail() {
    let dir = scratch("error");
    let file = dir.join("bad.ngc");
    std::fs::write(&file, "G0 X0\nG1 X1 X2 F1\nM2\n").unwrap();
    let out = kerf(&["canon", file.to_str().unwrap()]);
    assert!(!out.status.success());
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("bad.ngc:2:7: X: Multiple x words on one line"),
        "{stderr}"
    );
    // The commands before the error were printed.
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("bad.ngc:1: rapid X0.0000"), "{stdout}");
    std::fs::remove_dir_all(&dir).unwrap();
}
