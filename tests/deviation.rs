//! The path deviation `kerf plan` reports (`offline::run`): each commanded
//! point's distance from the programmed moves its segment runs along,
//! checked against geometry worked out here, on programs whose source
//! lines do not say where the tool is (loops, subroutines called again,
//! moves merged under G64 Q).

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, Report, RunConfig};
use kerf_motion::PlannerConfig;

/// `text` run on mill3 from machine zero, at 1 ms.
fn run(text: &str) -> Report {
    let machine = kerf_machines::load("mill3").unwrap();
    offline::run(
        Interpreter::from_text(text, "t.ngc", Position::ZERO),
        &*machine.kinematics,
        Position::ZERO,
        RunConfig {
            planner: PlannerConfig::default(),
            record: 0,
            follow: None,
        },
    )
    .unwrap()
}

/// Eight holes around a circle of R40, one source line for every rapid
/// between them (a while loop), each hole drilled by a feed down and a
/// rapid up, in path mode `mode`.
fn holes_in_a_loop(mode: &str) -> String {
    format!(
        "G21 G90 {mode}\nG0 Z-1\n#1=0\nO1 while [#1 LT 360]\n\
         G0 X[150+40*COS[#1]] Y[100+40*SIN[#1]] Z-1\nG1 Z-6 F600\nG0 Z-1\n\
         #1=[#1+45]\nO1 endwhile\nG0 Z0\nM2\n"
    )
}

#[test]
fn exact_stops_in_a_loop_follow_every_pass_exactly() {
    // G61 stops at every move's end: the tool runs along the programmed
    // lines themselves, so the distance is rounding alone. Measured
    // against moves found by source line, a later pass of the loop was
    // compared with an earlier one, across the circle.
    let report = run(&holes_in_a_loop("G61"));
    assert_eq!(report.max_deviation_allowed, 0.0, "G61: none allowed");
    assert!(report.over_tolerance < 1e-9, "{}", report.over_tolerance);
    assert!(
        report.max_deviation < 1e-9,
        "deviation {} mm at line {} (t = {} s)",
        report.max_deviation,
        report.max_deviation_at.1,
        report.max_deviation_at.0
    );
}

#[test]
fn blended_passes_of_a_loop_stay_within_p() {
    // The corners between the rapids and the drilling moves are blended
    // within P = 0.05 mm of the programmed lines; the blends do leave
    // them (by about P·sin 45° at these square corners).
    let report = run(&holes_in_a_loop("G64 P0.05"));
    // Q defaults to P: the rapids are not merged (only feeds are), but
    // the program allows P + Q.
    assert_eq!(report.max_deviation_allowed, 0.1);
    assert!(report.over_tolerance < 1e-9, "{}", report.over_tolerance);
    assert!(
        report.max_deviation <= 0.05 + 1e-9,
        "deviation {} mm at line {}",
        report.max_deviation,
        report.max_deviation_at.1
    );
    assert!(report.max_deviation > 0.01, "{}", report.max_deviation);
}

#[test]
fn a_wiggle_merged_away_on_a_second_call_is_measured_against_that_call() {
    // One subroutine, called first under G61 and then under G64 with a Q
    // that merges its 0.2 mm wiggle away: from (100, 100) through
    // (110, 100.2) to (120, 100). The merged line passes (110, 100), whose
    // distance from the programmed wiggle is 0.2/√(1 + 0.02²). Measured
    // by source line, the second call was compared with the first call's
    // moves, which it retraces where it does not merge, and read zero.
    // Samples 1 ms apart at F1200 fall up to 0.01 mm either side of
    // X110, where the distance falls off by 0.02 mm per mm.
    let text = "G21 G90\nO100 sub\nG0 X100 Y100 Z-1\nG1 X110 Y100.2 F1200\n\
                X120 Y100\nY130\nG0 Z0\nO100 endsub\n\
                G61\nO100 call\nG64 P0.01 Q0.3\nO100 call\nM2\n";
    let report = run(text);
    // Allowed there: P + Q of the second call, not the first call's G61.
    assert!((report.max_deviation_allowed - 0.31).abs() < 1e-12);
    assert!(report.over_tolerance < 1e-9, "{}", report.over_tolerance);
    let expected = 0.2 / (1.0f64 + 0.02 * 0.02).sqrt();
    assert!(
        report.max_deviation <= expected + 1e-9 && report.max_deviation > expected - 3e-4,
        "deviation {} mm at line {}, expected {expected}",
        report.max_deviation,
        report.max_deviation_at.1
    );
}
