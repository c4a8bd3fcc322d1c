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
    /// Ignored if that marker has already been reached or discarded.
    Abort { program: u32 },
    /// Drives on or off. Off stops motion at once (no deceleration: this is
    /// the e-stop path) and discards everything queued from then on until
    /// the drives are on again; on restarts the executor from the measured
    /// pose, so nothing jumps. Refused (stays off) while a fault is latched.
    Enable(bool),
    /// Forget a latched fault. The drives stay off until `Enable(true)`.
    ClearFault,
}

/// Why the servo stopped motion. `Copy`, so it fits in the snapshot.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ServoFault {
    #[error("hardware: {0}")]
    Hal(HalFault),
    #[error("kinematics: {0}")]
    Kinematics(KinematicsError),
    /// A joint lagged (or led) its command by more than its limit, mm.
    #[error("joint {joint} following error {error:.4} exceeds its limit {limit:.4}")]
    FollowingError {
        joint: usize,
        error: f64,
        limit: f64,
    },
}

impl ServoFault {
    /// The fault as the operator should read it, naming joints by their
    /// names on `kins`.
    pub fn describe(&self, kins: &dyn Kinematics) -> String {
        let name = |j: usize| {
            kins.joints()
                .get(j)
                .map(|s| s.name.clone())
                .unwrap_or_else(|| j.to_string())
        };
        match *self {
            ServoFault::Hal(e) => format!("hardware: {e}"),
            ServoFault::Kinematics(e) => format!("kinematics: {}", e.describe(kins)),
            ServoFault::FollowingError {
                joint,
                error,
                limit,
            } => format!(
                "following error: joint {} is {:.4} from its command, more than its limit {:.4}",
                name(joint),
                error.abs(),
                limit
            ),
        }
    }
}

/// Upper bounds of the wake-up latency histogram buckets, ns; the last
/// bucket counts everything later than the last bound.
pub const LATENCY_BOUNDS_NS: [u64; 7] =
    [10_000, 20_000, 50_000, 100_000, 200_000, 500_000, 1_000_000];

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
    /// Set when motion was stopped by a fault; latched until `ClearFault`.
    pub fault: Option<ServoFault>,
    /// The drives are enabled (and no fault is latched).
    pub enabled: bool,
    /// Single-block mode is on.
    pub single_block: bool,
    /// Queue items taken off the queue since start, run or discarded; the
    /// producer counts what it pushes, so it can tell when an item is done.
    pub consumed: u64,
    /// Latest wake-up of the servo thread after its deadline, ns.
    pub latency_max_ns: u64,
    /// Wake-ups by lateness: bucket `i` counts those up to
    /// [`LATENCY_BOUNDS_NS`]`[i]`, the last bucket the rest.
    pub latency_histogram: [u64; LATENCY_BOUNDS_NS.len() + 1],
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
            enabled: false,
            single_block: false,
            consumed: 0,
            latency_max_ns: 0,
            latency_histogram: [0; LATENCY_BOUNDS_NS.len() + 1],
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
    /// Drives commanded on (cleared by a fault).
    enabled: bool,
    /// Largest |command − feedback| per joint before a fault, mm (infinite: unchecked).
    following_limits: [f64; MAX_JOINTS],
    setpoints: Setpoints,
    feedback: Feedback,
    snapshot: Snapshot,
    export: Option<Box<Export>>,
}

impl ServoTick {
    /// A tick of `period` seconds for a machine resting at `start`, with
    /// its drives off until [`ServoCommand::Enable`].
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
        Ok(ServoTick {
            period,
            executor: Executor::new(start),
            kins,
            hal,
            queue,
            commands,
            aborting: None,
            enabled: false,
            following_limits: [f64::INFINITY; MAX_JOINTS],
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

    /// Fault when a joint's feedback is further than `limits[j]` (mm) from
    /// its command; `None` (or a missing entry) leaves the joint unchecked.
    pub fn set_following_error_limits(&mut self, limits: &[Option<f64>]) {
        for (slot, limit) in self.following_limits.iter_mut().zip(limits) {
            *slot = limit.unwrap_or(f64::INFINITY);
        }
    }

    fn command(&mut self, cmd: ServoCommand) {
        match cmd {
            ServoCommand::FeedOverride(f) => self.executor.set_feed_override(f),
            ServoCommand::RapidOverride(f) => self.executor.set_rapid_override(f),
            ServoCommand::Hold(on) => self.executor.set_hold(on),
            ServoCommand::SingleBlock(on) => {
                self.executor.set_single_block(on);
                self.snapshot.single_block = on;
            }
            ServoCommand::Step => self.executor.step(),
            ServoCommand::Abort { program } => {
                let snap = &self.snapshot;
                if program > snap.program_done.max(snap.program_aborted) {
                    self.aborting = Some(program);
                    self.executor.set_hold(true);
                }
            }
            ServoCommand::Enable(true) if self.snapshot.fault.is_some() => {}
            ServoCommand::Enable(true) => {
                if !self.enabled {
                    // Start over from where the machine really is; the
                    // overrides survive, like on a real control panel.
                    let snap = &mut self.snapshot;
                    let (feed, rapid) = (
                        self.executor.feed_override(),
                        self.executor.rapid_override(),
                    );
                    self.executor = Executor::new(snap.position);
                    self.executor.set_feed_override(feed);
                    self.executor.set_rapid_override(rapid);
                    snap.single_block = false;
                    snap.commanded = snap.position;
                    for (cmd, &q) in self.setpoints.joints.iter_mut().zip(&snap.joints) {
                        cmd.position = q;
                        cmd.velocity = 0.0;
                    }
                }
                self.enabled = true;
            }
            ServoCommand::Enable(false) => self.enabled = false,
            ServoCommand::ClearFault => self.snapshot.fault = None,
        }
    }

    /// Take everything off the queue without running it (drives off or
    /// faulted); `Stop` markers taken this way count as aborted.
    fn discard_queue(&mut self) {
        let snap = &mut self.snapshot;
        while let Ok(seg) = self.queue.pop() {
            snap.consumed += 1;
            if let SegmentKind::Stop { tag } = seg.kind {
                snap.program_aborted = tag;
                if self.aborting.is_some_and(|a| a <= tag) {
                    self.aborting = None;
                }
            }
        }
    }

    /// Run one servo period.
    pub fn tick(&mut self) -> &Snapshot {
        while let Ok(cmd) = self.commands.pop() {
            self.command(cmd);
        }
        self.snapshot.ticks += 1;
        let n = self.snapshot.joint_count;
        let active = self.enabled && self.snapshot.fault.is_none();
        if !active {
            self.discard_queue();
            let snap = &mut self.snapshot;
            snap.moving = false;
            snap.velocity = 0.0;
        } else {
            self.run_executor(n);
        }
        let snap = &mut self.snapshot;
        snap.hold = self.executor.is_held();
        snap.feed_override = self.executor.feed_override();
        snap.rapid_override = self.executor.rapid_override();
        // A fault or e-stop disables the drives: they hold where they are.
        self.setpoints.enable = active && snap.fault.is_none();
        if let Err(e) = self
            .hal
            .exchange(self.period, &self.setpoints, &mut self.feedback)
        {
            snap.fault.get_or_insert(ServoFault::Hal(e));
        }
        for i in 0..n {
            snap.joints[i] = self.feedback.joints[i].position;
        }
        if self.setpoints.enable && snap.fault.is_none() {
            for i in 0..n {
                let error = self.setpoints.joints[i].position - snap.joints[i];
                if error.abs() > self.following_limits[i] {
                    snap.fault = Some(ServoFault::FollowingError {
                        joint: i,
                        error,
                        limit: self.following_limits[i],
                    });
                    break;
                }
            }
        }
        match self.kins.forward(&snap.joints[..n], &snap.position) {
            Ok(p) => snap.position = p,
            Err(e) => {
                snap.fault.get_or_insert(ServoFault::Kinematics(e));
            }
        }
        if !self.setpoints.enable {
            // Off: the command follows the machine, so turning on is smooth.
            snap.commanded = snap.position;
            for (cmd, &q) in self.setpoints.joints.iter_mut().zip(&snap.joints[..n]) {
                cmd.position = q;
                cmd.velocity = 0.0;
            }
        }
        if snap.fault.is_some() {
            snap.moving = false;
            self.enabled = false;
        }
        snap.enabled = self.enabled;
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

    fn run_executor(&mut self, n: usize) {
        let snap = &mut self.snapshot;
        if let (Some(program), true) = (self.aborting, self.executor.velocity() == 0.0) {
            // At rest: drop what is queued up to the planner's final marker.
            while let Ok(seg) = self.queue.pop() {
                snap.consumed += 1;
                if seg.kind == (SegmentKind::Stop { tag: program }) {
                    self.aborting = None;
                    snap.program_aborted = program;
                    self.executor.reset_queue();
                    self.executor.set_hold(false);
                    self.executor.set_single_block(false);
                    snap.single_block = false;
                    break;
                }
            }
        }
        if self.aborting.is_some() && self.executor.velocity() == 0.0 {
            // Still waiting for the planner's marker: stay put.
            snap.moving = false;
            return;
        }
        let chunk = self
            .queue
            .read_chunk(self.queue.slots())
            .expect("slots() items are readable");
        let (head, tail) = chunk.as_slices();
        let sample = self.executor.tick(self.period, head, tail);
        chunk.commit(sample.consumed);
        snap.consumed += sample.consumed as u64;
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
    ///
    /// With `priority` 1 to 99 the thread asks for `SCHED_FIFO` at that
    /// priority first; where the OS refuses (no `CAP_SYS_NICE`, no
    /// `LimitRTPRIO`), it says so in the log and runs at normal priority.
    /// With `cpu`, it pins itself to that CPU (e.g. one isolated with
    /// `isolcpus=`), or says in the log why it could not.
    pub fn spawn(
        mut tick: ServoTick,
        mut status: Writer<Snapshot>,
        priority: u8,
        cpu: Option<usize>,
    ) -> std::io::Result<ServoThread> {
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let period = Duration::from_secs_f64(tick.period());
        let handle = std::thread::Builder::new()
            .name("kerf-servo".into())
            .spawn(move || {
                if priority > 0 {
                    match make_realtime(priority) {
                        Ok(()) => tracing::info!(priority, "servo thread runs SCHED_FIFO"),
                        Err(e) => tracing::warn!(
                            "servo thread runs without real-time priority ({e}): expect late \
                             ticks under load; see docs/deploy.md"
                        ),
                    }
                }
                // Pinned after going real-time, so the move to the CPU
                // itself happens at real-time priority.
                if let Some(cpu) = cpu {
                    match pin_to_cpu(cpu) {
                        Ok(()) => tracing::info!(cpu, "servo thread pinned"),
                        Err(e) => tracing::warn!(cpu, "cannot pin the servo thread: {e}"),
                    }
                }
                let period_ns = period.as_nanos() as i64;
                let mut deadline = now_ns();
                let mut overruns = 0;
                let mut latency_max = 0u64;
                let mut histogram = [0u64; LATENCY_BOUNDS_NS.len() + 1];
                while !stop_flag.load(Ordering::Relaxed) {
                    deadline += period_ns;
                    sleep_until_ns(deadline);
                    let late = now_ns() - deadline;
                    let late_ns = late.max(0) as u64;
                    latency_max = latency_max.max(late_ns);
                    let bucket = LATENCY_BOUNDS_NS
                        .iter()
                        .position(|&b| late_ns <= b)
                        .unwrap_or(LATENCY_BOUNDS_NS.len());
                    histogram[bucket] += 1;
                    if late >= period_ns {
                        // Missed at least a whole period: count it and restart the
                        // schedule from now rather than running a burst of ticks.
                        overruns += 1;
                        deadline = now_ns();
                    }
                    tick.tick();
                    let mut snap = *tick.snapshot();
                    snap.overruns = overruns;
                    snap.latency_max_ns = latency_max;
                    snap.latency_histogram = histogram;
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

/// Run the calling thread on `cpu` only.
fn pin_to_cpu(cpu: usize) -> nix::Result<()> {
    let mut set = nix::sched::CpuSet::new();
    set.set(cpu)?;
    nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set)
}

/// Switch the calling thread to `SCHED_FIFO` at `priority`.
fn make_realtime(priority: u8) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: i32::from(priority),
    };
    // SAFETY: valid pointer to a sched_param for the calling thread.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::from_raw_os_error(rc))
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
