//! Offline simulation: a program through the real servo tick — executor,
//! kinematics, position loops, force controller — against the simulated
//! plant and cutting process, on a virtual clock, as fast as the CPU
//! allows. `kerf sim` prints what [`simulate`] measures; the servo
//! benchmark compares it with the targets.
//!
//! Everything is measured on what the simulated machine did, not taken
//! from the controllers' own bookkeeping: following error is commanded
//! minus measured joint position after each period; contour error is the
//! distance of the tool tip (forward kinematics of the measured joints)
//! from the programmed moves; force is the process model's largest
//! cutting force per controller step.

use std::collections::VecDeque;
use std::time::Instant;

use anyhow::{anyhow, bail, Context};
use kerf_interp::{Canon, InterpError};
use kerf_io::sim::cutting::CuttingConfig;
use kerf_io::sim::Plant;
use kerf_io::HalConfig;
use kerf_machines::Machine;
use kerf_motion::fuzzy;
use kerf_motion::offline::PathWindow;
use kerf_motion::{Planner, PlannerConfig, Segment, MAX_JOINTS};

use crate::latency::{LatencyHistogram, LatencyStats};
use crate::servo::{self, ServoTick};

/// Settings of a simulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// Servo period, s.
    pub period: f64,
    /// Velocity and acceleration feedforward (false: the seed's pure PD).
    pub feedforward: bool,
    /// Plant of every joint; `None`: as the machine's `[hal.sim]` says.
    pub plant: Option<Plant>,
    /// Turn force control on from the start with this target force, N,
    /// through the program path ([`Planner::set_force_control`]).
    pub force_target: Option<f64>,
    /// Keep a trace for plots.
    pub record: bool,
    /// Give up after this much machine time, s.
    pub time_limit: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            period: 0.001,
            feedforward: true,
            plant: Some(Plant::Identified),
            force_target: None,
            record: false,
            time_limit: 3600.0,
        }
    }
}

/// Following error of one joint.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointFigures {
    /// Joint name.
    pub name: String,
    /// Largest |commanded − measured|, joint units (mm).
    pub max_following_error: f64,
    /// Root mean square over the run, joint units (mm).
    pub rms_following_error: f64,
}

/// A sudden change of the depth of cut (a stock step, or entering the
/// stock) and how the force answered it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DepthChange {
    /// When the tool axis crossed it, s.
    pub time: f64,
    /// Depth of cut before, mm.
    pub depth_from: f64,
    /// Depth of cut after, mm.
    pub depth_to: f64,
    /// Largest force of the last controller step before it, N.
    pub force_before: f64,
    /// Largest force of the last step cut at this depth, N.
    pub force_after: f64,
    /// With force control: time from the change until the force is within
    /// ±5 % of the target and stays there while cutting at this depth, s
    /// (`None`: never).
    pub settle: Option<f64>,
}

/// The cutting process over the run (whenever the machine simulates one).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CuttingFigures {
    /// Largest cutting force, N.
    pub max_force: f64,
    /// Time spent cutting, s.
    pub cutting_time: f64,
    /// Every sudden change of the depth of cut, in order.
    pub changes: Vec<DepthChange>,
}

/// Force control figures (when it was on).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForceFigures {
    /// Target force F_d, N.
    pub target: f64,
    /// Largest force of any controller step, N.
    pub max: f64,
    /// RMS of (F − F_d)/F_d over the steps cut after settling, %.
    pub rms_error_pct: Option<f64>,
    /// Longest settling time after a depth change, s (`None`: one never
    /// settled).
    pub settle: Option<f64>,
}

/// One period of the run, for plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint {
    /// End of the period, s.
    pub time: f64,
    /// Commanded tool position XYZ, mm.
    pub commanded: [f64; 3],
    /// Measured tool position XYZ, mm.
    pub actual: [f64; 3],
    /// Commanded minus measured per joint, mm.
    pub following_error: [f64; MAX_JOINTS],
    /// Path speed commanded, mm/s.
    pub velocity: f64,
}

/// One force-controller step, for plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForcePoint {
    /// End of the step, s.
    pub time: f64,
    /// Largest cutting force of the step (process model), N.
    pub force: f64,
    /// The controller's estimate from the spindle current, N.
    pub estimated: f64,
    /// The controller's feed override.
    pub feed_override: f64,
    /// Depth of cut at the end of the step, mm.
    pub depth: f64,
}

/// What a simulation measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimReport {
    /// Time from start until the executor finished the program, s.
    pub cycle_time: f64,
    /// Following error per joint, in joint order.
    pub joints: Vec<JointFigures>,
    /// Largest following error of any joint, mm.
    pub max_following_error: f64,
    /// Largest distance of the measured tool tip from the programmed
    /// moves, mm.
    pub max_contour_error: f64,
    /// The cutting process, when the machine simulates one.
    pub cutting: Option<CuttingFigures>,
    /// Force control figures, when it was on.
    pub force: Option<ForceFigures>,
    /// Wall-clock compute time of each tick, ns (reported, never asserted).
    pub tick_time: LatencyStats,
    /// Servo periods run.
    pub ticks: u64,
    /// Every period (with `record`).
    pub trace: Vec<TracePoint>,
    /// Every controller step of a cutting run.
    pub forces: Vec<ForcePoint>,
    /// Programmed move end points, XYZ.
    pub programmed: Vec<[f64; 3]>,
}

/// Band around the target force that counts as settled.
const SETTLE_BAND: f64 = 0.05;
/// A depth change larger than this within one period is a step, mm.
const DEPTH_STEP: f64 = 0.05;
/// Programmed moves kept behind the executing line for the contour error,
/// mm of path: more than the largest following error.
const CONTOUR_WINDOW: f64 = 5.0;

/// Run `program` on `machine` from its home pose.
pub fn simulate(
    program: impl IntoIterator<Item = Result<Canon, InterpError>>,
    machine: &Machine,
    options: &SimOptions,
) -> anyhow::Result<SimReport> {
    let kins = machine.kinematics.clone();
    let description = &machine.description;
    let n = kins.joints().len();
    let home = machine.home();
    let mut hal: HalConfig = description
        .hal
        .clone()
        .try_into()
        .with_context(|| format!("{}: [hal]", machine.origin))?;
    // Every joint simulated, whatever drives it on the real machine.
    hal.backend = Some("sim".into());
    hal.stepdir = None;
    hal.can = None;
    hal.shm = None;
    if let Some(plant) = options.plant {
        hal.sim.plant = plant;
        if plant == Plant::Ideal {
            hal.sim.gain = None;
            hal.sim.time_constant = None;
        }
    }
    servo::check_cutting(&hal, &*kins).with_context(|| machine.origin.clone())?;
    let cutting = hal.sim.cutting.clone();
    let mut joints = [0.0; MAX_JOINTS];
    kins.inverse(&home, &mut joints[..n])
        .map_err(|e| anyhow!("home pose: {}", e.describe(&*kins)))?;
    let backend = kerf_io::build(&hal, &joints[..n]).with_context(|| machine.origin.clone())?;
    let (mut producer, consumer) = rtrb::RingBuffer::new(crate::daemon::QUEUE_CAPACITY);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(4);
    // The servo starts with its drives off, like the daemon's machine before
    // `on`; an offline run is a machine switched on.
    commands
        .push(servo::ServoCommand::Enable(true))
        .expect("a fresh command queue has room");
    let mut tick = ServoTick::new(
        options.period,
        home,
        kins.clone(),
        backend,
        consumer,
        command_queue,
    )?;
    tick.configure(description);
    tick.set_feedforward(options.feedforward);

    let planner_config = PlannerConfig {
        period: options.period,
        ..PlannerConfig::default()
    };
    let mut planner = Planner::new(&*kins, home, planner_config);
    planner.set_force_control(options.force_target);
    let mut program = program.into_iter();
    let mut pending: VecDeque<Segment> = VecDeque::new();
    let mut program_read = false;
    let mut path = PathWindow::new(home, CONTOUR_WINDOW, &planner_config);

    let mut report = SimReport {
        joints: kins
            .joints()
            .iter()
            .map(|j| JointFigures {
                name: j.name.clone(),
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    };
    let mut squares = [0.0; MAX_JOINTS];
    let mut timing = LatencyHistogram::default();
    let mut process = cutting
        .as_ref()
        .map(|c| Process::new(c.clone(), description, options.period));
    loop {
        // Keep the queue full, as the daemon's planner thread does.
        while producer.slots() > 0 {
            if let Some(seg) = pending.pop_front() {
                producer.push(seg).expect("a free slot");
                continue;
            }
            if program_read {
                break;
            }
            match program.next() {
                Some(canon) => {
                    let canon = canon?;
                    report.programmed.extend(path.push(&canon));
                    planner.plan(&canon)?;
                }
                None => {
                    planner.finish();
                    program_read = true;
                }
            }
            pending.extend(std::iter::from_fn(|| planner.next_segment()));
            if program_read {
                pending.push_back(planner.end_marker(1));
            }
        }
        let started = Instant::now();
        let snap = *tick.tick();
        timing.record(started.elapsed().as_nanos() as u64);
        report.ticks += 1;
        let time = report.ticks as f64 * options.period;
        if let Some(fault) = snap.fault {
            bail!("stopped by a fault at t = {time:.3} s: {fault}");
        }
        for ((f, sq), e) in report
            .joints
            .iter_mut()
            .zip(&mut squares)
            .zip(&snap.following_error)
        {
            f.max_following_error = f.max_following_error.max(e.abs());
            *sq += e * e;
        }
        if let Some(d) = path.distance(&snap.position, snap.moves) {
            report.max_contour_error = report.max_contour_error.max(d.distance);
        }
        if options.record {
            report.trace.push(TracePoint {
                time,
                commanded: xyz(&snap.commanded),
                actual: xyz(&snap.position),
                following_error: snap.following_error,
                velocity: snap.velocity,
            });
        }
        if let Some(p) = &mut process {
            p.tick(time, &snap, tick.feedback().cutting_force);
        }
        if snap.at_program_stop {
            // Nobody is there to resume an M0 or M1: go on at once, and
            // leave the operator's part out of the cycle time.
            commands
                .push(servo::ServoCommand::ReleaseStop {
                    reached: snap.program_stops,
                })
                .map_err(|_| anyhow!("the servo's command queue is full"))?;
        }
        if snap.program_done == 1 {
            report.cycle_time = time;
            break;
        }
        if time > options.time_limit {
            bail!(
                "the program did not finish within {} s of machine time",
                options.time_limit
            );
        }
    }
    for (f, sq) in report.joints.iter_mut().zip(squares) {
        f.rms_following_error = (sq / report.ticks as f64).sqrt();
    }
    report.max_following_error = report
        .joints
        .iter()
        .map(|j| j.max_following_error)
        .fold(0.0, f64::max);
    report.tick_time = timing.stats();
    if let Some(p) = process {
        (report.cutting, report.force, report.forces) = p.finish();
    }
    Ok(report)
}

fn xyz(p: &kerf_interp::Position) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// Watches the cutting process tick by tick, in the force controller's steps.
struct Process {
    stock: CuttingConfig,
    /// Ticks per controller step (as the servo's controller counts them).
    step_ticks: u64,
    period: f64,
    /// The last target force seen, N.
    target: Option<f64>,
    ticks: u64,
    depth: f64,
    /// Over the step in progress: largest force, smallest depth.
    step_force: f64,
    step_min_depth: f64,
    cutting_ticks: u64,
    max_force: f64,
    changes: Vec<DepthChange>,
    steps: Vec<ForcePoint>,
    /// Per step: cut at full depth the whole step.
    cut_whole_step: Vec<bool>,
    ever_on: bool,
}

impl Process {
    fn new(stock: CuttingConfig, description: &kerf_machines::Description, period: f64) -> Process {
        // Without a spindle speed nothing cuts; steps of 10 ms then.
        let rpm = description.spindle.map_or(6000.0, |s| s.rpm);
        Process {
            stock,
            step_ticks: fuzzy::ticks_per_step(rpm, period) as u64,
            period,
            target: None,
            ticks: 0,
            depth: 0.0,
            step_force: 0.0,
            step_min_depth: f64::INFINITY,
            cutting_ticks: 0,
            max_force: 0.0,
            changes: Vec::new(),
            steps: Vec::new(),
            cut_whole_step: Vec::new(),
            ever_on: false,
        }
    }

    fn tick(&mut self, time: f64, snap: &servo::Snapshot, force: f64) {
        self.ticks += 1;
        let p = &snap.position;
        let depth = self
            .stock
            .top_at(p.x)
            .map_or(0.0, |top| (top - p.z).max(0.0));
        if (depth - self.depth).abs() > DEPTH_STEP {
            self.changes.push(DepthChange {
                time,
                depth_from: self.depth,
                depth_to: depth,
                force_before: self.steps.last().map_or(0.0, |s| s.force),
                ..Default::default()
            });
        }
        self.depth = depth;
        if depth > 0.0 && force > 0.0 {
            self.cutting_ticks += 1;
        }
        self.max_force = self.max_force.max(force);
        self.step_force = self.step_force.max(force);
        self.step_min_depth = self
            .step_min_depth
            .min(if force > 0.0 { depth } else { 0.0 });
        if let Some(f) = &snap.force {
            self.target = f.target.or(self.target);
            self.ever_on |= f.target.is_some();
        }
        if self.ticks.is_multiple_of(self.step_ticks) {
            let (estimated, feed_override) = snap
                .force
                .map_or((0.0, 1.0), |f| (f.force, f.feed_override));
            self.steps.push(ForcePoint {
                time,
                force: self.step_force,
                estimated,
                feed_override,
                depth,
            });
            self.cut_whole_step.push(self.step_min_depth > 0.0);
            self.step_force = 0.0;
            self.step_min_depth = f64::INFINITY;
        }
    }

    fn finish(
        mut self,
    ) -> (
        Option<CuttingFigures>,
        Option<ForceFigures>,
        Vec<ForcePoint>,
    ) {
        let target = self.target.filter(|_| self.ever_on);
        let mut settled_errors = Vec::new();
        let mut longest: Option<f64> = Some(0.0);
        let count = self.changes.len();
        for k in 0..count {
            let start = self.changes[k].time;
            let end = self.changes.get(k + 1).map_or(f64::INFINITY, |c| c.time);
            // Steps that end after this change and before the next, cut
            // at depth the whole step.
            let steps: Vec<(usize, &ForcePoint)> = self
                .steps
                .iter()
                .enumerate()
                .filter(|(i, s)| s.time > start && s.time <= end && self.cut_whole_step[*i])
                .collect();
            let change = &mut self.changes[k];
            change.force_after = steps.last().map_or(0.0, |(_, s)| s.force);
            if let (Some(t), false) = (target, steps.is_empty()) {
                let inside = |s: &ForcePoint| (s.force - t).abs() <= SETTLE_BAND * t;
                // The first step of the last unbroken run inside the band.
                let first_in = steps
                    .iter()
                    .rposition(|(_, s)| !inside(s))
                    .map_or(0, |i| i + 1);
                change.settle = steps.get(first_in).map(|(_, s)| s.time - start);
                for (_, s) in &steps[first_in.min(steps.len())..] {
                    settled_errors.push((s.force - t) / t);
                }
                longest = match (longest, change.settle) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    _ => None,
                };
            }
        }
        let cutting = CuttingFigures {
            max_force: self.max_force,
            cutting_time: self.cutting_ticks as f64 * self.period,
            changes: self.changes,
        };
        let force = target.map(|t| ForceFigures {
            target: t,
            max: self.steps.iter().map(|s| s.force).fold(0.0, f64::max),
            rms_error_pct: (!settled_errors.is_empty()).then(|| {
                100.0
                    * (settled_errors.iter().map(|e| e * e).sum::<f64>()
                        / settled_errors.len() as f64)
                        .sqrt()
            }),
            settle: if count == 0 { None } else { longest },
        });
        (Some(cutting), force, self.steps)
    }
}
