//! Hairpins on dense curves: where stopping at one is quicker than its
//! blend, the planner stops there, as it does at any corner between lines.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, RunConfig};
use kerf_motion::path::Shape;
use kerf_motion::{PlannerConfig, Segment};

/// stellabee1.ngc lines 22960–22985 (a Z profile of 0.05–0.6 mm moves
/// with sharp reversals), as an inch program under `G64 P0.01 Q0`: a
/// tolerance of 0.254 mm lets blends take whole halves of the moves, so
/// every corner is on a dense curve. The moves start at text line 7.
const STRETCH: &str = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 P0.01 Q0 G18 G94\nF999\n\
    G0 X1.5960 Y4.0420 Z-0.0752\nG1\n\
    X1.5980 Z-0.0614\nX1.6040 Z-0.0556\nX1.6060 Z-0.0310\nX1.6120\nX1.6160 Z-0.0477\n\
    X1.6180 Z-0.0291\nX1.6260 Z-0.0265\nX1.6300 Z-0.0271\nX1.6320 Z-0.0128\nX1.6340 Z-0.0118\n\
    X1.6440 Z-0.0144\nX1.6520 Z-0.0369\nX1.6560 Z-0.0379\nX1.6580 Z-0.0408\nX1.6640\n\
    X1.6660 Z-0.0516\nX1.6700 Z-0.0507\nX1.6720 Z-0.0477\nX1.6760 Z-0.0471\nX1.6780 Z-0.0340\n\
    X1.6840\nX1.6880 Z-0.0575\nX1.6900 Z-0.0275\nX1.6920 Z-0.0196\nX1.6940 Z-0.0186\n\
    X1.6980 Z-0.0196\nM2\n";

/// Length in mm of each programmed move, by text line (X and Z words of
/// the inch program, modal; the G0 line sets the start).
fn move_lengths(text: &str) -> Vec<(u32, f64)> {
    let (mut x, mut z) = (None::<f64>, None::<f64>);
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let word = |c: char| {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(c).and_then(|v| v.parse::<f64>().ok()))
        };
        let (nx, nz) = (word('X').or(x), word('Z').or(z));
        if let (Some(x0), Some(z0), Some(x1), Some(z1), false) =
            (x, z, nx, nz, line.starts_with("G0"))
        {
            out.push(((n + 1) as u32, 25.4 * (x1 - x0).hypot(z1 - z0)));
        }
        (x, z) = (nx, nz);
    }
    out
}

fn run(planner: PlannerConfig) -> offline::Report {
    let machine = kerf_machines::load("mill3").unwrap();
    offline::run(
        Interpreter::from_text(STRETCH, "stretch.ngc", Position::ZERO),
        &*machine.kinematics,
        Position::ZERO,
        RunConfig {
            planner,
            record: 0,
            follow: None,
        },
    )
    .unwrap()
}

/// Of the hairpins a blend took the whole first half of the incoming move
/// up to, the planner stops at some (the blend into that move then ends on
/// it, straight: `hairpin` in `plan.rs`), and the stretch runs quicker than
/// blending every corner, within the tolerance and the limits.
#[test]
fn dense_corners_stop_where_that_is_quicker() {
    let machine = kerf_machines::load("mill3").unwrap();
    let planner = PlannerConfig::default();
    let program = Interpreter::from_text(STRETCH, "stretch.ngc", Position::ZERO);
    let segments: Vec<Segment> =
        offline::plan_program(program, &*machine.kinematics, Position::ZERO, planner, 1).unwrap();
    let lengths = move_lengths(STRETCH);
    let programmed = |line: u32| lengths.iter().find(|l| l.0 == line).map(|l| l.1);
    // A stop on the second half of a move whose first half a blend took.
    let dense_stops = segments
        .windows(2)
        .filter(|w| {
            let (blend, line) = (&w[0], &w[1]);
            let (Shape::Blend(_), Shape::Line(_)) = (&blend.shape, &line.shape) else {
                return false;
            };
            let end = blend.shape.frame(blend.length);
            let start = line.shape.frame(0.0);
            let straight = (0..3).all(|i| {
                end.curvature[i].abs() < 1e-9 && (end.tangent[i] - start.tangent[i]).abs() < 1e-9
            });
            line.exit_velocity == 0.0
                && blend.line == line.line
                && straight
                && programmed(line.line).is_some_and(|l| (line.length - l / 2.0).abs() < 1e-6)
        })
        .count();
    assert!(dense_stops >= 2, "{dense_stops} stops at dense corners");
    let stopping = run(planner);
    let blending = run(PlannerConfig {
        stop_when_quicker: false,
        ..planner
    });
    for r in [&stopping, &blending] {
        assert!(r.max_deviation <= 0.254 && r.max_limit_ratio() <= 1.0 + 1e-6);
    }
    assert!(
        stopping.cycle_time < blending.cycle_time,
        "stopping {} s, blending {} s",
        stopping.cycle_time,
        blending.cycle_time
    );
}
