//! Behaviour of the interpreter against hand-worked expectations: the
//! geometry of moves and arcs in machine millimetres, offsets, units,
//! expressions, O-word control flow, probing, the parameter file, cutter
//! compensation, canned cycles, the order of execution within a block and
//! the form of errors.
//!
//! Each expected value is derived in the comment beside it from the program
//! text, not from the interpreter's output.

use std::cell::RefCell;
use std::rc::Rc;

use kerf_interp::{
    Axis, CanonCmd, Config, Environment, Interpreter, Offline, Plane, Position, ProbeKind,
    ProbeOutcome, ToolTable,
};

const MM: f64 = 25.4;

/// Run a program with a configuration; return the commands from its lines
/// (not the start-up ones) or the first error's text.
fn run_cfg(text: &str, cfg: Config, env: Box<dyn Environment>) -> Result<Vec<CanonCmd>, String> {
    let interp = Interpreter::with_source(
        Box::new(std::io::Cursor::new(text.as_bytes().to_vec())),
        "t.ngc",
        None,
        cfg,
        env,
    );
    let mut out = Vec::new();
    for c in interp {
        let c = c.map_err(|e| e.to_string())?;
        if c.source.line > 0 {
            out.push(c.cmd);
        }
    }
    Ok(out)
}

/// The default configuration with a tool table given as text.
fn with_tools(table: &str) -> Config {
    Config {
        tool_table: ToolTable::parse(table, false).unwrap(),
        ..Config::default()
    }
}

fn run(text: &str) -> Vec<CanonCmd> {
    run_cfg(text, Config::default(), Box::new(Offline::default())).unwrap_or_else(|e| panic!("{e}"))
}

fn error(text: &str) -> String {
    match run_cfg(text, Config::default(), Box::new(Offline::default())) {
        Ok(cmds) => panic!("expected an error, got {cmds:?}"),
        Err(e) => e,
    }
}

/// Just the moves, as (kind, end) with kind 'T' traverse, 'F' feed, 'A' arc.
fn moves(cmds: &[CanonCmd]) -> Vec<(char, Position)> {
    cmds.iter()
        .filter_map(|c| match c {
            CanonCmd::StraightTraverse { end } => Some(('T', *end)),
            CanonCmd::StraightFeed { end } => Some(('F', *end)),
            CanonCmd::ArcFeed { end, .. } => Some(('A', *end)),
            CanonCmd::StraightProbe { end, .. } => Some(('P', *end)),
            _ => None,
        })
        .collect()
}

fn close(a: Position, b: Position) -> bool {
    a.to_array()
        .iter()
        .zip(b.to_array())
        .all(|(x, y)| (x - y).abs() < 1e-9)
}

#[track_caller]
fn assert_moves(text: &str, expected: &[(char, [f64; 3])]) {
    let got = moves(&run(text));
    assert_eq!(got.len(), expected.len(), "moves of {text:?}: {got:?}");
    for (i, ((k, p), (ek, e))) in got.iter().zip(expected).enumerate() {
        let e = Position::xyz(e[0], e[1], e[2]);
        assert!(
            k == ek && close(*p, e),
            "move {i}: got {k} {p:?}, expected {ek} {e:?}"
        );
    }
}

/// The X of the single move of a program (for expression tests).
#[track_caller]
fn x_of(text: &str) -> f64 {
    let m = moves(&run(text));
    assert_eq!(m.len(), 1, "{m:?}");
    m[0].1.x
}

fn arcs(cmds: &[CanonCmd]) -> Vec<(Position, [f64; 2], Plane, i32)> {
    cmds.iter()
        .filter_map(|c| match c {
            CanonCmd::ArcFeed {
                end,
                center,
                plane,
                turns,
            } => Some((*end, *center, *plane, *turns)),
            _ => None,
        })
        .collect()
}

// ---- moves, units, arcs ----

#[test]
fn inch_programs_move_in_millimetres() {
    // G20: 1 inch = 25.4 mm; G91 adds to the current point.
    assert_moves(
        "G20 G0 X1 Y2\nG91 G1 X0.5 F10\nM2\n",
        &[('T', [MM, 2.0 * MM, 0.0]), ('F', [1.5 * MM, 2.0 * MM, 0.0])],
    );
    // Feed 10 in/min is 254 mm/min.
    let feed = |text: &str| -> Vec<f64> {
        run(text)
            .iter()
            .filter_map(|c| match c {
                CanonCmd::SetFeedRate { mm_per_min } => Some(*mm_per_min),
                _ => None,
            })
            .collect()
    };
    assert!((feed("G20\nF10\nM2\n")[0] - 254.0).abs() < 1e-9);
    // On one line the feed rate is set before the units change (LinuxCNC's
    // order of execution), so F10 is still read in millimetres.
    assert!((feed("G20 F10\nM2\n")[0] - 10.0).abs() < 1e-9);
}

#[test]
fn arc_with_centre_offsets() {
    // From (0,0) to (10,0) clockwise about I5 J0: centre (5,0), one turn CW.
    let a = arcs(&run("G0 X0 Y0\nG2 X10 Y0 I5 J0 F100\nM2\n"));
    assert_eq!(a.len(), 1);
    let (end, center, plane, turns) = a[0];
    assert!(close(end, Position::xyz(10.0, 0.0, 0.0)));
    assert_eq!((center, plane, turns), ([5.0, 0.0], Plane::XY, -1));
}

#[test]
fn arc_with_radius_picks_the_short_or_long_way() {
    // Chord (0,0)-(10,10), R10: centres at (10,0) and (0,10). Clockwise with
    // R+ sweeps 90° about (10,0); R- sweeps 270° about (0,10).
    let a = arcs(&run("G2 X10 Y10 R10 F100\nM2\n"));
    assert!((a[0].1[0] - 10.0).abs() < 1e-9 && a[0].1[1].abs() < 1e-9);
    let b = arcs(&run("G2 X10 Y10 R-10 F100\nM2\n"));
    assert!(b[0].1[0].abs() < 1e-9 && (b[0].1[1] - 10.0).abs() < 1e-9);
    // Counter-clockwise turns are positive.
    let c = arcs(&run("G3 X10 Y10 R10 F100\nM2\n"));
    assert!(c[0].1[0].abs() < 1e-9 && (c[0].1[1] - 10.0).abs() < 1e-9);
    assert_eq!(c[0].3, 1);
}

#[test]
fn full_circle_helix_with_extra_turns() {
    // Start = end in XY makes a full circle; P2 asks for two turns; Z moves
    // to -2 along the way.
    let a = arcs(&run("G2 X0 Y0 Z-2 I5 J0 P2 F100\nM2\n"));
    let (end, center, _, turns) = a[0];
    assert!(close(end, Position::xyz(0.0, 0.0, -2.0)));
    assert_eq!((center, turns), ([5.0, 0.0], -2));
}

#[test]
fn arc_in_the_xz_plane_in_inches() {
    // G18: the plane's first axis is Z and second X. From (0,0,0) to X1 Z0
    // about I0.5 K0: centre X 0.5 in = 12.7 mm, Z 0.
    let a = arcs(&run("G20 G18 G2 X1 Z0 I0.5 K0 F10\nM2\n"));
    let (end, center, plane, _) = a[0];
    assert_eq!(plane, Plane::XZ);
    assert!(close(end, Position::xyz(MM, 0.0, 0.0)));
    let [first, second, _] = plane.axes();
    assert_eq!((first, second), (Axis::Z, Axis::X));
    assert!(center[0].abs() < 1e-9 && (center[1] - 12.7).abs() < 1e-9);
}

#[test]
fn arc_radius_too_small_is_an_error_naming_the_word() {
    // The chord is 10 long; a radius of 2 cannot span it.
    let e = error("G2 X10 Y0 R2 F100\nM2\n");
    assert_eq!(e, "t.ngc:1:1: G2: Arc radius too small to reach end point");
}

// ---- offsets ----

#[test]
fn work_offsets_g92_g52_g53_and_rotation() {
    // G10 L2 P1 puts G54's origin at machine (10,20).
    assert_moves(
        "G10 L2 P1 X10 Y20\nG0 X1 Y1\nM2\n",
        &[('T', [11.0, 21.0, 0.0])],
    );
    // G55 is coordinate system 2.
    assert_moves("G10 L2 P2 X-5\nG55 G0 X1\nM2\n", &[('T', [-4.0, 0.0, 0.0])]);
    // At X5, G92 X0 makes here zero: X1 is then machine 6. G92.1 clears it.
    assert_moves(
        "G0 X5\nG92 X0\nG0 X1\nG92.1\nG0 X1\nM2\n",
        &[
            ('T', [5.0, 0.0, 0.0]),
            ('T', [6.0, 0.0, 0.0]),
            ('T', [1.0, 0.0, 0.0]),
        ],
    );
    // G52 shifts by 3; G53 moves in machine coordinates whatever the offsets.
    assert_moves(
        "G10 L2 P1 X100\nG52 X3\nG0 X1\nG53 G0 X7\nM2\n",
        &[('T', [104.0, 0.0, 0.0]), ('T', [7.0, 0.0, 0.0])],
    );
    // G10 L20 sets the offset so that the current point reads as given:
    // at machine X5, L20 X1 puts the origin at 4; X0 is then machine 4.
    assert_moves(
        "G0 X5\nG10 L20 P1 X1\nG0 X0\nM2\n",
        &[('T', [5.0, 0.0, 0.0]), ('T', [4.0, 0.0, 0.0])],
    );
    // R90 rotates the system a quarter turn: program X1 Y0 is machine (0,1).
    assert_moves("G10 L2 P1 R90\nG0 X1 Y0\nM2\n", &[('T', [0.0, 1.0, 0.0])]);
}

#[test]
fn tool_length_offsets() {
    // Tool 1 is 5 mm long: with G43, program Z0 is machine Z5; G49 drops it;
    // G43.1 applies a length given in the program.
    let cfg = with_tools("T1 P1 Z5 D6\n");
    let cmds = run_cfg(
        "T1 M6\nG43 G0 Z0\nG49 G0 Z0\nG43.1 Z2\nG0 Z1\nM2\n",
        cfg,
        Box::new(Offline::default()),
    )
    .unwrap();
    let z: Vec<f64> = moves(&cmds).iter().map(|m| m.1.z).collect();
    assert_eq!(z, vec![5.0, 0.0, 3.0]);
}

#[test]
fn g28_returns_through_the_intermediate_point_to_the_stored_home() {
    // #5161.. hold the G28 position (machine coordinates, user units).
    let cfg = Config {
        parameters: vec![(5161, 50.0), (5162, 60.0), (5163, 70.0)],
        ..Config::default()
    };
    let cmds = run_cfg("G0 X1 Y1\nG28 Z5\nM2\n", cfg, Box::new(Offline::default())).unwrap();
    let m = moves(&cmds);
    // First to the given point (Z5, other axes stay), then home on Z only.
    assert!(close(m[1].1, Position::xyz(1.0, 1.0, 5.0)), "{m:?}");
    assert!(close(m[2].1, Position::xyz(1.0, 1.0, 70.0)), "{m:?}");
}

// ---- parameters and expressions ----

#[test]
fn expression_precedence_and_functions() {
    // ** binds tighter than *, which binds tighter than +.
    assert_eq!(x_of("G0 X[2 + 3 * 4 ** 2]\nM2\n"), 50.0);
    // Left to right at equal precedence.
    assert_eq!(x_of("G0 X[1 - 2 - 3]\nM2\n"), -4.0);
    assert_eq!(x_of("G0 X[7 MOD 3]\nM2\n"), 1.0);
    // MOD of a negative number is made positive, as LinuxCNC does.
    assert_eq!(x_of("G0 X[-7 MOD 3]\nM2\n"), 2.0);
    assert!((x_of("G0 X[SIN[30]]\nM2\n") - 0.5).abs() < 1e-12);
    assert!((x_of("G0 X[ATAN[1]/[1]]\nM2\n") - 45.0).abs() < 1e-12);
    assert!((x_of("G0 X[ACOS[0]]\nM2\n") - 90.0).abs() < 1e-12);
    assert_eq!(x_of("G0 X[SQRT[16] + ABS[-2]]\nM2\n"), 6.0);
    // FIX rounds down, FUP up, ROUND to nearest.
    assert_eq!(x_of("G0 X[FIX[-2.5]]\nM2\n"), -3.0);
    assert_eq!(x_of("G0 X[FUP[-2.5]]\nM2\n"), -2.0);
    assert_eq!(x_of("G0 X[ROUND[2.4]]\nM2\n"), 2.0);
    assert_eq!(x_of("G0 X[EXP[0] + LN[1]]\nM2\n"), 1.0);
    // Comparisons and logic give 1 or 0.
    assert_eq!(x_of("G0 X[[1 LT 2] AND [3 GE 3]]\nM2\n"), 1.0);
    assert_eq!(x_of("G0 X[[1 EQ 2] OR [2 NE 2]]\nM2\n"), 0.0);
    assert_eq!(x_of("G0 X[1 XOR 1]\nM2\n"), 0.0);
    // Spaces inside words and numbers are ignored; case does not matter.
    assert_eq!(x_of("g 0 x 1 2 . 5\nm2\n"), 12.5);
}

#[test]
fn parameters_numbered_named_and_read_before_written() {
    assert_eq!(x_of("#1 = 3\n#2 = [#1 * 2]\nG0 X#2\nM2\n"), 6.0);
    // Indirection: #[#1] with #1 = 5 reads #5.
    assert_eq!(x_of("#5 = 9\n#1 = 5\nG0 X#[#1]\nM2\n"), 9.0);
    assert_eq!(x_of("#<depth> = 4\nG0 X#<depth>\nM2\n"), 4.0);
    assert_eq!(
        x_of("#<_g> = 2\nG0 X[EXISTS[#<_g>] + EXISTS[#<nope>]]\nM2\n"),
        1.0
    );
    // All reads on a line happen before its writes: X sees the old #1.
    assert_eq!(x_of("#1 = 1\n#1 = 2 G0 X#1\nM2\n"), 1.0);
    // The current position parameters read in program units: at X2 in,
    // #5420 + 1 is 3 in.
    let m = moves(&run("G20 G0 X2\nG0 X[#5420 + 1]\nM2\n"));
    assert!((m[1].1.x - 3.0 * MM).abs() < 1e-9, "{m:?}");
}

#[test]
fn undefined_named_parameter_is_an_error() {
    let e = error("G0 X#<missing>\nM2\n");
    assert!(e.starts_with("t.ngc:1:"), "{e}");
    assert!(e.contains("Named parameter #<missing> not defined"), "{e}");
}

#[test]
fn division_by_zero_is_an_error() {
    // The word whose value failed is named, at its column.
    assert_eq!(
        error("G0 X[1/0]\nM2\n"),
        "t.ngc:1:4: X: Attempt to divide by zero"
    );
    assert_eq!(
        error("M3 S-1\nM2\n"),
        "t.ngc:1:4: S: Negative spindle speed used"
    );
}

// ---- O-words ----

#[test]
fn subroutine_with_arguments_and_return_value() {
    // Arguments arrive as #1, #2; the return value lands in #<_value>.
    assert_moves(
        "o100 sub\nG0 X#1 Y#2\no100 endsub\no100 call [3] [4]\nM2\n",
        &[('T', [3.0, 4.0, 0.0])],
    );
    assert_eq!(
        x_of("o200 sub\no200 return [7]\no200 endsub\no200 call\nG0 X#<_value>\nM2\n"),
        7.0
    );
}

#[test]
fn loops_and_conditionals() {
    // while: X 0, 1, 2.
    assert_moves(
        "#1 = 0\no1 while [#1 LT 3]\nG1 X#1 F100\n#1 = [#1 + 1]\no1 endwhile\nM2\n",
        &[
            ('F', [0.0, 0.0, 0.0]),
            ('F', [1.0, 0.0, 0.0]),
            ('F', [2.0, 0.0, 0.0]),
        ],
    );
    // do-while runs its body once even when the condition is false.
    assert_moves(
        "o2 do\nG0 X5\no2 while [0]\nM2\n",
        &[('T', [5.0, 0.0, 0.0])],
    );
    // repeat twice.
    assert_moves(
        "o3 repeat [2]\nG0 X1\nG0 X0\no3 endrepeat\nM2\n",
        &[
            ('T', [1.0, 0.0, 0.0]),
            ('T', [0.0, 0.0, 0.0]),
            ('T', [1.0, 0.0, 0.0]),
            ('T', [0.0, 0.0, 0.0]),
        ],
    );
    // if / elseif / else takes the first true branch only.
    assert_moves(
        "#1 = 2\no4 if [#1 EQ 1]\nG0 X1\no4 elseif [#1 EQ 2]\nG0 X2\no4 else\nG0 X3\no4 endif\nM2\n",
        &[('T', [2.0, 0.0, 0.0])],
    );
    // break leaves the loop; continue skips the rest of one pass.
    assert_moves(
        "#1 = 0\no5 while [#1 LT 10]\n#1 = [#1 + 1]\no6 if [#1 EQ 2]\no5 continue\no6 endif\no7 if [#1 EQ 4]\no5 break\no7 endif\nG0 X#1\no5 endwhile\nM2\n",
        &[('T', [1.0, 0.0, 0.0]), ('T', [3.0, 0.0, 0.0])],
    );
}

#[test]
fn subroutine_files_on_the_search_path() {
    let dir = std::env::temp_dir().join(format!("kerf-interp-subs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("square.ngc"),
        "o<square> sub\nG1 X#1 F100\nG1 Y#1\no<square> endsub\n",
    )
    .unwrap();
    let cfg = Config {
        subroutine_path: vec![dir.clone()],
        ..Config::default()
    };
    let cmds = run_cfg(
        "o<square> call [2]\nM2\n",
        cfg,
        Box::new(Offline::default()),
    )
    .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let ends: Vec<Position> = moves(&cmds).iter().map(|m| m.1).collect();
    assert!(close(ends[0], Position::xyz(2.0, 0.0, 0.0)));
    assert!(close(ends[1], Position::xyz(2.0, 2.0, 0.0)));
}

// ---- probing ----

/// A probe that trips at a fixed machine Z and records what it was asked.
struct Touch {
    trip_z: f64,
    asked: Rc<RefCell<Vec<(Position, Position)>>>,
}

impl Environment for Touch {
    fn probe(&mut self, start: Position, end: Position, _kind: ProbeKind) -> ProbeOutcome {
        self.asked.borrow_mut().push((start, end));
        let mut at = end;
        at.z = self.trip_z;
        ProbeOutcome {
            tripped: true,
            trip_position: at,
            final_position: at,
        }
    }
}

#[test]
fn probe_results_land_in_parameters_and_the_position() {
    // Probe from Z0 towards Z-1 in; it trips at machine Z -12.7 mm = -0.5 in.
    // #5063 reads -0.5 (program units), #5070 reads 1, and the next
    // incremental move starts from the trip point.
    let asked = Rc::new(RefCell::new(Vec::new()));
    let env = Touch {
        trip_z: -12.7,
        asked: asked.clone(),
    };
    let cmds = run_cfg(
        "G20 G38.2 Z-1 F10\nG0 X[#5063] Y#5070\nG91 G0 Z0.1\nM2\n",
        Config::default(),
        Box::new(env),
    )
    .unwrap();
    let m = moves(&cmds);
    assert_eq!(m[0].0, 'P');
    assert!(close(m[0].1, Position::xyz(0.0, 0.0, -MM)));
    assert!(close(m[1].1, Position::xyz(-12.7, MM, -12.7)), "{m:?}");
    assert!(
        close(m[2].1, Position::xyz(-12.7, MM, -12.7 + 2.54)),
        "{m:?}"
    );
    assert_eq!(
        asked.borrow()[0],
        (Position::ZERO, Position::xyz(0.0, 0.0, -MM))
    );
}

// ---- parameter file ----

#[test]
fn persistent_parameters_are_saved_at_program_end_and_read_back() {
    let dir = std::env::temp_dir().join(format!("kerf-interp-var-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("kerf.var");
    // G28.1 stores the current machine position in #5161–#5169.
    let env = Offline {
        parameter_file: Some(file.clone()),
    };
    run_cfg(
        "G0 X10 Y20 Z30\nG28.1\n#5220 = 1\nM2\n",
        Config::default(),
        Box::new(env),
    )
    .unwrap();
    let text = std::fs::read_to_string(&file).unwrap();
    let value = |n: usize| -> f64 {
        text.lines()
            .find_map(|l| {
                let mut w = l.split_whitespace();
                (w.next()? == n.to_string()).then(|| w.next()?.parse().ok())?
            })
            .unwrap_or(f64::NAN)
    };
    assert_eq!((value(5161), value(5162), value(5163)), (10.0, 20.0, 30.0));
    // A second run loads the file: G28 goes (by way of where it is) to the
    // stored point.
    let mut cfg = Config::default();
    cfg.load_parameters(&file).unwrap();
    let cmds = run_cfg("G28\nM2\n", cfg, Box::new(Offline::default())).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let m = moves(&cmds);
    assert!(
        close(m[m.len() - 1].1, Position::xyz(10.0, 20.0, 30.0)),
        "{m:?}"
    );
}

// ---- cutter compensation ----

#[test]
fn cutter_compensation_left_around_a_square() {
    // Tool diameter 0.2 in (radius 0.1 in = 2.54 mm). Entry along +Y to the
    // origin ends 0.1 to the left of the path: (-0.1, 0). The turn onto +X
    // is an outside corner: an arc about (0,0) to (0, 0.1). Inside corners
    // at (1,0) and (1,1) put the tool at (0.9, 0.1) and (0.9, 0.9); the last
    // compensated move ends at (0, 0.9); after G40 the tool goes to (-1, 1).
    let cfg = with_tools("T1 P1 D5.08\n");
    let cmds = run_cfg(
        "G20 G17 G90\nT1 M6\nG0 X0 Y-1\nG41 G1 Y0 F100\nX1\nY1\nX0\nG40 G0 X-1\nM2\n",
        cfg,
        Box::new(Offline::default()),
    )
    .unwrap();
    let m = moves(&cmds);
    let inch = |x: f64, y: f64| Position::xyz(x * MM, y * MM, 0.0);
    let expected = [
        ('T', inch(0.0, -1.0)),
        ('F', inch(-0.1, 0.0)),
        ('A', inch(0.0, 0.1)),
        ('F', inch(0.9, 0.1)),
        ('F', inch(0.9, 0.9)),
        ('F', inch(0.0, 0.9)),
        ('T', inch(-1.0, 1.0)),
    ];
    assert_eq!(m.len(), expected.len(), "{m:?}");
    for (got, want) in m.iter().zip(expected) {
        assert!(
            got.0 == want.0 && close(got.1, want.1),
            "{got:?} vs {want:?}"
        );
    }
    let a = arcs(&cmds);
    assert!(a[0].1[0].abs() < 1e-9 && a[0].1[1].abs() < 1e-9);
    assert_eq!(a[0].3, -1);
}

#[test]
fn cutter_compensation_entry_shorter_than_the_radius_is_refused() {
    let cfg = with_tools("T1 P1 D10\n");
    let e = run_cfg(
        "T1 M6\nG0 X0 Y-1\nG41 G1 Y0 F100\nX10\nM2\n",
        cfg,
        Box::new(Offline::default()),
    )
    .unwrap_err();
    assert!(e.contains("not greater than the tool radius"), "{e}");
}

// ---- canned cycles ----

#[test]
fn drilling_cycle_retracts_to_old_z_or_r() {
    // G98: rapid over the hole at the old Z 10, down to R1, feed to Z-2,
    // back up to 10. G99: the same but back up to R1.
    assert_moves(
        "G0 X0 Y0 Z10\nG98 G81 X5 Y5 Z-2 R1 F100\nG99 G81 X8 Y5 Z-2 R1\nG80\nM2\n",
        &[
            ('T', [0.0, 0.0, 10.0]),
            ('T', [5.0, 5.0, 10.0]),
            ('T', [5.0, 5.0, 1.0]),
            ('F', [5.0, 5.0, -2.0]),
            ('T', [5.0, 5.0, 10.0]),
            ('T', [8.0, 5.0, 10.0]),
            ('T', [8.0, 5.0, 1.0]),
            ('F', [8.0, 5.0, -2.0]),
            ('T', [8.0, 5.0, 1.0]),
        ],
    );
}

#[test]
fn cycle_repeats_in_incremental_mode() {
    // G91 with L3: three holes 2 apart in X; R and Z are relative to the
    // start height (Z 5): R at 5-1 = 4, bottom at 4-3 = 1.
    let m = moves(&run("G0 Z5\nG91 G99 G81 X2 R-1 Z-3 L3 F100\nM2\n"));
    let feeds: Vec<(f64, f64)> = m
        .iter()
        .filter(|(k, _)| *k == 'F')
        .map(|(_, p)| (p.x, p.z))
        .collect();
    assert_eq!(feeds, vec![(2.0, 1.0), (4.0, 1.0), (6.0, 1.0)]);
}

// ---- order of execution and modal groups ----

#[test]
fn a_block_runs_in_linuxcncs_order() {
    // Written backwards on purpose: comment, feed, speed, tool select,
    // spindle, coolant, dwell, then the motion.
    let cfg = with_tools("T1 P1 D1\n");
    let cmds = run_cfg(
        "G0 X1 G4 P0.5 M8 M3 T1 S1000 F50 (first)\nM2\n",
        cfg,
        Box::new(Offline::default()),
    )
    .unwrap();
    let names: Vec<&str> = cmds
        .iter()
        .take(8)
        .map(|c| match c {
            CanonCmd::Comment(_) => "comment",
            CanonCmd::SetFeedRate { .. } => "feed",
            CanonCmd::SetSpindleSpeed { .. } => "speed",
            CanonCmd::SelectTool { .. } => "tool",
            CanonCmd::StartSpindleClockwise { .. } => "spindle",
            CanonCmd::FloodOn => "coolant",
            CanonCmd::Dwell { .. } => "dwell",
            CanonCmd::StraightTraverse { .. } => "move",
            _ => "other",
        })
        .collect();
    assert_eq!(
        names,
        ["comment", "feed", "speed", "tool", "spindle", "coolant", "dwell", "move"]
    );
}

#[test]
fn two_codes_of_one_modal_group_are_an_error_at_the_second() {
    // Line 2, the second G (column 7) is at fault.
    let e = error("G0 X0\nG0 X1 G1 X2\nM2\n");
    assert!(e.starts_with("t.ngc:2:"), "{e}");
    let e = error("G0 X0\nG0 G1 X2\nM2\n");
    assert_eq!(e, "t.ngc:2:4: G1: Two g codes used from same modal group");
}

#[test]
fn errors_name_file_line_column_and_word() {
    // The second X, at column 7, repeats a word.
    assert_eq!(
        error("G1 X1 X2 F1\nM2\n"),
        "t.ngc:1:7: X: Multiple x words on one line"
    );
    let e = error("G0 X0\nG7.5\nM2\n");
    assert!(e.starts_with("t.ngc:2:1: G7.5: "), "{e}");
    let e = error("M200\nM2\n");
    assert!(e.starts_with("t.ngc:1:1: M200: "), "{e}");
    // Feed moves need a feed rate.
    let e = error("G1 X1\nM2\n");
    assert!(e.starts_with("t.ngc:1:1: G1: "), "{e}");
}

#[test]
fn a_program_without_an_end_is_reported() {
    let e = error("G0 X1\n");
    assert!(e.contains("percent sign or program end"), "{e}");
}

#[test]
fn unsupported_codes_are_refused_clearly() {
    let e = error("G5.1 X1 Y1 I1 J1 F100\nM2\n");
    assert!(e.contains("not supported"), "{e}");
    let e = error("G0 X10 Z0\nG71 Q2 D0.5\nM2\n");
    assert!(e.contains("not supported"), "{e}");
}

#[test]
fn deeply_nested_values_are_an_error_not_a_crash() {
    // Each level of brackets, signs or indirection is a level of
    // recursion; it is bounded (at 100) rather than left to the stack.
    for text in [
        format!("G0 X{}1{}\nM2\n", "[".repeat(110), "]".repeat(110)),
        format!("G0 X{}ABS[1]\nM2\n", "-".repeat(150)),
        format!("G0 X{}1\nM2\n", "#".repeat(150)),
    ] {
        let e = error(&text);
        assert!(e.contains("X: Expression nested too deeply"), "{e}");
    }
    // Ordinary nesting is untouched.
    let fifty = format!("G0 X{}2{}\nM2\n", "[".repeat(50), "]".repeat(50));
    assert_eq!(x_of(&fifty), 2.0);
}

#[test]
fn lines_longer_than_linuxcnc_accepts_are_refused() {
    // LinuxCNC reads lines into a 255-byte buffer: 252 characters and the
    // newline fit, 253 do not.
    let fits = format!("G0 X1 ({})\nM2\n", "a".repeat(252 - 8));
    assert_eq!(moves(&run(&fits)).len(), 1);
    let long = format!("G0 X0\nG0 X1 ({})\nM2\n", "a".repeat(253 - 8));
    assert_eq!(error(&long), "t.ngc:2:1: Command too long");
    // A huge line costs no more than the limit: it is read and dropped.
    let huge = format!("({})\nM2\n", "a".repeat(5_000_000));
    assert_eq!(error(&huge), "t.ngc:1:1: Command too long");
}

#[test]
fn m170_and_m171_switch_force_control_without_a_user_program() {
    // No USER_M_PATH is configured, so any other M1xx is unknown; kerf's
    // force-control codes are built in and carry P as the force in N.
    let cmds = run("M170 P250\nG1 X1 F100\nM171\nM2\n");
    let force: Vec<_> = cmds
        .iter()
        .filter_map(|c| match c {
            CanonCmd::ForceControl { target } => Some(*target),
            _ => None,
        })
        .collect();
    assert_eq!(force, [Some(250.0), None]);
    // On comes before the move, off after it, as written.
    let first = cmds
        .iter()
        .position(|c| matches!(c, CanonCmd::ForceControl { .. }))
        .unwrap();
    let feed = cmds
        .iter()
        .position(|c| matches!(c, CanonCmd::StraightFeed { .. }))
        .unwrap();
    assert!(first < feed);
    // The force is a P word, positive; anything else names the code, the
    // file and the line.
    for bad in ["M170\nM2\n", "M170 P0\nM2\n", "M170 P-5\nM2\n"] {
        let e = error(bad);
        assert!(
            e.contains("t.ngc:1") && e.contains("M170 needs P"),
            "{bad:?}: {e}"
        );
    }
    assert!(error("M172\nM2\n").contains("Unknown m code used: M172"));
}

/// The modes one program text leaves, set up again by `modal_gcode` before
/// another, give the same motion as one program would (MDI's carry-over).
#[test]
fn modal_gcode_carries_the_modes_to_the_next_text() {
    let mut first = kerf_interp::Interpreter::from_text(
        "%\nG20 G91 G18\nG1 F20 S900\n%\n",
        "a",
        Position::ZERO,
    );
    for c in first.by_ref() {
        c.unwrap();
    }
    let modal = first.modal_gcode();
    assert_eq!(modal[0], "G20 G18 G91 G91.1");
    assert_eq!(modal[1], "G94 F20 S900 G1");
    let text = format!("%\n{}\n{}\nX1\nX1\n%\n", modal[0], modal[1]);
    let second = kerf_interp::Interpreter::from_text(text, "b", Position::ZERO);
    let ends: Vec<_> = second
        .map(|c| c.unwrap().cmd)
        .filter_map(|cmd| match cmd {
            kerf_interp::CanonCmd::StraightFeed { end, .. } => Some(end.x),
            _ => None,
        })
        .collect();
    // The G1 of the modal lines is a move to where the tool is.
    assert_eq!(ends, [0.0, 25.4, 50.8]);

    // An inverse-time G1 needs its own F: the mode is not carried then.
    let mut g93 = kerf_interp::Interpreter::from_text("%\nG93 G1 X1 F10\n%\n", "c", Position::ZERO);
    for c in g93.by_ref() {
        c.unwrap();
    }
    assert_eq!(g93.modal_gcode()[1], "G93 S0");
}
