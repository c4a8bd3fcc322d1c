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
use kerf_machines::Description;
use kerf_motion::control::{JointLoops, LoopGains};
use kerf_motion::fuzzy::{self, ForceControl};
use kerf_motion::{
    Executor, InputRequest, Kinematics, KinematicsError, OutputChange, Segment, SegmentKind,
    MAX_ANALOG_OUTPUTS, MAX_DIGITAL_OUTPUTS, MAX_JOINTS,
};

use crate::latency::{LatencyHistogram, LatencyStats};
use crate::seqlock::Writer;

const _: () = assert!(MAX_JOINTS == kerf_io::MAX_JOINTS);
const _: () = assert!(MAX_DIGITAL_OUTPUTS == kerf_io::pins::MAX_DIGITAL);
const _: () = assert!(MAX_ANALOG_OUTPUTS == kerf_io::pins::MAX_ANALOG);

/// An operator command for the servo thread, sent through a lock-free queue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ServoCommand {
    /// Feed override factor, 0 to 2.
    FeedOverride(f64),
    /// Rapid override factor, 0 to 1.
    RapidOverride(f64),
    /// Spindle speed override factor, 0 to 2.
    SpindleOverride(f64),
    /// Feed hold on (decelerate on the path and wait) or off (resume).
    Hold(bool),
    /// Single-block mode on or off.
    SingleBlock(bool),
    /// In single-block mode, run the next source line.
    Step,
    /// The operator resumed at program stop number `reached` (as counted
    /// in [`Snapshot::program_stops`]): go on if the tool still waits
    /// there. A release for another stop, or sent while the tool moves,
    /// does nothing, so it can never carry the tool past a stop it has
    /// not reached yet.
    ReleaseStop { reached: u64 },
    /// The optional-stop switch: whether M1 waits for the operator.
    OptionalStop(bool),
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
    /// Cutting-force control on with this target force (N), or off. Ignored
    /// by a machine without `[force_control]`.
    ForceControl(Option<f64>),
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

/// The cutting-force controller as the snapshot shows it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForceStatus {
    /// Target force F_d, N, while on.
    pub target: Option<f64>,
    /// Largest force of the last controller step, estimated from the
    /// spindle current, N.
    pub force: f64,
    /// Feed override the controller asks for (1 while off); it multiplies
    /// the operator's feed override.
    pub feed_override: f64,
}

/// What the servo thread publishes every tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// Ticks run since start.
    pub ticks: u64,
    /// Wake-ups that came a whole period or more late.
    pub overruns: u64,
    /// Periods in which the executor followed its guard (a checked way to
    /// rest) instead of the state its search chose
    /// ([`Executor::guard_takeovers`](kerf_motion::Executor::guard_takeovers)).
    pub guard_takeovers: u64,
    /// A segment is in progress.
    pub moving: bool,
    /// Source line of the current (or last) segment.
    pub line: u32,
    /// The programmed moves the commanded position lies along
    /// ([`Sample::moves`](kerf_motion::Sample::moves)).
    pub moves: kerf_motion::SourceMoves,
    /// Id of the last program whose every segment has run (0: none yet).
    pub program_done: u32,
    /// Id of the last program that was aborted and flushed (0: none yet).
    pub program_aborted: u32,
    /// M66 waits answered so far, and the last answer (#5399: 1/0 for a
    /// digital input, the reading for an analog one, −1 on timeout).
    pub inputs_answered: u64,
    pub input_value: f64,
    /// Path speed, mm/s.
    pub velocity: f64,
    /// Feed and rapid override factors in force.
    pub feed_override: f64,
    pub rapid_override: f64,
    /// Spindle speed override factor in force.
    pub spindle_override: f64,
    /// Feed hold is on.
    pub hold: bool,
    /// Program stops (M0, M60, M1 with the switch on) the tool has come to
    /// wait at since start.
    pub program_stops: u64,
    /// The tool waits at program stop number `program_stops` for
    /// [`ServoCommand::ReleaseStop`].
    pub at_program_stop: bool,
    /// The optional-stop switch is on: M1 waits for the operator.
    pub optional_stop: bool,
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
    /// Commanded minus measured position per joint at the end of the
    /// last period, mm; the first `joint_count` are used.
    pub following_error: [f64; MAX_JOINTS],
    /// The cutting-force controller, if the machine has one.
    pub force: Option<ForceStatus>,
    /// Wake-up latency of the servo thread (zero on a virtual clock).
    pub latency: LatencyStats,
}

impl Snapshot {
    /// The snapshot of a machine at rest at `position`.
    pub fn at_rest(position: Position, joints: &[f64]) -> Snapshot {
        let mut j = [0.0; MAX_JOINTS];
        j[..joints.len()].copy_from_slice(joints);
        Snapshot {
            ticks: 0,
            overruns: 0,
            guard_takeovers: 0,
            moving: false,
            line: 0,
            moves: kerf_motion::SourceMoves::default(),
            program_done: 0,
            inputs_answered: 0,
            input_value: 0.0,
            program_aborted: 0,
            velocity: 0.0,
            feed_override: 1.0,
            rapid_override: 1.0,
            spindle_override: 1.0,
            hold: false,
            program_stops: 0,
            at_program_stop: false,
            optional_stop: true,
            commanded: position,
            position,
            joints: j,
            joint_count: joints.len(),
            fault: None,
            enabled: false,
            single_block: false,
            consumed: 0,
            following_error: [0.0; MAX_JOINTS],
            force: None,
            latency: LatencyStats::default(),
        }
    }
}

/// Status and pins published to shared memory every tick.
struct Export {
    shm: ShmExport,
    frame: StatusFrame,
}

/// Everything one servo tick touches.
pub struct ServoTick {
    /// Set while a planner thread is still feeding the queue (see
    /// [`ServoTick::set_streaming_flag`]); read only on a virtual clock.
    streaming: Option<Arc<AtomicBool>>,
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
    /// The I/O pins M62–M68 set (none until [`ServoTick::set_pins`]).
    pins: PinBank,
    /// The head segment's synchronised outputs have been applied (its
    /// motion started in an earlier tick).
    head_outputs_done: bool,
    /// The M66 wait at the head of the queue, while it waits.
    input_wait: Option<kerf_io::pins::InputWait>,
    /// The executor's last tick found the queued motion waiting on the
    /// operator alone.
    waits_on_operator: bool,
    /// Position loops of the joints (their output drives plants that take
    /// an effort; position drives ignore it).
    loops: JointLoops,
    /// Spindle speed while enabled, rpm.
    spindle_rpm: f64,
    force: Option<ForceControl>,
    /// Force control as the running program last set it.
    program_force: Option<f64>,
    /// The executor moved at the feed the override asks for this tick
    /// (see [`FEEDING_SHARE`]), for the force controller.
    feeding: bool,
}

/// Share of the commanded feed (programmed × overrides, capped by the
/// segment's speed limit) below which the force controller takes the
/// machine to be changing speed, not cutting at the feed it set.
const FEEDING_SHARE: f64 = 0.5;

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
        let mut feedback = Feedback::default();
        for ((cmd, fb), q) in setpoints
            .joints
            .iter_mut()
            .zip(feedback.joints.iter_mut())
            .zip(&joints[..n])
        {
            cmd.position = *q;
            fb.position = *q;
        }
        Ok(ServoTick {
            streaming: None,
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
            feedback,
            snapshot: Snapshot::at_rest(start, &joints[..n]),
            export: None,
            pins: PinBank::new(&kerf_io::PinConfig::default()),
            head_outputs_done: false,
            input_wait: None,
            waits_on_operator: false,
            loops: JointLoops::new(&[LoopGains::SEED; MAX_JOINTS][..n], &joints[..n]),
            spindle_rpm: 0.0,
            force: None,
            program_force: None,
            feeding: false,
        })
    }

    /// Take the servo settings of a machine description: each joint's loop
    /// gains and following-error limit, the spindle speed, and the force
    /// controller.
    pub fn configure(&mut self, machine: &Description) {
        let n = self.snapshot.joint_count;
        let gains: Vec<LoopGains> = machine.joints.iter().map(|j| j.loop_gains()).collect();
        self.loops = JointLoops::new(&gains[..n], &self.snapshot.joints[..n]);
        let limits: Vec<Option<f64>> = machine.joints.iter().map(|j| j.following_error).collect();
        self.set_following_error_limits(&limits);
        self.spindle_rpm = machine.spindle.map_or(0.0, |s| s.rpm);
        self.force = match (&machine.spindle, &machine.force_control) {
            (Some(spindle), Some(fc)) => {
                let mut control = ForceControl::new(
                    fc.config(),
                    spindle.sensor(),
                    fuzzy::ticks_per_step(spindle.rpm, self.period),
                );
                control.set_target(fc.target);
                Some(control)
            }
            _ => None,
        };
        self.publish_force();
    }

    /// Fault when a joint's feedback is further than `limits[j]` (mm) from
    /// its command; `None` (or a missing entry) leaves the joint unchecked.
    pub fn set_following_error_limits(&mut self, limits: &[Option<f64>]) {
        for (slot, limit) in self.following_limits.iter_mut().zip(limits) {
            *slot = limit.unwrap_or(f64::INFINITY);
        }
    }

    /// Velocity and acceleration feedforward on (default) or off (the
    /// seed's pure PD).
    pub fn set_feedforward(&mut self, on: bool) {
        self.loops.set_feedforward(on);
    }

    /// This period's setpoints, as sent to the HAL.
    pub fn setpoints(&self) -> &Setpoints {
        &self.setpoints
    }

    /// The HAL's feedback from the last period.
    pub fn feedback(&self) -> &Feedback {
        &self.feedback
    }

    /// The force controller's state into the snapshot.
    fn publish_force(&mut self) {
        self.snapshot.force = self.force.as_ref().map(|fc| ForceStatus {
            target: fc.target(),
            force: fc.last_step().force,
            feed_override: fc.feed_override(),
        });
    }

    /// Share the flag a planner thread holds up while it still has
    /// segments to queue. On a virtual clock an empty queue then means the
    /// planner is behind, not that the program has ended, and the servo
    /// waits for it instead of stopping the machine mid-path.
    pub fn set_streaming_flag(&mut self, flag: Arc<AtomicBool>) {
        self.streaming = Some(flag);
    }

    /// True while the queue is empty but a planner thread is still feeding it.
    fn starved(&self) -> bool {
        self.queue.slots() == 0
            && self
                .streaming
                .as_ref()
                .is_some_and(|f| f.load(Ordering::Acquire))
    }

    /// Commands are waiting for the next tick.
    pub fn has_commands(&self) -> bool {
        !self.commands.is_empty()
    }

    /// True while queued motion waits on the operator alone, as of the
    /// last tick ([`Sample::waits_on_operator`]).
    ///
    /// [`Sample::waits_on_operator`]: kerf_motion::Sample::waits_on_operator
    pub fn waiting_on_operator(&self) -> bool {
        self.waits_on_operator
    }

    /// True once everything the executor needs ahead is queued: the queue
    /// is empty, full, or holds a `Stop` marker (the rest of a program) or
    /// an M66 wait (the planner waits for its answer).
    /// A servo on a virtual clock waits for this before each tick, so a
    /// run does not depend on how fast the planner thread is.
    pub fn input_complete(&mut self) -> bool {
        let slots = self.queue.slots();
        if slots == 0 || slots == self.queue.buffer().capacity() {
            return true;
        }
        let Ok(chunk) = self.queue.read_chunk(slots) else {
            return true;
        };
        let (head, tail) = chunk.as_slices();
        head.iter()
            .chain(tail)
            // A Stop ends the program; nothing follows an M66 until the
            // servo has answered it.
            .any(|s| matches!(s.kind, SegmentKind::Stop { .. } | SegmentKind::WaitInput(_)))
    }

    /// Publish the status and `pins` through `shm` every tick from now on.
    pub fn export_to(&mut self, shm: ShmExport, pins: PinBank) {
        self.pins = pins;
        self.export = Some(Box::new(Export {
            shm,
            frame: StatusFrame::default(),
        }));
    }

    /// The machine's I/O pins (from `[hal.pins]`), which the program's
    /// M62–M68 set.
    pub fn set_pins(&mut self, pins: PinBank) {
        self.pins = pins;
    }

    /// The I/O pins as of the last tick.
    pub fn pins(&self) -> &PinBank {
        &self.pins
    }

    /// Store an input pin's value, as the shared-memory export does (for
    /// tests and machines without one).
    pub fn pins_mut(&mut self) -> &mut PinBank {
        &mut self.pins
    }

    /// The servo period in seconds.
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The last published snapshot.
    pub fn snapshot(&self) -> &Snapshot {
        &self.snapshot
    }

    fn command(&mut self, cmd: ServoCommand) {
        match cmd {
            ServoCommand::FeedOverride(f) => self.executor.set_feed_override(f),
            ServoCommand::RapidOverride(f) => self.executor.set_rapid_override(f),
            // Outside the executor, so it survives a re-enable as the
            // other overrides do.
            ServoCommand::SpindleOverride(f) => self.snapshot.spindle_override = f,
            ServoCommand::Hold(on) => self.executor.set_hold(on),
            ServoCommand::SingleBlock(on) => {
                self.executor.set_single_block(on);
                self.snapshot.single_block = on;
            }
            ServoCommand::Step => self.executor.step(),
            ServoCommand::ReleaseStop { reached } => {
                let snap = &self.snapshot;
                if snap.at_program_stop && snap.program_stops == reached {
                    self.executor.release_stop();
                }
            }
            ServoCommand::OptionalStop(on) => {
                self.executor.set_optional_stop(on);
                self.snapshot.optional_stop = on;
            }
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
                    self.executor.set_optional_stop(snap.optional_stop);
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
            ServoCommand::ForceControl(target) => {
                if let Some(fc) = &mut self.force {
                    fc.set_target(target);
                }
            }
        }
    }

    /// Take everything off the queue without running it (drives off or
    /// faulted); `Stop` markers taken this way count as aborted.
    fn discard_queue(&mut self) {
        let snap = &mut self.snapshot;
        snap.at_program_stop = false;
        while let Ok(seg) = self.queue.pop() {
            snap.consumed += 1;
            self.head_outputs_done = false;
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
        // Set again where the executor runs.
        self.feeding = false;
        self.waits_on_operator = false;
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
        snap.guard_takeovers = self.executor.guard_takeovers();
        // A fault or e-stop disables the drives: they hold where they are.
        self.setpoints.enable = active && snap.fault.is_none();
        self.inner_loop(n);
        let snap = &mut self.snapshot;
        if let Err(e) = self
            .hal
            .exchange(self.period, &self.setpoints, &mut self.feedback)
        {
            snap.fault.get_or_insert(ServoFault::Hal(e));
        }
        for i in 0..n {
            snap.joints[i] = self.feedback.joints[i].position;
            snap.following_error[i] = self.setpoints.joints[i].position - snap.joints[i];
        }
        if self.setpoints.enable && snap.fault.is_none() {
            for i in 0..n {
                let error = snap.following_error[i];
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
        if let Some(fc) = &mut self.force {
            fc.tick(self.feedback.spindle_current, self.feeding);
            self.executor.set_feed_scale(fc.feed_override());
        }
        self.publish_force();
        let snap = &mut self.snapshot;
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
            // The feed override that acts: the operator's times the force
            // controller's.
            let force = snap.force.unwrap_or_default();
            f.feed_override = snap.feed_override * snap.force.map_or(1.0, |c| c.feed_override);
            f.force = force.force;
            f.fault = snap.fault.is_some() as u32;
            ex.shm.exchange(f, &mut self.pins);
        }
        &self.snapshot
    }

    fn run_executor(&mut self, n: usize) {
        let snap = &mut self.snapshot;
        if let (Some(program), true) = (self.aborting, self.executor.velocity() == 0.0) {
            // At rest: drop what is queued up to the planner's final marker.
            while let Ok(seg) = self.queue.pop() {
                snap.consumed += 1;
                self.head_outputs_done = false;
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
            snap.at_program_stop = false;
            return;
        }
        let chunk = self
            .queue
            .read_chunk(self.queue.slots())
            .expect("slots() items are readable");
        let (head, tail) = chunk.as_slices();
        // An M66 at the head (the tool is at rest there): poll its input
        // each period and let the executor pass once it answers.
        match head.first().or(tail.first()).map(|s| s.kind) {
            Some(SegmentKind::WaitInput(req)) => {
                let wait = match self.input_wait {
                    Some(w) => Some(w),
                    None => start_input_wait(&self.pins, req),
                };
                let answer = match wait {
                    Some(mut w) => {
                        let answer = w.poll(&self.pins, self.period);
                        self.input_wait = Some(w);
                        answer
                    }
                    // The planner checked the pin; a machine without it
                    // answers "timed out" rather than hang.
                    None => Some(-1.0),
                };
                if let Some(value) = answer {
                    self.input_wait = None;
                    snap.inputs_answered += 1;
                    snap.input_value = value;
                    self.executor.release_input();
                }
            }
            _ => self.input_wait = None,
        }
        let sample = self.executor.tick(self.period, head, tail);
        self.waits_on_operator = sample.waits_on_operator;
        if sample.program_stop && !snap.at_program_stop {
            snap.program_stops += 1;
        }
        snap.at_program_stop = sample.program_stop;
        // The program's force control changes when a segment that asks for
        // something else starts.
        let current = match head.get(sample.consumed) {
            Some(seg) => Some(seg),
            None => tail.get(sample.consumed - head.len()),
        };
        self.feeding = current.is_some_and(|seg| {
            let ex = &self.executor;
            let commanded = seg
                .max_velocity
                .min(seg.feed * ex.feed_override() * ex.feed_scale());
            seg.kind == SegmentKind::Feed
                && !ex.is_held()
                && sample.velocity >= FEEDING_SHARE * commanded
        });
        if let (Some(seg), Some(fc)) = (current.filter(|s| s.is_motion()), &mut self.force) {
            if seg.force_control != self.program_force {
                self.program_force = seg.force_control;
                fc.set_target(seg.force_control);
            }
        }
        // Outputs, in queue order: what was passed this period (markers,
        // and motion that started and ended within it), then the segment
        // now running once the tool has left its start.
        for (i, seg) in head.iter().chain(tail).take(sample.consumed).enumerate() {
            if !(i == 0 && self.head_outputs_done) {
                apply_outputs(&mut self.pins, seg);
            }
        }
        if sample.consumed > 0 {
            self.head_outputs_done = false;
        }
        if let Some(seg) = current.filter(|s| s.is_motion()) {
            if !self.head_outputs_done && self.executor.progress() > 0.0 {
                apply_outputs(&mut self.pins, seg);
                self.head_outputs_done = true;
            }
        }
        chunk.commit(sample.consumed);
        snap.consumed += sample.consumed as u64;
        if let Some(tag) = sample.stopped_at {
            snap.program_done = tag;
        }
        snap.moving = sample.moving;
        snap.line = sample.line;
        snap.moves = sample.moves;
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

/// The wait an M66 asks for, if this machine has its input. Checked here
/// rather than left to `InputWait::new`, whose error message would
/// allocate inside the tick.
fn start_input_wait(pins: &PinBank, req: InputRequest) -> Option<kerf_io::pins::InputWait> {
    use kerf_io::pins::{InputWait, WaitInput, WaitMode};
    let (_, digital_in, _, analog_in) = pins.counts();
    let n = req.index as usize;
    let input = match req.digital {
        true if n < digital_in => WaitInput::Digital(n),
        false if n < analog_in && req.mode == 0 => WaitInput::Analog(n),
        _ => return None,
    };
    if !(req.timeout >= 0.0 && req.timeout.is_finite()) {
        return None;
    }
    let mode = match req.mode {
        1 => WaitMode::Rise,
        2 => WaitMode::Fall,
        3 => WaitMode::High,
        4 => WaitMode::Low,
        _ => WaitMode::Immediate,
    };
    InputWait::new(pins, input, mode, req.timeout).ok()
}

/// Set the outputs `seg` changes: an immediate output marker's, or the
/// synchronised ones a motion segment carries. Pin numbers were checked
/// against the machine when planned, so a bad one is ignored here.
fn apply_outputs(pins: &mut PinBank, seg: &Segment) {
    match seg.kind {
        SegmentKind::Output(OutputChange::Digital { index, on }) => {
            let _ = pins.set_digital(index as usize, on);
        }
        SegmentKind::Output(OutputChange::Analog { index, value }) => {
            let _ = pins.set_analog(index as usize, value);
        }
        _ if seg.is_motion() && !seg.outputs.is_empty() => {
            let out = &seg.outputs;
            for n in 0..MAX_DIGITAL_OUTPUTS {
                if out.digital_mask >> n & 1 == 1 {
                    let _ = pins.set_digital_synced(n, out.digital_bits >> n & 1 == 1);
                }
            }
            for n in 0..MAX_ANALOG_OUTPUTS {
                if out.analog_mask >> n & 1 == 1 {
                    let _ = pins.set_analog_synced(n, out.analog[n]);
                }
            }
            pins.motion_started();
        }
        _ => {}
    }
}

impl ServoTick {
    /// The drive inputs for the coming period: each joint's loop from its
    /// setpoint for the end of the period and its position measured now.
    /// With the drives off the loops rest where the joints are.
    fn inner_loop(&mut self, n: usize) {
        let mut next = [0.0; MAX_JOINTS];
        let mut measured = [0.0; MAX_JOINTS];
        for i in 0..n {
            next[i] = self.setpoints.joints[i].position;
            measured[i] = self.feedback.joints[i].position;
        }
        let mut effort = [0.0; MAX_JOINTS];
        if self.setpoints.enable {
            self.loops
                .update(&next[..n], &measured[..n], self.period, &mut effort[..n]);
            // The simulated cut sees the overridden speed, as a real
            // spindle drive would turn at it.
            self.setpoints.spindle_speed = self.spindle_rpm * self.snapshot.spindle_override;
        } else {
            self.loops.reset(&measured[..n]);
            self.setpoints.spindle_speed = 0.0;
        }
        for (cmd, e) in self.setpoints.joints.iter_mut().zip(&effort[..n]) {
            cmd.effort = *e;
        }
    }
}

/// Check that a simulated cutting process reads the tool tip from joints
/// that drive X, Y and Z directly (it works on joint positions).
pub fn check_cutting(
    hal: &kerf_io::HalConfig,
    kins: &dyn Kinematics,
) -> Result<(), kerf_io::HalConfigError> {
    use kerf_interp::Axis;
    let Some(cutting) = &hal.sim.cutting else {
        return Ok(());
    };
    for (&joint, axis) in cutting.joints.iter().zip([Axis::X, Axis::Y, Axis::Z]) {
        if kins.joint_axis(joint) != Some(axis) {
            let name = kins.joints().get(joint).map_or("?", |j| j.name.as_str());
            return Err(kerf_io::HalConfigError::key(
                "sim.cutting.joints",
                format!(
                    "joint {joint} ({name}) does not drive axis {axis} directly; \
                     the simulated cutting process needs joints that do"
                ),
            ));
        }
    }
    Ok(())
}

/// How the servo thread keeps time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pacing {
    /// One tick per period of the wall clock (`CLOCK_MONOTONIC`).
    #[default]
    Wall,
    /// Ticks back to back on a virtual clock that advances one period per
    /// tick: deterministic and as fast as the CPU allows. Before each tick
    /// the thread waits until the planner has queued what the executor
    /// needs ahead ([`ServoTick::input_complete`]). Idle — no motion
    /// queued, no command waiting — it runs 200 more ticks for things to
    /// settle and then stops the clock until something arrives, so a run
    /// does not depend on how long the client paused before it.
    Virtual,
}

/// Real-time settings of the servo thread.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RealTime {
    /// Try SCHED_FIFO at this priority (1–99); `None`: normal scheduling.
    pub fifo_priority: Option<i32>,
    /// Pin the servo thread to this CPU.
    pub cpu: Option<usize>,
}

/// What the servo thread got of what [`RealTime`] asked for.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RealTimeReport {
    /// Running under SCHED_FIFO.
    pub fifo: bool,
    /// Pinned to this CPU.
    pub cpu: Option<usize>,
    /// Why something asked for was not granted, one line each.
    pub warnings: Vec<String>,
}

/// Lock all of the process's memory now and in future, so the servo never
/// waits for a page fault. Returns why not where the OS refuses (the
/// process needs CAP_IPC_LOCK or a large enough RLIMIT_MEMLOCK).
pub fn lock_memory() -> Result<(), String> {
    // With a finite memory-lock limit, MCL_FUTURE would make allocations
    // past it fail later, which is worse than page faults: lock only where
    // the limit is unlimited, or as root.
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: valid pointer to an rlimit.
    let unlimited = unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut limit) } == 0
        && limit.rlim_cur == libc::RLIM_INFINITY;
    // SAFETY: no arguments.
    let root = unsafe { libc::geteuid() } == 0;
    if !unlimited && !root {
        return Err(
            "not locking memory: the memory-lock limit is finite (LimitMEMLOCK=infinity \
                    in the unit, or `ulimit -l unlimited`); page faults may delay the servo"
                .into(),
        );
    }
    // SAFETY: plain system call with flag arguments.
    let r = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if r == 0 {
        Ok(())
    } else {
        Err(format!(
            "mlockall failed ({}): memory is not locked, so a page fault can delay a servo tick \
             (needs CAP_IPC_LOCK or `ulimit -l unlimited`)",
            std::io::Error::last_os_error()
        ))
    }
}

/// Apply `rt` to the calling thread.
fn apply_realtime(rt: RealTime) -> RealTimeReport {
    let mut report = RealTimeReport::default();
    if let Some(priority) = rt.fifo_priority {
        let param = libc::sched_param {
            sched_priority: priority.clamp(1, 99),
        };
        // SAFETY: valid pointer to a sched_param for the calling thread.
        let r =
            unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        if r == 0 {
            report.fifo = true;
        } else {
            report.warnings.push(format!(
                "SCHED_FIFO priority {priority} refused ({}): the servo runs at normal priority \
                 and its wake-ups will be later (needs CAP_SYS_NICE or an rtprio limit)",
                std::io::Error::from_raw_os_error(r)
            ));
        }
    }
    if let Some(cpu) = rt.cpu {
        // SAFETY: cpu_set_t is plain data; CPU_SET bounds-checks `cpu`.
        let r = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu < libc::CPU_SETSIZE as usize {
                libc::CPU_SET(cpu, &mut set);
                libc::pthread_setaffinity_np(
                    libc::pthread_self(),
                    std::mem::size_of::<libc::cpu_set_t>(),
                    &set,
                )
            } else {
                libc::EINVAL
            }
        };
        if r == 0 {
            report.cpu = Some(cpu);
        } else {
            report.warnings.push(format!(
                "cannot pin the servo thread to CPU {cpu} ({}): it runs on any CPU",
                std::io::Error::from_raw_os_error(r)
            ));
        }
    }
    report
}

/// A running servo thread.
pub struct ServoThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    realtime: RealTimeReport,
}

impl ServoThread {
    /// Start ticking `tick`, publishing each snapshot to `status`. With
    /// [`Pacing::Wall`] it wakes on absolute `CLOCK_MONOTONIC` deadlines
    /// one period apart (so sleep jitter does not accumulate), counts
    /// overruns and measures how late each wake-up is; `rt` is applied to
    /// the thread first.
    pub fn spawn(
        mut tick: ServoTick,
        mut status: Writer<Snapshot>,
        pacing: Pacing,
        rt: RealTime,
    ) -> std::io::Result<ServoThread> {
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = stop.clone();
        let period = Duration::from_secs_f64(tick.period());
        let (report_tx, report_rx) = std::sync::mpsc::channel();
        let handle = std::thread::Builder::new()
            .name("kerf-servo".into())
            .spawn(move || {
                let _ = report_tx.send(apply_realtime(rt));
                match pacing {
                    Pacing::Wall => run_wall(&mut tick, &mut status, &stop_flag, period),
                    Pacing::Virtual => run_virtual(&mut tick, &mut status, &stop_flag),
                }
            })?;
        let realtime = report_rx.recv().unwrap_or_default();
        Ok(ServoThread {
            stop,
            handle: Some(handle),
            realtime,
        })
    }

    /// What the thread got of the real-time settings asked for.
    pub fn realtime(&self) -> &RealTimeReport {
        &self.realtime
    }

    /// Stop the thread and wait for it.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// How often the latency percentiles are recomputed, in ticks (the scan
/// of the histogram is kept out of most ticks).
const LATENCY_EVERY: u64 = 256;

fn run_wall(
    tick: &mut ServoTick,
    status: &mut Writer<Snapshot>,
    stop: &AtomicBool,
    period: Duration,
) {
    let period_ns = period.as_nanos() as i64;
    let mut deadline = now_ns();
    let mut overruns = 0;
    let mut histogram = LatencyHistogram::default();
    let mut latency = LatencyStats::default();
    let mut n: u64 = 0;
    while !stop.load(Ordering::Relaxed) {
        deadline += period_ns;
        sleep_until_ns(deadline);
        let late = now_ns() - deadline;
        histogram.record(late.max(0) as u64);
        if late >= period_ns {
            // Missed at least a whole period: count it and restart the
            // schedule from now rather than running a burst of ticks.
            overruns += 1;
            deadline = now_ns();
        }
        tick.tick();
        n += 1;
        if n % LATENCY_EVERY == 1 {
            latency = histogram.stats();
        }
        let mut snap = *tick.snapshot();
        snap.overruns = overruns;
        snap.latency = latency;
        status.write(&snap);
    }
}

/// Ticks a virtual-clock servo runs on after the last sign of activity
/// (a command, queued motion), so drives, loops and controllers settle.
const VIRTUAL_SETTLE_TICKS: u32 = 200;

fn run_virtual(tick: &mut ServoTick, status: &mut Writer<Snapshot>, stop: &AtomicBool) {
    let mut settle = VIRTUAL_SETTLE_TICKS;
    let mut moving = false;
    while !stop.load(Ordering::Relaxed) {
        // Wait for the planner (it is fast; this is rarely more than a
        // few polls), so the executor sees the same queue as on a real run.
        while (!tick.input_complete() || tick.starved()) && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_micros(50));
        }
        // Idle and settled, virtual time stands still: ticking once per
        // millisecond of wall time would advance the simulation (its
        // seeded noise, the controllers) by however long the client took
        // between commands, and a run would depend on it.
        // So is motion held for the operator (a program stop, feed hold,
        // single block): how long they take must not matter either.
        let queued = tick.queue.slots() > 0 && !tick.waiting_on_operator();
        let busy = moving || queued || tick.has_commands();
        if busy {
            settle = VIRTUAL_SETTLE_TICKS;
        } else if settle == 0 {
            std::thread::sleep(Duration::from_micros(200));
            continue;
        } else {
            settle -= 1;
        }
        let snap = *tick.tick();
        status.write(&snap);
        moving = snap.moving;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refused_real_time_settings_are_warned_about_not_fatal() {
        // No machine has CPU 1000 (CPU_SETSIZE is 1024) nor 5000.
        for cpu in [1000, 5000] {
            let report = std::thread::spawn(move || {
                apply_realtime(RealTime {
                    fifo_priority: None,
                    cpu: Some(cpu),
                })
            })
            .join()
            .unwrap();
            assert_eq!(report.cpu, None);
            assert!(!report.fifo);
            assert_eq!(report.warnings.len(), 1, "{report:?}");
            assert!(
                report.warnings[0].contains(&format!("cannot pin the servo thread to CPU {cpu}")),
                "{report:?}"
            );
        }
    }
}
