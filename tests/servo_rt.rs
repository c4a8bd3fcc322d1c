//! The servo tick is real-time safe: it never allocates (or frees).
//!
//! A counting global allocator counts allocations made on this test's
//! thread while it runs ticks through a whole program on the simulated mill.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use kerf::servo::{ServoCommand, ServoTick};
use kerf_interp::{Interpreter, Position};
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

    let program = "G21 G90 G0 X50 Y40 Z-10\nG1 X80 F900\nY60\nX70 Y70\nG4 P0.05\nG20 G91 G1 Y1 Z-0.1\nG0 X-1\nM2\n";
    let mut planner = Planner::new(&*kins, Position::ZERO, PlannerConfig::default());
    for canon in Interpreter::new(program.as_bytes(), "rt.ngc", Position::ZERO) {
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
    commands.push(ServoCommand::Enable(true)).unwrap();
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
        tick.tick();
        ticks += 1;
    }
    COUNTING.with(|c| c.set(false));

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
}
