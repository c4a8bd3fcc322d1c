//! The daemon: loads the machine, runs the servo thread, serves the command
//! socket and feeds motion to the servo.
//!
//! Everything that moves the machine — a program, an MDI line, a jog, homing
//! — is a *job*: canon commands checked whole against the machine's limits
//! before anything moves, then interpreted and planned again just ahead of
//! the machine by a planner thread that feeds the lock-free queue the servo
//! tick reads, ending with a `Stop` marker carrying the job's tag. The servo
//! reports the last tag it reached (`program_done`) or discarded
//! (`program_aborted`), which is how [`Control`] learns that a job ended.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use kerf_interp::{
    Axis, Canon, CanonCmd, Config, Environment, Interpreter, Offline, Position, ProbeKind,
    ProbeOutcome, Source,
};
use kerf_machines::Machine;
use kerf_motion::{Kinematics, PathMode, Planner, PlannerConfig, Segment};
use serde_json::{json, Map, Value};
use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncRead, AsyncWrite, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, UnixListener};
use tokio::sync::{broadcast, mpsc};

use crate::machine::{Control, JobKind, Program, Refusal};
use crate::protocol::{
    self, Command, ErrorCode, Event, Fields, ForceStatus, JointRef, Latency, MachineState,
    Overrides, ServerLine, ServoStatus, Status, PROTOCOL_VERSION,
};
use crate::seqlock::{seqlock, Reader};
use crate::servo::{self, Pacing, RealTime, ServoCommand, ServoThread, ServoTick, Snapshot};
use crate::state::{tools_to_text, Parameters, Store, Tool, COORDINATE_SYSTEMS};

/// Segments the planner may run ahead of the servo: the executor looks
/// ahead over all of them (at least 2000 segments, and 0.5 s of motion even
/// for 0.02 mm segments at 2 m/min).
pub const QUEUE_CAPACITY: usize = 8192;

/// How often the daemon looks at the servo for faults, ended jobs, lines
/// and messages, and so the longest delay of a state event.
const OBSERVE_PERIOD: Duration = Duration::from_millis(5);

/// How the daemon is started.
#[derive(Clone, Debug)]
pub struct Options {
    /// Machine: embedded name or TOML path.
    pub machine: String,
    /// Servo period, µs (250 to 10000).
    pub period_us: u32,
    /// Wall-clock or virtual-clock servo.
    pub pacing: Pacing,
    /// Real-time settings of the servo thread (with a wall clock); `None`:
    /// ordinary scheduling and no memory locking.
    pub realtime: Option<RealTime>,
    /// Where the parameter file and tool table live.
    pub state_dir: PathBuf,
    /// Bearer token TCP clients must present with `auth` (none: TCP needs
    /// none, which the configuration allows only on loopback).
    pub tcp_token: Option<String>,
}

/// The planner end of the servo queue, with the count of items ever
/// pushed through it (compared with the servo's count of consumed items).
struct Feed {
    producer: rtrb::Producer<Segment>,
    pushed: u64,
}

/// Where a job's canon commands come from.
enum JobSource {
    /// A program file, interpreted again while streaming.
    File(PathBuf),
    /// Canon already produced and checked (MDI, jog, homing).
    Canons(Vec<Canon>),
}

struct Shared {
    machine: String,
    kins: Arc<dyn Kinematics>,
    /// The pose every joint at its home position gives.
    home_pose: Position,
    status: Reader<Snapshot>,
    period_us: u32,
    planner: PlannerConfig,
    control: Mutex<Control>,
    /// The queue's producer, away while a planner thread streams.
    feed: Mutex<Option<Feed>>,
    feed_back: Condvar,
    /// Operator commands to the servo thread.
    commands: Mutex<rtrb::Producer<ServoCommand>>,
    /// Machine events, as lines ready to send.
    events: broadcast::Sender<Arc<str>>,
    store: Mutex<Store>,
    tcp_token: Option<String>,
    next_client: AtomicU64,
    pacing: Pacing,
    memory_locked: bool,
    realtime: servo::RealTimeReport,
    /// The machine's `[force_control]` target, if it has the table.
    force_control: Option<Option<f64>>,
    /// The modal state the last MDI line left (as G-code lines that set it
    /// up), carried to the next MDI line; a program run or a reset drops
    /// it, as LinuxCNC's interpreter starts afresh then.
    mdi_modal: Mutex<Option<[String; 2]>>,
    /// Number of the tool M6 last put in the spindle (0: none), so that the
    /// next program or MDI line starts with it loaded, as the machine has it.
    tool_in_spindle: Mutex<i32>,
    /// Up from a job's start until its planner thread has queued the final
    /// `Stop` marker: a servo on a virtual clock waits on an empty queue
    /// meanwhile, so a run never depends on how fast the planner is.
    streaming: Arc<AtomicBool>,
    /// The answer to the M66 the running program waits on, handed from its
    /// planner thread to the interpreter's environment (#5399).
    input_answer: Mutex<Option<f64>>,
}

/// A running daemon: the servo thread and the state the socket serves.
pub struct Daemon {
    shared: Arc<Shared>,
    servo: ServoThread,
}

impl Daemon {
    /// Load the machine and the state directory, build the HAL and start
    /// the servo thread. The machine starts in e-stop.
    pub fn start(options: &Options) -> anyhow::Result<Daemon> {
        if !(250..=10_000).contains(&options.period_us) {
            bail!(
                "servo period {} µs is out of range: use 250 to 10000",
                options.period_us
            );
        }
        let Machine {
            description,
            kinematics,
            origin,
        } = kerf_machines::load(&options.machine)?;
        let store = Store::open(&options.state_dir)?;
        let hal_config: kerf_io::HalConfig = description
            .hal
            .clone()
            .try_into()
            .with_context(|| format!("{origin}: [hal]"))?;
        let start = description.home();
        let n = kinematics.joints().len();
        let mut joints = vec![0.0; n];
        kinematics
            .inverse(&start, &mut joints)
            .map_err(|e| anyhow::anyhow!("{origin}: the machine origin is not reachable: {e}"))?;
        let home_joints: Vec<f64> = description
            .joints
            .iter()
            .zip(&joints)
            .map(|(j, at_origin)| j.home.unwrap_or(*at_origin))
            .collect();
        let home_pose = kinematics
            .forward(&home_joints, &start)
            .map_err(|e| anyhow::anyhow!("{origin}: the home pose is not reachable: {e}"))?;
        servo::check_cutting(&hal_config, &*kinematics).with_context(|| origin.clone())?;
        let hal = kerf_io::build(&hal_config, &joints).with_context(|| origin.clone())?;
        let (producer, consumer) = rtrb::RingBuffer::new(QUEUE_CAPACITY);
        let (commands, command_queue) = rtrb::RingBuffer::new(64);
        let period = options.period_us as f64 * 1e-6;
        let mut tick = ServoTick::new(
            period,
            start,
            kinematics.clone(),
            hal,
            consumer,
            command_queue,
        )?;
        tick.configure(&description);
        tick.set_pins(kerf_io::PinBank::new(&hal_config.pins));
        if let Some(shm) = &hal_config.shm {
            let instance = shm
                .instance
                .clone()
                .unwrap_or_else(|| description.name.clone());
            let export = kerf_io::shm::ShmExport::start(&instance, &hal_config.pins)
                .with_context(|| format!("{origin}: [hal.shm]"))?;
            tick.export_to(export, kerf_io::PinBank::new(&hal_config.pins));
            tracing::info!(%instance, "status and pins exported over shared memory");
        }
        let limits: Vec<Option<f64>> = description
            .joints
            .iter()
            .map(|j| j.following_error)
            .collect();
        tick.set_following_error_limits(&limits);
        let streaming = Arc::new(AtomicBool::new(false));
        tick.set_streaming_flag(streaming.clone());
        let (writer, reader) = seqlock(*tick.snapshot());
        let realtime = match options.pacing {
            Pacing::Wall => options.realtime,
            Pacing::Virtual => None,
        };
        let memory_locked = match realtime.map(|_| servo::lock_memory()) {
            Some(Ok(())) => true,
            Some(Err(why)) => {
                tracing::warn!("{why}");
                false
            }
            None => false,
        };
        let servo = ServoThread::spawn(tick, writer, options.pacing, realtime.unwrap_or_default())
            .context("cannot start the servo thread")?;
        for warning in &servo.realtime().warnings {
            tracing::warn!("{warning}");
        }
        tracing::info!(
            machine = %description.name,
            %origin,
            period_us = options.period_us,
            state_dir = %options.state_dir.display(),
            clock = ?options.pacing,
            sched_fifo = servo.realtime().fifo,
            memory_locked,
            "servo running"
        );
        let realtime = servo.realtime().clone();
        let joint_names = kinematics.joints().iter().map(|j| j.name.clone()).collect();
        Ok(Daemon {
            shared: Arc::new(Shared {
                machine: description.name,
                kins: kinematics,
                home_pose,
                status: reader,
                period_us: options.period_us,
                planner: PlannerConfig {
                    period,
                    digital_outputs: hal_config.pins.digital_out.len(),
                    analog_outputs: hal_config.pins.analog_out.len(),
                    digital_inputs: hal_config.pins.digital_in.len(),
                    analog_inputs: hal_config.pins.analog_in.len(),
                    ..PlannerConfig::default()
                },
                control: Mutex::new(Control::new(joint_names)),
                feed: Mutex::new(Some(Feed {
                    producer,
                    pushed: 0,
                })),
                feed_back: Condvar::new(),
                commands: Mutex::new(commands),
                events: broadcast::channel(1024).0,
                store: Mutex::new(store),
                tcp_token: options.tcp_token.clone(),
                next_client: AtomicU64::new(1),
                pacing: options.pacing,
                memory_locked,
                realtime,
                force_control: description.force_control.map(|f| f.target),
                mdi_modal: Mutex::new(None),
                tool_in_spindle: Mutex::new(0),
                streaming,
                input_answer: Mutex::new(None),
            }),
            servo,
        })
    }

    /// The current status.
    pub fn status(&self) -> Status {
        self.shared.status()
    }

    /// A reader of the servo's snapshots, for watchers outside the socket
    /// (the systemd watchdog).
    pub fn snapshot_reader(&self) -> Reader<Snapshot> {
        self.shared.status.clone()
    }

    /// Machine events as they happen, for watchers outside the socket (the
    /// systemd status line).
    pub fn events(&self) -> broadcast::Receiver<Arc<str>> {
        self.shared.events.subscribe()
    }

    /// Serve clients on the Unix socket `unix` and, when given, on `tcp`,
    /// until `shutdown` completes. Also watches the servo for faults, ended
    /// jobs and messages, and turns them into events.
    pub async fn serve(
        &self,
        unix: UnixListener,
        tcp: Option<TcpListener>,
        shutdown: impl std::future::Future<Output = ()>,
    ) {
        let watcher = {
            let shared = self.shared.clone();
            tokio::spawn(async move {
                let mut interval = tokio::time::interval(OBSERVE_PERIOD);
                interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
                loop {
                    interval.tick().await;
                    drop(shared.observe());
                }
            })
        };
        tokio::pin!(shutdown);
        loop {
            tokio::select! {
                _ = &mut shutdown => break,
                accepted = unix.accept() => match accepted {
                    Ok((stream, _)) => self.spawn_client(stream, false),
                    Err(e) => {
                        tracing::warn!("accept failed: {e}");
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                },
                accepted = accept_tcp(tcp.as_ref()) => match accepted {
                    Ok((stream, peer)) => {
                        tracing::info!(%peer, "TCP client");
                        let _ = stream.set_nodelay(true);
                        self.spawn_client(stream, self.shared.tcp_token.is_some());
                    }
                    Err(e) => {
                        tracing::warn!("TCP accept failed: {e}");
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                },
            }
        }
        watcher.abort();
    }

    fn spawn_client<S: AsyncRead + AsyncWrite + Send + 'static>(&self, stream: S, auth: bool) {
        let shared = self.shared.clone();
        tokio::spawn(async move { serve_client(stream, shared, auth).await });
    }

    /// Send an operator command to the servo thread.
    pub fn servo_command(&self, cmd: ServoCommand) -> Result<(), Refusal> {
        self.shared.send(cmd)
    }

    /// Stop in order: a job in progress decelerates to rest (at most
    /// `timeout`), the drives go off, the state is written, the servo thread
    /// stops. Returns what it did, for the log.
    pub async fn shutdown(&mut self, timeout: Duration) -> String {
        let shared = self.shared.clone();
        let mut report = String::from("no motion in progress");
        let tag = shared.observe().abort(false).ok();
        if let Some(tag) = tag {
            let _ = shared.send(ServoCommand::Abort { program: tag });
            let started = Instant::now();
            let stopped = loop {
                if shared.observe().job().is_none() {
                    break true;
                }
                if started.elapsed() > timeout {
                    break false;
                }
                tokio::time::sleep(OBSERVE_PERIOD).await;
            };
            report = if stopped {
                format!(
                    "motion stopped on the path in {:.3} s",
                    started.elapsed().as_secs_f64()
                )
            } else {
                format!("motion did not stop within {timeout:?}: drives switched off")
            };
        }
        shared.observe().estop();
        let _ = shared.send(ServoCommand::Enable(false));
        let flushed = {
            let store = shared.store.lock().expect("store lock poisoned");
            store.flush()
        };
        if let Err(e) = flushed {
            tracing::error!("cannot write the state: {e}");
            report.push_str(&format!("; state NOT written: {e}"));
        } else {
            report.push_str("; state written");
        }
        // Let the servo see the drives-off command before it stops.
        let ticks = shared.status.read().ticks;
        let started = Instant::now();
        while shared.status.read().ticks < ticks + 2 && started.elapsed() < Duration::from_secs(1) {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        self.servo.stop();
        report
    }

    /// Stop the servo thread.
    pub fn stop(&mut self) {
        self.servo.stop();
    }
}

async fn accept_tcp(
    tcp: Option<&TcpListener>,
) -> std::io::Result<(tokio::net::TcpStream, std::net::SocketAddr)> {
    match tcp {
        Some(l) => l.accept().await,
        None => std::future::pending().await,
    }
}

/// Bind the command socket at `path`: creates the directory, replaces a
/// stale socket file, refuses if another daemon answers there, and gives the
/// socket mode 0660 and, when named, the group `group`.
pub fn bind_socket(path: &Path, group: Option<&str>) -> anyhow::Result<UnixListener> {
    use std::os::unix::fs::PermissionsExt;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create socket directory {}", dir.display()))?;
    }
    if path.exists() {
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            bail!(
                "another kerfd is already listening on {}: stop it, or give this one --socket PATH",
                path.display()
            );
        }
        std::fs::remove_file(path)
            .with_context(|| format!("cannot remove stale socket {}", path.display()))?;
    }
    let listener =
        UnixListener::bind(path).with_context(|| format!("cannot listen on {}", path.display()))?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o660))
        .with_context(|| format!("cannot set permissions on {}", path.display()))?;
    if let Some(name) = group {
        let group = nix::unistd::Group::from_name(name)
            .with_context(|| format!("cannot look up group {name:?}"))?
            .with_context(|| format!("socket group {name:?} does not exist"))?;
        nix::unistd::chown(path, None, Some(group.gid)).with_context(|| {
            format!(
                "cannot give socket {} to group {name:?} (kerfd must run as root or be a member)",
                path.display()
            )
        })?;
    }
    Ok(listener)
}

impl Shared {
    /// Queue a command for the servo thread.
    fn send(&self, cmd: ServoCommand) -> Result<(), Refusal> {
        let mut commands = self.commands.lock().expect("command lock poisoned");
        commands.push(cmd).map_err(|_| {
            (
                ErrorCode::Busy,
                "the servo is not taking commands (64 waiting); try again".into(),
            )
        })
    }

    /// Bring the state machine up to date with the servo, publish the
    /// events that produced, and hand back the locked state machine.
    fn observe(&self) -> MutexGuard<'_, Control> {
        let mut control = self.control.lock().expect("control lock poisoned");
        let snap = self.status.read();
        let events = control.observe(&snap, || {
            snap.fault
                .map(|f| f.describe(&*self.kins))
                .unwrap_or_default()
        });
        for e in events {
            // Sent under the lock, so every client sees events in order.
            let line: Arc<str> = ServerLine::Event(e).to_line().into();
            let _ = self.events.send(line);
        }
        control
    }

    fn axes_map(&self, p: &Position) -> Map<String, Value> {
        self.kins
            .axes()
            .iter()
            .map(|spec| {
                (
                    spec.axis.letter().to_ascii_lowercase().to_string(),
                    json!(p.get(spec.axis)),
                )
            })
            .collect()
    }

    fn status(&self) -> Status {
        let control = self.observe();
        let snap = self.status.read();
        let (state, execution) = control.state();
        let program = control.program().map(|p| p.status.clone());
        Status {
            machine: self.machine.clone(),
            state,
            execution,
            optional_stop: snap.optional_stop,
            homed: control.homed().to_vec(),
            line: snap.line,
            position: self.axes_map(&snap.position),
            commanded: self.axes_map(&snap.commanded),
            joints: snap.joints[..snap.joint_count].to_vec(),
            velocity: snap.velocity * 60.0,
            overrides: Overrides {
                feed: snap.feed_override * 100.0,
                rapid: snap.rapid_override * 100.0,
                spindle: snap.spindle_override * 100.0,
            },
            job: control.job_status().cloned(),
            program,
            fault: control.fault().map(str::to_string),
            following_error: snap.following_error[..snap.joint_count].to_vec(),
            force: snap.force.map(|f| ForceStatus {
                enabled: f.target.is_some(),
                target_n: f.target,
                force_n: f.force,
                feed_override: f.feed_override,
            }),
            servo: ServoStatus {
                period_us: self.period_us,
                ticks: snap.ticks,
                overruns: snap.overruns,
                guard_takeovers: snap.guard_takeovers,
                clock: match self.pacing {
                    Pacing::Wall => "wall",
                    Pacing::Virtual => "virtual",
                }
                .into(),
                sched_fifo: self.realtime.fifo,
                memory_locked: self.memory_locked,
                cpu: self.realtime.cpu,
                latency: {
                    let l = snap.latency;
                    let us = |ns: u64| ns as f64 / 1000.0;
                    Latency {
                        samples: l.samples,
                        min_us: us(l.min_ns),
                        median_us: us(l.median_ns),
                        p99_us: us(l.p99_ns),
                        p999_us: us(l.p999_ns),
                        max_us: us(l.max_ns),
                    }
                },
            },
        }
    }

    /// Resolve a joint reference to its index.
    fn joint(&self, j: &JointRef) -> Result<usize, Refusal> {
        let joints = self.kins.joints();
        let found = match j {
            JointRef::Index(i) => (*i < joints.len()).then_some(*i),
            JointRef::Name(name) => joints.iter().position(|s| &s.name == name),
        };
        found.ok_or_else(|| {
            let names: Vec<&str> = joints.iter().map(|s| s.name.as_str()).collect();
            (
                ErrorCode::InvalidArgument,
                format!(
                    "no joint {}: this machine has joints {} (or 0 to {})",
                    match j {
                        JointRef::Index(i) => i.to_string(),
                        JointRef::Name(n) => format!("{n:?}"),
                    },
                    names.join(", "),
                    joints.len() - 1
                ),
            )
        })
    }

    /// The axis a joint drives alone, for jogging and homing it.
    fn joint_axis(&self, j: usize) -> Result<Axis, Refusal> {
        self.kins.joint_axis(j).ok_or_else(|| {
            (
                ErrorCode::InvalidArgument,
                format!(
                    "joint {} does not drive a single axis on this machine's kinematics, so it cannot be moved on its own",
                    self.kins.joints()[j].name
                ),
            )
        })
    }

    fn axis(&self, letter: &str) -> Result<Axis, Refusal> {
        letter
            .chars()
            .next()
            .filter(|_| letter.chars().count() == 1)
            .and_then(Axis::from_letter)
            .filter(|a| self.kins.axes().iter().any(|s| s.axis == *a))
            .ok_or_else(|| {
                (
                    ErrorCode::InvalidArgument,
                    format!(
                        "no axis {letter:?}: this machine has axes {}",
                        self.kins
                            .axes()
                            .iter()
                            .map(|s| s.axis.letter().to_ascii_lowercase().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })
    }

    /// `force_control`: turn the force controller on or off.
    fn force_control(&self, enabled: bool, target_n: Option<f64>) -> Result<Value, Refusal> {
        let Some(configured) = self.force_control else {
            return Err((
                ErrorCode::InvalidArgument,
                format!(
                    "machine {} has no force controller: add [spindle] and [force_control] to its description",
                    self.machine
                ),
            ));
        };
        let target = if enabled {
            let current = self.status.read().force.and_then(|f| f.target);
            match target_n.or(current).or(configured) {
                Some(t) if t.is_finite() && t > 0.0 => Some(t),
                Some(t) => {
                    return Err((
                        ErrorCode::InvalidArgument,
                        format!("target_n {t} is not a usable force: give newtons > 0"),
                    ))
                }
                None => {
                    return Err((
                        ErrorCode::InvalidArgument,
                        "no target force: give target_n (N)".into(),
                    ))
                }
            }
        } else {
            None
        };
        self.send(ServoCommand::ForceControl(target))?;
        Ok(json!({"enabled": enabled, "target_n": target}))
    }
}

enum Frame {
    Line,
    TooLong,
    Eof,
}

/// Read one newline-terminated frame into `buf`, refusing to buffer more
/// than [`protocol::MAX_LINE`] bytes of it.
async fn read_frame<R: AsyncBufRead + Unpin>(
    reader: &mut R,
    buf: &mut Vec<u8>,
) -> std::io::Result<Frame> {
    buf.clear();
    let mut too_long = false;
    loop {
        let available = reader.fill_buf().await?;
        if available.is_empty() {
            return Ok(if too_long {
                Frame::TooLong
            } else if buf.is_empty() {
                Frame::Eof
            } else {
                Frame::Line
            });
        }
        let (chunk, used, end) = match available.iter().position(|&b| b == b'\n') {
            Some(i) => (&available[..i], i + 1, true),
            None => (available, available.len(), false),
        };
        if !too_long {
            if buf.len() + chunk.len() > protocol::MAX_LINE {
                too_long = true;
                buf.clear();
            } else {
                buf.extend_from_slice(chunk);
            }
        }
        reader.consume(used);
        if end {
            return Ok(if too_long {
                Frame::TooLong
            } else {
                Frame::Line
            });
        }
    }
}

/// One client's connection.
struct Connection {
    id: u64,
    /// Still has to present the bearer token.
    needs_auth: bool,
    tx: mpsc::Sender<String>,
    subscription: Vec<tokio::task::JoinHandle<()>>,
}

impl Connection {
    /// Stop this client's event tasks and wait until they have stopped, so
    /// no event of the old subscription follows the reply.
    async fn unsubscribe(&mut self) {
        for task in self.subscription.drain(..) {
            task.abort();
            let _ = task.await;
        }
    }
}

async fn serve_client<S: AsyncRead + AsyncWrite + Send + 'static>(
    stream: S,
    shared: Arc<Shared>,
    needs_auth: bool,
) {
    let (read_half, mut write_half) = tokio::io::split(stream);
    // Replies wait for room; status events are dropped for a client too slow
    // to take them, so one slow client never holds up anything else.
    let (tx, mut rx) = mpsc::channel::<String>(256);
    let writer = tokio::spawn(async move {
        while let Some(line) = rx.recv().await {
            if write_half.write_all(line.as_bytes()).await.is_err() {
                break;
            }
        }
    });
    let mut conn = Connection {
        id: shared.next_client.fetch_add(1, Ordering::Relaxed),
        needs_auth,
        tx,
        subscription: Vec::new(),
    };
    let mut reader = BufReader::new(read_half);
    let mut buf = Vec::new();
    loop {
        let reply = match read_frame(&mut reader, &mut buf).await {
            Ok(Frame::Eof) | Err(_) => break,
            Ok(Frame::TooLong) => ServerLine::error(
                Value::Null,
                ErrorCode::LineTooLong,
                format!("request longer than {} bytes", protocol::MAX_LINE),
            ),
            Ok(Frame::Line) if buf.iter().all(|b| b.is_ascii_whitespace()) => continue,
            Ok(Frame::Line) => match protocol::parse_request(&buf) {
                Err(reply) => reply,
                Ok((id, cmd)) => match handle(&shared, &mut conn, cmd).await {
                    Ok(v) => ServerLine::ok(id, v),
                    Err((code, message)) => ServerLine::error(id, code, message),
                },
            },
        };
        if conn.tx.send(reply.to_line()).await.is_err() {
            break;
        }
    }
    conn.unsubscribe().await;
    // A continuous jog is a dead man's switch: it stops with its client.
    let orphan = shared.observe().stop_orphaned_jog(conn.id);
    if let Some(tag) = orphan {
        tracing::info!(
            client = conn.id,
            "jogging client disconnected: stopping the jog"
        );
        let _ = shared.send(ServoCommand::Abort { program: tag });
    }
    drop(conn);
    let _ = writer.await;
}

fn invalid(message: impl Into<String>) -> Refusal {
    (ErrorCode::InvalidArgument, message.into())
}

/// Carry out one request.
async fn handle(
    shared: &Arc<Shared>,
    conn: &mut Connection,
    cmd: Command,
) -> Result<Value, Refusal> {
    if conn.needs_auth && !matches!(cmd, Command::Hello | Command::Auth { .. }) {
        return Err((
            ErrorCode::Unauthorized,
            "this connection must present its token first: {\"cmd\": \"auth\", \"token\": \"...\"}"
                .into(),
        ));
    }
    match cmd {
        Command::Hello => Ok(json!({
            "protocol": PROTOCOL_VERSION,
            "server": "kerfd",
            "version": env!("CARGO_PKG_VERSION"),
            "machine": shared.machine,
            "auth_required": conn.needs_auth,
        })),
        Command::Auth { token } => {
            let expected = shared.tcp_token.as_deref().unwrap_or("");
            if shared.tcp_token.is_some()
                && !constant_time_eq(token.as_bytes(), expected.as_bytes())
            {
                tracing::warn!(client = conn.id, "wrong bearer token");
                return Err((ErrorCode::Unauthorized, "wrong token".into()));
            }
            conn.needs_auth = false;
            Ok(json!({}))
        }
        Command::Status => Ok(json!(shared.status())),
        Command::Subscribe {
            rate_hz,
            fields,
            events,
        } => {
            if let Some(r) = rate_hz.filter(|r| !(1.0..=1000.0).contains(r)) {
                return Err(invalid(format!(
                    "rate_hz {r} is out of range: use 1 to 1000"
                )));
            }
            conn.unsubscribe().await;
            if events {
                conn.subscription
                    .push(spawn_events(shared.events.subscribe(), conn.tx.clone()));
            }
            if let Some(rate) = rate_hz {
                conn.subscription
                    .push(spawn_status(shared.clone(), conn.tx.clone(), rate, fields));
            }
            Ok(json!({"rate_hz": rate_hz, "fields": fields, "events": events}))
        }
        Command::Unsubscribe => {
            conn.unsubscribe().await;
            Ok(json!({}))
        }
        Command::ForceControl { enabled, target_n } => shared.force_control(enabled, target_n),
        Command::Estop => {
            shared.observe().estop();
            shared.send(ServoCommand::Enable(false))?;
            tracing::warn!(client = conn.id, "e-stop");
            Ok(json!({}))
        }
        Command::Reset => {
            // A faulted job ends once the servo has discarded its queue,
            // within a few periods of the fault; give it that long.
            let started = Instant::now();
            loop {
                let outcome = {
                    let mut control = shared.observe();
                    let was_fault = control.fault().is_some();
                    control.reset().map(|()| was_fault)
                };
                match outcome {
                    Err((ErrorCode::Busy, _)) if started.elapsed() < Duration::from_secs(2) => {
                        tokio::time::sleep(OBSERVE_PERIOD).await;
                    }
                    Err(e) => return Err(e),
                    Ok(was_fault) => {
                        *shared.mdi_modal.lock().expect("MDI lock poisoned") = None;
                        if was_fault {
                            shared.send(ServoCommand::ClearFault)?;
                        }
                        return Ok(json!({}));
                    }
                }
            }
        }
        Command::On => operator(shared, Control::on, &[ServoCommand::Enable(true)]),
        Command::Off => operator(shared, Control::off, &[ServoCommand::Enable(false)]),
        Command::Home { joint } => home(shared, joint).await,
        Command::Jog {
            axis,
            joint,
            direction,
            speed,
            distance,
        } => jog(shared, conn.id, axis, joint, direction, speed, distance).await,
        Command::JogStop => {
            let mut control = shared.observe();
            let tag = control.abort(true)?;
            shared.send(ServoCommand::Abort { program: tag })?;
            Ok(json!({}))
        }
        Command::Mdi { line } => mdi(shared, line).await,
        Command::Open { path } => {
            let path = absolute(&path)?;
            if matches!(
                shared.observe().job().map(|j| &j.kind),
                Some(JobKind::Program)
            ) {
                return Err((ErrorCode::Busy, "cannot open: a program is running".into()));
            }
            let start = shared.status.read().commanded;
            let lines = check_file(shared, &path, start, 1).await?;
            let program = Program::ready(path, lines, 1);
            let file = program.status.file.clone();
            shared.observe().set_opened(program);
            Ok(json!({"file": file, "lines": lines}))
        }
        Command::Run { path, line } => run(shared, path, line, false).await,
        Command::Pause => operator(shared, Control::pause, &[ServoCommand::Hold(true)]),
        Command::Resume => {
            // Control stays locked until the servo has its commands, so no
            // other client's command comes between.
            let mut control = shared.observe();
            let stop = control.resume()?;
            go_on(shared, false, stop)?;
            Ok(json!({}))
        }
        Command::Step => {
            let stepping_program = {
                let mut control = shared.observe();
                if control.state().0 == MachineState::Idle {
                    false
                } else {
                    let stop = control.step()?;
                    go_on(shared, true, stop)?;
                    shared.send(ServoCommand::Step)?;
                    true
                }
            };
            if stepping_program {
                Ok(json!({}))
            } else {
                run(shared, None, None, true).await
            }
        }
        Command::OptionalStop { enabled } => {
            shared.send(ServoCommand::OptionalStop(enabled))?;
            Ok(json!({ "enabled": enabled }))
        }
        Command::Abort => {
            let mut control = shared.observe();
            let tag = control.abort(false)?;
            shared.send(ServoCommand::Abort { program: tag })?;
            Ok(json!({"aborted": tag}))
        }
        Command::Override {
            feed,
            rapid,
            spindle,
        } => {
            if feed.is_none() && rapid.is_none() && spindle.is_none() {
                return Err(invalid(
                    "give `feed` (0–200), `rapid` (0–100) and/or `spindle` (0–200), percent",
                ));
            }
            if let Some(s) = spindle.filter(|s| !(0.0..=200.0).contains(s)) {
                return Err(invalid(format!(
                    "spindle override {s} % is out of range 0 to 200"
                )));
            }
            if let Some(f) = feed.filter(|f| !(0.0..=200.0).contains(f)) {
                return Err(invalid(format!(
                    "feed override {f} % is out of range 0 to 200"
                )));
            }
            if let Some(r) = rapid.filter(|r| !(0.0..=100.0).contains(r)) {
                return Err(invalid(format!(
                    "rapid override {r} % is out of range 0 to 100"
                )));
            }
            if let Some(f) = feed {
                shared.send(ServoCommand::FeedOverride(f / 100.0))?;
            }
            if let Some(r) = rapid {
                shared.send(ServoCommand::RapidOverride(r / 100.0))?;
            }
            if let Some(s) = spindle {
                shared.send(ServoCommand::SpindleOverride(s / 100.0))?;
            }
            Ok(json!({"feed": feed, "rapid": rapid, "spindle": spindle}))
        }
        Command::Offsets => {
            let store = shared.store.lock().expect("store lock poisoned");
            Ok(offsets_json(shared, store.parameters()))
        }
        Command::SetOffset { system, values } => set_offset(shared, &system, &values).await,
        Command::Tools => {
            let store = shared.store.lock().expect("store lock poisoned");
            let tools: Vec<Value> = store
                .tools()
                .values()
                .map(|t| tool_json(shared, t))
                .collect();
            Ok(json!({ "tools": tools }))
        }
        Command::SetTool {
            tool,
            pocket,
            offsets,
            diameter,
            comment,
        } => {
            if tool == 0 {
                return Err(invalid("tool numbers start at 1"));
            }
            let offsets = offsets.map(|o| axis_values(shared, &o)).transpose()?;
            if let Some(d) = diameter.filter(|d| !(d.is_finite() && *d >= 0.0)) {
                return Err(invalid(format!("diameter {d} must be 0 or more")));
            }
            if comment.as_deref().is_some_and(|c| c.contains(['\n', '\r'])) {
                return Err(invalid("a tool comment is one line"));
            }
            let shared2 = shared.clone();
            let entry = blocking(move || {
                let mut store = shared2.store.lock().expect("store lock poisoned");
                let mut tools = store.tools().clone();
                let entry = tools.entry(tool).or_insert_with(|| Tool::new(tool));
                if let Some(p) = pocket {
                    entry.pocket = p;
                }
                for (axis, v) in offsets.into_iter().flatten() {
                    entry.offsets[axis.index()] = v;
                }
                if let Some(d) = diameter {
                    entry.diameter = d;
                }
                if let Some(c) = comment {
                    entry.comment = c;
                }
                let entry = entry.clone();
                store.set_tools(tools).map_err(io_refusal)?;
                Ok(entry)
            })
            .await?;
            Ok(tool_json(shared, &entry))
        }
        Command::RemoveTool { tool } => {
            let shared2 = shared.clone();
            blocking(move || {
                let mut store = shared2.store.lock().expect("store lock poisoned");
                let mut tools = store.tools().clone();
                if tools.remove(&tool).is_none() {
                    return Err(invalid(format!("no tool {tool} in the table")));
                }
                store.set_tools(tools).map_err(io_refusal)
            })
            .await?;
            Ok(json!({}))
        }
    }
}

/// Tell the servo to go on after `resume` or `step`: single block on or
/// off, feed hold off, and the program stop the tool waits at (if any, by
/// its number) released.
fn go_on(shared: &Shared, single_block: bool, stop: Option<u64>) -> Result<(), Refusal> {
    shared.send(ServoCommand::SingleBlock(single_block))?;
    shared.send(ServoCommand::Hold(false))?;
    if let Some(reached) = stop {
        shared.send(ServoCommand::ReleaseStop { reached })?;
    }
    Ok(())
}

/// An operator command that only changes state: apply `change` to the
/// state machine and, if it allows it, send `commands` to the servo (under
/// the same lock, so commands reach the servo in the order of the changes).
fn operator(
    shared: &Shared,
    change: fn(&mut Control) -> Result<(), Refusal>,
    commands: &[ServoCommand],
) -> Result<Value, Refusal> {
    let mut control = shared.observe();
    change(&mut control)?;
    for cmd in commands {
        shared.send(*cmd)?;
    }
    Ok(json!({}))
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    // Compare every byte whatever the first difference, so the time taken
    // does not tell an attacker how much of a guess was right.
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn io_refusal(e: crate::state::StateError) -> Refusal {
    tracing::error!("{e}");
    (ErrorCode::IoError, e.to_string())
}

/// Run blocking work (file I/O, program checks) off the async workers.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, Refusal> + Send + 'static,
) -> Result<T, Refusal> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| (ErrorCode::IoError, format!("internal task failed: {e}")))?
}

fn spawn_events(
    mut events: broadcast::Receiver<Arc<str>>,
    tx: mpsc::Sender<String>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            let line = match events.recv().await {
                Ok(line) => line.to_string(),
                Err(broadcast::error::RecvError::Lagged(missed)) => {
                    ServerLine::Event(Event::Lagged { missed }).to_line()
                }
                Err(broadcast::error::RecvError::Closed) => break,
            };
            // Machine events wait for the client (a fault must not be
            // dropped); a client that falls 1024 events behind is told.
            if tx.send(line).await.is_err() {
                break;
            }
        }
    })
}

fn spawn_status(
    shared: Arc<Shared>,
    tx: mpsc::Sender<String>,
    rate_hz: f64,
    fields: Fields,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut interval = tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz));
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut last: Map<String, Value> = Map::new();
        loop {
            interval.tick().await;
            let status = shared.status();
            let event = match fields {
                Fields::Full => Event::Status { status },
                Fields::Changed => {
                    let Value::Object(now) = json!(status) else {
                        continue;
                    };
                    let changes: Map<String, Value> = now
                        .iter()
                        .filter(|(k, v)| last.get(*k) != Some(v))
                        .map(|(k, v)| (k.clone(), v.clone()))
                        .collect();
                    last = now;
                    if changes.is_empty() {
                        continue;
                    }
                    Event::Changes { changes }
                }
            };
            let line = ServerLine::Event(event).to_line();
            if let Err(mpsc::error::TrySendError::Closed(_)) = tx.try_send(line) {
                break;
            }
        }
    })
}

fn absolute(path: &str) -> Result<PathBuf, Refusal> {
    let path = PathBuf::from(path);
    if !path.is_absolute() {
        return Err(invalid(format!(
            "program path {} must be absolute (the daemon has its own working directory)",
            path.display()
        )));
    }
    Ok(path)
}

/// Run a program: `path`, or the opened one; from `line`; in single-block
/// mode when `single_block`.
async fn run(
    shared: &Arc<Shared>,
    path: Option<String>,
    line: Option<u32>,
    single_block: bool,
) -> Result<Value, Refusal> {
    let what = if single_block { "step" } else { "run" };
    shared.observe().check_motion(what, true)?;
    let path = match path {
        Some(p) => absolute(&p)?,
        None => shared
            .observe()
            .program()
            .map(|p| p.path.clone())
            .ok_or_else(|| {
                (
                    ErrorCode::InvalidState,
                    format!("cannot {what}: no program is open; `open` one or give `path`"),
                )
            })?,
    };
    let from_line = line.unwrap_or(1);
    if from_line == 0 {
        return Err(invalid("lines count from 1"));
    }
    *shared.mdi_modal.lock().expect("MDI lock poisoned") = None;
    let start = shared.status.read().commanded;
    let lines = check_file(shared, &path, start, from_line).await?;
    let program = Program::ready(path.clone(), lines, from_line);
    let id = start_job(
        shared,
        what,
        JobKind::Program,
        Some(program),
        JobSource::File(path),
        start,
        from_line,
        single_block,
    )
    .await?;
    tracing::info!(program = id, lines, from_line, "program started");
    Ok(json!({"program": id, "lines": lines}))
}

async fn mdi(shared: &Arc<Shared>, line: String) -> Result<Value, Refusal> {
    if line.contains(['\n', '\r']) {
        return Err(invalid("MDI takes one line"));
    }
    shared.observe().check_motion("run MDI", true)?;
    let start = shared.status.read().commanded;
    // One MDI session is one interpreter's state: the last line's modal
    // state is set up first, and `%` (not M2, which resets the modes and
    // the coordinate system) ends the text.
    let modal = shared.mdi_modal.lock().expect("MDI lock poisoned").clone();
    let preamble: Vec<String> = modal.map(Vec::from).unwrap_or_default();
    let shift = 1 + preamble.len() as u32;
    let mut text = String::from("%\n");
    for l in &preamble {
        text.push_str(l);
        text.push('\n');
    }
    text.push_str(&format!("{line}\n%\n"));
    let MdiLine {
        canons,
        modal,
        parameters,
    } = interpret_mdi(shared, text, shift, start)?;
    check_canons(shared, &canons, start)?;
    let changed_tool = canons.iter().rev().find_map(|c| match c.cmd {
        CanonCmd::ChangeTool { tool, .. } => Some(tool),
        _ => None,
    });
    let tool_entries: Vec<_> = canons
        .iter()
        .filter_map(|c| match &c.cmd {
            CanonCmd::SetToolTableEntry { data, .. } => Some(*data),
            _ => None,
        })
        .collect();
    if parameters.is_some() || !tool_entries.is_empty() {
        // Before it moves: a line whose changes cannot be kept is refused.
        let shared2 = shared.clone();
        blocking(move || {
            for data in &tool_entries {
                keep_tool_entry(&shared2, data)?;
            }
            parameters.map_or(Ok(()), |p| save_parameters(&shared2, p))
        })
        .await?;
    }
    let id = start_job(
        shared,
        "run MDI",
        JobKind::Mdi,
        None,
        JobSource::Canons(canons),
        start,
        1,
        false,
    )
    .await?;
    *shared.mdi_modal.lock().expect("MDI lock poisoned") = Some(modal);
    if let Some(tool) = changed_tool {
        *shared.tool_in_spindle.lock().expect("tool lock poisoned") = tool;
    }
    Ok(json!({"mdi": id}))
}

/// Interpret MDI `text` whose first `shift` lines are the `%` and the
/// modal preamble; returns its canon and the modal state it leaves. Apart
/// from `mdi` because the interpreter is not `Send` and so cannot live in
/// an async function across an await.
fn interpret_mdi(
    shared: &Arc<Shared>,
    text: String,
    shift: u32,
    start: Position,
) -> Result<MdiLine, Refusal> {
    let held = Arc::new(Mutex::new(None));
    let mut interp = Interpreter::with_source(
        Box::new(std::io::Cursor::new(text.into_bytes())),
        "MDI",
        None,
        interp_config(shared, start),
        Box::new(HoldParameters(held.clone())),
    );
    let mut canons = Vec::new();
    for c in interp.by_ref() {
        // Lines are counted as the operator sees them: the preamble is line
        // 1 too, then the MDI line.
        match c {
            // The preamble's G0/G1 only sets the motion mode: its move to
            // where the tool is would be a needless stop.
            Ok(c)
                if c.source.line <= shift
                    && matches!(
                        c.cmd,
                        CanonCmd::StraightTraverse { .. } | CanonCmd::StraightFeed { .. }
                    ) => {}
            Ok(mut c) => {
                c.source.line = c.source.line.saturating_sub(shift).max(1);
                canons.push(c);
            }
            Err(mut e) => {
                e.line = e.line.saturating_sub(shift).max(1);
                return Err((ErrorCode::ProgramError, e.to_string()));
            }
        }
    }
    let modal = interp.modal_gcode();
    drop(interp);
    let parameters = held
        .lock()
        .expect("MDI parameters lock poisoned")
        .take()
        .transpose()
        .map_err(|e| (ErrorCode::ProgramError, format!("MDI: {e}")))?;
    Ok(MdiLine {
        canons,
        modal,
        parameters,
    })
}

/// An interpreted MDI line.
struct MdiLine {
    canons: Vec<Canon>,
    /// G-code that sets up the modes the line leaves.
    modal: [String; 2],
    /// The parameters it leaves (none if the interpreter saved none).
    parameters: Option<Parameters>,
}

/// The interpreter set-up of a run or MDI: it starts from the daemon's
/// stored parameters (work offsets, G92, G28/G30 positions, active
/// coordinate system) and tool table, at the machine's position.
fn interp_config(shared: &Shared, start: Position) -> Config {
    let store = shared.store.lock().expect("store lock poisoned");
    let parameters = store
        .parameters()
        .to_numbered()
        .into_iter()
        .map(|(n, v)| (n as usize, v))
        .collect();
    // The store's tool table was validated when it was read or set, so a
    // line the interpreter's reader skips here cannot occur.
    let (mut tool_table, _) =
        kerf_interp::ToolTable::parse_lenient(&tools_to_text(store.tools()), false);
    // Entry 0 is the spindle: the loaded tool's data there, as M6 leaves it.
    let loaded = *shared.tool_in_spindle.lock().expect("tool lock poisoned");
    let mut spindle_tool_index = 0;
    if loaded > 0 {
        if let Some(i) = tool_table.find(loaded) {
            tool_table.put(0, tool_table.get(i));
            spindle_tool_index = i;
        }
    }
    Config {
        tool_table,
        parameters,
        start_position: start,
        spindle_tool_index,
        ..Config::default()
    }
}

/// The environment of programs and MDI the machine runs: the parameters a
/// program leaves (G10 L2, G92, G28.1 …) go to the same parameter file the
/// `offsets` commands use, written atomically, so `offsets` shows them and
/// a restart keeps them. The interpreter saves when its program ends, which
/// is when it has read the program, a little ahead of the motion.
struct SaveToStore(Arc<Shared>);

impl Environment for SaveToStore {
    fn probe(&mut self, start: Position, end: Position, kind: ProbeKind) -> ProbeOutcome {
        // The simulated machine has no probe input: the offline model
        // (no trip at the programmed end) is what the check planned too.
        Offline::default().probe(start, end, kind)
    }

    fn save_parameters(&mut self, values: &[f64]) -> Result<(), String> {
        save_parameters(&self.0, stored_parameters(values)?).map_err(|(_, e)| e)
    }

    fn wait_input(&mut self, index: u32, digital: bool, mode: u8, timeout: f64, prev: f64) -> f64 {
        // The planner thread has already waited for the machine (see
        // `stream`); without an answer (none was asked) read as offline.
        let answer = self
            .0
            .input_answer
            .lock()
            .expect("input lock poisoned")
            .take();
        answer.unwrap_or_else(|| Offline::default().wait_input(index, digital, mode, timeout, prev))
    }
}

/// Keep a tool table entry a program or MDI line set (G10 L1/L10/L11) in
/// `tool.tbl`, as LinuxCNC's tool table keeps them; the comment stays.
fn keep_tool_entry(shared: &Shared, data: &kerf_interp::ToolData) -> Result<(), Refusal> {
    let Ok(number) = u32::try_from(data.tool) else {
        return Ok(());
    };
    if number == 0 {
        return Ok(());
    }
    let mut store = shared.store.lock().expect("store lock poisoned");
    let mut tools = store.tools().clone();
    let entry = tools.entry(number).or_insert_with(|| Tool::new(number));
    entry.pocket = u32::try_from(data.pocket).unwrap_or(number);
    entry.offsets = data.offset.to_array();
    entry.diameter = data.diameter;
    if tools != *store.tools() {
        store.set_tools(tools).map_err(io_refusal)?;
    }
    Ok(())
}

/// The persistent parameters among all of an interpreter's, by number.
fn stored_parameters(values: &[f64]) -> Result<Parameters, String> {
    let numbered = (5161..=5390u32)
        .filter_map(|n| values.get(n as usize).map(|v| (n, *v)))
        .collect();
    Parameters::from_numbered(&numbered)
}

/// Write `p` to the parameter file if it differs from what is stored.
fn save_parameters(shared: &Shared, p: Parameters) -> Result<(), Refusal> {
    let mut store = shared.store.lock().expect("store lock poisoned");
    if *store.parameters() != p {
        store.set_parameters(p).map_err(io_refusal)?;
    }
    Ok(())
}

/// The environment of MDI lines: the parameters the line leaves are held
/// until the line has passed its check, so a refused line changes nothing.
struct HoldParameters(Arc<Mutex<Option<Result<Parameters, String>>>>);

impl Environment for HoldParameters {
    fn probe(&mut self, start: Position, end: Position, kind: ProbeKind) -> ProbeOutcome {
        Offline::default().probe(start, end, kind)
    }

    fn save_parameters(&mut self, values: &[f64]) -> Result<(), String> {
        *self.0.lock().expect("MDI parameters lock poisoned") = Some(stored_parameters(values));
        Ok(())
    }
}

/// A canon command of a job kerfd makes itself (jog, homing): line 1 of
/// a pseudo-file named after it.
fn canon(file: &Arc<str>, cmd: CanonCmd) -> Canon {
    Canon {
        source: Source::new(file.clone(), 1),
        cmd,
    }
}

async fn home(shared: &Arc<Shared>, joint: Option<JointRef>) -> Result<Value, Refusal> {
    shared.observe().check_motion("home", false)?;
    let start = shared.status.read().commanded;
    let n = shared.kins.joints().len();
    // The simulated machine always knows where it is: homing is a rapid
    // move to the home pose, after which the joints count as homed.
    let (target, joints) = match joint {
        None => (shared.home_pose, (0..n).collect::<Vec<_>>()),
        Some(j) => {
            let j = shared.joint(&j)?;
            let axis = shared.joint_axis(j)?;
            let mut target = start;
            target.set(axis, shared.home_pose.get(axis));
            let joints = (0..n)
                .filter(|&k| shared.kins.joint_axis(k) == Some(axis))
                .collect();
            (target, joints)
        }
    };
    let file: Arc<str> = "home".into();
    let canons = vec![
        canon(&file, CanonCmd::StraightTraverse { end: target }),
        canon(&file, CanonCmd::ProgramEnd),
    ];
    check_canons(shared, &canons, start)?;
    let id = start_job(
        shared,
        "home",
        JobKind::Home { joints },
        None,
        JobSource::Canons(canons),
        start,
        1,
        false,
    )
    .await?;
    Ok(json!({"home": id}))
}

#[allow(clippy::too_many_arguments)] // the jog request's own fields
async fn jog(
    shared: &Arc<Shared>,
    client: u64,
    axis: Option<String>,
    joint: Option<JointRef>,
    direction: i32,
    speed: f64,
    distance: Option<f64>,
) -> Result<Value, Refusal> {
    let axis = match (axis, joint) {
        (Some(a), None) => shared.axis(&a)?,
        (None, Some(j)) => {
            let j = shared.joint(&j)?;
            shared.joint_axis(j)?
        }
        _ => return Err(invalid("give either `axis` or `joint`")),
    };
    if direction != 1 && direction != -1 {
        return Err(invalid(format!("direction {direction}: use 1 or -1")));
    }
    if !(speed.is_finite() && speed > 0.0) {
        return Err(invalid(format!("speed {speed} mm/min must be positive")));
    }
    if let Some(d) = distance.filter(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(invalid(format!("distance {d} must be positive")));
    }
    shared.observe().check_motion("jog", true)?;
    let start = shared.status.read().commanded;
    let limits = shared
        .kins
        .axes()
        .iter()
        .find(|s| s.axis == axis)
        .map(|s| s.limits)
        .expect("axis() checked the machine has it");
    let here = start.get(axis);
    let to = match distance {
        Some(d) => here + direction as f64 * d,
        // Continuous: toward the end of travel, until `jog_stop`.
        None if direction > 0 => limits.max.max(here),
        None => limits.min.min(here),
    };
    let mut target = start;
    target.set(axis, to);
    let file: Arc<str> = "jog".into();
    let canons = vec![
        canon(&file, CanonCmd::SetFeedRate { mm_per_min: speed }),
        canon(&file, CanonCmd::StraightFeed { end: target }),
        canon(&file, CanonCmd::ProgramEnd),
    ];
    check_canons(shared, &canons, start).map_err(|(_, m)| invalid(format!("jog refused: {m}")))?;
    let id = start_job(
        shared,
        "jog",
        JobKind::Jog {
            client,
            continuous: distance.is_none(),
        },
        None,
        JobSource::Canons(canons),
        start,
        1,
        false,
    )
    .await?;
    Ok(json!({"jog": id, "target": to}))
}

/// Take the queue's producer, waiting up to two seconds for the planner
/// thread of the job before to hand it back (it does right after its last
/// push, so the wait is short).
async fn take_feed(shared: &Arc<Shared>) -> Result<Feed, Refusal> {
    let shared = shared.clone();
    blocking(move || {
        let slot = shared.feed.lock().expect("feed lock poisoned");
        let (mut slot, _) = shared
            .feed_back
            .wait_timeout_while(slot, Duration::from_secs(2), |f| f.is_none())
            .expect("feed lock poisoned");
        slot.take().ok_or_else(|| {
            (
                ErrorCode::Busy,
                "the previous job is still streaming; try again".into(),
            )
        })
    })
    .await
}

fn return_feed(shared: &Shared, feed: Feed) {
    *shared.feed.lock().expect("feed lock poisoned") = Some(feed);
    shared.feed_back.notify_all();
}

/// Start a checked job: re-check the state (it may have changed while the
/// job was checked), tell the servo the execution mode, and start the
/// planner thread.
#[allow(clippy::too_many_arguments)]
async fn start_job(
    shared: &Arc<Shared>,
    what: &str,
    kind: JobKind,
    program: Option<Program>,
    source: JobSource,
    start: Position,
    from_line: u32,
    single_block: bool,
) -> Result<u32, Refusal> {
    let needs_homing = !matches!(kind, JobKind::Home { .. });
    let feed = take_feed(shared).await?;
    let mut control = shared.observe();
    let refusal = control.check_motion(what, needs_homing).err().or_else(|| {
        (shared.status.read().commanded != start).then(|| {
            (
                ErrorCode::Busy,
                format!(
                    "cannot {what}: the machine moved while the request was checked; try again"
                ),
            )
        })
    });
    if let Some(r) = refusal {
        drop(control);
        return_feed(shared, feed);
        return Err(r);
    }
    let (tag, cancel) = control.start_job(kind, program, single_block);
    let sent = shared
        .send(ServoCommand::SingleBlock(single_block))
        .and_then(|_| shared.send(ServoCommand::Hold(false)))
        .and_then(|_| {
            if single_block {
                shared.send(ServoCommand::Step)
            } else {
                Ok(())
            }
        });
    drop(control);
    sent?;
    let stream_shared = shared.clone();
    shared.streaming.store(true, Ordering::Release);
    std::thread::Builder::new()
        .name(format!("kerf-plan-{tag}"))
        .spawn(move || {
            let mut config = stream_shared.planner;
            if single_block {
                // Stepping stops at every block end, as LinuxCNC does: no
                // corner blend may span two blocks.
                config.mode = PathMode::ExactStop;
            }
            let job = Stream {
                tag,
                source,
                start,
                from_line,
                config,
                cancel,
            };
            stream(stream_shared, feed, job)
        })
        .map_err(|e| {
            shared.streaming.store(false, Ordering::Release);
            (
                ErrorCode::IoError,
                format!("cannot start the planner thread: {e}"),
            )
        })?;
    Ok(tag)
}

/// True for canon that a run from a later line skips: what moves, waits or
/// speaks. The rest (units, feed rate, …) still sets up the modal state.
/// No catch-all arm, so a new canon command must be sorted here.
fn skipped_before_start(cmd: &CanonCmd) -> bool {
    match cmd {
        CanonCmd::StraightTraverse { .. }
        | CanonCmd::StraightFeed { .. }
        | CanonCmd::ArcFeed { .. }
        | CanonCmd::StraightProbe { .. }
        | CanonCmd::RigidTap { .. }
        | CanonCmd::Dwell { .. }
        | CanonCmd::WaitInput { .. }
        | CanonCmd::WaitSpindleOrientComplete { .. }
        | CanonCmd::ProgramStop
        | CanonCmd::OptionalProgramStop
        | CanonCmd::PalletShuttle
        | CanonCmd::Message(_)
        | CanonCmd::Print(_)
        | CanonCmd::Log(_)
        | CanonCmd::LogOpen(_)
        | CanonCmd::LogAppend(_)
        | CanonCmd::LogClose => true,
        CanonCmd::UseLengthUnits(_)
        | CanonCmd::SetG5xOffset { .. }
        | CanonCmd::SetG92Offset { .. }
        | CanonCmd::SetXYRotation { .. }
        | CanonCmd::UseToolLengthOffset { .. }
        | CanonCmd::SelectPlane(_)
        | CanonCmd::SetFeedRate { .. }
        | CanonCmd::SetFeedMode { .. }
        | CanonCmd::SetMotionControlMode(_)
        | CanonCmd::SetNaivecamTolerance { .. }
        | CanonCmd::SetPlannerMode { .. }
        | CanonCmd::StartSpeedFeedSync { .. }
        | CanonCmd::StopSpeedFeedSync
        | CanonCmd::SetSpindleSpeed { .. }
        | CanonCmd::StartSpindleClockwise { .. }
        | CanonCmd::StartSpindleCounterclockwise { .. }
        | CanonCmd::StopSpindleTurning { .. }
        | CanonCmd::SetSpindleMode { .. }
        | CanonCmd::OrientSpindle { .. }
        | CanonCmd::SelectTool { .. }
        | CanonCmd::StartChange
        | CanonCmd::ChangeTool { .. }
        | CanonCmd::ChangeToolNumber { .. }
        | CanonCmd::SetToolTableEntry { .. }
        | CanonCmd::MistOn
        | CanonCmd::MistOff
        | CanonCmd::FloodOn
        | CanonCmd::FloodOff
        | CanonCmd::EnableFeedOverride
        | CanonCmd::DisableFeedOverride
        | CanonCmd::EnableSpeedOverride { .. }
        | CanonCmd::DisableSpeedOverride { .. }
        | CanonCmd::EnableAdaptiveFeed
        | CanonCmd::DisableAdaptiveFeed
        | CanonCmd::EnableFeedHold
        | CanonCmd::DisableFeedHold
        | CanonCmd::SetMotionOutputBit { .. }
        | CanonCmd::ClearMotionOutputBit { .. }
        | CanonCmd::SetMotionOutputValue { .. }
        | CanonCmd::SetAuxOutputBit { .. }
        | CanonCmd::ClearAuxOutputBit { .. }
        | CanonCmd::SetAuxOutputValue { .. }
        | CanonCmd::UserMCode { .. }
        | CanonCmd::ForceControl { .. }
        | CanonCmd::Comment(_)
        | CanonCmd::Finish
        | CanonCmd::ProgramEnd => false,
    }
}

/// Plan `canons` from `start` against the machine's limits without moving.
fn check_canons(shared: &Shared, canons: &[Canon], start: Position) -> Result<(), Refusal> {
    let mut planner = Planner::new(&*shared.kins, start, shared.planner);
    for c in canons {
        planner
            .plan(c)
            .map_err(|e| (ErrorCode::ProgramError, e.to_string()))?;
        while planner.next_segment().is_some() {}
    }
    Ok(())
}

/// Interpret and plan a whole program file from `from_line` without moving;
/// returns its line count.
async fn check_file(
    shared: &Arc<Shared>,
    path: &Path,
    start: Position,
    from_line: u32,
) -> Result<u32, Refusal> {
    let kins = shared.kins.clone();
    let config = shared.planner;
    let config_for_check = interp_config(shared, start);
    let path = path.to_path_buf();
    blocking(move || {
        let io_err = |e: std::io::Error| {
            (
                ErrorCode::IoError,
                format!("cannot read {}: {e}", path.display()),
            )
        };
        // A check only: what the program would leave in the parameters is
        // kept when it really runs.
        let interp = Interpreter::open_with(&path, config_for_check, Box::new(Offline::default()))
            .map_err(io_err)?;
        let mut planner = Planner::new(&*kins, start, config);
        for canon in interp {
            let canon = canon.map_err(|e| (ErrorCode::ProgramError, e.to_string()))?;
            if canon.source.line < from_line {
                if canon.cmd == CanonCmd::ProgramEnd {
                    return Err(invalid(format!(
                        "cannot start at line {from_line}: the program ends on line {}",
                        canon.source.line
                    )));
                }
                if skipped_before_start(&canon.cmd) {
                    continue;
                }
            }
            planner
                .plan(&canon)
                .map_err(|e| (ErrorCode::ProgramError, e.to_string()))?;
            while planner.next_segment().is_some() {}
        }
        let text = std::fs::read(&path).map_err(io_err)?;
        let lines = text.split(|b| *b == b'\n').count() as u32 - u32::from(text.ends_with(b"\n"));
        Ok(lines)
    })
    .await
}

/// What a planner thread streams.
struct Stream {
    tag: u32,
    source: JobSource,
    start: Position,
    from_line: u32,
    config: PlannerConfig,
    cancel: Arc<AtomicBool>,
}

/// The planner thread of one job: interpret (for files) and plan just
/// ahead of the servo, feeding its queue, then the job's `Stop` marker.
fn stream(shared: Arc<Shared>, mut feed: Feed, job: Stream) {
    let Stream {
        tag,
        source,
        start,
        from_line,
        config,
        cancel,
    } = job;
    let mut failure = None;
    let mut planner = Planner::new(&*shared.kins, start, config);
    let canons: Box<dyn Iterator<Item = Result<Canon, String>>> = match source {
        JobSource::Canons(c) => Box::new(c.into_iter().map(Ok)),
        JobSource::File(path) => match Interpreter::open_with(
            &path,
            interp_config(&shared, start),
            Box::new(SaveToStore(shared.clone())),
        ) {
            Ok(i) => Box::new(i.map(|r| r.map_err(|e| e.to_string()))),
            Err(e) => {
                failure = Some(format!("cannot read {}: {e}", path.display()));
                Box::new(std::iter::empty())
            }
        },
    };
    'program: for canon in canons {
        if cancel.load(Ordering::Relaxed) {
            break;
        }
        let c = match canon {
            Ok(c) => c,
            Err(e) => {
                failure = Some(format!("{e} (the file changed after it was checked?)"));
                break;
            }
        };
        if c.source.line < from_line && skipped_before_start(&c.cmd) {
            continue;
        }
        if let CanonCmd::SetToolTableEntry { data, .. } = &c.cmd {
            if let Err((_, e)) = keep_tool_entry(&shared, data) {
                failure = Some(e);
                break;
            }
        }
        if let CanonCmd::ChangeTool { tool, .. } = c.cmd {
            *shared.tool_in_spindle.lock().expect("tool lock poisoned") = tool;
        }
        if let CanonCmd::Message(text) = &c.cmd {
            let mut control = shared.control.lock().expect("control lock poisoned");
            control.queue_message(tag, feed.pushed, c.source.line, text.trim().to_string());
        }
        if let Err(e) = planner.plan(&c) {
            failure = Some(format!("{e} (the file changed after it was checked?)"));
            break;
        }
        // An M66: the servo answers once the tool has reached it; the
        // interpreter reads the answer (#5399) before its next line.
        let answered = shared.status.read().inputs_answered;
        while let Some(segment) = planner.next_segment() {
            if !push(&mut feed, segment, Some(&cancel)) {
                break 'program;
            }
        }
        if matches!(c.cmd, CanonCmd::WaitInput { .. }) {
            loop {
                if cancel.load(Ordering::Relaxed) {
                    break 'program;
                }
                let snap = shared.status.read();
                if snap.inputs_answered > answered {
                    *shared.input_answer.lock().expect("input lock poisoned") =
                        Some(snap.input_value);
                    break;
                }
                if let Some(fault) = snap.fault {
                    failure = Some(format!(
                        "line {}: stopped waiting for an input (M66): {}",
                        c.source.line,
                        fault.describe(&*shared.kins)
                    ));
                    break 'program;
                }
                // The wait is the program's: poll at the servo's pace.
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }
    if failure.is_none() && !cancel.load(Ordering::Relaxed) {
        planner.finish();
        while let Some(segment) = planner.next_segment() {
            if !push(&mut feed, segment, Some(&cancel)) {
                break;
            }
        }
    }
    // The marker follows even a failure or a cancel, so the servo stops
    // there (or, aborting, knows where the job's segments end).
    push(&mut feed, planner.end_marker(tag), None);
    shared.streaming.store(false, Ordering::Release);
    if let Some(reason) = failure {
        tracing::warn!(job = tag, %reason, "job failed");
        shared
            .control
            .lock()
            .expect("control lock poisoned")
            .job_failed(tag, reason);
    }
    return_feed(&shared, feed);
}

/// Push onto the servo queue, waiting while it is full; gives up (false)
/// when `cancel` is set. The servo always makes room eventually: it runs
/// the queue, discards it while aborting, or drains it with the drives off.
fn push(feed: &mut Feed, mut item: Segment, cancel: Option<&AtomicBool>) -> bool {
    loop {
        match feed.producer.push(item) {
            Ok(()) => {
                feed.pushed += 1;
                return true;
            }
            Err(rtrb::PushError::Full(back)) => {
                item = back;
                if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                    return false;
                }
                // The queue holds seconds of motion; polling at 1 ms keeps it full.
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }
}

/// Values in [`Axis::ALL`] order as `{"x": .., ...}` for this machine's axes.
fn axes_json(shared: &Shared, v: &[f64; 9]) -> Value {
    Value::Object(shared.axes_map(&Position::from_array(*v)))
}

fn offsets_json(shared: &Shared, p: &Parameters) -> Value {
    let axes = |v: &[f64; 9]| axes_json(shared, v);
    let mut systems = Map::new();
    for (name, v) in COORDINATE_SYSTEMS.iter().zip(&p.work_offsets) {
        systems.insert((*name).into(), axes(v));
    }
    json!({
        "active": COORDINATE_SYSTEMS[p.active_system],
        "systems": systems,
        "g92": axes(&p.g92),
        "g92_active": p.g92_active,
        "g28": axes(&p.g28),
        "g30": axes(&p.g30),
    })
}

fn tool_json(shared: &Shared, t: &Tool) -> Value {
    json!({
        "tool": t.number,
        "pocket": t.pocket,
        "offsets": axes_json(shared, &t.offsets),
        "diameter": t.diameter,
        "comment": t.comment,
    })
}

/// `{"x": 1.0, ...}` to (axis, value) pairs of this machine's axes.
fn axis_values(shared: &Shared, values: &Map<String, Value>) -> Result<Vec<(Axis, f64)>, Refusal> {
    if values.is_empty() {
        return Err(invalid("no axis values given, e.g. {\"x\": 10.0}"));
    }
    values
        .iter()
        .map(|(k, v)| {
            let axis = shared.axis(k)?;
            let v = v
                .as_f64()
                .filter(|v| v.is_finite())
                .ok_or_else(|| invalid(format!("{k}: {v} is not a number")))?;
            Ok((axis, v))
        })
        .collect()
}

async fn set_offset(
    shared: &Arc<Shared>,
    system: &str,
    values: &Map<String, Value>,
) -> Result<Value, Refusal> {
    let name = system.to_ascii_uppercase();
    let values = axis_values(shared, values)?;
    enum Slot {
        Work(usize),
        G92,
        G28,
        G30,
    }
    let slot = match name.as_str() {
        "G92" => Slot::G92,
        "G28" => Slot::G28,
        "G30" => Slot::G30,
        n => Slot::Work(
            COORDINATE_SYSTEMS
                .iter()
                .position(|s| *s == n)
                .ok_or_else(|| {
                    invalid(format!(
                        "no offset {system:?}: use G54 … G59.3, G92, G28 or G30"
                    ))
                })?,
        ),
    };
    let shared2 = shared.clone();
    blocking(move || {
        let mut store = shared2.store.lock().expect("store lock poisoned");
        let mut p = store.parameters().clone();
        let target = match slot {
            Slot::Work(k) => &mut p.work_offsets[k],
            Slot::G92 => &mut p.g92,
            Slot::G28 => &mut p.g28,
            Slot::G30 => &mut p.g30,
        };
        for (axis, v) in values {
            target[axis.index()] = v;
        }
        store.set_parameters(p).map_err(io_refusal)?;
        Ok(offsets_json(&shared2, store.parameters()))
    })
    .await
}
