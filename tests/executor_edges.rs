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

/// stellabee1.ngc lines 125930–125956 (shifted into mill3's travel). With
/// 60 % of the jerk budget on the curvature rate the blends get low
/// acceleration limits; braking on the 0.026 mm line before one of them,
/// the only jerk that kept every cap reachable landed the acceleration
/// exactly on the blend's limit. The jerk search tried 16 evenly spaced
/// jerks, missed it, braked hardest instead and snapped into the blend at
/// 1.31 times the X jerk limit. It now also tries the jerks that land on
/// the limits of the segments ahead.
#[test]
fn braking_onto_a_blends_acceleration_limit_stays_within_limits() {
    let text = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
        G0 X0.3340 Z-0.1392\nG1\nX0.3360 Z-0.1350\n\
        G2 X0.3440 Y1.0980 Z-0.1294 I-0.0004 K0.0092\n\
        G1 X0.3500 Z-0.1275\nX0.3580 Z-0.1314\nX0.3620 Z-0.1284\nX0.3660\n\
        X0.3720 Z-0.1330\nX0.3760 Z-0.1324\nX0.3800 Z-0.1294\nX0.3860 Z-0.1324\n\
        X0.3960 Z-0.1314\nX0.4060 Z-0.1369\nX0.4080 Z-0.1402\nX0.4120 Z-0.1422\n\
        X0.4160 Z-0.1412\nX0.4200 Z-0.1451\nX0.4240 Z-0.1458\nX0.4380 Z-0.1431\n\
        X0.4460 Z-0.1461\nX0.4520 Z-0.1431\nX0.4560 Z-0.1340\nX0.4620 Z-0.1304\n\
        X0.4880 Z-0.1389\nX0.4900 Z-0.1408\nX0.5000 Z-0.1392\nX0.5120 Z-0.1451\n\
        X0.5180 Z-0.1431\nM2\n";
    let planner = PlannerConfig {
        mode: PathMode::Blend { tolerance: 0.01 },
        jerk_rate_share: 0.6,
        ..PlannerConfig::default()
    };
    let ratio = limit_use(text, planner);
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
