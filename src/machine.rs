//! The machine state machine: what the operator asked for, what the servo
//! reports, and which commands are allowed when.
//!
//! ```text
//!            reset          on              home (all joints)
//!   ESTOP ─────────► ESTOP_RESET ────► ON ──────────────────► IDLE ◄──┐
//!     ▲                  ▲    ◄──── off │                       │      │ ends
//!     │ estop (any)      │ reset        ▼                       ├─► AUTO (running/paused/stepping)
//!     │                FAULT ◄──── servo fault (any powered)    ├─► MDI  (running/paused)
//!                                                               └─► MANUAL (jog)
//! ```
//!
//! [`Control`] holds the operator's side (power, homed joints, the job in
//! progress, feed hold and single block as requested) and learns the
//! servo's side from [`Snapshot`]s in [`Control::observe`], which also
//! produces the events clients see. Every refused command gets a
//! [`Refusal`] saying why and what to do instead.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::protocol::{
    ErrorCode, Event, Execution, JobStatus, JobType, MachineState, ProgramState, ProgramStatus,
};
use crate::servo::Snapshot;

/// A refused command: the error code and the message for the operator.
pub type Refusal = (ErrorCode, String);

/// Drive power as the operator set it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Power {
    /// Emergency stop: drives off; `reset` to leave.
    Estop,
    /// E-stop released, drives off.
    EstopReset,
    /// Drives on.
    On,
}

/// What a job moves for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum JobKind {
    /// A program file.
    Program,
    /// One MDI line.
    Mdi,
    /// A jog started by client `client`; a continuous one stops when that
    /// client disconnects.
    Jog { client: u64, continuous: bool },
    /// Homing the listed joints.
    Home { joints: Vec<usize> },
}

/// Motion in progress: everything queued for the servo under one tag.
#[derive(Debug)]
pub struct Job {
    /// The tag of the `Stop` marker that ends it (also the program id).
    pub tag: u32,
    /// What it moves for.
    pub kind: JobKind,
    /// Set to make its planner thread stop feeding the servo.
    pub cancel: Arc<AtomicBool>,
    /// Why its planner thread failed, if it did.
    pub error: Option<String>,
}

/// The opened (or last run) program.
#[derive(Clone, Debug)]
pub struct Program {
    /// The file, absolute.
    pub path: PathBuf,
    /// How it stands, as status shows it.
    pub status: ProgramStatus,
}

impl Program {
    /// A checked program of `lines` lines, to run from `start_line`.
    pub fn ready(path: PathBuf, lines: u32, start_line: u32) -> Program {
        Program {
            status: ProgramStatus {
                id: 0,
                file: path.display().to_string(),
                state: ProgramState::Ready,
                lines,
                start_line,
                line: 0,
                error: None,
            },
            path,
        }
    }
}

struct PendingMessage {
    tag: u32,
    /// Due when the servo has consumed this many queue items.
    due: u64,
    line: u32,
    text: String,
}

/// The operator's side of the machine.
pub struct Control {
    power: Power,
    fault: Option<String>,
    /// A `ClearFault` is on its way to the servo: ignore its stale fault.
    clearing_fault: bool,
    homed: Vec<bool>,
    job: Option<Job>,
    program: Option<Program>,
    last_job: Option<JobStatus>,
    /// Feed hold requested.
    held: bool,
    /// Single-block mode requested.
    single_block: bool,
    /// The program stop (M0, M1, M60) the tool waits at, by the servo's
    /// count ([`Snapshot::program_stops`]), and its source line.
    stopped_at: Option<(u64, u32)>,
    /// The last program stop the operator resumed from: the servo may
    /// still report waiting at it for a period.
    resumed_stop: u64,
    next_tag: u32,
    messages: VecDeque<PendingMessage>,
    /// State last reported in an event.
    reported: (MachineState, Option<Execution>),
    /// Why the job in progress is ending (an operator's abort), for the
    /// event when it has.
    reason: Option<String>,
    outbox: Vec<Event>,
    joint_names: Vec<String>,
}

impl Control {
    /// A machine with `joint_names.len()` unhomed joints, in e-stop.
    pub fn new(joint_names: Vec<String>) -> Control {
        Control {
            power: Power::Estop,
            fault: None,
            clearing_fault: false,
            homed: vec![false; joint_names.len()],
            job: None,
            program: None,
            last_job: None,
            held: false,
            single_block: false,
            stopped_at: None,
            resumed_stop: 0,
            next_tag: 1,
            messages: VecDeque::new(),
            reported: (MachineState::Estop, None),
            reason: None,
            outbox: Vec::new(),
            joint_names,
        }
    }

    /// The machine state and, in `auto` and `mdi`, how it executes.
    pub fn state(&self) -> (MachineState, Option<Execution>) {
        if self.fault.is_some() {
            return (MachineState::Fault, None);
        }
        let state = match self.power {
            Power::Estop => MachineState::Estop,
            Power::EstopReset => MachineState::EstopReset,
            Power::On => match self.job.as_ref().map(|j| &j.kind) {
                Some(JobKind::Program) => MachineState::Auto,
                Some(JobKind::Mdi) => MachineState::Mdi,
                Some(JobKind::Jog { .. }) => MachineState::Manual,
                Some(JobKind::Home { .. }) => MachineState::Homing,
                None if self.homed.iter().all(|h| *h) => MachineState::Idle,
                None => MachineState::On,
            },
        };
        let execution = matches!(state, MachineState::Auto | MachineState::Mdi).then(|| {
            if self.held || self.stopped_at.is_some() {
                Execution::Paused
            } else if self.single_block {
                Execution::Stepping
            } else {
                Execution::Running
            }
        });
        (state, execution)
    }

    /// Per joint: homed.
    pub fn homed(&self) -> &[bool] {
        &self.homed
    }

    /// The latched fault.
    pub fn fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }

    /// The job in progress.
    pub fn job(&self) -> Option<&Job> {
        self.job.as_ref()
    }

    /// The current or last job, for status.
    pub fn job_status(&self) -> Option<&JobStatus> {
        self.last_job.as_ref()
    }

    /// The opened or last program.
    pub fn program(&self) -> Option<&Program> {
        self.program.as_ref()
    }

    /// Feed hold and single block as requested.
    pub fn hold_and_single_block(&self) -> (bool, bool) {
        (self.held, self.single_block)
    }

    /// Why `what` cannot start motion now, if it cannot. `needs_homing`:
    /// every joint must be homed first (everything but homing itself).
    pub fn check_motion(&self, what: &str, needs_homing: bool) -> Result<(), Refusal> {
        if let Some(f) = &self.fault {
            return Err((
                ErrorCode::Fault,
                format!("cannot {what}: machine fault: {f}; `reset` clears it"),
            ));
        }
        match self.power {
            Power::Estop => {
                return Err(refuse(format!(
                    "cannot {what}: the machine is in e-stop; `reset`, then `on`"
                )))
            }
            Power::EstopReset => {
                return Err(refuse(format!(
                    "cannot {what}: the machine is off; `on` first"
                )))
            }
            Power::On => {}
        }
        if let Some(job) = &self.job {
            let doing = match job.kind {
                JobKind::Program => "a program is running",
                JobKind::Mdi => "an MDI line is running",
                JobKind::Jog { .. } => "the machine is jogging",
                JobKind::Home { .. } => "the machine is homing",
            };
            return Err((
                ErrorCode::Busy,
                format!("cannot {what}: {doing}; wait for it or `abort`"),
            ));
        }
        if needs_homing && !self.homed.iter().all(|h| *h) {
            let unhomed: Vec<&str> = self
                .joint_names
                .iter()
                .zip(&self.homed)
                .filter(|(_, h)| !**h)
                .map(|(n, _)| n.as_str())
                .collect();
            let (noun, verb) = if unhomed.len() == 1 {
                ("joint", "is")
            } else {
                ("joints", "are")
            };
            return Err(refuse(format!(
                "cannot {what}: {noun} {} {verb} not homed; `home` first",
                unhomed.join(", ")
            )));
        }
        Ok(())
    }

    /// Start a job of `kind` (after [`check_motion`](Self::check_motion)):
    /// returns its tag and cancel flag. `program` is the program record for
    /// a program job.
    pub fn start_job(
        &mut self,
        kind: JobKind,
        program: Option<Program>,
        single_block: bool,
    ) -> (u32, Arc<AtomicBool>) {
        let tag = self.next_tag;
        self.next_tag += 1;
        let cancel = Arc::new(AtomicBool::new(false));
        if let Some(mut p) = program {
            p.status.id = tag;
            p.status.state = ProgramState::Running;
            p.status.error = None;
            p.status.line = 0;
            self.outbox.push(Event::Program {
                program: p.status.clone(),
            });
            self.program = Some(p);
        }
        self.last_job = Some(JobStatus {
            id: tag,
            kind: job_type(&kind),
            state: ProgramState::Running,
            error: None,
        });
        let reason = match &kind {
            JobKind::Program => "program started",
            JobKind::Mdi => "MDI started",
            JobKind::Jog { .. } => "jog started",
            JobKind::Home { .. } => "homing started",
        };
        self.job = Some(Job {
            tag,
            kind,
            cancel: cancel.clone(),
            error: None,
        });
        self.held = false;
        self.single_block = single_block;
        self.transition(reason.into());
        (tag, cancel)
    }

    /// Remember an opened program (not running).
    pub fn set_opened(&mut self, program: Program) {
        self.program = Some(program);
    }

    /// A planner thread failed: the job ends as failed when the servo
    /// reaches its marker.
    pub fn job_failed(&mut self, tag: u32, reason: String) {
        if let Some(job) = self.job.as_mut().filter(|j| j.tag == tag) {
            job.error = Some(reason);
        }
    }

    /// Queue an operator message of job `tag`, to show once the servo has
    /// consumed `due` queue items.
    pub fn queue_message(&mut self, tag: u32, due: u64, line: u32, text: String) {
        self.messages.push_back(PendingMessage {
            tag,
            due,
            line,
            text,
        });
    }

    /// `estop`: always accepted. Stops the job without deceleration.
    pub fn estop(&mut self) {
        self.cancel_job();
        self.power = Power::Estop;
        self.transition("e-stop".into());
    }

    /// `reset`: leave e-stop, or clear a fault once its job has ended.
    pub fn reset(&mut self) -> Result<(), Refusal> {
        if self.fault.is_some() {
            if self.job.is_some() {
                return Err((
                    ErrorCode::Busy,
                    "cannot reset yet: the faulted job is still being stopped; try again".into(),
                ));
            }
            self.fault = None;
            self.clearing_fault = true;
            self.power = Power::EstopReset;
            self.transition("fault cleared by operator".into());
            return Ok(());
        }
        match self.power {
            Power::Estop => {
                self.power = Power::EstopReset;
                self.transition("e-stop reset".into());
                Ok(())
            }
            _ => Err(refuse(
                "nothing to reset: the machine is neither in e-stop nor faulted".into(),
            )),
        }
    }

    /// `on`: drives on, from `estop_reset`.
    pub fn on(&mut self) -> Result<(), Refusal> {
        if let Some(f) = &self.fault {
            return Err((
                ErrorCode::Fault,
                format!("cannot turn on: machine fault: {f}; `reset` clears it"),
            ));
        }
        match self.power {
            Power::Estop => Err(refuse(
                "cannot turn on: the machine is in e-stop; `reset` first".into(),
            )),
            Power::On => Err(refuse("the machine is already on".into())),
            Power::EstopReset => {
                self.power = Power::On;
                self.transition("drives on".into());
                Ok(())
            }
        }
    }

    /// `off`: drives off, unless something moves.
    pub fn off(&mut self) -> Result<(), Refusal> {
        if self.power != Power::On {
            return Err(refuse("the machine is already off".into()));
        }
        if self.job.is_some() {
            return Err((
                ErrorCode::Busy,
                "cannot turn off while the machine moves: `abort` first, or `estop`".into(),
            ));
        }
        self.power = Power::EstopReset;
        self.transition("drives off".into());
        Ok(())
    }

    /// `pause`: feed hold of a program or MDI line.
    pub fn pause(&mut self) -> Result<(), Refusal> {
        self.check_executing("pause")?;
        if self.held {
            return Err(refuse("already paused".into()));
        }
        self.held = true;
        self.transition("paused by operator".into());
        Ok(())
    }

    /// `resume`: release feed hold, single block and the program stop the
    /// tool waits at. Returns that stop's number, for the servo's
    /// [`ServoCommand::ReleaseStop`](crate::servo::ServoCommand::ReleaseStop).
    pub fn resume(&mut self) -> Result<Option<u64>, Refusal> {
        self.check_executing("resume")?;
        if !self.held && !self.single_block && self.stopped_at.is_none() {
            return Err(refuse("not paused or stepping: nothing to resume".into()));
        }
        self.held = false;
        self.single_block = false;
        let stop = self.leave_stop();
        self.transition("resumed by operator".into());
        Ok(stop)
    }

    /// `step` during a program: single-block mode, run one more line (out
    /// of a program stop too). Returns the program stop left, as
    /// [`Control::resume`] does.
    pub fn step(&mut self) -> Result<Option<u64>, Refusal> {
        self.check_executing("step")?;
        if !matches!(self.job.as_ref().map(|j| &j.kind), Some(JobKind::Program)) {
            return Err(refuse("only a program can be stepped".into()));
        }
        self.held = false;
        self.single_block = true;
        let stop = self.leave_stop();
        self.transition("single-block step".into());
        Ok(stop)
    }

    /// Forget the program stop the tool waits at, and return its number.
    fn leave_stop(&mut self) -> Option<u64> {
        let (stop, _) = self.stopped_at.take()?;
        self.resumed_stop = stop;
        Some(stop)
    }

    fn check_executing(&self, what: &str) -> Result<(), Refusal> {
        let (state, _) = self.state();
        match state {
            MachineState::Auto | MachineState::Mdi => Ok(()),
            other => Err(refuse(format!(
                "cannot {what}: no program or MDI line is running (state {})",
                state_name(other)
            ))),
        }
    }

    /// `abort` (or `jog_stop` when `jog_only`): the tag to abort.
    pub fn abort(&mut self, jog_only: bool) -> Result<u32, Refusal> {
        let Some(job) = &self.job else {
            return Err(refuse(if jog_only {
                "not jogging".into()
            } else {
                "nothing to abort: no program, MDI, jog or homing in progress".into()
            }));
        };
        if jog_only && !matches!(job.kind, JobKind::Jog { .. }) {
            return Err(refuse("not jogging: use `abort`".into()));
        }
        let tag = job.tag;
        job.cancel.store(true, Ordering::Relaxed);
        self.reason = Some(if jog_only {
            "jog stopped".into()
        } else {
            "aborted by operator".into()
        });
        Ok(tag)
    }

    /// `client` has disconnected: if it was running a continuous jog, stop
    /// it (a jog key is a dead man's switch) and return the tag to abort.
    pub fn stop_orphaned_jog(&mut self, client: u64) -> Option<u32> {
        let job = self.job.as_ref()?;
        let JobKind::Jog {
            client: owner,
            continuous: true,
        } = job.kind
        else {
            return None;
        };
        if owner != client {
            return None;
        }
        job.cancel.store(true, Ordering::Relaxed);
        self.reason = Some("jog stopped: the client that started it disconnected".into());
        Some(job.tag)
    }

    fn cancel_job(&mut self) {
        if let Some(job) = &self.job {
            job.cancel.store(true, Ordering::Relaxed);
        }
    }

    /// Learn what the servo did: faults, jobs that ended, lines reached and
    /// messages due. Returns the events this produced, in order.
    pub fn observe(&mut self, snap: &Snapshot, describe_fault: impl Fn() -> String) -> Vec<Event> {
        if self.clearing_fault {
            self.clearing_fault = snap.fault.is_some();
        } else if snap.fault.is_some() && self.fault.is_none() {
            let reason = describe_fault();
            tracing::error!(fault = %reason, "servo fault");
            self.fault = Some(reason.clone());
            self.cancel_job();
            self.transition(reason);
        }
        let current = self.job.as_ref().map(|j| j.tag);
        let ended = self.job.as_ref().and_then(|job| {
            let done = job.tag <= snap.program_done;
            let aborted = job.tag <= snap.program_aborted;
            (done || aborted).then_some(done && !aborted)
        });
        if ended == Some(false) {
            // Aborted: its queue was discarded, so its messages were never
            // reached (the count of consumed items includes discarded ones).
            self.messages.retain(|m| Some(m.tag) != current);
        }
        while self
            .messages
            .front()
            .is_some_and(|m| m.due <= snap.consumed)
        {
            let m = self.messages.pop_front().expect("front exists");
            self.outbox.push(Event::Message {
                text: m.text,
                line: m.line,
            });
        }
        let stop = (snap.at_program_stop && snap.program_stops > self.resumed_stop)
            .then_some((snap.program_stops, snap.line))
            .filter(|_| ended.is_none() && self.job.is_some());
        if stop != self.stopped_at {
            self.stopped_at = stop;
            if let Some((_, line)) = stop {
                tracing::info!(line, "program stop");
                self.transition(format!(
                    "program stop (M0 or M1) at line {line}: `resume` to go on"
                ));
            }
        }
        if let (Some(job), Some(p)) = (&self.job, self.program.as_mut()) {
            if job.kind == JobKind::Program && p.status.id == job.tag && snap.line != p.status.line
            {
                p.status.line = snap.line;
                self.outbox.push(Event::Program {
                    program: p.status.clone(),
                });
            }
        }
        if let Some(reached_end) = ended {
            let job = self.job.take().expect("ended implies a job");
            if let Some(p) = self.program.as_mut().filter(|p| p.status.id == job.tag) {
                p.status.line = snap.line;
            }
            self.end_job(job, reached_end);
        }
        std::mem::take(&mut self.outbox)
    }

    fn end_job(&mut self, job: Job, reached_end: bool) {
        self.held = false;
        self.single_block = false;
        self.stopped_at = None;
        let (state, error) = if let Some(f) = &self.fault {
            (ProgramState::Failed, Some(format!("stopped by fault: {f}")))
        } else if let Some(e) = job.error {
            (ProgramState::Failed, Some(e))
        } else if reached_end {
            (ProgramState::Finished, None)
        } else if self.power != Power::On {
            (
                ProgramState::Aborted,
                Some("stopped by e-stop or drives off".into()),
            )
        } else {
            let why = self.reason.clone().unwrap_or_else(|| "aborted".into());
            (ProgramState::Aborted, Some(why))
        };
        if let (JobKind::Home { joints }, ProgramState::Finished) = (&job.kind, state) {
            for &j in joints {
                self.homed[j] = true;
            }
        }
        // An operator's abort gave its reason already; otherwise say how it ended.
        let reason = self
            .reason
            .take()
            .unwrap_or_else(|| match (&job.kind, state) {
                (JobKind::Program, ProgramState::Finished) => "program finished".into(),
                (JobKind::Home { .. }, ProgramState::Finished) => "homed".into(),
                (_, ProgramState::Finished) => "done".into(),
                (_, _) => error.clone().unwrap_or_default(),
            });
        if let Some(last) = self.last_job.as_mut().filter(|j| j.id == job.tag) {
            last.state = state;
            last.error = error.clone();
        }
        if let Some(e) = error.as_ref().filter(|_| state == ProgramState::Failed) {
            self.outbox.push(Event::Error { message: e.clone() });
        }
        if job.kind == JobKind::Program {
            if let Some(p) = self.program.as_mut().filter(|p| p.status.id == job.tag) {
                p.status.state = state;
                p.status.error = error;
                self.outbox.push(Event::Program {
                    program: p.status.clone(),
                });
            }
        }
        tracing::info!(job = job.tag, kind = ?job.kind, ?state, "job ended");
        self.transition(reason);
    }

    /// Report a change of state (or of execution) with its reason.
    fn transition(&mut self, reason: String) {
        let now = self.state();
        if now != self.reported {
            self.outbox.push(Event::State {
                state: now.0,
                execution: now.1,
                previous: self.reported.0,
                reason: Some(reason),
            });
            self.reported = now;
        }
    }
}

fn job_type(kind: &JobKind) -> JobType {
    match kind {
        JobKind::Program => JobType::Program,
        JobKind::Mdi => JobType::Mdi,
        JobKind::Jog { .. } => JobType::Jog,
        JobKind::Home { .. } => JobType::Home,
    }
}

fn refuse(message: String) -> Refusal {
    (ErrorCode::InvalidState, message)
}

/// The protocol name of a state, e.g. `estop_reset`.
pub fn state_name(state: MachineState) -> &'static str {
    match state {
        MachineState::Estop => "estop",
        MachineState::EstopReset => "estop_reset",
        MachineState::On => "on",
        MachineState::Homing => "homing",
        MachineState::Idle => "idle",
        MachineState::Auto => "auto",
        MachineState::Mdi => "mdi",
        MachineState::Manual => "manual",
        MachineState::Fault => "fault",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kerf_interp::Position;

    fn snap() -> Snapshot {
        Snapshot::at_rest(Position::ZERO, &[0.0, 0.0])
    }

    fn control() -> Control {
        Control::new(vec!["x".into(), "y".into()])
    }

    #[test]
    fn power_up_sequence_and_refusals() {
        let mut c = control();
        assert_eq!(c.state().0, MachineState::Estop);
        let e = c.check_motion("run", true).unwrap_err();
        assert_eq!(e.0, ErrorCode::InvalidState);
        assert!(e.1.contains("e-stop") && e.1.contains("`reset`"), "{}", e.1);
        assert!(c.on().unwrap_err().1.contains("`reset` first"));
        c.reset().unwrap();
        assert_eq!(c.state().0, MachineState::EstopReset);
        assert!(c.reset().is_err(), "nothing left to reset");
        c.on().unwrap();
        assert_eq!(c.state().0, MachineState::On);
        let e = c.check_motion("run", true).unwrap_err();
        assert_eq!(e.1, "cannot run: joints x, y are not homed; `home` first");
        assert!(c.check_motion("home", false).is_ok());

        let (tag, _) = c.start_job(JobKind::Home { joints: vec![0, 1] }, None, false);
        assert_eq!(c.state().0, MachineState::Homing);
        assert_eq!(c.check_motion("jog", true).unwrap_err().0, ErrorCode::Busy);
        let mut s = snap();
        s.program_done = tag;
        let events = c.observe(&s, String::new);
        assert_eq!(c.state().0, MachineState::Idle);
        assert_eq!(c.homed(), &[true, true]);
        assert!(events.contains(&Event::State {
            state: MachineState::Idle,
            execution: None,
            previous: MachineState::Homing,
            reason: Some("homed".into())
        }));
    }

    #[test]
    fn pause_resume_step_and_abort_follow_the_job() {
        let mut c = control();
        c.reset().unwrap();
        c.on().unwrap();
        assert!(c.pause().unwrap_err().1.contains("no program"));
        let (tag, cancel) = c.start_job(JobKind::Mdi, None, false);
        assert_eq!(c.state(), (MachineState::Mdi, Some(Execution::Running)));
        c.pause().unwrap();
        assert_eq!(c.state().1, Some(Execution::Paused));
        assert!(c.pause().is_err(), "already paused");
        assert!(c.step().is_err(), "MDI cannot be stepped");
        c.resume().unwrap();
        assert!(c.resume().is_err());
        assert!(c.off().is_err(), "cannot turn off while moving");
        assert_eq!(c.abort(true).unwrap_err().1, "not jogging: use `abort`");
        assert_eq!(c.abort(false).unwrap(), tag);
        assert!(cancel.load(Ordering::Relaxed));
        let mut s = snap();
        s.program_aborted = tag;
        c.observe(&s, String::new);
        assert_eq!(c.state().0, MachineState::On);
        assert!(c.abort(false).is_err());
    }

    #[test]
    fn a_fault_latches_until_reset_after_its_job_ends() {
        let mut c = control();
        c.reset().unwrap();
        c.on().unwrap();
        let (tag, cancel) = c.start_job(JobKind::Program, None, false);
        let mut s = snap();
        s.fault = Some(crate::servo::ServoFault::FollowingError {
            joint: 0,
            error: 1.0,
            limit: 0.5,
        });
        let events = c.observe(&s, || "joint x lags".into());
        assert!(cancel.load(Ordering::Relaxed), "the job is told to stop");
        assert_eq!(c.state().0, MachineState::Fault);
        assert_eq!(
            events.last(),
            Some(&Event::State {
                state: MachineState::Fault,
                execution: None,
                previous: MachineState::Auto,
                reason: Some("joint x lags".into())
            })
        );
        assert_eq!(c.reset().unwrap_err().0, ErrorCode::Busy);
        s.program_aborted = tag;
        c.observe(&s, String::new);
        assert_eq!(c.on().unwrap_err().0, ErrorCode::Fault);
        c.reset().unwrap();
        // The servo has not cleared it yet: the stale fault is not re-latched.
        c.observe(&s, || "stale".into());
        assert_eq!(c.state().0, MachineState::EstopReset);
        s.fault = None;
        c.observe(&s, String::new);
        c.on().unwrap();
    }

    #[test]
    fn messages_show_when_reached_and_drop_when_aborted() {
        let mut c = control();
        c.reset().unwrap();
        c.on().unwrap();
        let (tag, _) = c.start_job(JobKind::Mdi, None, false);
        c.queue_message(tag, 3, 1, "first".into());
        c.queue_message(tag, 10, 2, "second".into());
        let mut s = snap();
        s.consumed = 2;
        let msgs = |events: Vec<Event>| -> Vec<String> {
            events
                .into_iter()
                .filter_map(|e| match e {
                    Event::Message { text, .. } => Some(text),
                    _ => None,
                })
                .collect()
        };
        assert!(msgs(c.observe(&s, String::new)).is_empty());
        s.consumed = 3;
        assert_eq!(msgs(c.observe(&s, String::new)), vec!["first"]);
        c.abort(false).unwrap();
        s.consumed = 20;
        s.program_aborted = tag;
        assert!(msgs(c.observe(&s, String::new)).is_empty());
    }
}
