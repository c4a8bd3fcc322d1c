//! The benchmark programs, shared by `benches/motion.rs` and
//! `tests/time_bound.rs` (included with `#[path]`), short test programs
//! the schedule's tests share, and the machine
//! LinuxCNC's sample programs run on, shared by `benches/motion.rs` and
//! `tests/linuxcnc_programs.rs`.

#![allow(dead_code)]

/// A circle of R = 20 mm in 0.05 mm chords (2513 segments) at 3000 mm/min.
pub fn circle_small_segments() -> String {
    let r = 20.0;
    let n = (2.0 * std::f64::consts::PI * r / 0.05).round() as usize;
    let mut t = format!("G21 G90\nG0 X{:.6} Y100\nG1 F3000\n", 150.0 + r);
    for k in 1..=n {
        let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        t += &format!("X{:.6} Y{:.6}\n", 150.0 + r * a.cos(), 100.0 + r * a.sin());
    }
    t + "M2\n"
}

/// A 60 x 40 mm zig-zag pocket, 1 mm stepover, at 2400 mm/min.
pub fn zigzag_pocket() -> String {
    let mut t = "G21 G90\nG0 X20 Y20\nG1 Z-2 F600\nG1 F2400\n".to_string();
    let mut y = 20.0;
    let mut left = true;
    while y <= 60.0 + 1e-9 {
        t += &format!("X{} Y{y}\n", if left { 80 } else { 20 });
        left = !left;
        y += 1.0;
        if y <= 60.0 + 1e-9 {
            t += &format!("Y{y}\n");
        }
    }
    t + "G0 Z0\nM2\n"
}

/// An Archimedean spiral in 0.02 mm chords: a smooth curve of tiny moves.
pub fn spiral(segments: usize) -> String {
    let mut t = String::with_capacity(segments * 24);
    t += "G21 G90\nG0 X150 Y100\nG1 F3000\n";
    let (mut theta, b) = (0.0f64, 0.5 / (2.0 * std::f64::consts::PI));
    for _ in 0..segments {
        let r = 1.0 + b * theta;
        theta += 0.02 / r;
        let r = 1.0 + b * theta;
        let (x, y) = (150.0 + r * theta.cos(), 100.0 + r * theta.sin());
        t += &format!("X{x:.5} Y{y:.5}\n");
        if r > 90.0 {
            theta = 0.0;
            t += "G0 X150 Y100\nG1\n";
        }
    }
    t + "M2\n"
}

/// LinuxCNC's planner stress file stellabee1.ngc (G18 profiles in inches,
/// arcs and dense lines), shifted into mill3's travel with a G54 offset.
/// `None` when the shared conformance material is not checked out.
pub fn stellabee() -> Option<String> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/conformance/linuxcnc-programs/tp-stress/performance/stellabee1.ngc"
    );
    let text = std::fs::read_to_string(path).ok()?;
    Some(format!("G21 G10 L2 P1 X100 Y50 Z-20\nG54\n{text}"))
}

/// A trivial machine moving all nine axes over ±10 m, for LinuxCNC's
/// sample programs, which come in inches and anywhere: mill3's dynamics
/// on the linear axes (jerk its default, 50 times the acceleration), fast
/// rotary ones, and a few simulated pins for their M62–M66.
pub fn corpus_machine() -> String {
    let mut text = String::from(
        r#"name = "big9"
description = "Nine trivial axes over +-10 m, for LinuxCNC's sample programs"
kinematics = "trivial"
[hal]
backend = "sim"
[hal.pins]
digital_out = ["d0", "d1", "d2", "d3"]
digital_in = ["i0", "i1"]
analog_out = ["a0", "a1"]
"#,
    );
    for (i, axis) in "xyzabcuvw".chars().enumerate() {
        let (v, a) = if (3..6).contains(&i) {
            (3600.0, 36000.0)
        } else {
            (150.0, 1500.0)
        };
        let limits = format!(
            "min = -10000.0\nmax = 10000.0\nmax_velocity = {v:.1}\nmax_acceleration = {a:.1}\n"
        );
        text += &format!("[axes.{axis}]\n{limits}");
        text += &format!("[[joints]]\nname = \"{axis}\"\naxis = \"{axis}\"\n{limits}");
    }
    text
}

/// Corners, an arc and a dense curve from (50, 50), blended and stopped
/// (`tests/schedule.rs`, `tests/follow.rs`).
pub fn corners_arc_and_curve() -> String {
    let mut program =
        String::from("G21 G90 G64 P0.01 G1 F3000 X60 Y52\nG3 X64 Y56 R4\nG1 X64 Y60\n");
    for k in 1..=60 {
        let a = k as f64 * 0.02;
        program += &format!(
            "X{:.5} Y{:.5}\n",
            64.0 - 8.0 * (1.0 - a.cos()),
            60.0 + 8.0 * a.sin()
        );
    }
    program + "G61 G1 X50 Y50\nM2\n"
}
