//! The executor on stretches of real programs where its look ahead once
//! let the motion exceed a limit, planned on mill3 with the budget splits
//! that exposed them.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, RunConfig};
use kerf_motion::path::Shape;
use kerf_motion::{Executor, PathMode, PlannerConfig};

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

/// stellabee1.ngc lines 22750–22780. Program line 29 here (22774 there)
/// is a 0.166 mm line into a stop after a blend passed at 4.2 mm/s with
/// an acceleration limit of 55 mm/s². The stop comes into reach on the
/// blend, and its profile is aimed there, under the blend's limits; the
/// executor kept that profile, and with it 54.5 mm/s² of braking, all
/// along the line, whose own limit is 1669 mm/s²: 79 ms where the line
/// from rest to rest takes 40. It now drops a kept stop once the limits
/// up to the stop have risen well above the profile's (34 ms).
#[test]
fn a_stop_aimed_on_a_slow_blend_brakes_under_the_lines_own_limits() {
    let text = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
        G0 X0.3960 Y4.0420 Z-0.2392\nG1\n\
        X0.4000 Z-0.2363\nX0.4280 Z-0.2392\nX0.4340 Z-0.2373\nX0.4540 Z-0.2383\n\
        X0.4640 Z-0.2363\nX0.4780 Z-0.2382\nX0.4840 Z-0.2363\nX0.4920\n\
        X0.4980 Z-0.2382\nX0.5280 Z-0.2373\nX0.5360 Z-0.2389\nX0.5440 Z-0.2363\n\
        X0.5500 Z-0.2379\nX0.5580 Z-0.2363\nX0.5620 Z-0.2379\nX0.5640 Z-0.2353\n\
        X0.5680 Z-0.2343\nX0.5720 Z-0.2383\nX0.5840 Z-0.2382\nX0.5900 Z-0.2363\n\
        X0.5940 Z-0.2373\nX0.5980 Z-0.2353\nX0.6060 Z-0.2392\nX0.6100 Z-0.2363\n\
        X0.6160 Z-0.2373\nX0.6200 Z-0.2353\nX0.6320 Z-0.2379\nX0.6380 Z-0.2363\n\
        X0.6420 Z-0.2382\nX0.6640 Z-0.2383\nX0.6680 Z-0.2353\nM2\n";
    let machine = kerf_machines::load("mill3").unwrap();
    let planner = PlannerConfig::default();
    let program = Interpreter::from_text(text, "stretch.ngc", Position::ZERO);
    let segments =
        offline::plan_program(program, &*machine.kinematics, Position::ZERO, planner, 1).unwrap();
    // Periods spent on each segment (the one at the front of the queue).
    let mut executor = Executor::new(Position::ZERO);
    let mut periods = vec![0usize; segments.len()];
    let mut front = 0;
    loop {
        let sample = executor.tick(planner.period, &segments[front..], &[]);
        periods[front.min(segments.len() - 1)] += 1;
        front += sample.consumed;
        if sample.stopped_at == Some(1) {
            break;
        }
    }
    let k = (1..segments.len())
        .find(|&k| {
            let s = &segments[k];
            s.line == 29 && s.exit_velocity == 0.0 && matches!(s.shape, Shape::Line(_))
        })
        .expect("the line into the stop");
    let (line, before) = (&segments[k], &segments[k - 1]);
    assert!(
        matches!(before.shape, Shape::Blend(_)) && before.max_velocity < 5.0,
        "a slow blend before it: {before:?}"
    );
    let took = periods[k] as f64 * planner.period;
    let least = 4.0 * (line.length / (2.0 * line.max_jerk)).cbrt();
    assert!(
        took <= least + 2.0 * planner.period,
        "{took} s on the {} mm line, {least} s from rest to rest",
        line.length
    );
    assert!(limit_use(text, planner) <= 1.0 + 1e-6);
}
