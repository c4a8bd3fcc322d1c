//! Servo benchmark: the control targets, measured by simulation on
//! a virtual clock, and the tick's compute time and the servo thread's
//! wake-up latency on this machine, measured on the wall clock.
//!
//! Run: `cargo bench --bench servo`.
//!
//! Every figure comes from `kerf::simulate` (the same engine as `kerf sim`)
//! running the real servo tick against the simulated plant; the expected
//! values printed next to them are computed here from the seed's models,
//! not taken from the code under test. Compute time and latency depend on
//! the machine and its load: they are printed, never asserted.

use std::f64::consts::PI;
use std::time::Duration;

use kerf::seqlock::seqlock;
use kerf::servo::{Pacing, RealTime, ServoThread, ServoTick};
use kerf::simulate::{simulate, SimOptions, SimReport};
use kerf_interp::{Interpreter, Position};
use kerf_io::sim::cutting::CuttingConfig;
use kerf_io::sim::plant::DriveModel;
use kerf_machines::Machine;
use kerf_motion::control::LoopGains;

const ALUMINIUM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");

fn run(text: &str, machine: &Machine, options: SimOptions) -> SimReport {
    let program = Interpreter::from_text(text, "bench.ngc", machine.home());
    simulate(program, machine, &options).unwrap_or_else(|e| panic!("{e:#}"))
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "MISSED"
    }
}

/// A 50 mm radius circle in XY at 1000 mm/min in 0.05 mm chords, entered
/// with an exact stop (a dwell) so that no corner blend is measured.
fn circle(cx: f64, cy: f64, z: f64) -> String {
    let r = 50.0;
    let n = (2.0 * PI * r / 0.05).round() as usize;
    let mut t = format!(
        "G21 G90\nG0 X{:.4} Y{cy:.4} Z{z:.4}\nG1 F1000\nG4 P0.1\n",
        cx + r
    );
    for k in 1..=n {
        let a = 2.0 * PI * k as f64 / n as f64;
        t += &format!("X{:.6} Y{:.6}\n", cx + r * a.cos(), cy + r * a.sin());
    }
    t + "M2\n"
}

fn following_error() {
    println!("== following error, straight move at 1000 mm/min (mill3, identified plant)");
    let mill = kerf_machines::load("mill3").unwrap();
    let text = "G21 G90\nG1 X150 F1000\nM2\n";
    // Type-1 loop: steady error v / (K·kp), K from seed eq. (2).
    let v_over_kv = 1000.0 / 60.0 / (DriveModel::SEED.gain * LoopGains::SEED.kp);
    let pd = run(
        text,
        &mill,
        SimOptions {
            feedforward: false,
            ..Default::default()
        },
    );
    println!(
        "  seed PD, no feedforward: max {:.4} mm, v/Kv = {:.4} mm  (reproduce ≈ 0.46 mm: {})",
        pd.max_following_error,
        v_over_kv,
        verdict((pd.max_following_error - v_over_kv).abs() < 0.01 * v_over_kv)
    );
    let ff = run(text, &mill, SimOptions::default());
    println!(
        "  with feedforward:        max {:.5} mm = {:.3} µm  (target ≤ 5 µm: {})",
        ff.max_following_error,
        ff.max_following_error * 1000.0,
        verdict(ff.max_following_error <= 0.005)
    );
}

fn contour_error() {
    println!("== contour error, R50 circle at 1000 mm/min (oxglide-x, identified plant)");
    let ox = kerf_machines::load("oxglide-x").unwrap();
    let text = circle(250.0, 150.0, -300.0);
    let ff = run(&text, &ox, SimOptions::default());
    let pd = run(
        &text,
        &ox,
        SimOptions {
            feedforward: false,
            ..Default::default()
        },
    );
    println!(
        "  with feedforward: {:.5} mm = {:.3} µm  (target ≤ 10 µm: {}); following error max {:.5} mm",
        ff.max_contour_error,
        ff.max_contour_error * 1000.0,
        verdict(ff.max_contour_error <= 0.010),
        ff.max_following_error
    );
    println!(
        "  seed PD only:     {:.5} mm; following error max {:.4} mm (joint s3)",
        pd.max_contour_error, pd.max_following_error
    );
}

fn force_control() {
    println!(
        "== cutting-force control, aluminium, 10 mm 2-flute, 1000 rpm, depth 2 → 4 mm, F_d = 250 N"
    );
    let machine = kerf_machines::load(ALUMINIUM).unwrap();
    let program = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/aluminium-step.ngc"
    ))
    .unwrap();
    let hal: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let cut: CuttingConfig = hal.sim.cutting.unwrap();
    let step = |r: &SimReport| {
        *r.cutting
            .as_ref()
            .unwrap()
            .changes
            .iter()
            .find(|c| c.depth_from == 2.0 && c.depth_to == 4.0)
            .expect("the depth step")
    };

    let free = run(&program, &machine, SimOptions::default());
    let s = step(&free);
    let model = cut.force(0.15, 4.0, 1.0) / cut.force(0.15, 2.0, 1.0);
    println!(
        "  no control at 300 mm/min: {:.1} N → {:.1} N across the step, ×{:.2} (eq. 1: ×{model:.2}; \"nearly doubles\": {})",
        s.force_before,
        s.force_after,
        s.force_after / s.force_before,
        verdict(s.force_after / s.force_before > 1.8)
    );
    let held = run(
        &program,
        &machine,
        SimOptions {
            force_target: Some(250.0),
            ..Default::default()
        },
    );
    let f = held.force.unwrap();
    let s = step(&held);
    match s.settle {
        Some(t) => println!(
            "  controlled: back within ±5 % of 250 N {t:.3} s after the step (target ≤ 1.0 s: {})",
            verdict(t <= 1.0)
        ),
        None => {
            println!("  controlled: never back within ±5 % after the step (target ≤ 1.0 s: MISSED)")
        }
    }
    let rms = f.rms_error_pct.unwrap_or(f64::INFINITY);
    println!(
        "  controlled: RMS force error after settling {rms:.2} % (target ≤ 3 %: {}); largest force {:.1} N (the step's first revolutions)",
        verdict(rms <= 3.0),
        f.max
    );
    // The constant feed that never exceeds F_d: force is proportional to
    // the feed, so scale the programmed feed by 250 N over the largest
    // force of the uncontrolled run, and check by running it.
    let scale = 250.0 / free.cutting.as_ref().unwrap().max_force;
    let feed = 300.0 * scale;
    let constant = run(
        &program.replace("F300", &format!("F{feed:.2}")),
        &machine,
        SimOptions::default(),
    );
    let max = constant.cutting.as_ref().unwrap().max_force;
    println!(
        "  constant {feed:.1} mm/min (largest force {max:.1} N): {:.3} s; controlled: {:.3} s; ratio {:.3} (target < 1: {})",
        constant.cycle_time,
        held.cycle_time,
        held.cycle_time / constant.cycle_time,
        verdict(held.cycle_time < constant.cycle_time)
    );
}

/// A 6-axis machine (XYZ + ABC, trivial kinematics) with everything on:
/// identified plants behind noisy encoders, feedforward, following-error
/// checks, the cutting process and the force controller.
fn six_joints() -> Machine {
    let mut t = String::from("name = \"six\"\nkinematics = \"trivial\"\n");
    for a in ["x", "y", "z", "a", "b", "c"] {
        let (min, max) = if a == "z" {
            (-100.0, 0.0)
        } else {
            (0.0, 300.0)
        };
        let limits =
            format!("min = {min}\nmax = {max}\nmax_velocity = 100.0\nmax_acceleration = 1000.0\n");
        t += &format!("[axes.{a}]\n{limits}");
        t +=
            &format!("[[joints]]\nname = \"{a}\"\naxis = \"{a}\"\n{limits}following_error = 1.0\n");
    }
    t += "[spindle]\nrpm = 1000.0\n[force_control]\ntarget = 250.0\n";
    t += "[hal]\nbackend = \"sim\"\n[hal.sim]\nplant = \"identified\"\nencoder_resolution = 0.0001\nposition_noise = 0.00005\n";
    t += "[hal.sim.cutting]\nstock_top = 0.0\nsteps = [{ x = 40.0, top = 2.0 }]\n";
    kerf_machines::from_toml(&t, "bench:six").unwrap()
}

fn tick_compute() {
    println!(
        "== tick compute time, 6 joints, every control law on (wall clock; reported, not asserted)"
    );
    let machine = six_joints();
    // A zig-zag through all six axes, cutting 2 then 4 mm deep.
    let mut t = String::from("G21 G90\nG0 X0 Y10 A0 B0 C0\nG0 Z-2\nG1 F600\n");
    for k in 1..=100 {
        let x = k as f64 * 0.8;
        let y = 10.0 + if k % 2 == 0 { 0.0 } else { 1.0 };
        let w = (k % 7) as f64 * 0.2;
        t += &format!("X{x:.3} Y{y:.3} A{w:.3} B{:.3} C{:.3}\n", 2.0 * w, 3.0 * w);
    }
    t += "G0 Z0\nM2\n";
    print_tick_time(&run(&t, &machine, SimOptions::default()));
    // The executor's guard walks every segment its stop crosses: dense
    // chords at speed are its heaviest case (a stop from 100 mm/s crosses
    // about 500 chords of 0.01 mm).
    println!("   the same on mill3, a circle of R10 in 0.01 mm chords at 6000 mm/min:");
    let mill3 = kerf_machines::load("mill3").unwrap();
    let n = 6283;
    let mut t = String::from("G21 G90 G64 P0.01\nG0 X60 Y50\nG1 F6000\n");
    for k in 1..=n {
        let u = k as f64 / n as f64 * std::f64::consts::TAU;
        t += &format!(
            "X{:.5} Y{:.5}\n",
            50.0 + 10.0 * u.cos(),
            50.0 + 10.0 * u.sin()
        );
    }
    t += "M2\n";
    print_tick_time(&run(&t, &mill3, SimOptions::default()));
}

fn print_tick_time(r: &SimReport) {
    let us = |ns: u64| ns as f64 / 1000.0;
    let tt = r.tick_time;
    println!(
        "  {} ticks: min {:.1} µs, median {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs  (target p99 ≤ 50 µs: {})",
        r.ticks,
        us(tt.min_ns),
        us(tt.median_ns),
        us(tt.p99_ns),
        us(tt.p999_ns),
        us(tt.max_ns),
        verdict(tt.p99_ns <= 50_000)
    );
}

fn wake_up_latency() {
    println!(
        "== servo thread wake-up latency, 1 ms period, 3 s idle on mill3 (reported, not asserted)"
    );
    let machine = kerf_machines::load("mill3").unwrap();
    let hal: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let backend = kerf_io::build(&hal, &[0.0, 0.0, 0.0]).unwrap();
    let (_producer, consumer) = rtrb::RingBuffer::new(16);
    let (_commands, command_queue) = rtrb::RingBuffer::new(4);
    let tick = ServoTick::new(
        0.001,
        Position::ZERO,
        machine.kinematics.clone(),
        backend,
        consumer,
        command_queue,
    )
    .unwrap();
    let (writer, reader) = seqlock(*tick.snapshot());
    let locked = kerf::servo::lock_memory();
    let mut thread = ServoThread::spawn(
        tick,
        writer,
        Pacing::Wall,
        RealTime {
            fifo_priority: Some(80),
            cpu: None,
        },
    )
    .unwrap();
    for w in &thread.realtime().warnings {
        println!("  warning: {w}");
    }
    if let Err(w) = locked {
        println!("  warning: {w}");
    }
    std::thread::sleep(Duration::from_secs(3));
    let snap = reader.read();
    thread.stop();
    let l = snap.latency;
    let us = |ns: u64| ns as f64 / 1000.0;
    println!(
        "  SCHED_FIFO {}: {} wake-ups, min {:.1} µs, median {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs, {} overruns",
        thread.realtime().fifo,
        l.samples,
        us(l.min_ns),
        us(l.median_ns),
        us(l.p99_ns),
        us(l.p999_ns),
        us(l.max_ns),
        snap.overruns
    );
}

fn main() {
    following_error();
    contour_error();
    force_control();
    tick_compute();
    wake_up_latency();
}
