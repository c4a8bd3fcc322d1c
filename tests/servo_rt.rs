//! The servo tick is real-time safe: it never allocates (or frees).
//!
//! A counting global allocator counts allocations made on this test's
//! thread while it runs ticks through a whole program on the simulated mill.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use kerf::servo::{ServoCommand, ServoTick};
use kerf_interp::{Interpreter, Position};
use kerf_motion::offline::plan_program;
use kerf_motion::{Planner, PlannerConfig, Segment, SegmentKind};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if COUNTING.with(|c| c.get()) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn ticks_through_a_program_without_allocating() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(256);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(16);

    // With outputs on the way: synchronised ones riding on moves (M62,
    // M67) and immediate ones as queue markers (M64, M65, M68), and an
    // input read at rest (M66).
    let program = "G21 G90 G0 X50 Y40 Z-10\nM62 P0\nM67 E0 Q1.5\nG1 X80 F900\nY60\nM0\nM64 P1\nX70 Y70\nM1\nG4 P0.05\nM68 E1 Q2\nM66 P0 L0\nM66 P1 L3 Q0.01\nG20 G91 G1 Y1 Z-0.1\nM63 P0\nM65 P1\nG0 X-1\nM2\n";
    let mut planner = Planner::new(&*kins, Position::ZERO, PlannerConfig::default());
    for canon in Interpreter::from_text(program, "rt.ngc", Position::ZERO) {
        planner.plan(&canon.unwrap()).unwrap();
        while let Some(seg) = planner.next_segment() {
            producer.push(seg).unwrap();
        }
    }
    let expected_end = planner.position();
    producer
        .push(Segment::marker(
            SegmentKind::Stop { tag: 1 },
            0,
            expected_end,
        ))
        .unwrap();

    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    tick.set_following_error_limits(&[Some(0.1), Some(0.1), None]);
    tick.set_pins(kerf_io::PinBank::new(&hal_config.pins));
    commands.push(ServoCommand::Enable(true)).unwrap();
    // Program stops seen waiting, by number (room made before counting).
    let mut waited: Vec<u64> = Vec::with_capacity(1000);
    COUNTING.with(|c| c.set(true));
    let mut ticks = 0u64;
    while tick.snapshot().program_done != 1 && ticks < 1_000_000 {
        // Exercise the operator commands on the way.
        let cmd = match ticks {
            100 => Some(ServoCommand::FeedOverride(1.5)),
            200 => Some(ServoCommand::Hold(true)),
            700 => Some(ServoCommand::Hold(false)),
            800 => Some(ServoCommand::RapidOverride(0.5)),
            _ => None,
        };
        if let Some(cmd) = cmd {
            commands.push(cmd).unwrap();
        }
        let snap = tick.snapshot();
        if snap.at_program_stop && waited.len() < waited.capacity() {
            waited.push(snap.program_stops);
        }
        if snap.at_program_stop && ticks.is_multiple_of(50) {
            // The operator resumes the program stop (M0, M1) a while later.
            let reached = snap.program_stops;
            commands.push(ServoCommand::OptionalStop(true)).unwrap();
            commands
                .push(ServoCommand::ReleaseStop { reached })
                .unwrap();
        }
        tick.tick();
        ticks += 1;
    }
    COUNTING.with(|c| c.set(false));
    // Both stops held the tool (for some ticks each) and were released.
    waited.dedup();
    assert_eq!(waited, [1, 2], "program stops waited at");

    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the servo tick allocated"
    );
    let snap = tick.snapshot();
    assert_eq!(
        snap.program_done, 1,
        "program did not finish in {ticks} ticks"
    );
    assert!(snap.fault.is_none());
    assert_eq!(snap.position, expected_end);
    assert!(ticks > 1000, "ran {ticks} ticks: too few to mean anything");
    let pins = tick.pins();
    assert_eq!(pins.digital_outputs(), 0, "M63 and M65 turned both off");
    assert_eq!((pins.analog_out(0), pins.analog_out(1)), (1.5, 2.0));
    // Both waits answered: input 1 never went high, so the last timed out.
    assert_eq!((snap.inputs_answered, snap.input_value), (2, -1.0));
}

/// Every embedded machine's inverse and forward kinematics, called as the
/// tick calls them (caller storage, previous pose as the seed), allocate
/// nothing — rfmt5's Newton iteration included.
#[test]
fn kinematics_of_every_machine_run_without_allocating() {
    for (name, _) in kerf_machines::EMBEDDED {
        let machine = kerf_machines::load(name).unwrap();
        let kins = &*machine.kinematics;
        let n = kins.joints().len();
        let home = machine.home();
        // A short path from home through the travel: each axis swept 10 %
        // of its travel up, in 1000 steps.
        let path: Vec<Position> = (0..1000)
            .map(|i| {
                let mut p = home;
                for spec in kins.axes() {
                    let span = spec.limits.max - spec.limits.min;
                    let v = (p.get(spec.axis) + 0.1 * span * i as f64 / 1000.0)
                        .clamp(spec.limits.min, spec.limits.max);
                    p.set(spec.axis, v);
                }
                p
            })
            .collect();
        let mut q = [0.0; kerf_motion::MAX_JOINTS];
        let mut last = home;
        COUNTING.with(|c| c.set(true));
        for p in &path {
            kins.inverse(p, &mut q[..n]).unwrap();
            last = kins.forward(&q[..n], &last).unwrap();
        }
        COUNTING.with(|c| c.set(false));
        assert_eq!(
            ALLOCATIONS.load(Ordering::Relaxed),
            0,
            "{name}: kinematics allocated"
        );
        // The walk ends where the path does (1e-9 mm: the round trip bound).
        let end = path.last().unwrap();
        for spec in kins.axes() {
            let (got, want) = (last.get(spec.axis), end.get(spec.axis));
            assert!(
                (got - want).abs() < 1e-9,
                "{name} {}: {got} vs {want}",
                spec.axis
            );
        }
    }
}

/// Plan `program` from the origin into a fresh queue, ending with a `Stop`
/// marker tagged `tag`.
fn queue_program(producer: &mut rtrb::Producer<Segment>, program: &str, tag: u32) -> Position {
    let machine = kerf_machines::load("mill3").unwrap();
    let mut planner = Planner::new(
        &*machine.kinematics,
        Position::ZERO,
        PlannerConfig::default(),
    );
    for canon in Interpreter::from_text(program, "rt.ngc", Position::ZERO) {
        planner.plan(&canon.unwrap()).unwrap();
        while let Some(seg) = planner.next_segment() {
            producer.push(seg).unwrap();
        }
    }
    planner.finish();
    while let Some(seg) = planner.next_segment() {
        producer.push(seg).unwrap();
    }
    let end = planner.position();
    producer
        .push(Segment::marker(SegmentKind::Stop { tag }, 0, end))
        .unwrap();
    end
}

#[test]
fn faults_abort_and_estop_allocate_nothing_either() {
    use kerf::servo::ServoFault;
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = machine.kinematics.clone();
    // Joint x seizes at 20 mm; its following error limit is 0.5 mm.
    let hal_config: kerf_io::HalConfig =
        toml::from_str("backend = \"sim\"\n[sim.jam]\njoint = 0\nat = 20.0\n").unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(256);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(16);
    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    tick.set_following_error_limits(&[Some(0.5), None, None]);

    queue_program(&mut producer, "G1 X50 F1200\nM2\n", 1);
    queue_program(&mut producer, "G1 Y50 F1200\nM2\n", 2);
    queue_program(&mut producer, "G1 Y10 F1200\nM2\n", 3);
    commands.push(ServoCommand::Enable(true)).unwrap();

    COUNTING.with(|c| c.set(true));
    // Program 1 runs into the jam: a following-error fault, drives off, and
    // the queue drained (programs 1 to 3 count as aborted).
    let mut ticks = 0;
    while tick.snapshot().fault.is_none() && ticks < 10_000 {
        tick.tick();
        ticks += 1;
    }
    let faulted = *tick.snapshot();
    tick.tick();
    let drained = *tick.snapshot();
    // Clearing the fault and turning on again starts from the measured pose.
    commands.push(ServoCommand::ClearFault).unwrap();
    commands.push(ServoCommand::Enable(true)).unwrap();
    tick.tick();
    let restarted = *tick.snapshot();
    // An abort of a program already discarded is ignored; turning the drives
    // off and on again is harmless at rest.
    commands.push(ServoCommand::Abort { program: 2 }).unwrap();
    commands.push(ServoCommand::Enable(false)).unwrap();
    tick.tick();
    commands.push(ServoCommand::Enable(true)).unwrap();
    tick.tick();
    COUNTING.with(|c| c.set(false));

    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the servo tick allocated"
    );
    match faulted.fault {
        Some(ServoFault::FollowingError {
            joint,
            error,
            limit,
        }) => {
            assert_eq!((joint, limit), (0, 0.5));
            assert!(error > 0.5, "error {error}");
        }
        other => panic!("expected a following error, got {other:?}"),
    }
    // The jammed joint stays at 20 mm; the command ran at most one period
    // past the limit (1200 mm/min = 0.02 mm per period).
    assert_eq!(faulted.joints[0], 20.0);
    assert!(!faulted.enabled);
    assert_eq!(drained.program_aborted, 3, "the whole queue was discarded");
    assert_eq!(drained.program_done, 0);
    assert!(restarted.fault.is_none() && restarted.enabled);
    assert_eq!(restarted.commanded, restarted.position);
    assert_eq!(restarted.position.x, 20.0);
    let last = tick.snapshot();
    assert_eq!(last.program_aborted, 3, "a stale abort changed nothing");
    assert!(last.enabled && !last.moving);
}

/// The tick with everything issue 6 adds switched on — the position loops
/// with feedforward, the identified plant behind a noisy quantising
/// encoder, the cutting process and the fuzzy force controller changing
/// the feed override every revolution, following-error checks — cuts the
/// stepped aluminium block without allocating.
#[test]
fn control_loops_plant_and_force_control_run_without_allocating() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");
    let machine = kerf_machines::load(path).unwrap();
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    assert!(hal_config.sim.cutting.is_some());
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(1024);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(16);
    let program = "G21 G90\nG0 X0 Y50\nG0 Z-2\nG1 X80 F300\nG0 Z0\nM2\n";
    let canon = Interpreter::from_text(program, "cut.ngc", Position::ZERO);
    for seg in plan_program(canon, &*kins, Position::ZERO, PlannerConfig::default(), 1).unwrap() {
        producer.push(seg).unwrap();
    }
    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    tick.configure(&machine.description);
    commands.push(ServoCommand::Enable(true)).unwrap();
    commands
        .push(ServoCommand::ForceControl(Some(250.0)))
        .unwrap();
    let mut lowest_override: f64 = 1.0;
    COUNTING.with(|c| c.set(true));
    let mut ticks = 0u64;
    while tick.snapshot().program_done != 1 && ticks < 100_000 {
        tick.tick();
        if let Some(f) = tick.snapshot().force {
            lowest_override = lowest_override.min(f.feed_override);
        }
        ticks += 1;
    }
    COUNTING.with(|c| c.set(false));
    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the servo tick allocated"
    );
    let snap = tick.snapshot();
    assert_eq!(snap.program_done, 1, "did not finish in {ticks} ticks");
    assert!(snap.fault.is_none(), "{:?}", snap.fault);
    // The controller acted: at 4 mm deep it must about halve the feed.
    assert!(
        lowest_override < 0.6,
        "override went no lower than {lowest_override}"
    );
}

/// The spindle override scales the speed the servo gives the spindle (and
/// so the simulated cut), and survives the drives going off and on.
#[test]
fn the_spindle_override_scales_the_commanded_spindle_speed() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/aluminium-step.toml");
    let machine = kerf_machines::load(path).unwrap();
    let rpm = machine.description.spindle.as_ref().unwrap().rpm;
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (_producer, consumer) = rtrb::RingBuffer::<Segment>::new(16);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(16);
    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    tick.configure(&machine.description);
    commands.push(ServoCommand::Enable(true)).unwrap();
    tick.tick();
    tick.tick();
    assert_eq!(tick.setpoints().spindle_speed, rpm);
    commands.push(ServoCommand::SpindleOverride(0.8)).unwrap();
    tick.tick();
    tick.tick();
    assert_eq!(tick.setpoints().spindle_speed, rpm * 0.8);
    assert_eq!(tick.snapshot().spindle_override, 0.8);
    commands.push(ServoCommand::Enable(false)).unwrap();
    tick.tick();
    commands.push(ServoCommand::Enable(true)).unwrap();
    tick.tick();
    tick.tick();
    assert_eq!(tick.setpoints().spindle_speed, rpm * 0.8);
}

/// The executor's half of third-order planning: a `Follower` running a
/// jerk-limited schedule's intervals handed over through a lock-free ring,
/// as a planner solving ahead in windows would hand them, allocates
/// nothing in its tick. When the ring runs dry it waits where it is and
/// carries on when intervals come: the samples are those of the same
/// schedule followed in one go, to the bit.
#[test]
fn a_schedule_is_followed_through_a_ring_without_allocating() {
    use kerf_motion::schedule::{schedule, Follower, Sample, ScheduleConfig};
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(50.0, 50.0, -5.0);
    let program = "G21 G90 G64 P0.01 G1 F3000 X60 Y52\nG3 X64 Y56 R4\nG1 X64 Y60\nM2\n";
    let segments = plan_program(
        Interpreter::from_text(program, "rt.ngc", start),
        kins,
        start,
        PlannerConfig::default(),
        1,
    )
    .unwrap();
    let config = ScheduleConfig {
        ds: 0.02,
        ..ScheduleConfig::default()
    };
    let intervals = schedule(&segments, kins, config).unwrap().intervals();
    assert!(intervals.len() > 500, "{} intervals", intervals.len());

    // In one go, from the whole list.
    let mut whole = Follower::new(0.001);
    let mut all = intervals.iter().copied();
    let mut expected = Vec::new();
    while let Some(sample) = whole.tick(&mut all) {
        expected.push(sample);
    }
    assert!(expected.len() > 100, "{} samples", expected.len());

    // Through a ring of 64, refilled 4 at a time every 5 periods: the
    // follower outruns the planner and waits.
    let (mut producer, mut consumer) = rtrb::RingBuffer::new(64);
    let mut follower = Follower::new(0.001);
    let mut got: Vec<Sample> = Vec::with_capacity(expected.len() + 1);
    let (mut handed, mut dry) = (0, 0);
    let mut periods = 0u64;
    // Until every interval is handed over and the follower has run past
    // them all.
    let mut finished = false;
    while !finished && periods < 10_000_000 {
        if periods.is_multiple_of(5) {
            for interval in intervals.iter().skip(handed).take(4) {
                if producer.push(*interval).is_err() {
                    break;
                }
                handed += 1;
            }
        }
        COUNTING.with(|c| c.set(true));
        let sample = follower.tick(&mut std::iter::from_fn(|| consumer.pop().ok()));
        COUNTING.with(|c| c.set(false));
        match sample {
            Some(sample) => got.push(sample),
            None if handed == intervals.len() => finished = true,
            None => dry += 1,
        }
        periods += 1;
    }
    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the follower's tick allocated"
    );
    assert!(dry > 0, "the ring never ran dry: the test tests nothing");
    assert_eq!(got, expected);
    assert_eq!(follower.passed_time(), whole.passed_time());
}

/// The executor following a schedule (`Executor::tick_following`)
/// allocates nothing in its tick either: taking stretches, following
/// them under overrides and a hold, leaving one for single block, and
/// its own profiles between them.
#[test]
fn the_executor_follows_a_schedule_without_allocating() {
    use kerf_motion::exec::Intervals;
    use kerf_motion::schedule::{RateLimits, ScheduleConfig, ScheduleStream, Window};
    use kerf_motion::Executor;
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = &*machine.kinematics;
    let start = Position::xyz(50.0, 50.0, -5.0);
    let program = "G21 G90 G64 P0.01 G1 F3000 X60 Y52\nG3 X64 Y56 R4\nG1 X64 Y60\nG4 P0.05\nG0 X80\nG61 G1 X90 Y50\nG64 X60 Y40\nM2\n";
    let segments = plan_program(
        Interpreter::from_text(program, "rt.ngc", start),
        kins,
        start,
        PlannerConfig::default(),
        1,
    )
    .unwrap();
    let config = ScheduleConfig {
        ds: 0.02,
        reserve: 0.1,
        ..ScheduleConfig::default()
    };
    let window = Window {
        horizon: 2000,
        commit: 500,
    };
    let mut stream = ScheduleStream::new(kins, config, window).unwrap();
    let mut intervals = Vec::new();
    for segment in &segments {
        stream.push(segment, &mut |i| intervals.push(i));
    }
    stream.finish(&mut |i| intervals.push(i));

    let mut executor = Executor::new(start);
    executor.follow_schedules(RateLimits::for_machine(kins, 0.1).unwrap());
    let (mut front, mut taken) = (0, 0);
    let mut ticks = 0u64;
    let mut done = false;
    COUNTING.with(|c| c.set(true));
    while !done && ticks < 1_000_000 {
        match ticks {
            50 => executor.set_feed_override(0.5),
            150 => executor.set_hold(true),
            1500 => executor.set_hold(false),
            1600 => executor.set_feed_override(1.0),
            1700 => executor.set_single_block(true),
            3500 => executor.set_single_block(false),
            _ => {}
        }
        let sample = executor.tick_following(
            0.001,
            &segments[front..],
            &[],
            Intervals {
                head: &intervals[taken..],
                tail: &[],
            },
        );
        front += sample.consumed;
        taken += sample.intervals_consumed;
        done = sample.stopped_at == Some(1);
        ticks += 1;
    }
    COUNTING.with(|c| c.set(false));
    assert!(done, "the program did not end in {ticks} ticks");
    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "the executor's tick allocated while following"
    );
    assert!(
        executor.stretches_followed() >= 2,
        "{} stretches followed",
        executor.stretches_followed()
    );
    assert_eq!(taken, intervals.len(), "every interval passed");
}
