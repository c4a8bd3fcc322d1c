//! The servo tick and the thread that paces it.
//!
//! One tick: take the executor's commanded pose for this period, map it to
//! joints through the machine's kinematics, exchange setpoints and feedback
//! with the HAL, map the feedback back to a pose, and publish a status
//! snapshot. The tick allocates nothing, takes no lock and does no I/O (see
//! `tests/servo_rt.rs`, which counts allocations): segments arrive through a
//! lock-free SPSC queue and status leaves through a seqlock.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use kerf_interp::Position;
use kerf_io::shm::{self, ShmExport, StatusFrame};
use kerf_io::{Feedback, Hal, HalFault, PinBank, Setpoints};
use kerf_motion::{Executor, Kinematics, KinematicsError, Segment, SegmentKind, MAX_JOINTS};

use crate::seqlock::Writer;

const _: () = assert!(MAX_JOINTS == kerf_io::MAX_JOINTS);

/// An operator command for the servo thread, sent through a lock-free queue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ServoCommand {
    /// Feed override factor, 0 to 2.
    FeedOverride(f64),
    /// Rapid override factor, 0 to 1.
    RapidOverride(f64),
    /// Feed hold on (decelerate on the path and wait) or off (resume).
    Hold(bool),
    /// Single-block mode on or off.
    SingleBlock(bool),
    /// In single-block mode, run the next source line.
    Step,
    /// Stop on the path, then discard the queue up to the `Stop` marker
    /// tagged `program`, which the planner sends when it has stopped.
    Abort { program: u32 },
}

/// Why the servo stopped motion. `Copy`, so it fits in the snapshot.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ServoFault {
    #[error("hardware: {0}")]
    Hal(HalFault),
    #[error("kinematics: {0}")]
    Kinematics(KinematicsError),
}

/// What the servo thread publishes every tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// Ticks run since start.
    pub ticks: u64,
    /// Wake-ups that came a whole period or more late.
    pub overruns: u64,
    /// A segment is in progress.
    pub moving: bool,
    /// Source line of the current (or last) segment.
    pub line: u32,
    /// Id of the last program whose every segment has run (0: none yet).
    pub program_done: u32,
    /// Id of the last program that was aborted and flushed (0: none yet).
    pub program_aborted: u32,
    /// Path speed, mm/s.
    pub velocity: f64,
    /// Feed and rapid override factors in force.
    pub feed_override: f64,
    pub rapid_override: f64,
    /// Feed hold is on.
    pub hold: bool,
    /// Commanded tool position.
    pub commanded: Position,
    /// Tool position from joint feedback through forward kinematics.
    pub position: Position,
    /// Joint feedback positions; the first `joint_count` are used.
    pub joints: [f64; MAX_JOINTS],
    pub joint_count: usize,
    /// Set when motion was stopped by a fault; latched.
    pub fault: Option<ServoFault>,
}

impl Snapshot {
    /// The snapshot of a machine at rest at `position`.
    pub fn at_rest(position: Position, joints: &[f64]) -> Snapshot {
        let mut j = [0.0; MAX_JOINTS];
        j[..joints.len()].copy_from_slice(joints);
        Snapshot {
            ticks: 0,
            overruns: 0,
            moving: false,
            line: 0,
            program_done: 0,
            program_aborted: 0,
            velocity: 0.0,
            feed_override: 1.0,
            rapid_override: 1.0,
            hold: false,
            commanded: position,
            position,
            joints: j,
            joint_count: joints.len(),
            fault: None,
        }
    }
}

/// Status and pins published to shared memory every tick.
struct Export {
    shm: ShmExport,
    pins: PinBank,
    frame: StatusFrame,
}

/// Everything one servo tick touches.
pub struct ServoTick {
    period: f64,
    executor: Executor,
    kins: Arc<dyn Kinematics>,
    hal: Box<dyn Hal>,
    queue: rtrb::Consumer<Segment>,
    commands: rtrb::Consumer<ServoCommand>,
    /// Aborting this program: stop, then flush to its marker.
    aborting: Option<u32>,
    setpoints: Setpoints,
    feedback: Feedback,
    snapshot: Snapshot,
    export: Option<Box<Export>>,
}

impl ServoTick {
    /// A tick of `period` seconds for a machine resting at `start`.
    pub fn new(
        period: f64,
        start: Position,
        kins: Arc<dyn Kinematics>,
        hal: Box<dyn Hal>,
        queue: rtrb::Consumer<Segment>,
        commands: rtrb::Consumer<ServoCommand>,
    ) -> Result<ServoTick, KinematicsError> {
        let n = kins.joints().len();
        let mut joints = [0.0; MAX_JOINTS];
        kins.inverse(&start, &mut joints[..n])?;
        let mut setpoints = Setpoints::default();
        for (cmd, q) in setpoints.joints.iter_mut().zip(&joints[..n]) {
            cmd.position = *q;
        }
        setpoints.enable = true;
        Ok(ServoTick {
            period,
            executor: Executor::new(start),
            kins,
            hal,
            queue,
            commands,
            aborting: None,
            setpoints,
            feedback: Feedback::default(),
            snapshot: Snapshot::at_rest(start, &joints[..n]),
            export: None,
        })
    }

    /// Publish the status and `pins` through `shm` every tick from now on.
    pub fn export_to(&mut self, shm: ShmExport, pins: PinBank) {
        self.export = Some(Box::new(Export {
            shm,
            pins,
            frame: StatusFrame::default(),
        }));
    }

    /// The servo period in seconds.
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The last published snapshot.
    pub fn snapshot(&self) -> &Snapshot {
        &self.snapshot
    }

    /// Run one servo period.
    pub fn tick(&mut self) -> &Snapshot {
        while let Ok(cmd) = self.commands.pop() {
            match cmd {
                ServoCommand::FeedOverride(f) => self.executor.set_feed_override(f),
                ServoCommand::RapidOverride(f) => self.executor.set_rapid_override(f),
                ServoCommand::Hold(on) => self.executor.set_hold(on),
                ServoCommand::SingleBlock(on) => self.executor.set_single_block(on),
                ServoCommand::Step => self.executor.step(),
                ServoCommand::Abort { program } => {
                    self.aborting = Some(program);
                    self.executor.set_hold(true);
                }
            }
        }
        let snap = &mut self.snapshot;
        snap.ticks += 1;
        let n = snap.joint_count;
        if let (Some(program), true) = (self.aborting, self.executor.velocity() == 0.0) {
            // At rest: drop what is queued up to the planner's final marker.
            while let Ok(seg) = self.queue.pop() {
                if seg.kind == (SegmentKind::Stop { tag: program }) {
                    self.aborting = None;
                    snap.program_aborted = program;
                    self.executor.reset_queue();
                    self.executor.set_hold(false);
                    break;
                }
            }
        }
        if snap.fault.is_none() && self.aborting.is_none_or(|_| self.executor.velocity() > 0.0) {
            let chunk = self
                .queue
                .read_chunk(self.queue.slots())
                .expect("slots() items are readable");
            let (head, tail) = chunk.as_slices();
            let sample = self.executor.tick(self.period, head, tail);
            chunk.commit(sample.consumed);
            if let Some(tag) = sample.stopped_at {
                snap.program_done = tag;
            }
            snap.moving = sample.moving;
            snap.line = sample.line;
            snap.velocity = sample.velocity;
            let mut q = [0.0; MAX_JOINTS];
            match self.kins.inverse(&sample.position, &mut q[..n]) {
                Ok(()) => {
                    snap.commanded = sample.position;
                    for (cmd, &target) in self.setpoints.joints.iter_mut().zip(&q[..n]) {
                        cmd.velocity = (target - cmd.position) / self.period;
                        cmd.position = target;
                    }
                }
                Err(e) => snap.fault = Some(ServoFault::Kinematics(e)),
            }
        }
        snap.hold = self.executor.is_held();
        snap.feed_override = self.executor.feed_override();
        snap.rapid_override = self.executor.rapid_override();
        // A fault disables the drives: they hold where they are.
        self.setpoints.enable = snap.fault.is_none();
        if let Err(e) = self
            .hal
            .exchange(self.period, &self.setpoints, &mut self.feedback)
        {
            snap.fault.get_or_insert(ServoFault::Hal(e));
        }
        for i in 0..n {
            snap.joints[i] = self.feedback.joints[i].position;
        }
        match self.kins.forward(&snap.joints[..n], &snap.position) {
            Ok(p) => snap.position = p,
            Err(e) => {
                snap.fault.get_or_insert(ServoFault::Kinematics(e));
            }
        }
        if snap.fault.is_some() {
            snap.moving = false;
        }
        if let Some(ex) = self.export.as_deref_mut() {
            let f = &mut ex.frame;
            f.tick = snap.ticks;
            f.joint_count = n as u32;
            f.state = match (snap.fault.is_some(), snap.moving) {
                (true, _) => shm::state::FAULT,
                (false, true) => shm::state::RUNNING,
                (false, false) => shm::state::IDLE,
            };
            for i in 0..n {
                let (cmd, fb) = (&self.setpoints.joints[i], &self.feedback.joints[i]);
                f.position[i] = fb.position;
                f.velocity[i] = fb.velocity;
                f.following_error[i] = cmd.position - fb.position;
            }
            f.line = snap.line;
            f.feed_override = snap.feed_override;
            f.fault = snap.fault.is_some() as u32;
            ex.shm.exchange(f, &mut ex.pins);
        }
        &self.snapshot
    }
}

/// A running servo thread.
pub struct ServoThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl ServoThread {
    /// Start ticking `tick` every period on the wall clock (CLOCK_MONOTONIC,
    /// absolute deadlines, so sleep jitter does not accumulate), publishing
    /// each snapshot to `status`.
    pub fn spawn(
        mut tick: ServoTick,
        mut status: Writer<Snapshot>,
    ) -> std::io::Result<ServoThread> {
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let period = Duration::from_secs_f64(tick.period());
        let handle = std::thread::Builder::new()
            .name("kerf-servo".into())
            .spawn(move || {
                let period_ns = period.as_nanos() as i64;
                let mut deadline = now_ns();
                let mut overruns = 0;
                while !stop_flag.load(Ordering::Relaxed) {
                    deadline += period_ns;
                    sleep_until_ns(deadline);
                    let late = now_ns() - deadline;
                    if late >= period_ns {
                        // Missed at least a whole period: count it and restart the
                        // schedule from now rather than running a burst of ticks.
                        overruns += 1;
                        deadline = now_ns();
                    }
                    tick.tick();
                    let mut snap = *tick.snapshot();
                    snap.overruns = overruns;
                    status.write(&snap);
                }
            })?;
        Ok(ServoThread {
            stop,
            handle: Some(handle),
        })
    }

    /// Stop the thread and wait for it.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

impl Drop for ServoThread {
    fn drop(&mut self) {
        self.stop();
    }
}

fn now_ns() -> i64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec * 1_000_000_000 + ts.tv_nsec
}

fn sleep_until_ns(deadline: i64) {
    let ts = libc::timespec {
        tv_sec: deadline / 1_000_000_000,
        tv_nsec: deadline % 1_000_000_000,
    };
    // SAFETY: valid timespec; an EINTR wake-up simply returns early and the
    // lateness check in the loop handles it.
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        );
    }
}
