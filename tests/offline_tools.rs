//! The offline tools through the real `kerf` binary.

use std::process::Command;

fn kerf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(args)
        .output()
        .unwrap()
}

fn program(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// `kerf plan --json` of `text` on mill3: the report, once it succeeded.
fn plan_json(text: &str) -> serde_json::Value {
    plan_json_with(text, &[])
}

/// [`plan_json`] with more of `kerf plan`'s options.
fn plan_json_with(text: &str, options: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let p = program(&dir, "plan.ngc", text);
    let out = kerf(&[&["plan", p.as_str(), "--json"], options].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn check_lists_every_violation_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = program(
        &dir,
        "bad.ngc",
        "G0 X10\nG1 Z-150 F100\nG1 X400\nG1 X20\nM2\n",
    );
    let out = kerf(&["check", &p]);
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("bad.ngc:2: ") && text.contains("axis Z at -150"),
        "{text}"
    );
    assert!(
        text.contains("bad.ngc:3: ") && text.contains("axis X at 400"),
        "{text}"
    );
    // Line 4 stays at Z-150 from line 2, so it is outside the travel too.
    assert!(
        text.contains("bad.ngc:4: ") && text.contains("axis Z at -150"),
        "{text}"
    );
    assert_eq!(text.lines().count(), 3, "{text}");

    let good = program(&dir, "good.ngc", "G0 X10 Y10\nG1 Z-5 F100\nM2\n");
    let out = kerf(&["check", &good, "--json"]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["ok"], true);
}

#[test]
fn plan_of_one_move_takes_the_jerk_limited_rest_to_rest_time() {
    // mill3 X: 150 mm/s, 1500 mm/s², jerk 50 × 1500 = 75000 mm/s³.
    // At F6000 (100 mm/s) over 100 mm: speeding up takes
    // dv/A + A/J = 1/15 + 1/50 s and covers half the speed times that time;
    // slowing down mirrors it; the rest is cruise.
    let (v, a, j, len) = (100.0f64, 1500.0f64, 75_000.0f64, 100.0f64);
    let ramp = v / a + a / j;
    let ramp_distance = v / 2.0 * ramp;
    let want = 2.0 * ramp + (len - 2.0 * ramp_distance) / v;

    let json = plan_json("G1 X100 F6000\nM2\n");
    let got = json["cycle_time_s"].as_f64().unwrap();
    // Whole servo periods (1 ms) and the executor's J·dt²/8 speed margin
    // add at most 2 ms.
    assert!(
        got >= want - 1e-9 && got <= want + 0.002,
        "planned {got} s, closed form {want} s"
    );
    assert!(json["max_limit_ratio"].as_f64().unwrap() <= 1.0 + 1e-6);
    // A straight move: any deviation is floating-point rounding.
    assert!(json["max_deviation_mm"].as_f64().unwrap() < 1e-12);
    assert_eq!(json["segments"], 1);
    // One straight move: the executor's search never needs its guard.
    assert_eq!(json["guard_takeovers"], 0);
}

/// `kerf plan --trapezoidal`: acceleration-limited profiles, for
/// comparison. Until 2026-11-26 the motion never started in that mode
/// (the executor's guard found no way to rest under an infinite jerk
/// limit), so `kerf plan --trapezoidal` waited for ever.
#[test]
fn trapezoidal_plan_takes_the_trapezoid_time() {
    // mill3 X: 1500 mm/s²; at F6000 (100 mm/s) over 100 mm the speed
    // ramps for v/A each way and cruises the rest.
    let (v, a, len) = (100.0f64, 1500.0f64, 100.0f64);
    let want = 2.0 * v / a + (len - v * v / a) / v;
    let json = plan_json_with("G1 X100 F6000\nM2\n", &["--trapezoidal"]);
    let got = json["cycle_time_s"].as_f64().unwrap();
    // Within 0.6 %: whole periods at each end, cruising 0.1 % under the
    // feed, and the stop's profile braking a little under the limit so as
    // to arrive exactly (1.072 s against 1.0667 s).
    assert!(
        got >= want - 1e-9 && got <= want * 1.006,
        "planned {got} s, trapezoid {want} s"
    );
    // Velocity and acceleration only: the jerk is not limited.
    let ratio = json["max_limit_ratio"].as_f64().unwrap();
    assert!(ratio <= 1.0 + 1e-6, "limit use {ratio}");
    let x = &json["axes"][0];
    assert!(x["acceleration"].as_f64().unwrap() > 0.999, "{x}");
}

/// The deviation is measured against the programmed moves up to the
/// program's end, the last sample included. Until 2026-11-26 the end
/// marker had no source line, and the last sample was measured against
/// the moves of line 1 alone: a program starting with a rapid on line 1
/// reported its distance from that rapid (here 10 mm), and one starting
/// on a later line skipped the sample.
#[test]
fn plan_measures_the_deviation_at_the_end_against_the_last_move() {
    let json = plan_json("G0 X150 Y100 Z-10\nG1 X160 F600\nM2\n");
    let deviation = json["max_deviation_mm"].as_f64().unwrap();
    // The rapid's corner into the feed is blended within G64's default
    // tolerance, 0.01 mm; the end is on the last move.
    assert!(deviation <= 0.01 + 1e-9, "max deviation {deviation} mm");
}

/// `kerf check`, `plan` and `sim` read a program's tools from
/// `--tool-table`, as `kerf canon` does; without it a program that loads
/// a tool stops at its T word.
#[test]
fn check_plan_and_sim_take_a_tool_table() {
    let dir = tempfile::tempdir().unwrap();
    let tbl = program(&dir, "tools.tbl", "T1 P1 Z10 D6 ;10 mm long\n");
    // Z-5 at the tool tip is Z5 of the spindle with a 10 mm tool: above
    // mill3's travel (Z at most 0).
    let p = program(
        &dir,
        "tool.ngc",
        "G21 G90\nT1 M6\nG43 H1\nG0 X10 Y10 Z-20\nG1 Z-5 F600\nM2\n",
    );
    // What a failing `kerf` printed, both streams.
    let refused = |args: &[&str]| {
        let out = kerf(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr)
    };
    let text = refused(&["check", &p]);
    assert!(
        text.contains("tool.ngc:2") && text.contains("tool 1"),
        "{text}"
    );
    let text = refused(&["check", &p, "--tool-table", &tbl]);
    assert!(
        text.contains("tool.ngc:5") && text.contains("axis Z"),
        "{text}"
    );

    // Within the travel, the offset is planned and simulated.
    let inside = program(
        &dir,
        "inside.ngc",
        "G21 G90\nT1 M6\nG43 H1\nG0 X10 Y10 Z-20\nG1 Z-15 F600\nM2\n",
    );
    for cmd in ["plan", "sim"] {
        let out = kerf(&[cmd, &inside, "--tool-table", &tbl, "--json"]);
        assert!(
            out.status.success(),
            "{cmd}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let text = refused(&["plan", &inside, "--tool-table", "/nonexistent/tools.tbl"]);
    assert!(text.contains("/nonexistent/tools.tbl"), "{text}");
}

#[test]
fn plan_plot_writes_an_svg() {
    let dir = tempfile::tempdir().unwrap();
    let p = program(&dir, "sq.ngc", "G1 X10 F3000\nY10\nX0\nY0\nM2\n");
    let svg = dir.path().join("out.svg");
    let out = kerf(&["plan", &p, "--plot", svg.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
    assert_eq!(text.matches("<polyline").count(), 2 + 3 + 3 + 1);
    let human = String::from_utf8_lossy(&out.stdout);
    assert!(human.contains("cycle time") && human.contains("axis X"));
}

/// Plan `program` on the embedded machine `name` with every joint's speed
/// limit lowered to `joint_speed`, so the joints rather than the axes bind,
/// and return the largest joint velocity use and the largest limit use of
/// anything, both measured by finite differences of the sampled trajectory.
fn plan_with_slow_joints(name: &str, joint_speed: f64, program_text: &str) -> (f64, f64) {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(format!(
        "{}/machines/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    // Only the [[joints]] tables: axis limits stay as they are.
    let split = text.find("[[joints]]").expect("the machine has joints");
    let (axes, joints) = text.split_at(split);
    let slowed: String = joints
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("max_velocity") {
                format!("max_velocity = {joint_speed}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(
        slowed.trim(),
        joints.trim(),
        "the joint limits to lower are in the file"
    );
    let machine = dir.path().join(format!("slow-{name}.toml"));
    std::fs::write(&machine, format!("{axes}{slowed}\n")).unwrap();
    let p = program(&dir, "p.ngc", program_text);
    let out = kerf(&["plan", &p, "--machine", machine.to_str().unwrap(), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let joint_velocity = json["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["velocity"].as_f64().unwrap())
        .fold(0.0, f64::max);
    (joint_velocity, json["max_limit_ratio"].as_f64().unwrap())
}

#[test]
fn joints_stay_within_their_limits_on_the_o_x_glide() {
    // Near the bottom of the travel a slider moves about 8 times as fast as
    // the tool moves in Z.
    let (joint, all) = plan_with_slow_joints(
        "oxglide-x",
        60.0,
        "G21 G90\nG1 X250 Z-350 F3000\nG1 Z-295\nG1 X200 Z-340\nG1 X320\nM2\n",
    );
    assert!(joint <= 1.0 + 1e-6, "joint velocity use {joint}");
    assert!(joint > 0.9, "the slow joints should bind: use {joint}");
    assert!(all <= 1.0 + 1e-6, "limit use {all}");

    let (joint, all) = plan_with_slow_joints(
        "oxglide-o",
        30.0,
        "G21 G90\nG1 X210 Z-354 F3000\nG1 X295 Z-341\nG1 X210\nG1 Z-350\nM2\n",
    );
    assert!(
        joint <= 1.0 + 1e-6 && joint > 0.9,
        "extended form: joint velocity use {joint}"
    );
    assert!(all <= 1.0 + 1e-6, "extended form: limit use {all}");
}

#[test]
fn joints_stay_within_their_limits_on_the_5_axis_platform() {
    // Tool-centre-point moves with tilt: the X-Y table swings under the tool
    // tip while the actuators tilt the platform.
    let (joint, all) = plan_with_slow_joints(
        "rfmt5",
        40.0,
        "G21 G90\nG1 X200 Y150 Z100 A20 B-15 F3000\nG1 A-20 B20\nG1 X100 Y50 Z150 A0 B0\nM2\n",
    );
    assert!(joint <= 1.0 + 1e-6, "joint velocity use {joint}");
    assert!(joint > 0.9, "the slow joints should bind: use {joint}");
    assert!(all <= 1.0 + 1e-6, "limit use {all}");
}

/// Three lines from stellabee1.ngc (an XZ profile, inches) on mill3. The
/// blend into the steep last line has half the acceleration and a third of
/// the jerk of the line after it. The look ahead used to stop scanning
/// where a stop under the current line's limits would end, so it met the
/// slow blend only once too close to brake under its limits, and the
/// motion entered the last line too fast to stop in it (limit use ≈ 340).
#[test]
fn a_steep_final_line_after_a_slow_blend_stops_within_limits() {
    plans_within_limits(
        "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18\nF999\n\
         G0 X0.4200 Y2.4420 Z-0.1859\nG1 X0.4260 Z-0.1755\nX0.4300 Z-0.0726\n\
         X0.4360 Z-0.0049\nM2\n",
    );
}

/// Arcs whose end lies off their circle spiral to it, and the interpreter
/// accepts up to 0.02 mm of difference however small the arc: here arcs of
/// 0.01 mm spiral out to 0.03 mm. Their limits once took the start radius
/// for the whole arc, and the motion ran at 1.13 times the jerk limit.
#[test]
fn spiral_arcs_stay_within_limits() {
    let mut text = String::from("G21 G90 G64 P0.01\nG0 X150 Y100 Z-10\nG1 F3000\n");
    for _ in 0..20 {
        text += "G2 X150.02 Y100 I0.01 J0\nG3 X150 Y100 I0.01 J0\n";
    }
    plans_within_limits(&(text + "M2\n"));
}

/// `kerf plan --json` on mill3 measures limit use at most 1 + 1e-6.
fn plans_within_limits(text: &str) {
    let json = plan_json(text);
    let ratio = json["max_limit_ratio"].as_f64().unwrap();
    assert!(ratio <= 1.0 + 1e-6, "limit use {ratio}");
}

/// A stretch of stellabee1.ngc where a line is followed by two blends with
/// ever lower limits and a stop. Aiming one zero-acceleration profile at a
/// time, the executor used to re-aim between the near cap and the far one
/// and enter the slowest blend decelerating harder than it allows (jerk
/// use 1.66); now a cap also counts as met when braking at once passes it
/// below its speed, and the jerk search does that braking.
#[test]
fn two_blends_with_falling_limits_before_a_stop_stay_within_limits() {
    plans_within_limits(
        "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
         G0 X1.1240 Z-0.2203\nG1 X1.1200 Z-0.2291\nX1.1120 Z-0.2314\nX1.1100 Z-0.2304\n\
         G3 X1.1060 Y0.6020 Z-0.1941 I0.2535 K0.0463\n\
         G3 X1.1020 Y0.6020 Z-0.1069 I1.9066 K0.1311\n\
         G1 X1.1000 Z-0.1059\nX1.0960 Z-0.1069\nX1.0940 Z-0.1255\nX1.0920 Z-0.1932\n\
         X1.0900 Z-0.1980\nX1.0880 Z-0.1990\nM2\n",
    );
}

#[test]
fn offline_tools_take_programs_that_set_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let p = program(
        &dir,
        "pins.ngc",
        "G21 G90 G1 X10 F600\nM62 P0\nM67 E0 Q2\nG1 X20\nM64 P1\nM68 E1 Q1\nG1 X30\nM65 P1\nM63 P0\nM2\n",
    );
    for tool in ["check", "plan", "sim"] {
        let out = kerf(&[tool, &p]);
        assert!(
            out.status.success(),
            "kerf {tool}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // M64, M68 and M65 are markers where the tool rests; M62 and M67 ride
    // on the move after them (M63 has none, so it never acts).
    let out = kerf(&["plan", "--segments", &p]);
    let text = String::from_utf8_lossy(&out.stdout);
    let kinds: Vec<(&str, &str)> = text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            Some((w.next()?, w.next()?))
        })
        .collect();
    assert_eq!(
        kinds,
        [
            ("1", "line"),
            ("4", "line"),
            ("5", "output"),
            ("6", "output"),
            ("7", "line"),
            ("8", "output"),
        ],
        "{text}"
    );
}

#[test]
fn a_reader_that_stops_early_ends_kerf_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    // Canon output far beyond a pipe's 64 KiB buffer, so kerf is still
    // writing when the reader has gone.
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("G21 G90 F1000\n");
    for k in 0..5000 {
        text.push_str(&format!("G1 X{} Y{}\n", k % 100, (k * 7) % 100));
    }
    let file = program(&dir, "long.ngc", &text);
    let mut child = Command::new(env!("CARGO_BIN_EXE_kerf"))
        .args(["canon", &file])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reader closes its end before reading anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "kerf panicked: {stderr}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "kerf should end by SIGPIPE like other tools: {:?}, {stderr}",
        out.status
    );
}

/// `kerf plan --period-us` plans and measures at the servo period given.
/// A line running on into a tangent arc under G61 keeps the curvature
/// jump's cap v²·|Δκ| ≤ J·T: on mill3 (J = 75,000 mm/s³, R5) about
/// 19.4 mm/s at 1 ms and half that at 250 µs, so the shorter period plans
/// slower, by the time the slower junction costs. Out of range is refused.
#[test]
fn plan_takes_the_servo_period() {
    let text = "G21 G90 G61\nG0 X10 Y10\nG1 X50 F6000\nG3 X50 Y20 J5\nM2\n";
    let usual = plan_json(text);
    let fine = plan_json_with(text, &["--period-us", "250"]);
    let time = |j: &serde_json::Value| j["cycle_time_s"].as_f64().unwrap();
    assert!(
        time(&fine) > time(&usual) + 0.01,
        "250 µs {} s against 1 ms {} s",
        time(&fine),
        time(&usual)
    );
    for report in [&usual, &fine] {
        assert!(report["max_limit_ratio"].as_f64().unwrap() <= 1.0 + 1e-6);
    }
    // The samples are a quarter period apart: the cycle time is a whole
    // number of 250 µs periods.
    let periods = time(&fine) / 250e-6;
    assert!((periods - periods.round()).abs() < 1e-6, "{periods}");

    let dir = tempfile::tempdir().unwrap();
    let p = program(&dir, "p.ngc", text);
    let out = kerf(&["plan", &p, "--period-us", "100"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("250..=10000"), "{err}");
}

/// On a deployed controller `kerf check`, `plan` and `sim` take the
/// machine and servo period kerfd runs from its configuration file
/// (`--config`; `/etc/kerf/kerf.toml` when it exists), flags still
/// winning, and say so on stderr; a bad configuration is refused with the
/// file and key.
#[test]
fn offline_tools_take_the_machine_and_period_from_kerfds_configuration() {
    let dir = tempfile::tempdir().unwrap();
    // Inside the O-X glide's travel (Z -355 .. -292), far below mill3's.
    let p = program(
        &dir,
        "ox.ngc",
        "G21 G90 G64 P0.01\nG0 X250 Y100 Z-320\nG1 X280 Y150 F3000\nG2 X280 Y200 J25\nM2\n",
    );
    let config = program(
        &dir,
        "kerf.toml",
        "machine = \"oxglide-x\"\n[servo]\nperiod_us = 250\n",
    );
    let text = |out: &std::process::Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };

    let configured = kerf(&["plan", &p, "--json", "--config", &config]);
    let said = String::from_utf8_lossy(&configured.stderr).into_owned();
    assert!(
        said.contains("machine oxglide-x, servo period 250 µs from") && said.contains("kerf.toml"),
        "{said}"
    );
    let explicit = kerf(&[
        "plan",
        &p,
        "--json",
        "--machine",
        "oxglide-x",
        "--period-us",
        "250",
    ]);
    assert_eq!(text(&configured), text(&explicit));
    // A flag wins over the file.
    let coarse = kerf(&[
        "plan",
        &p,
        "--json",
        "--config",
        &config,
        "--period-us",
        "1000",
    ]);
    let coarse_explicit = kerf(&["plan", &p, "--json", "--machine", "oxglide-x"]);
    assert_eq!(text(&coarse), text(&coarse_explicit));
    assert_ne!(
        text(&coarse),
        text(&configured),
        "the period reaches the plan"
    );

    // Without the file, the simulated mill, whose travel refuses the program.
    assert_eq!(kerf(&["check", &p]).status.code(), Some(1));
    text(&kerf(&["check", &p, "--config", &config]));
    assert!(
        text(&kerf(&["sim", &p, "--config", &config])).contains("oxglide-x"),
        "sim runs the configured machine"
    );
    let joints = text(&kerf(&[
        "kins", "--config", &config, "inverse", "250", "0", "-300",
    ]));
    assert!(joints.contains("s1"), "the O-X glide's sliders: {joints}");

    let bad = program(&dir, "bad.toml", "[servo]\nperiod_us = 100\n");
    let out = kerf(&["plan", &p, "--config", &bad]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.toml") && err.contains("servo.period_us") && err.contains("250 to 10000"),
        "{err}"
    );
}

/// `kerf plan --follow`: the executor follows the jerk-limited schedule
/// (every stretch of a short program is solved in time), within every
/// limit; a reserve outside 0 ≤ r < 1 is refused by the schedule before
/// anything runs, naming the reserve.
#[test]
fn plan_follows_the_schedule_and_refuses_a_bad_reserve() {
    let text = "G21 G90 G0 X10 Y10\nG1 F600 X16 Y10\nG1 X16 Y14\nG4 P0.1\nG1 X10 Y14\nM2\n";
    let report = plan_json_with(text, &["--follow"]);
    assert!(
        report["stretches_followed"].as_u64().unwrap() >= 2,
        "{report}"
    );
    assert!(
        report["max_limit_ratio"].as_f64().unwrap() <= 1.0 + 1e-6,
        "{report}"
    );
    let own = plan_json(text);
    assert_eq!(own["stretches_followed"].as_u64(), Some(0), "{own}");

    let dir = tempfile::tempdir().unwrap();
    let p = program(&dir, "plan.ngc", text);
    let out = kerf(&["plan", &p, "--follow", "--reserve", "1.5"]);
    assert!(!out.status.success());
    assert!(
        out.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("reserve") && err.contains("1.5"), "{err}");
}
