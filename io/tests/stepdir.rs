//! The step/dir backend against the simulated MCU (a separate process on a
//! pseudo-terminal), on a virtual clock: step edges against the
//! trajectory's crossing instants, lead, clock sync, compression, and link
//! faults.

mod support;

use kerf_io::stepdir::TracePoint;
use kerf_io::{build, Hal, HalConfig, HalConfigError, HalFault};
use support::{config, joint, Driver, Mcu};

/// Simulated MCU clock, Hz (the sim's default).
const CLOCK_HZ: f64 = 10_000_000.0;
/// The timing bound of the issue: ±5 µs.
const BOUND_TICKS: f64 = 5e-6 * CLOCK_HZ;

/// Joint positions (mm) at time `t` (s) of the test move: a cosine swing,
/// a sine with two reversals, and a trapezoidal move, with rests before
/// and after.
fn trajectory(t: f64) -> [f64; 3] {
    let m = (t - 0.02).clamp(0.0, 1.2);
    let tau = std::f64::consts::TAU;
    let swing = 20.0 * (1.0 - (tau * m / 1.2).cos());
    let sine = -15.0 * (tau * m / 0.8).sin() + 5.0;
    // Trapezoid: 0.1 s at 500 mm/s² to 50 mm/s, cruise, 0.1 s down.
    let (a, v, ta, tc) = (500.0, 50.0, 0.1, 0.9);
    let trap = if m < ta {
        0.5 * a * m * m
    } else if m < ta + tc {
        0.5 * a * ta * ta + v * (m - ta)
    } else {
        let d = (m - ta - tc).min(ta);
        0.5 * a * ta * ta + v * tc + v * d - 0.5 * a * d * d
    };
    [swing, sine, -2.0 + trap]
}

/// The exact instants (ticks) and directions at which the piecewise-linear
/// trajectory through `trace` crosses half-steps of `steps_per_mm`.
fn expected_crossings(trace: &[TracePoint], ch: usize, steps_per_mm: f64) -> Vec<(f64, bool)> {
    let mut out = Vec::new();
    for w in trace.windows(2) {
        let (ta, tb) = (w[0].time, w[1].time);
        let (ua, ub) = (
            w[0].positions[ch] * steps_per_mm,
            w[1].positions[ch] * steps_per_mm,
        );
        // The counter is floor(u + ½); it changes at u = c + ½.
        let (ca, cb) = ((ua + 0.5).floor() as i64, (ub + 0.5).floor() as i64);
        let at = |h: f64| ta + (h - ua) / (ub - ua) * (tb - ta);
        for c in ca..cb {
            out.push((at(c as f64 + 0.5), true));
        }
        for c in (cb..ca).rev() {
            out.push((at(c as f64 + 0.5), false));
        }
    }
    out
}

#[test]
fn step_edges_follow_the_trajectory_within_5_us() {
    let mcu = Mcu::start(
        "timing",
        &[
            "--channels",
            "3",
            "--drift-ppm",
            "120",
            "--offset",
            "123456789",
        ],
    );
    let joints = vec![
        joint(0, 800.0, false),
        joint(1, 320.0, true),
        joint(2, 1000.5, false),
    ];
    let spm = [800.0, 320.0, 1000.5];
    let invert = [false, true, false];
    let cfg = config(&mcu.port, joints);
    let start = trajectory(0.0);
    let mut d = Driver::open(&cfg, &start);
    let mut commanded = Vec::new();
    let ticks = 1400;
    for k in 1..=ticks {
        let p = trajectory(k as f64 * d.period);
        d.tick(&p, true).expect("no fault");
        commanded.push(p);
    }
    let stats = d.hal.stats();
    let end = trajectory(ticks as f64 * d.period);
    // The MCU's own counters, from its last clock reply, show it took
    // every step: net steps from the start to the end position.
    for j in 0..3 {
        let net = ((end[j] * spm[j] + 0.5).floor() - (start[j] * spm[j] + 0.5).floor()) as i64;
        assert_eq!(d.hal.executed_steps(j), net, "joint {j}");
    }
    let Driver { hal, trace, .. } = d;
    drop(hal);
    let trace: Vec<TracePoint> = trace.try_iter().collect();
    let record = mcu.finish();

    // The trace is the commanded trajectory, one point per tick.
    assert_eq!(trace.len(), ticks);
    for (tp, p) in trace.iter().zip(&commanded) {
        for (traced, commanded) in tp.positions.iter().zip(p) {
            assert!((traced - commanded).abs() < 1e-9);
        }
    }
    // Clock sync: the first setpoint lies the lead (60 ms) plus the
    // compression hold (4 ms) after the MCU clock, which starts at the
    // offset; later periods are the servo period on the MCU's clock,
    // which runs 120 ppm fast.
    let lead0 = (trace[0].time - 123_456_789.0) / CLOCK_HZ;
    assert!(
        (0.064..0.066).contains(&lead0),
        "first setpoint {lead0} s ahead"
    );
    for w in trace[700..1200].windows(2) {
        let ppm = ((w[1].time - w[0].time) / (0.001 * CLOCK_HZ) - 1.0) * 1e6;
        assert!((ppm - 120.0).abs() < 5.0, "period off by {ppm} ppm");
    }

    let mut worst: f64 = 0.0;
    for ch in 0..3 {
        let expected = expected_crossings(&trace, ch, spm[ch]);
        let edges: Vec<(u64, bool)> = record
            .edges
            .iter()
            .filter(|e| e.0 as usize == ch)
            .map(|e| (e.1, e.2))
            .collect();
        assert_eq!(edges.len(), expected.len(), "channel {ch} step count");
        assert!(
            expected.len() > 1000,
            "channel {ch}: only {} steps",
            expected.len()
        );
        for (i, ((t, pin), (x, fwd))) in edges.iter().zip(&expected).enumerate() {
            let err = *t as f64 - x;
            worst = worst.max(err.abs());
            assert!(
                err.abs() <= BOUND_TICKS,
                "channel {ch} step {i}: edge at {t}, crossing at {x:.2} ({:.2} µs off)",
                err / CLOCK_HZ * 1e6
            );
            assert_eq!(
                *pin,
                fwd ^ invert[ch],
                "channel {ch} step {i}: direction pin"
            );
        }
    }
    // The configured bound is 2 µs (max_error_us).
    assert!(worst / CLOCK_HZ * 1e6 <= 2.0, "worst {worst} ticks");

    // Every step command reached the MCU at least 50 ms before its first step.
    let least = *record.slacks.iter().min().unwrap();
    assert!(
        least as f64 >= 0.050 * CLOCK_HZ,
        "least slack {least} ticks"
    );
    // No underrun or other MCU fault: Ok at hello, Stopped at shutdown.
    assert_eq!(record.statuses, vec![0, 4]);
    let ratio = stats.steps as f64 / stats.commands as f64;
    println!(
        "stepdir timing: {} steps in {} commands (ratio {ratio:.1}), worst edge error {:.3} µs, least slack {:.1} ms, least host lead {:.1} ms",
        stats.steps,
        stats.commands,
        worst / CLOCK_HZ * 1e6,
        least as f64 / CLOCK_HZ * 1e3,
        stats.min_lead_ticks.unwrap() as f64 / CLOCK_HZ * 1e3
    );
    assert_eq!(stats.steps as usize, record.edges.len());
    assert!(ratio > 10.0, "compression ratio {ratio}");
}

/// Drive a moving joint until the backend faults; returns the fault and
/// the tick it came at. With `settle`, each tick waits until every frame
/// is answered (or a fault), so the virtual clock never runs ahead of a
/// slow MCU process; without it only until the link thread took the tick.
fn run_until_fault(d: &mut Driver, max_ticks: u64, settle: bool) -> (HalFault, u64) {
    for k in 1..=max_ticks {
        let p = [k as f64 * 0.05];
        if let Err(f) = d.tick(&p, settle) {
            return (f, k);
        }
    }
    panic!("no fault in {max_ticks} ticks");
}

#[test]
fn an_unanswered_frame_is_a_fault_within_the_deadline_and_stops_the_mcu() {
    // Hello, config and the first clock sample are answered (3 frames);
    // then the MCU falls silent.
    let mcu = Mcu::start("mute", &["--channels", "1", "--mute-after", "3"]);
    let mut d = Driver::open(&config(&mcu.port, vec![joint(0, 400.0, false)]), &[0.0]);
    // Nothing is ever answered, so settling is impossible: the deadline
    // runs on the virtual clock alone.
    let (fault, tick) = run_until_fault(&mut d, 500, false);
    assert_eq!(
        fault,
        HalFault::Link {
            reason: "no acknowledgement from the MCU within ack_timeout_ms"
        }
    );
    // The deadline is 50 ms and the first unanswered frame goes out at
    // tick 0 or 1; the link thread may read the clock one tick late, and
    // the tick sees the latched fault at its next exchange.
    assert!((50..=55).contains(&tick), "fault at tick {tick}");
    // Latched: nothing is sent after the fault, whatever is commanded.
    let sent = d.hal.stats().commands;
    for k in 0..20 {
        assert_eq!(d.tick(&[100.0 + k as f64], false), Err(fault));
    }
    assert_eq!(d.hal.stats().commands, sent);
    drop(d);
    let record = mcu.finish();
    // The MCU got the stop command after the fault and nothing after it.
    assert_eq!(record.statuses.last(), Some(&4));
    assert_eq!(record.order.last(), Some(&'t'));
}

#[test]
fn a_corrupted_answer_is_a_crc_fault() {
    let mcu = Mcu::start("crc", &["--channels", "1", "--corrupt-reply", "10"]);
    let mut d = Driver::open(&config(&mcu.port, vec![joint(0, 400.0, false)]), &[0.0]);
    let (fault, _) = run_until_fault(&mut d, 500, true);
    assert_eq!(
        fault,
        HalFault::Link {
            reason: "CRC error on a frame from the MCU"
        }
    );
}

#[test]
fn after_a_fault_only_the_operator_reset_moves_again() {
    let mcu = Mcu::start(
        "reset",
        &["--channels", "1", "--corrupt-reply", "10", "--persist"],
    );
    let mut d = Driver::open(&config(&mcu.port, vec![joint(0, 400.0, false)]), &[0.0]);
    let (fault, k) = run_until_fault(&mut d, 500, true);
    let sent = d.hal.stats().steps;
    for _ in 0..10 {
        assert_eq!(d.tick(&[k as f64 * 0.05], true), Err(fault));
    }
    assert_eq!(d.hal.stats().steps, sent, "steps sent while faulted");
    // The reset reconnects (a new hello) and motion resumes from where the
    // joint was held.
    d.hal.clear_fault().expect("the MCU answers again");
    assert_eq!(d.hal.fault(), None);
    d.ticks = 0;
    for j in 1..=200 {
        d.tick(&[(k + j) as f64 * 0.05], true)
            .expect("running again");
    }
    let stats = d.hal.stats();
    assert!(stats.steps >= 3900, "{stats:?}");
}

#[test]
fn a_vanished_mcu_is_a_fault() {
    let mcu = Mcu::start("gone", &["--channels", "1", "--exit-after", "8"]);
    let mut d = Driver::open(&config(&mcu.port, vec![joint(0, 400.0, false)]), &[0.0]);
    let (fault, _) = run_until_fault(&mut d, 500, true);
    let HalFault::Link { reason } = fault else {
        panic!("{fault:?}")
    };
    assert!(reason.contains("port"), "{reason}");
    // The operator's reset cannot bring back an MCU that is gone.
    assert!(d.hal.clear_fault().is_err());
}

#[test]
fn configuration_errors_name_the_key() {
    let parse = |text: &str| -> HalConfig { toml::from_str(text).unwrap() };
    let base = "backend = \"sim\"\n[stepdir]\nport = \"/nonexistent/tty\"\n";
    let e = build(
        &parse(&format!(
            "{base}lead_ms = 20.0\n[[stepdir.joints]]\njoint = 0\nsteps_per_mm = 80.0\n"
        )),
        &[0.0],
    )
    .err()
    .expect("an error");
    assert!(e.to_string().contains("hal.stepdir.lead_ms"), "{e}");
    let e = build(
        &parse(&format!(
            "{base}[[stepdir.joints]]\njoint = 0\nsteps_per_mm = 0.0\n"
        )),
        &[0.0],
    )
    .err()
    .expect("an error");
    assert!(
        e.to_string().contains("hal.stepdir.joints[0].steps_per_mm"),
        "{e}"
    );
    let e = build(
        &parse(&format!(
            "{base}[[stepdir.joints]]\njoint = 5\nsteps_per_mm = 80.0\n"
        )),
        &[0.0, 0.0],
    )
    .err()
    .expect("an error");
    assert!(e.to_string().contains("joint 5 does not exist"), "{e}");
    let e = build(
        &parse(&format!(
            "{base}[[stepdir.joints]]\njoint = 0\nsteps_per_mm = 80.0\n"
        )),
        &[0.0],
    )
    .err()
    .expect("an error");
    assert!(
        matches!(&e, HalConfigError::Device { reason, .. } if reason.contains("/nonexistent/tty")),
        "{e}"
    );
    let e = toml::from_str::<HalConfig>(&format!("{base}baud_rate = 9600\n")).unwrap_err();
    assert!(e.to_string().contains("baud_rate"), "{e}");
}
