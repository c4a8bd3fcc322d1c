//! The servo tick publishes its status over shared memory every tick when
//! the machine asks for it (`[hal.shm]`): a subscriber sees frames whose
//! positions are the tick's joint feedback.

use std::time::{Duration, Instant};

use kerf::servo::ServoTick;
use kerf_interp::{Interpreter, Position};
use kerf_io::shm::{state, Services, ShmExport};
use kerf_io::{PinBank, PinConfig};
use kerf_motion::{Planner, PlannerConfig, Segment, SegmentKind};

#[test]
fn a_subscriber_sees_every_tick_s_status() {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(64);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(4);
    // The servo starts with the drives off; a program runs only once on.
    commands
        .push(kerf::servo::ServoCommand::Enable(true))
        .unwrap();
    let mut planner = Planner::new(&*kins, Position::ZERO, PlannerConfig::default());
    for canon in Interpreter::from_text("G0 X12 Y5 Z-3\nM2\n", "shm.ngc", Position::ZERO) {
        planner.plan(&canon.unwrap()).unwrap();
        while let Some(seg) = planner.next_segment() {
            producer.push(seg).unwrap();
        }
    }
    producer
        .push(Segment::marker(
            SegmentKind::Stop { tag: 1 },
            0,
            planner.position(),
        ))
        .unwrap();

    let instance = format!("kerf-servo-test-{}", std::process::id());
    let services = Services::new().unwrap();
    let subscriber = services.status_subscriber(&instance).unwrap();
    let mut tick =
        ServoTick::new(0.001, Position::ZERO, kins, hal, consumer, command_queue).unwrap();
    let pins = PinConfig::default();
    tick.export_to(
        ShmExport::start(&instance, &pins).unwrap(),
        PinBank::new(&pins),
    );

    let mut running = false;
    let deadline = Instant::now() + Duration::from_secs(20);
    while tick.snapshot().program_done != 1 {
        assert!(Instant::now() < deadline, "program did not finish");
        tick.tick();
        while let Some(f) = subscriber.receive().unwrap() {
            running |= f.state == state::RUNNING;
        }
    }
    // A few idle ticks, then wait for the last one's frame.
    for _ in 0..5 {
        tick.tick();
    }
    let last = *tick.snapshot();
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        assert!(Instant::now() < deadline, "the last frame never arrived");
        let Some(f) = subscriber.receive().unwrap() else {
            std::thread::yield_now();
            continue;
        };
        running |= f.state == state::RUNNING;
        if f.tick == last.ticks {
            assert_eq!(f.state, state::IDLE);
            assert_eq!(f.joint_count, 3);
            assert_eq!(&f.position[..3], &last.joints[..3]);
            assert_eq!(&f.position[..3], &[12.0, 5.0, -3.0]);
            assert_eq!(&f.following_error[..3], &[0.0; 3]);
            break;
        }
    }
    assert!(running, "no frame showed the machine running");
}
