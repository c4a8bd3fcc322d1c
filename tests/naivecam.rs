//! G64 Q: nearly collinear straight feeds merged into one line
//! (`kerf_motion::merge`), planned and run on mill3.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, plan_program, RunConfig};
use kerf_motion::path::Shape;
use kerf_motion::{PlannerConfig, Segment};

fn mill3() -> kerf_machines::Machine {
    kerf_machines::load("mill3").unwrap()
}

fn start() -> Position {
    Position::xyz(10.0, 100.0, -5.0)
}

fn plan(program: &str) -> Vec<Segment> {
    let machine = mill3();
    plan_program(
        Interpreter::from_text(program, "t.ngc", start()),
        &*machine.kinematics,
        start(),
        PlannerConfig::default(),
        1,
    )
    .unwrap()
}

fn motion(segments: &[Segment]) -> Vec<&Segment> {
    segments.iter().filter(|s| s.is_motion()).collect()
}

/// A CAM-style line from (10, 100) to (110, 100) in 0.01 mm steps with
/// points scattered up to `noise` mm across it (deterministic).
fn noisy_line(header: &str, noise: f64) -> (String, Vec<[f64; 2]>) {
    let mut text = format!("G21 G90 {header}\nG1 F1200\n");
    let mut points = Vec::new();
    for k in 1..=10_000 {
        let x = 10.0 + k as f64 * 0.01;
        // A fixed pseudo-random sequence in -1..1.
        let r = ((k as f64 * 12.9898).sin() * 43758.5453).rem_euclid(1.0) * 2.0 - 1.0;
        let y = if k == 10_000 {
            100.0
        } else {
            100.0 + noise * r
        };
        text += &format!("X{x:.4} Y{y:.4}\n");
        points.push([x, y]);
    }
    (text + "M2\n", points)
}

/// Distance from (x, y) to the path of `segments`: exact on lines, blends
/// sampled every 2 µm.
fn distance_to_path(segments: &[&Segment], p: [f64; 2]) -> f64 {
    let mut best = f64::INFINITY;
    for s in segments {
        let (a, b) = (s.start(), s.end());
        // Skip segments nowhere near.
        let (lo, hi) = (a.x.min(b.x) - 0.1, a.x.max(b.x) + 0.1);
        if p[0] < lo || p[0] > hi {
            continue;
        }
        if let Shape::Line(_) = s.shape {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            let t = (((p[0] - a.x) * dx + (p[1] - a.y) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            best = best.min((a.x + t * dx - p[0]).hypot(a.y + t * dy - p[1]));
            continue;
        }
        let n = ((s.length / 0.002).ceil() as usize).max(1);
        for k in 0..=n {
            let q = s.position_at(s.length * k as f64 / n as f64);
            best = best.min((q.x - p[0]).hypot(q.y - p[1]));
        }
    }
    best
}

#[test]
fn a_noisy_cam_polyline_becomes_a_few_lines_within_p_plus_q() {
    let (p, q) = (0.01, 0.005);
    let (text, points) = noisy_line(&format!("G64 P{p} Q{q}"), 0.002);
    let segments = plan(&text);
    let moves = motion(&segments);
    // At most 101 moves per merged line, so at least 99 lines; the noise
    // (under Q) breaks none of them early. The planner blends the nearly
    // collinear lines midpoint to midpoint: one segment each.
    assert!(
        moves.len() <= 120,
        "{} segments for 10,000 moves",
        moves.len()
    );
    // Measured on the planned geometry: every programmed point is within
    // P + Q of the path...
    let worst = points
        .iter()
        .step_by(53)
        .map(|&pt| distance_to_path(&moves, pt))
        .fold(0.0, f64::max);
    assert!(worst <= p + q, "programmed point {worst} mm from the path");
    // ... and, on the trajectory the executor runs, no commanded point is
    // farther than P + Q from the programmed moves.
    let machine = mill3();
    let report = offline::run(
        Interpreter::from_text(&text, "t.ngc", start()),
        &*machine.kinematics,
        start(),
        RunConfig {
            planner: PlannerConfig::default(),
            record: 0,
            follow: None,
        },
    )
    .unwrap();
    assert!(
        report.max_deviation <= p + q,
        "deviation {} mm",
        report.max_deviation
    );
    assert!(report.max_limit_ratio() <= 1.0 + 1e-6, "{report:?}");
}

#[test]
fn q0_and_g61_disable_the_merge() {
    for header in ["G64 P0.01 Q0", "G61"] {
        let (text, _) = noisy_line(header, 0.002);
        let segments = plan(&text);
        // Every move keeps at least its blend or its line.
        assert!(
            motion(&segments).len() >= 9_999,
            "{header}: {} segments",
            motion(&segments).len()
        );
    }
}

#[test]
fn points_beyond_q_are_kept_and_points_within_it_are_not() {
    // 1 mm steps along X with one point 0.03 mm off the line (three Q)
    // and one 0.005 mm off (half Q); P is small so blends hardly round.
    let text = "G21 G90 G64 P0.0005 Q0.01\nG1 F1200\n\
                X11 Y100\nX12\nX13\nX14\nX15 Y100.03\nX16 Y100\nX17\nX18\nX19 Y100.005\n\
                X20 Y100\nX21\nX22\nM2\n";
    let segments = plan(text);
    let moves = motion(&segments);
    let kept = distance_to_path(&moves, [15.0, 100.03]);
    // Within about P of the corner the blend rounds (2 µm sampling).
    assert!(
        kept <= 0.002,
        "the point beyond Q is {kept} mm from the path"
    );
    let dropped = distance_to_path(&moves, [19.0, 100.005]);
    assert!(
        dropped > 0.004 && dropped <= 0.005 + 1e-9,
        "the point within Q is {dropped} mm from the path"
    );
    // The merged lines: 10→14 (14 is 0.024 from the line 10→15.03),
    // 14→15.03 (15.03 is 0.03 from the line 14→16), 15.03→16 (16 is 0.015
    // from the line 15.03→17), then 16→22 in one, each named by the source
    // line of its last move.
    let lines: Vec<(f64, u32)> = moves
        .iter()
        .filter(|s| matches!(s.shape, Shape::Line(_)))
        .map(|s| (s.end().x, s.line))
        .collect();
    assert_eq!(lines.len(), 4, "{lines:?}");
    assert_eq!(lines.last().unwrap().1, 14, "line of X22");
}

#[test]
fn m62_and_feed_changes_end_the_chain() {
    // M62 between X15 and X16: the output rides on the move that starts
    // at X15, so the chain must end there.
    let text = "G21 G90 G64 P0.01 Q0.01\nG1 F1200\n\
                X11 Y100\nX12\nX13\nX14\nX15\nM62 P0\nX16\nX17\nX18\nM2\n";
    let segments = plan(text);
    let out: Vec<&Segment> = segments.iter().filter(|s| !s.outputs.is_empty()).collect();
    assert_eq!(out.len(), 1);
    assert!(
        (out[0].start().x - 15.0).abs() < 1e-9,
        "output at X{}",
        out[0].start().x
    );
    assert_eq!(motion(&segments).len(), 2, "{segments:#?}");
    // A new feed rate ends it too; the same one again does not.
    let text = "G21 G90 G64 P0.01 Q0.01\nG1 F1200\n\
                X11 Y100\nX12\nX13 F1200\nX14\nX15\nX16 F600\nX17\nX18\nM2\n";
    let segments = plan(text);
    let moves = motion(&segments);
    let feeds: Vec<(f64, f64, f64)> = moves
        .iter()
        .map(|s| (s.start().x, s.end().x, s.feed))
        .collect();
    assert_eq!(feeds, vec![(10.0, 15.0, 20.0), (15.0, 18.0, 10.0)]);
    // An immediate output (M64) and a dwell end it as well.
    for cut in ["M64 P0", "G4 P0.1"] {
        let text =
            format!("G21 G90 G64 P0.01 Q0.01\nG1 F1200\nX11 Y100\nX12\n{cut}\nX13\nX14\nM2\n");
        let ends: Vec<f64> = motion(&plan(&text)).iter().map(|s| s.end().x).collect();
        assert_eq!(ends, vec![12.0, 14.0], "{cut}");
    }
}
