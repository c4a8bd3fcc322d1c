//! Fuzzing: whatever the input, the interpreter ends with commands or an
//! error in `file:line:column: ` form, and never panics or hangs.
//!
//! Three generators, run with proptest:
//! - raw bytes;
//! - G-code-shaped token soup (words, numbers, expressions, parameters,
//!   O-words, comments) that gets past the lexer into the executor;
//! - mutations (cuts, splices, byte changes, inserted tokens) of the seed
//!   programs kept in `tests/fuzz-seeds/`.
//!
//! Every output goes through both printers (readable and rs274 text). The
//! tool table, parameter file, INI and canon text readers get arbitrary
//! text too.
//!
//! The number of cases per generator defaults to 256; set `PROPTEST_CASES`
//! for a longer run, e.g.
//! `PROPTEST_CASES=20000 cargo test --release -p kerf-interp --test fuzz`.
//! proptest keeps any failing input it finds in `proptest-regressions/`
//! next to this file, and replays it on every later run.

use std::path::Path;

use kerf_interp::canontext::read_canon_text;
use kerf_interp::ini::Ini;
use kerf_interp::linuxcnc::{run_rs274, Rs274Options};
use kerf_interp::{paramfile, Config, Interpreter, Offline, ToolTable};
use proptest::prelude::*;

const FILE: &str = "fuzz.ngc";

fn config() -> Config {
    Config {
        tool_table: ToolTable::parse(
            "T1 P1 Z1 D2\nT2 P2 X0.5 Z2 D0.8 I10 J80 Q2\nT3 P3 Z-1 D6\n",
            false,
        )
        .unwrap(),
        // Loops in fuzzed programs may never end; stop them.
        line_limit: Some(5_000),
        ..Config::default()
    }
}

fn interpreter(program: &[u8]) -> Interpreter<'static> {
    Interpreter::with_source(
        Box::new(std::io::Cursor::new(program.to_vec())),
        FILE,
        None,
        config(),
        Box::new(Offline::default()),
    )
}

/// Errors must name the file, a line (1 or more) and a column.
fn check_error_form(text: &str) {
    let rest = text
        .strip_prefix("fuzz.ngc:")
        .unwrap_or_else(|| panic!("error without file: {text:?}"));
    let mut parts = rest.splitn(3, ':');
    let line: u32 = parts
        .next()
        .and_then(|l| l.parse().ok())
        .unwrap_or_else(|| panic!("error without line: {text:?}"));
    let column: u32 = parts
        .next()
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("error without column: {text:?}"));
    assert!(line >= 1 && column >= 1, "{text:?}");
    assert!(parts.next().is_some_and(|m| m.len() > 1), "{text:?}");
}

/// Interpret `program` to the end through both printers.
fn exercise(program: &[u8]) {
    let mut shown = String::new();
    for (n, item) in interpreter(program).enumerate() {
        match item {
            Ok(c) => {
                use std::fmt::Write as _;
                let _ = writeln!(shown, "{c}");
            }
            Err(e) => check_error_form(&e.to_string()),
        }
        // Programs that emit without reading lines are bounded by the
        // line limit; this bound only keeps the test quick.
        if n > 50_000 {
            break;
        }
    }
    let out = run_rs274(
        interpreter(program),
        Rs274Options {
            ini_given: false,
            user_units_per_mm: 1.0,
            max_commands: Some(50_000),
        },
    );
    assert!(!out.stdout.is_empty() || !out.stderr.is_empty());
}

/// Tokens that make G-code-shaped text.
fn token() -> impl Strategy<Value = String> {
    let words = prop::sample::select(vec![
        "G0",
        "G1",
        "G2",
        "G3",
        "G4",
        "G10",
        "G17",
        "G18",
        "G19",
        "G20",
        "G21",
        "G28",
        "G28.1",
        "G30",
        "G33",
        "G33.1",
        "G38.2",
        "G38.3",
        "G40",
        "G41",
        "G42",
        "G41.1",
        "G43",
        "G43.1",
        "G49",
        "G52",
        "G53",
        "G54",
        "G55",
        "G59.3",
        "G61",
        "G64",
        "G73",
        "G76",
        "G80",
        "G81",
        "G82",
        "G83",
        "G84",
        "G85",
        "G86",
        "G89",
        "G90",
        "G91",
        "G90.1",
        "G91.1",
        "G92",
        "G92.1",
        "G92.2",
        "G92.3",
        "G93",
        "G94",
        "G95",
        "G96",
        "G97",
        "G98",
        "G99",
        "G7",
        "G8",
        "M0",
        "M1",
        "M2",
        "M3",
        "M4",
        "M5",
        "M6",
        "M7",
        "M8",
        "M9",
        "M19",
        "M48",
        "M50",
        "M61",
        "M62",
        "M66",
        "M67",
        "M70",
        "M71",
        "M72",
        "M73",
        "M100",
        "L",
        "P",
        "Q",
        "R",
        "X",
        "Y",
        "Z",
        "A",
        "I",
        "J",
        "K",
        "F",
        "S",
        "T",
        "H",
        "D",
        "E",
        "N",
        "U",
        "@",
        "^",
        "#1",
        "#2",
        "#<a>",
        "#<_b>",
        "##1",
        "#5420",
        "#5061",
        "=",
        "[",
        "]",
        "+",
        "-",
        "*",
        "/",
        "**",
        "MOD",
        "EQ",
        "LT",
        "AND",
        "OR",
        "XOR",
        "SIN[",
        "ATAN[1]/[",
        "SQRT[",
        "EXISTS[",
        "ABS[",
        "FIX[",
        "LN[",
        "ACOS[",
        "(",
        ")",
        "(MSG,",
        "(DEBUG,#1)",
        "(PRINT,",
        ";",
        "(LOGOPEN,x)",
        "%",
        "/",
        "o1 sub",
        "o1 endsub",
        "o1 call",
        "o1 return",
        "o2 while",
        "o2 endwhile",
        "o2 do",
        "o3 if",
        "o3 elseif",
        "o3 else",
        "o3 endif",
        "o4 repeat",
        "o4 endrepeat",
        "o2 break",
        "o2 continue",
        "o<x> call",
        "M98 P1",
        "M99",
        "o1",
        "\n",
        "\n",
        "\n",
        "\n",
    ])
    .prop_map(str::to_string);
    let numbers = prop_oneof![
        (-1000i32..1000).prop_map(|n| n.to_string()),
        (-100.0f64..100.0).prop_map(|v| format!("{v:.3}")),
        prop::sample::select(vec![
            "0", "1", "-1", "0.5", "1e5", "..", "1.2.3", "-0", "360"
        ])
        .prop_map(str::to_string),
    ];
    prop_oneof![3 => words, 2 => numbers]
}

fn soup() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(token(), 0..60).prop_map(|tokens| {
        let mut text = String::new();
        for t in tokens {
            text.push_str(&t);
            text.push(' ');
        }
        text.push_str("\nM2\n");
        text.into_bytes()
    })
}

fn seeds() -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-seeds");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// One edit of a seed program.
#[derive(Clone, Debug)]
enum Edit {
    Cut(usize, usize),
    Byte(usize, u8),
    Insert(usize, String),
    Splice(usize, usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 0usize..40).prop_map(|(a, n)| Edit::Cut(a, n)),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Edit::Byte(a, b)),
        (any::<usize>(), token()).prop_map(|(a, t)| Edit::Insert(a, t)),
        (any::<usize>(), any::<usize>(), 0usize..80).prop_map(|(a, b, n)| Edit::Splice(a, b, n)),
    ]
}

fn apply(mut text: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let len = text.len().max(1);
        match e {
            Edit::Cut(a, n) => {
                let a = a % len;
                let b = (a + n).min(text.len());
                if a < b {
                    text.drain(a..b);
                }
            }
            Edit::Byte(a, b) => {
                if !text.is_empty() {
                    text[a % len] = *b;
                }
            }
            Edit::Insert(a, t) => {
                let a = a % (text.len() + 1);
                text.splice(a..a, t.bytes());
            }
            Edit::Splice(a, b, n) => {
                // Copy a run of the program elsewhere (duplicates lines and
                // O-word labels).
                let a = a % len;
                let end = (a + n).min(text.len());
                let piece = text.get(a..end).unwrap_or(&[]).to_vec();
                let at = b % (text.len() + 1);
                text.splice(at..at, piece);
            }
        }
    }
    text
}

proptest! {
    // A fixed seed keeps every run the same case list (tests must be
    // deterministic); change it here to explore other cases.
    #![proptest_config(ProptestConfig {
        rng_seed: prop::test_runner::RngSeed::Fixed(0x6b65_7266_0040),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]
    #[test]
    fn raw_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        exercise(&bytes);
    }

    #[test]
    fn token_soup_never_panics(program in soup()) {
        exercise(&program);
    }

    #[test]
    fn mutated_seeds_never_panic(
        which in any::<prop::sample::Index>(),
        edits in prop::collection::vec(edit(), 1..8),
    ) {
        let seeds = seeds();
        let seed = seeds[which.index(seeds.len())].clone();
        exercise(&apply(seed, &edits));
    }

    #[test]
    fn side_files_never_panic(text in "[ -~\n\t]{0,300}") {
        let _ = ToolTable::parse_lenient(&text, false);
        let _ = ToolTable::parse_lenient(&text, true);
        let _ = paramfile::parse(&text);
        for item in read_canon_text(text.as_bytes(), FILE) {
            if let Err(e) = item {
                check_error_form(&e.to_string());
            }
        }
        let ini = Ini::parse(&text);
        let mut cfg = Config::default();
        let _ = cfg.apply_ini(&ini, Path::new("."));
    }
}

/// Canon-text-shaped lines: call names, numbers, separators.
fn canon_text() -> impl Strategy<Value = String> {
    let piece = prop_oneof![
        prop::sample::select(vec![
            "STRAIGHT_FEED(",
            "STRAIGHT_TRAVERSE(",
            "ARC_FEED(",
            "USE_LENGTH_UNITS(",
            "CANON_UNITS_INCHES",
            "SET_G5X_OFFSET(",
            "SET_XY_ROTATION(",
            "SELECT_PLANE(",
            "CANON_PLANE_XZ",
            "SET_MOTION_CONTROL_MODE(",
            "CANON_CONTINUOUS",
            "COMMENT(\"",
            "\"",
            "SET_FEED_RATE(",
            "USE_TOOL_LENGTH_OFFSET(",
            "SET_SPINDLE_SPEED(",
            "CHANGE_TOOL(",
            "1 N..... ",
            "N0010 ",
            ")",
            ",",
            " ",
            "\n",
            "\n",
        ])
        .prop_map(str::to_string),
        (-1e6f64..1e6).prop_map(|v| format!("{v}")),
        (-10i32..10).prop_map(|v| v.to_string()),
    ];
    prop::collection::vec(piece, 0..80).prop_map(|p| p.concat())
}

proptest! {
    // A fixed seed keeps every run the same case list (tests must be
    // deterministic); change it here to explore other cases.
    #![proptest_config(ProptestConfig {
        rng_seed: prop::test_runner::RngSeed::Fixed(0x6b65_7266_0041),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]
    #[test]
    fn canon_text_never_panics(text in canon_text()) {
        let mut fmt = kerf_interp::linuxcnc::Rs274Formatter::new(1.0);
        let mut out = String::new();
        for item in read_canon_text(text.as_bytes(), FILE) {
            match item {
                Ok(c) => fmt.write(&c, &mut out),
                Err(e) => check_error_form(&e.to_string()),
            }
        }
    }
}

/// The seeds themselves run (they must stay meaningful inputs).
#[test]
fn seeds_run() {
    for seed in seeds() {
        exercise(&seed);
    }
}
