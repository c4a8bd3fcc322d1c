//! The executor on stretches of real programs where its look ahead once
//! let the motion exceed a limit, planned on mill3 with the budget splits
//! that exposed them.

use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::{self, RunConfig};
use kerf_motion::path::Shape;
use kerf_motion::{Executor, PathMode, PlannerConfig, Segment};

/// Largest use of any axis or joint velocity, acceleration or jerk limit
/// when `text` runs on mill3 under `planner`.
fn limit_use(text: &str, planner: PlannerConfig) -> f64 {
    let machine = kerf_machines::load("mill3").unwrap();
    let report = offline::run(
        Interpreter::from_text(text, "stretch.ngc", Position::ZERO),
        &*machine.kinematics,
        Position::ZERO,
        RunConfig {
            planner,
            record: 0,
            follow: None,
        },
    )
    .unwrap();
    report.max_limit_ratio()
}

/// How the executor spent its time on each segment of a run.
#[derive(Clone, Copy, Debug, Default)]
struct OnSegment {
    /// Servo periods with the segment at the front of the queue.
    periods: usize,
    /// Speed entering it and leaving it, mm/s.
    entry: f64,
    exit: f64,
}

/// `text` planned on mill3 under the default planner and run through the
/// executor on a virtual clock: the segments, and the run on each.
fn run_by_segment(text: &str) -> (Vec<Segment>, Vec<OnSegment>) {
    let machine = kerf_machines::load("mill3").unwrap();
    let planner = PlannerConfig::default();
    let program = Interpreter::from_text(text, "stretch.ngc", Position::ZERO);
    let segments =
        offline::plan_program(program, &*machine.kinematics, Position::ZERO, planner, 1).unwrap();
    let mut executor = Executor::new(Position::ZERO);
    let mut runs = vec![OnSegment::default(); segments.len()];
    let (mut front, mut speed) = (0, 0.0);
    loop {
        let sample = executor.tick(planner.period, &segments[front..], &[]);
        let run = &mut runs[front.min(segments.len() - 1)];
        if run.periods == 0 {
            run.entry = speed;
        }
        run.periods += 1;
        if sample.consumed > 0 {
            run.exit = sample.velocity;
        }
        speed = sample.velocity;
        front += sample.consumed;
        if sample.stopped_at == Some(1) {
            break;
        }
    }
    (segments, runs)
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
    let planner = PlannerConfig::default();
    let (segments, runs) = run_by_segment(text);
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
    let took = runs[k].periods as f64 * planner.period;
    let least = 4.0 * (line.length / (2.0 * line.max_jerk)).cbrt();
    assert!(
        took <= least + 2.0 * planner.period,
        "{took} s on the {} mm line, {least} s from rest to rest",
        line.length
    );
    assert!(limit_use(text, planner) <= 1.0 + 1e-6);
}

/// Shortest time to cover `length` mm from speed `v0` to speed `v1`, both
/// with zero acceleration, under a speed cap `vmax`, |a| ≤ `amax` and
/// |jerk| ≤ `jmax`: up to a peak speed and back down, each side a
/// textbook S-curve, the peak found by bisection.
fn s_curve_time(length: f64, v0: f64, v1: f64, vmax: f64, amax: f64, jmax: f64) -> f64 {
    // Time and distance of one speed change between va and vb.
    let change = |va: f64, vb: f64| {
        let dv = (vb - va).abs();
        let t = if dv >= amax * amax / jmax {
            dv / amax + amax / jmax
        } else {
            2.0 * (dv / jmax).sqrt()
        };
        (t, (va + vb) / 2.0 * t)
    };
    let fits = |peak: f64| change(v0, peak).1 + change(peak, v1).1 <= length;
    let (mut lo, mut hi) = (v0.max(v1), vmax);
    assert!(fits(lo), "cannot go from {v0} to {v1} in {length} mm");
    if !fits(hi) {
        for _ in 0..100 {
            let mid = (lo + hi) / 2.0;
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi = lo;
    }
    let ((t0, d0), (t1, d1)) = (change(v0, hi), change(hi, v1));
    t0 + t1 + (length - d0 - d1) / hi
}

/// stellabee1.ngc lines 22528–22556. Program line 26 here (22547 there)
/// is a 1.13 mm arc between two slow blends; the one after it allows
/// 25 mm/s² and, two segments on, another 107 mm/s². Braking toward the
/// second blend's cap (1.46 mm/s) at the arc's 500 mm/s², the look ahead
/// checked that the deceleration could be eased at once into each later
/// segment's limit a period's travel early, at the speed before braking;
/// the approach, which brakes harder first and eases to zero right at the
/// blend, failed that check, and the search braked at 500 mm/s² until the
/// arc's end, where the motion came to rest and crept into the blend at
/// its 25 mm/s²: 125 ms on the arc. Segments past a cap the motion is
/// known to reach with zero acceleration are no longer checked so, and
/// the period's travel is at the speed the easing ends at: 112 ms, within
/// two periods of one S-curve from the arc's entry speed to that cap.
#[test]
fn an_approach_into_a_slow_blend_is_not_cut_off_by_the_segments_after_it() {
    let text = "G21 G10 L2 P1 X100 Y50 Z-20\nG54\nG20 G90 G64 G18 G94\nF999\n\
        G0 X1.2900 Y4.0580 Z-0.0650\nG1\n\
        X1.2880\nX1.2860 Z-0.0644\nX1.2820 Z-0.0608\nX1.2780 Z-0.0236\n\
        X1.2740 Z-0.0225\nX1.2700 Z-0.0271\nX1.2640\nX1.2600 Z-0.0526\n\
        X1.2580 Z-0.0487\nX1.2560 Z-0.0481\nX1.2520 Z-0.0245\nX1.2500 Z-0.0235\n\
        X1.2460 Z-0.0245\nX1.2440 Z-0.0324\n\
        G3 X1.2380 Y4.0580 Z-0.0105 I0.0493 K0.0253\nG1 X1.2340 Z-0.0098\n\
        X1.2300 Z-0.0124\nX1.2240 Z-0.0108\nX1.2220 Z-0.0118\n\
        G3 X1.2140 Y4.0580 Z-0.0585 I-0.1840 K0.0075\nG1 X1.2120 Z-0.0569\n\
        X1.2100 Z-0.0487\nX1.2080 Z-0.0252\nX1.2040 Z-0.0245\nX1.2020 Z-0.0114\n\
        X1.1940 Z-0.0098\nX1.1900 Z-0.0137\nX1.1880 Z-0.0075\nX1.1840 Z-0.0069\nM2\n";
    let planner = PlannerConfig::default();
    let (segments, runs) = run_by_segment(text);
    let arc = (0..segments.len())
        .find(|&k| segments[k].line == 26 && matches!(segments[k].shape, Shape::Arc(_)))
        .expect("the arc");
    let (seg, after) = (&segments[arc], &segments[arc + 1]);
    assert!(
        matches!(after.shape, Shape::Blend(_)) && after.max_acceleration < 30.0,
        "a slow blend after the arc: {after:?}"
    );
    let cap = seg.exit_velocity.min(after.max_velocity);
    let OnSegment {
        periods,
        entry,
        exit,
    } = runs[arc];
    assert!(periods > 0, "the arc was run");
    assert!(
        exit >= 0.9 * cap,
        "leaves the arc at {exit} mm/s, its exit cap {cap} mm/s"
    );
    let took = periods as f64 * planner.period;
    let least = s_curve_time(
        seg.length,
        entry,
        cap,
        seg.max_velocity,
        seg.max_acceleration,
        seg.max_jerk,
    );
    assert!(
        took <= least + 3.0 * planner.period,
        "{took} s on the {} mm arc, {least} s as one S-curve from {entry} to {cap} mm/s",
        seg.length
    );
    assert!(limit_use(text, planner) <= 1.0 + 1e-6);
}
