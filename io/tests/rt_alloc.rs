//! `Hal::exchange` is real-time safe for every backend: it never allocates
//! or frees. A counting global allocator counts allocations made on this
//! test's thread while it exchanges; the backends' I/O threads allocate
//! freely on their own threads and are not counted.

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use kerf_io::can::sim::{SimBus, SimDrive};
use kerf_io::can::{BusKind, CanConfig, CanHal, DriveConfig, Mode};
use kerf_io::clock::VirtualClock;
use kerf_io::pins::{PinBank, PinConfig};
use kerf_io::shm::{ShmExport, StatusFrame};
use kerf_io::{build, Feedback, Hal, HalConfig, Setpoints};

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

/// Allocations made on this thread by `f`.
fn count(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

// One test function: the allocation counter is global, and tests in one
// binary run on parallel threads.
#[test]
fn exchange_never_allocates() {
    // sim, and sim mixed with CAN through the router.
    let cfg: HalConfig = toml::from_str(
        "backend = \"sim\"\n[can]\nbus = \"sim\"\n[[can.drives]]\njoint = 1\nnode = 2\ncounts_per_mm = 100.0\n",
    )
    .unwrap();
    let mut mixed = build(&cfg, &[0.0, 0.0, 0.0]).unwrap();
    let mut out = Setpoints {
        enable: true,
        ..Default::default()
    };
    let mut fb = Feedback::default();
    let n = count(|| {
        // Fewer ticks than the CAN queue holds: this loop runs far faster
        // than a servo period and does not wait for the CAN thread.
        for k in 0..200 {
            out.joints[0].position = k as f64 * 0.001;
            out.joints[1].position = k as f64 * 0.002;
            mixed.exchange(0.001, &out, &mut fb).unwrap();
        }
    });
    assert_eq!(n, 0, "sim + can exchange allocated");

    // The identified plant with a noisy quantising encoder, cutting.
    let cfg: HalConfig = toml::from_str(
        "backend = \"sim\"\n[sim]\nplant = \"identified\"\nencoder_resolution = 0.001\nposition_noise = 0.0005\n[sim.cutting]\nstock_top = 0.0\nsteps = [{ x = 0.1, top = 2.0 }]\n",
    )
    .unwrap();
    let mut sim = build(&cfg, &[0.0, 0.0, -2.0]).unwrap();
    out.spindle_speed = 1000.0;
    let n = count(|| {
        for k in 0..2000 {
            out.joints[0].effort = 0.15 * (k as f64 * 0.01).sin().abs();
            sim.exchange(0.001, &out, &mut fb).unwrap();
        }
    });
    assert_eq!(n, 0, "identified sim with cutting allocated");
    assert!(fb.spindle_current > 2.0, "it cut: {}", fb.spindle_current);

    // CAN on a virtual clock, driven in lock step.
    let clock = VirtualClock::at(0);
    let can_cfg = CanConfig {
        bus: BusKind::Sim,
        interface: String::new(),
        mode: Mode::Csv,
        heartbeat_ms: 20,
        heartbeat_timeout_ms: 60.0,
        sdo_timeout_ms: 100.0,
        kp: 50.0,
        kd: 0.0,
        drives: vec![DriveConfig {
            joint: 0,
            node: 1,
            counts_per_mm: 1000.0,
        }],
    };
    let bus = SimBus::new(vec![SimDrive::new(1)], Arc::new(clock.clone()));
    let mut can =
        CanHal::with_bus(&can_cfg, &[0.0], Box::new(bus), Arc::new(clock.clone())).unwrap();
    let n = count(|| {
        for k in 1..=1000u64 {
            clock.advance(1_000_000);
            out.joints[0].position = k as f64 * 0.01;
            can.exchange(0.001, &out, &mut fb).unwrap();
            while can.processed() < k {
                std::thread::yield_now();
            }
        }
    });
    assert_eq!(n, 0, "can exchange allocated");

    // stepdir against the simulated MCU.
    let mcu = support::Mcu::start("alloc", &["--channels", "2"]);
    let mut d = support::Driver::open(
        &support::config(
            &mcu.port,
            vec![
                support::joint(0, 800.0, false),
                support::joint(1, 100.0, true),
            ],
        ),
        &[0.0, 0.0],
    );
    let n = count(|| {
        for k in 1..=1000u64 {
            let p = [k as f64 * 0.05, -(k as f64) * 0.02];
            d.tick(&p, true).unwrap();
        }
    });
    assert_eq!(n, 0, "stepdir exchange allocated");
    assert!(d.hal.stats().steps > 40_000);

    // Status and pins export: the tick's side only queues and reads atomics.
    let pins = PinConfig {
        digital_out: vec!["out0".into()],
        digital_in: vec!["in0".into()],
        analog_out: vec!["aout0".into()],
        analog_in: vec!["ain0".into()],
    };
    let mut export =
        ShmExport::start(&format!("kerf-alloc-{}", std::process::id()), &pins).unwrap();
    let mut bank = PinBank::new(&pins);
    let mut frame = StatusFrame::default();
    let n = count(|| {
        for k in 0..200u64 {
            frame.tick = k;
            bank.set_digital(0, k % 2 == 0).unwrap();
            bank.set_analog_synced(0, k as f64).unwrap();
            bank.motion_started();
            export.exchange(&frame, &mut bank);
        }
    });
    assert_eq!(n, 0, "shm export exchange allocated");
    assert!(!export.failed());
}
