//! LinuxCNC conformance: runs every case of LinuxCNC's interpreter
//! regression corpus (`../shared/conformance/linuxcnc/cases.json`) through
//! kerf's interpreter, printing its canon stream in `rs274`'s text format,
//! and compares with LinuxCNC's expected output.
//!
//! It prints `N passed, M failed` and each failure with its reason. The
//! suite fails only if fewer cases pass than the floor below, which is
//! raised as the interpreter improves, so a regression fails the build.
//!
//! Run it alone with `cargo test --test conformance -- --nocapture`.

#[path = "support/shared.rs"]
mod shared;

use std::fs;
use std::path::{Path, PathBuf};

use kerf_interp::canontext::read_canon_text;
use kerf_interp::linuxcnc::{run_rs274, Rs274Formatter, Rs274Options};
use kerf_interp::{Config, Interpreter, Offline};
use serde_json::Value;

/// The number of cases known to pass; the test fails below it.
const FLOOR: usize = 114;

fn corpus_dir() -> Option<PathBuf> {
    shared::conformance_dir("linuxcnc", "cases.json")
}

fn copy_dir(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for entry in fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            fs::copy(entry.path(), &target).unwrap();
            let mut perm = fs::metadata(&target).unwrap().permissions();
            #[allow(clippy::permissions_set_readonly_false)]
            perm.set_readonly(false);
            fs::set_permissions(&target, perm).unwrap();
        }
    }
}

/// `awk '{$1=""; print}'`.
fn drop_first_field(line: &str) -> String {
    let fields: Vec<&str> = line.split([' ', '\t']).filter(|f| !f.is_empty()).collect();
    if fields.len() < 2 {
        String::new()
    } else {
        format!(" {}", fields[1..].join(" "))
    }
}

/// `sed 's/^ *[0-9]* //'`.
fn strip_leading_seqno(line: &str) -> String {
    let b = line.as_bytes();
    let spaces = b.iter().take_while(|&&c| c == b' ').count();
    for k in (0..=spaces).rev() {
        let mut d = k;
        while d < b.len() && b[d].is_ascii_digit() {
            d += 1;
        }
        if d < b.len() && b[d] == b' ' {
            return line[d + 1..].to_string();
        }
    }
    line.to_string()
}

fn apply_filter(text: &str, filter: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let line = match filter {
            "drop_first_field" => drop_first_field(line),
            "keep_MESSAGE_lines_drop_first_field" => {
                if !line.contains("MESSAGE") {
                    continue;
                }
                drop_first_field(line)
            }
            "negzero_to_zero" => line.replace("-0.0000", "0.0000"),
            "strip_leading_seqno" => strip_leading_seqno(line),
            other => panic!("unknown filter {other}"),
        };
        out.push_str(&line);
        out.push('\n');
    }
    out
}

/// One emulated `rs274` invocation in `dir`.
struct RunOutput {
    stdout: String,
    stderr: String,
    merged: String,
    status: i32,
}

fn run(dir: &Path, argv: &[String]) -> Result<RunOutput, String> {
    let mut cfg = Config::rs274();
    let mut env = Offline::default();
    let mut ini_given = false;
    let mut input = None;
    let mut replay = false;
    let mut i = 0;
    while i < argv.len() {
        let a = argv[i].as_str();
        let mut value = || {
            i += 1;
            argv.get(i).cloned().ok_or(format!("{a} needs a value"))
        };
        match a {
            "-g" | "-s" | "-T" => {}
            "-b" => cfg.block_delete = !cfg.block_delete,
            "-t" => {
                cfg.load_tool_table(&dir.join(value()?))?;
            }
            "-v" => {
                let path = dir.join(value()?);
                cfg.load_parameters(&path)?;
                env.parameter_file = Some(path);
            }
            "-i" => {
                cfg.load_ini(&dir.join(value()?))?;
                ini_given = true;
            }
            "-n" => cfg.continue_after_error = value()? == "0",
            "-l" => {
                value()?;
            }
            // LinuxCNC's canterp plugin: the input is a canon listing.
            "-p" => {
                value()?;
                replay = true;
            }
            _ if !a.starts_with('-') && input.is_none() => input = Some(dir.join(a)),
            _ => {}
        }
        i += 1;
    }
    let input = input.ok_or("no input file")?;
    if replay {
        return replay_canon(&input);
    }
    let user_units_per_mm = cfg.user_units_per_mm;
    let interp = Interpreter::open_with(&input, cfg, Box::new(env))
        .map_err(|e| format!("cannot open {}: {e}", input.display()))?;
    let out = run_rs274(
        interp,
        Rs274Options {
            ini_given,
            user_units_per_mm,
            max_commands: Some(200_000),
        },
    );
    Ok(RunOutput {
        stdout: out.stdout,
        stderr: out.stderr,
        merged: out.merged,
        status: out.status,
    })
}

/// `rs274 -p canterp.so`: replay a canon listing and print it again.
fn replay_canon(input: &Path) -> Result<RunOutput, String> {
    let file =
        fs::File::open(input).map_err(|e| format!("cannot open {}: {e}", input.display()))?;
    let mut fmt = Rs274Formatter::new(Config::rs274().user_units_per_mm);
    fmt.skip_start_up();
    let mut out = RunOutput {
        stdout: String::new(),
        stderr: String::new(),
        merged: String::new(),
        status: 0,
    };
    for item in read_canon_text(std::io::BufReader::new(file), input.display().to_string()) {
        match item {
            Ok(c) => fmt.write(&c, &mut out.stdout),
            Err(e) => {
                out.stderr = format!("{e}\n");
                out.status = 1;
                break;
            }
        }
    }
    out.merged = format!("{}{}", out.stdout, out.stderr);
    Ok(out)
}

/// The first line where two texts differ, for failure reports.
fn first_difference(expected: &str, got: &str) -> String {
    let e: Vec<&str> = expected.lines().collect();
    let g: Vec<&str> = got.lines().collect();
    for i in 0..e.len().max(g.len()) {
        let (a, b) = (e.get(i), g.get(i));
        if a != b {
            return format!(
                "line {}: expected {:?}, got {:?}",
                i + 1,
                a.unwrap_or(&"<end>"),
                b.unwrap_or(&"<end>")
            );
        }
    }
    "outputs differ only in line endings".into()
}

fn run_case(root: &Path, case: &Value) -> Result<(), String> {
    let dir = root.join(case["dir"].as_str().unwrap());
    let scratch = tempfile::tempdir().unwrap();
    let work = scratch.path().join("case");
    copy_dir(&dir, &work);
    for step in case["setup"].as_array().into_iter().flatten() {
        if let Some(copy) = step["copy"].as_array() {
            let (a, b) = (copy[0].as_str().unwrap(), copy[1].as_str().unwrap());
            fs::copy(work.join(a), work.join(b)).map_err(|e| format!("setup copy: {e}"))?;
        }
    }
    let kind = case["kind"].as_str().unwrap();
    let mut text = String::new();
    let mut last = None;
    for r in case["runs"].as_array().unwrap() {
        if let Some(echo) = r["echo"].as_str() {
            text.push_str(echo);
            text.push('\n');
            continue;
        }
        let argv: Vec<String> = r["argv"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_str().unwrap().to_string())
            .collect();
        let out = run(&work, &argv)?;
        let mut part = match r["stderr"].as_str().unwrap() {
            "merge" => out.merged.clone(),
            _ => out.stdout.clone(),
        };
        for f in r["filters"].as_array().into_iter().flatten() {
            part = apply_filter(&part, f.as_str().unwrap());
        }
        match r["exit"].as_str().unwrap() {
            "zero" if out.status != 0 => {
                return Err(format!(
                    "exit status {} (expected 0); stderr: {:?}",
                    out.status,
                    out.stderr
                        .trim()
                        .lines()
                        .skip(1)
                        .take(4)
                        .collect::<Vec<_>>()
                        .join(" / ")
                ))
            }
            "nonzero" if out.status == 0 => {
                return Err("exit status 0 (expected an error)".into());
            }
            _ => {}
        }
        text.push_str(&part);
        last = Some(out);
    }
    if kind == "error-message" {
        let want = case["expected_error"].as_str().unwrap();
        let stderr = last.map(|o| o.stderr).unwrap_or_default();
        let lines: Vec<&str> = stderr.lines().collect();
        let got = if lines.len() >= 2 {
            lines[lines.len() - 2].trim()
        } else {
            ""
        };
        return if got == want {
            Ok(())
        } else {
            Err(format!("expected error {want:?}, got {got:?}"))
        };
    }
    let expected = fs::read_to_string(work.join(case["expected"].as_str().unwrap()))
        .map_err(|e| format!("cannot read expected output: {e}"))?;
    if expected == text {
        Ok(())
    } else {
        Err(first_difference(&expected, &text))
    }
}

#[test]
fn linuxcnc_conformance() {
    let Some(root) = corpus_dir() else {
        eprintln!("skipped: LinuxCNC corpus not found at ../shared/conformance/linuxcnc");
        return;
    };
    let cases: Value =
        serde_json::from_str(&fs::read_to_string(root.join("cases.json")).unwrap()).unwrap();
    let only = std::env::var("KERF_CASE").ok();
    let mut passed = 0;
    let mut failures = Vec::new();
    for case in cases["cases"].as_array().unwrap() {
        let id = case["id"].as_str().unwrap();
        if only.as_deref().is_some_and(|o| !id.contains(o)) {
            continue;
        }
        eprintln!("case {id}");
        let outcome = std::panic::catch_unwind(|| run_case(&root, case))
            .unwrap_or_else(|_| Err("the interpreter panicked".into()));
        match outcome {
            Ok(()) => passed += 1,
            Err(reason) => failures.push(format!("{id}: {reason}")),
        }
    }
    for f in &failures {
        println!("FAIL {f}");
    }
    println!("{passed} passed, {} failed", failures.len());
    assert!(
        passed >= FLOOR,
        "conformance regressed: {passed} passed, the floor is {FLOOR}"
    );
}
