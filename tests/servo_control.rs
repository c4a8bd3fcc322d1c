//! The servo's control: the position loops against the identified plant,
//! the following-error fault, the force controller driven by the program
//! and by commands, and the offline simulation's figures — each checked
//! against an expectation worked out independently (closed forms and the
//! process model), on a virtual clock.

use kerf::servo::{ServoCommand, ServoFault, ServoTick};
use kerf::simulate::{simulate, SimOptions};
use kerf_interp::{Interpreter, Position};
use kerf_io::sim::cutting::CuttingConfig;
use kerf_io::sim::plant::DriveModel;
use kerf_machines::Machine;
use kerf_motion::control::LoopGains;
use kerf_motion::offline::plan_program;
use kerf_motion::{Planner, PlannerConfig, Segment, SegmentKind};

const ALUMINIUM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");

fn program(
    text: &str,
) -> impl Iterator<Item = Result<kerf_interp::Canon, kerf_interp::InterpError>> + '_ {
    Interpreter::from_text(text, "t.ngc", Position::ZERO)
}

/// mill3 with the identified plant on every joint and `extra` appended.
fn identified_mill(extra: &str) -> Machine {
    let text = kerf_machines::EMBEDDED
        .iter()
        .find(|(n, _)| *n == "mill3")
        .unwrap()
        .1
        .replace(
            "[hal]\nbackend = \"sim\"",
            &format!("[hal]\nbackend = \"sim\"\n[hal.sim]\nplant = \"identified\"\n{extra}"),
        );
    kerf_machines::from_toml(&text, "mill3-identified").unwrap()
}

/// A servo tick on `machine` at 1 ms, reading a queue of `capacity`
/// segments and a command queue of 8, with the two queues' write ends.
fn servo_on(
    machine: &Machine,
    capacity: usize,
) -> (
    rtrb::Producer<Segment>,
    rtrb::Producer<ServoCommand>,
    ServoTick,
) {
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (producer, consumer) = rtrb::RingBuffer::new(capacity);
    let (commands, command_queue) = rtrb::RingBuffer::new(8);
    let kins = machine.kinematics.clone();
    let tick = ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue);
    (producer, commands, tick.unwrap())
}

#[test]
fn pure_pd_lags_by_v_over_kv_and_feedforward_removes_the_lag() {
    // 1000 mm/min along X. The loop is type 1 (the plant integrates): in
    // the steady ramp the drive input is kp·e and the axis moves at K·u, so
    // e = v / (K·kp) = 16.667 / (27.667 · 1.296) = 0.4648 mm.
    let machine = identified_mill("");
    let text = "G21 G90\nG1 X100 F1000\nM2\n";
    let k = DriveModel::SEED.gain;
    let v_over_kv = 1000.0 / 60.0 / (k * LoopGains::SEED.kp);
    let pd = simulate(
        program(text),
        &machine,
        &SimOptions {
            feedforward: false,
            ..Default::default()
        },
    )
    .unwrap();
    let x = &pd.joints[0];
    assert!(
        (x.max_following_error - v_over_kv).abs() < 0.005 * v_over_kv,
        "{} vs {v_over_kv}",
        x.max_following_error
    );
    // Straight along X: the other joints never move, and the tool stays on
    // the line.
    assert_eq!(pd.joints[1].max_following_error, 0.0);
    assert!(pd.max_contour_error < 1e-9);
    // Feedforward inverts the plant: what is left is the mismatch of a
    // held input against a smooth reference, over a hundred times smaller.
    let ff = simulate(program(text), &machine, &SimOptions::default()).unwrap();
    assert!(
        ff.max_following_error < v_over_kv / 100.0,
        "{}",
        ff.max_following_error
    );
    assert_eq!(
        ff.cycle_time, pd.cycle_time,
        "the loops do not change the trajectory"
    );
    // Deterministic: the same run gives the same figures.
    let again = simulate(program(text), &machine, &SimOptions::default()).unwrap();
    assert_eq!(
        (again.max_following_error, again.ticks),
        (ff.max_following_error, ff.ticks)
    );
}

#[test]
fn a_joint_lagging_beyond_its_limit_faults_and_disables_the_drives() {
    // Limit 0.1 mm on X; pure PD at 1000 mm/min lags 0.46 mm: the fault
    // comes during the acceleration, names joint 0, and stops everything.
    let machine = identified_mill("");
    let kins = machine.kinematics.clone();
    let (mut producer, mut commands, mut tick) = servo_on(&machine, 64);
    commands.push(ServoCommand::Enable(true)).unwrap();
    let canon = program("G1 X100 F1000\nM2\n");
    for seg in plan_program(canon, &*kins, Position::ZERO, PlannerConfig::default(), 1).unwrap() {
        producer.push(seg).unwrap();
    }
    tick.configure(&machine.description);
    tick.set_feedforward(false);
    tick.set_following_error_limits(&[Some(0.1), None, None]);
    let mut ticks = 0;
    while tick.snapshot().fault.is_none() && ticks < 5000 {
        tick.tick();
        ticks += 1;
    }
    let snap = *tick.snapshot();
    match snap.fault {
        Some(ServoFault::FollowingError {
            joint,
            error,
            limit,
        }) => {
            assert_eq!((joint, limit), (0, 0.1));
            assert!(error > 0.1 && error < 0.11, "{error}");
        }
        other => panic!("expected a following-error fault, got {other:?} after {ticks} ticks"),
    }
    // Well before the steady lag (reached after ~0.1 s of motion).
    assert!(ticks < 400, "{ticks}");
    // Drives off: no effort, no spindle, the executor stopped.
    tick.tick();
    assert!(!tick.setpoints().enable);
    assert_eq!(tick.setpoints().joints[0].effort, 0.0);
    assert!(!tick.snapshot().moving);
}

#[test]
fn the_program_and_the_operator_switch_force_control() {
    let machine = kerf_machines::load(ALUMINIUM).unwrap();
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(64);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(4);
    commands.push(ServoCommand::Enable(true)).unwrap();
    // The first move without force control, the second with 300 N, the
    // third off again: kerf's M170 P / M171, in step with the motion.
    let mut planner = Planner::new(
        &*kins,
        Position::ZERO,
        PlannerConfig {
            mode: kerf_motion::PathMode::ExactStop,
            ..PlannerConfig::default()
        },
    );
    for canon in program("G1 X5 F600\nM170 P300\nX10\nM171\nX15\nM2\n") {
        planner.plan(&canon.unwrap()).unwrap();
    }
    planner.finish();
    while let Some(seg) = planner.next_segment() {
        producer.push(seg).unwrap();
    }
    producer
        .push(Segment::marker(
            SegmentKind::Stop { tag: 1 },
            0,
            planner.position(),
        ))
        .unwrap();
    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    tick.configure(&machine.description);
    let target = |t: &ServoTick| t.snapshot().force.unwrap().target;
    let mut seen = Vec::new();
    let mut ticks = 0;
    while tick.snapshot().program_done != 1 {
        ticks += 1;
        assert!(ticks < 100_000, "the program never finished");
        tick.tick();
        let x = tick.snapshot().commanded.x;
        if seen.last() != Some(&target(&tick)) {
            seen.push(target(&tick));
            // The switch happens as the tool starts the next line.
            if seen.len() > 1 {
                assert!(
                    (x - 5.0).abs() < 0.01 || (x - 10.0).abs() < 0.01,
                    "switched at X {x}"
                );
            }
        }
    }
    assert_eq!(seen, [None, Some(300.0), None]);
    // The operator's command acts at once and stays until the program
    // changes it.
    commands
        .push(ServoCommand::ForceControl(Some(200.0)))
        .unwrap();
    tick.tick();
    assert_eq!(target(&tick), Some(200.0));
    commands.push(ServoCommand::ForceControl(None)).unwrap();
    tick.tick();
    let f = tick.snapshot().force.unwrap();
    assert_eq!((f.target, f.feed_override), (None, 1.0));
}

#[test]
fn input_is_complete_when_the_queue_is_empty_full_or_holds_the_end() {
    let machine = identified_mill("");
    // A tick reading a queue of `capacity` segments.
    let with_queue = |capacity: usize| {
        let (producer, _, tick) = servo_on(&machine, capacity);
        (producer, tick)
    };
    let dwell = Segment::marker(SegmentKind::Dwell { seconds: 1.0 }, 1, Position::ZERO);
    let (mut producer, mut tick) = with_queue(3);
    assert!(tick.input_complete(), "empty");
    producer.push(dwell).unwrap();
    assert!(!tick.input_complete(), "part of a program");
    producer
        .push(Segment::marker(
            SegmentKind::Stop { tag: 1 },
            2,
            Position::ZERO,
        ))
        .unwrap();
    assert!(tick.input_complete(), "the end is queued");
    let (mut producer, mut tick) = with_queue(2);
    producer.push(dwell).unwrap();
    producer.push(dwell).unwrap();
    assert!(tick.input_complete(), "full");
}

#[test]
fn force_control_holds_the_target_through_a_depth_step() {
    // The stepped aluminium block, fed at 300 mm/min. The process model's
    // force is proportional to the feed at a given depth, so the
    // uncontrolled force ratio across the step is eq. (1)'s ratio at the
    // same feed per tooth, computed here from the model directly.
    let machine = kerf_machines::load(ALUMINIUM).unwrap();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/aluminium-step.ngc"
    ))
    .unwrap();
    let hal: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let cut: CuttingConfig = hal.sim.cutting.unwrap();
    let ft = 300.0 / (1000.0 * 2.0);
    let peak = |d: f64| cut.force(ft, d, 1.0);

    let free = simulate(program(&text), &machine, &SimOptions::default()).unwrap();
    assert!(free.force.is_none(), "no force control asked for");
    let changes = &free.cutting.as_ref().unwrap().changes;
    let step = changes
        .iter()
        .find(|c| c.depth_from == 2.0 && c.depth_to == 4.0)
        .unwrap();
    // Within 0.5 %: the feed is steady both sides and the force is exact.
    assert!(
        (step.force_before - peak(2.0)).abs() < 0.005 * peak(2.0),
        "{step:?}"
    );
    assert!(
        (step.force_after - peak(4.0)).abs() < 0.005 * peak(4.0),
        "{step:?}"
    );

    let held = simulate(
        program(&text),
        &machine,
        &SimOptions {
            force_target: Some(250.0),
            ..Default::default()
        },
    )
    .unwrap();
    let force = held.force.unwrap();
    assert_eq!(force.target, 250.0);
    let changes = &held.cutting.as_ref().unwrap().changes;
    let step = changes
        .iter()
        .find(|c| c.depth_from == 2.0 && c.depth_to == 4.0)
        .unwrap();
    // Settles within ±5 % (some time) after the step, and stays near.
    assert!(step.settle.is_some(), "{step:?}");
    assert!((step.force_after - 250.0).abs() < 0.05 * 250.0, "{step:?}");
    assert!(force.rms_error_pct.unwrap() < 5.0, "{force:?}");
    // Holding 250 N means feeding slower than the uncontrolled 300 mm/min.
    assert!(held.cycle_time > free.cycle_time);
}

/// What a servo on a virtual clock asks before it stops the clock: does
/// the queued motion wait on the operator alone? A `step` that arrived
/// before the program's segments (the planner is still starting) is a
/// request the executor has not acted on yet: the motion does not wait,
/// and a clock stopped there would never start again. Once the stepped
/// line has run, it does wait, until the next `step`.
#[test]
fn a_step_sent_before_the_motion_arrives_is_not_waiting_on_the_operator() {
    let machine = identified_mill("");
    let kins = machine.kinematics.clone();
    let (mut producer, mut commands, mut tick) = servo_on(&machine, 64);
    tick.configure(&machine.description);
    for cmd in [
        ServoCommand::Enable(true),
        ServoCommand::SingleBlock(true),
        ServoCommand::Step,
    ] {
        commands.push(cmd).unwrap();
    }
    // The commands, then an idle servo's settling ticks, with nothing queued.
    for _ in 0..300 {
        tick.tick();
    }
    let canon = program("G21 G90\nG1 X5 F3000\nG1 X10\nM2\n");
    let segments = plan_program(canon, &*kins, Position::ZERO, PlannerConfig::default(), 1);
    for seg in segments.unwrap() {
        producer.push(seg).unwrap();
    }
    assert!(
        !tick.waiting_on_operator(),
        "the step asked for line 2 to run"
    );
    let mut ticks = 0;
    while !tick.waiting_on_operator() && ticks < 5000 {
        tick.tick();
        ticks += 1;
    }
    let snap = *tick.snapshot();
    assert!(!snap.moving, "waits at rest, after {ticks} ticks");
    assert_eq!(snap.commanded.x, 5.0, "at the end of the stepped line");
}
