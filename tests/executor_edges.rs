//! The executor on stretches of real programs where its look ahead once
//! let the motion exceed a limit, planned on mill3 with the budget splits
//! that exposed them.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, RunConfig};
use kerf_motion::{PathMode, PlannerConfig};

/// Largest use of any axis or joint velocity, acceleration or jerk limit
/// when `text` runs on mill3 under `planner`.
fn limit_use(text: &str, planner: PlannerConfig) -> f64 {
    let machine = kerf_machines::load("mill3").unwrap();
    let report = offline::run(
        Interpreter::from_text(text, "stretch.ngc", Position::ZERO),
        &*machine.kinematics,
        Position::ZERO,
        RunConfig { planner, record: 0 },
    )
    .unwrap();
    report.max_limit_ratio()
}

/// stellabee1.ngc lines 941–958 with the default splits. Braking on one of
/// these short lines toward a blend with a lower acceleration limit, the
/// only jerk that keeps every cap reachable lands the acceleration exactly
/// on the blend's limit. A search over 16 evenly spaced jerks misses it,
/// brakes hardest instead and snaps into the blend at 1.27 times a limit;
/// the executor also tries the jerks that land on the limits of the
/// segments ahead. (Found with those jerks switched off. The stretch this
/// test first used, lines 125930–125956 at a 0.6 rate share, stopped
/// reaching that search when the planner's blends changed.)
#[test]
fn braking_onto_a_blends_acceleration_limit_stays_within_limits() {
    let text = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
        G0 X2.7740 Y4.8420 Z-0.1529\nG1\n\
        X2.7780 Z-0.1569\nX2.7860 Z-0.1540\nX2.8020 Z-0.1549\nX2.8120 Z-0.1520\n\
        X2.8140 Z-0.1481\nX2.8180 Z-0.1471\nX2.8220 Z-0.1490\nX2.8260 Z-0.1549\n\
        X2.8320 Z-0.1549\nX2.8480 Z-0.1500\nX2.8520 Z-0.1539\nX2.8600 Z-0.1549\n\
        X2.8620 Z-0.1539\nX2.8700 Z-0.1549\nX2.8740 Z-0.1529\nX2.8820 Z-0.1549\n\
        X2.8860 Z-0.1520\nX2.8980 Z-0.1536\nM2\n";
    let ratio = limit_use(text, PlannerConfig::default());
    assert!(ratio <= 1.0 + 1e-6, "limit use {ratio}");
}

/// stellabee1.ngc lines 78670–78695 with the default splits. Speeding up
/// on a 0.038 mm line toward a blend with a lower jerk limit, the executor
/// kept each state whose shortest stop passed the cap after the blend one
/// period's travel early. That margin was the travel at the current speed,
/// so it grew as the motion sped up: a state passed one period failed the
/// next, whatever the jerk, and the motion snapped into the blend after the
/// line at 1.51 times the Z jerk limit. The margin is now the travel at the
/// faster of the current speed and the cap.
#[test]
fn speeding_up_toward_a_lower_jerk_limit_stays_within_limits() {
    let text = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
        G0 X0.9840 Y2.3300 Z-0.1285\nG1\nG1 X0.9800 Z-0.1232\nX0.9740 Z-0.0997\nX0.9680\n\
        X0.9660 Z-0.1105\nX0.9600 Z-0.2285\nX0.9580 Z-0.2304\nX0.9500 Z-0.2275\n\
        X0.9420 Z-0.2284\nX0.9360 Z-0.2196\nX0.9320 Z-0.2026\nX0.9300 Z-0.2020\n\
        G3 X0.9260 Y2.3300 Z-0.1585 I0.4216 K0.0607\nG1 X0.9240 Z-0.1546\n\
        X0.9220 Z-0.1222\nX0.9180 Z-0.1216\nX0.9160 Z-0.1222\nX0.9140 Z-0.1320\n\
        X0.9060 Z-0.2049\nX0.9040 Z-0.2059\nX0.9000 Z-0.2144\nX0.8980 Z-0.2242\n\
        X0.8940 Z-0.2284\nX0.8820 Z-0.2301\nG3 X0.8780 Y2.3300 Z-0.1810 I0.5919 K0.0730\n\
        G1 X0.8720\nG2 X0.8680 Y2.3300 Z-0.2301 I0.5919 K-0.0730\nM2\n";
    let planner = PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        ..PlannerConfig::default()
    };
    let ratio = limit_use(text, planner);
    assert!(ratio <= 1.0 + 1e-6, "limit use {ratio}");
}
