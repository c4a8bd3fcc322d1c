//! The daemon: loads the machine, runs the servo thread, serves the command
//! socket and feeds programs to the servo.
//!
//! A program is checked whole before anything moves (every block
//! interpreted and every move planned against the machine's limits); only
//! then is it streamed again, interpreted and planned just ahead of the
//! machine into the lock-free queue the servo tick reads.

use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{bail, Context};
use kerf_interp::{Interpreter, Position};
use kerf_machines::Machine;
use kerf_motion::{Kinematics, Planner, PlannerConfig, Segment, SegmentKind};
use serde_json::{json, Map, Value};
use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::mpsc;

use crate::protocol::{
    self, Command, ErrorCode, Event, ForceStatus, Latency, MachineState, ProgramState,
    ProgramStatus, ServerLine, ServoStatus, Status, PROTOCOL_VERSION,
};
use crate::seqlock::{seqlock, Reader};
use crate::servo::{self, Pacing, RealTime, ServoCommand, ServoThread, ServoTick, Snapshot};

/// Segments the planner may run ahead of the servo: the executor looks
/// ahead over all of them (at least 2000 segments, and 0.5 s of motion even
/// for 0.02 mm segments at 2 m/min).
pub const QUEUE_CAPACITY: usize = 8192;

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
}

impl Default for Options {
    fn default() -> Self {
        Options {
            machine: kerf_machines::DEFAULT_MACHINE.into(),
            period_us: 1000,
            pacing: Pacing::Wall,
            realtime: None,
        }
    }
}

struct ProgramInfo {
    id: u32,
    file: String,
    lines: u32,
    error: Option<String>,
}

struct Programs {
    current: Option<ProgramInfo>,
    next_id: u32,
    /// The planner end of the servo queue; taken by the streaming thread
    /// while a program streams.
    producer: Option<rtrb::Producer<Segment>>,
}

struct Shared {
    machine: String,
    kins: Arc<dyn Kinematics>,
    status: Reader<Snapshot>,
    period_us: u32,
    planner: PlannerConfig,
    programs: Mutex<Programs>,
    /// Operator commands to the servo thread.
    commands: Mutex<rtrb::Producer<ServoCommand>>,
    pacing: Pacing,
    memory_locked: bool,
    realtime: servo::RealTimeReport,
    /// The machine's `[force_control]` target, if it has the table.
    force_control: Option<Option<f64>>,
}

/// A running daemon: the servo thread and the state the socket serves.
pub struct Daemon {
    shared: Arc<Shared>,
    servo: ServoThread,
}

impl Daemon {
    /// Load the machine, build its HAL and start the servo thread.
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
            clock = ?options.pacing,
            sched_fifo = servo.realtime().fifo,
            memory_locked,
            "servo running"
        );
        let realtime = servo.realtime().clone();
        Ok(Daemon {
            shared: Arc::new(Shared {
                machine: description.name,
                kins: kinematics,
                status: reader,
                period_us: options.period_us,
                planner: PlannerConfig {
                    period,
                    ..PlannerConfig::default()
                },
                commands: Mutex::new(commands),
                pacing: options.pacing,
                memory_locked,
                realtime,
                force_control: description.force_control.map(|f| f.target),
                programs: Mutex::new(Programs {
                    current: None,
                    next_id: 1,
                    producer: Some(producer),
                }),
            }),
            servo,
        })
    }

    /// The current status.
    pub fn status(&self) -> Status {
        self.shared.status()
    }

    /// Serve clients on `listener` until `shutdown` completes.
    pub async fn serve(
        &self,
        listener: UnixListener,
        shutdown: impl std::future::Future<Output = ()>,
    ) {
        tokio::pin!(shutdown);
        loop {
            tokio::select! {
                _ = &mut shutdown => break,
                accepted = listener.accept() => match accepted {
                    Ok((stream, _)) => {
                        let shared = self.shared.clone();
                        tokio::spawn(async move { serve_client(stream, shared).await });
                    }
                    Err(e) => {
                        tracing::warn!("accept failed: {e}");
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                },
            }
        }
    }

    /// Send an operator command to the servo thread.
    pub fn servo_command(&self, cmd: ServoCommand) -> Result<(), ServoCommand> {
        self.shared.servo_command(cmd)
    }

    /// Stop the servo thread.
    pub fn stop(&mut self) {
        self.servo.stop();
    }
}

/// Bind the command socket at `path`: creates the directory, replaces a
/// stale socket file, refuses if another daemon answers there.
pub fn bind_socket(path: &Path) -> anyhow::Result<UnixListener> {
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
    Ok(listener)
}

impl Shared {
    /// Queue a command for the servo thread; fails if 64 are already waiting.
    fn servo_command(&self, cmd: ServoCommand) -> Result<(), ServoCommand> {
        let mut commands = self.commands.lock().expect("command lock poisoned");
        commands.push(cmd).map_err(|rtrb::PushError::Full(c)| c)
    }

    fn status(&self) -> Status {
        let snap = self.status.read();
        let program = {
            let programs = self.programs.lock().expect("program lock poisoned");
            programs.current.as_ref().map(|p| {
                let mut error = p.error.clone();
                let state = if error.is_some() {
                    ProgramState::Failed
                } else if snap.program_done >= p.id {
                    ProgramState::Finished
                } else if let Some(fault) = snap.fault {
                    error = Some(format!("stopped by fault: {fault}"));
                    ProgramState::Failed
                } else {
                    ProgramState::Running
                };
                ProgramStatus {
                    id: p.id,
                    file: p.file.clone(),
                    state,
                    lines: p.lines,
                    error,
                }
            })
        };
        let state = if snap.fault.is_some() {
            MachineState::Fault
        } else if program
            .as_ref()
            .is_some_and(|p| p.state == ProgramState::Running)
        {
            MachineState::Running
        } else {
            MachineState::Idle
        };
        let mut position = Map::new();
        for spec in self.kins.axes() {
            let key = spec.axis.letter().to_ascii_lowercase().to_string();
            position.insert(key, json!(snap.position.get(spec.axis)));
        }
        Status {
            machine: self.machine.clone(),
            state,
            line: snap.line,
            position,
            joints: snap.joints[..snap.joint_count].to_vec(),
            program,
            fault: snap.fault.map(|f| f.to_string()),
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
        self.servo_command(ServoCommand::ForceControl(target))
            .map_err(|_| (ErrorCode::Busy, "the servo's command queue is full".into()))?;
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

async fn serve_client(stream: UnixStream, shared: Arc<Shared>) {
    let (read_half, mut write_half) = stream.into_split();
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
    let mut reader = BufReader::new(read_half);
    let mut buf = Vec::new();
    let mut subscription: Option<tokio::task::JoinHandle<()>> = None;
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
                Ok((id, Command::Hello)) => ServerLine::ok(
                    id,
                    json!({"protocol": PROTOCOL_VERSION, "server": "kerfd", "version": env!("CARGO_PKG_VERSION"), "machine": shared.machine}),
                ),
                Ok((id, Command::Status)) => ServerLine::ok(id, json!(shared.status())),
                Ok((id, Command::Run { path })) => match run_program(&shared, &path).await {
                    Ok(v) => ServerLine::ok(id, v),
                    Err((code, message)) => ServerLine::error(id, code, message),
                },
                Ok((id, Command::Subscribe { rate_hz })) => {
                    if !(1.0..=1000.0).contains(&rate_hz) {
                        ServerLine::error(
                            id,
                            ErrorCode::InvalidArgument,
                            format!("rate_hz {rate_hz} is out of range: use 1 to 1000"),
                        )
                    } else {
                        if let Some(old) = subscription.take() {
                            old.abort();
                        }
                        subscription =
                            Some(spawn_subscription(shared.clone(), tx.clone(), rate_hz));
                        ServerLine::ok(id, json!({"rate_hz": rate_hz}))
                    }
                }
                Ok((id, Command::ForceControl { enabled, target_n })) => {
                    match shared.force_control(enabled, target_n) {
                        Ok(v) => ServerLine::ok(id, v),
                        Err((code, message)) => ServerLine::error(id, code, message),
                    }
                }
                Ok((id, Command::Unsubscribe)) => {
                    if let Some(old) = subscription.take() {
                        old.abort();
                    }
                    ServerLine::ok(id, json!({}))
                }
            },
        };
        if tx.send(reply.to_line()).await.is_err() {
            break;
        }
    }
    if let Some(s) = subscription {
        s.abort();
    }
    drop(tx);
    let _ = writer.await;
}

fn spawn_subscription(
    shared: Arc<Shared>,
    tx: mpsc::Sender<String>,
    rate_hz: f64,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut interval = tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz));
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        loop {
            interval.tick().await;
            let line = ServerLine::Event(Event::Status {
                status: shared.status(),
            })
            .to_line();
            if let Err(mpsc::error::TrySendError::Closed(_)) = tx.try_send(line) {
                break;
            }
        }
    })
}

type Refusal = (ErrorCode, String);

/// Check the program whole, then start streaming it to the servo.
async fn run_program(shared: &Arc<Shared>, path: &str) -> Result<Value, Refusal> {
    let path = PathBuf::from(path);
    if !path.is_absolute() {
        return Err((
            ErrorCode::InvalidArgument,
            format!(
                "program path {} must be absolute (the daemon has its own working directory)",
                path.display()
            ),
        ));
    }
    let status = shared.status();
    match status.state {
        MachineState::Fault => {
            return Err((
                ErrorCode::Fault,
                format!("machine fault: {}", status.fault.unwrap_or_default()),
            ));
        }
        MachineState::Running => return Err((ErrorCode::Busy, "a program is running".into())),
        MachineState::Idle => {}
    }
    let start = shared.status.read().commanded;
    let kins = shared.kins.clone();
    let check_path = path.clone();
    let config = shared.planner;
    let lines =
        tokio::task::spawn_blocking(move || check_program(&check_path, &*kins, start, config))
            .await
            .map_err(|e| (ErrorCode::IoError, format!("program check failed: {e}")))??;

    let mut programs = shared.programs.lock().expect("program lock poisoned");
    let Some(producer) = programs.producer.take() else {
        return Err((ErrorCode::Busy, "a program is still streaming".into()));
    };
    let id = programs.next_id;
    programs.next_id += 1;
    programs.current = Some(ProgramInfo {
        id,
        file: path.display().to_string(),
        lines,
        error: None,
    });
    drop(programs);
    let stream_shared = shared.clone();
    std::thread::Builder::new()
        .name(format!("kerf-plan-{id}"))
        .spawn(move || stream_program(stream_shared, producer, id, &path, start))
        .map_err(|e| {
            (
                ErrorCode::IoError,
                format!("cannot start the planner thread: {e}"),
            )
        })?;
    tracing::info!(program = id, lines, "program started");
    Ok(json!({"program": id, "lines": lines}))
}

/// Interpret and plan the whole program without moving; returns its line count.
fn check_program(
    path: &Path,
    kins: &dyn Kinematics,
    start: Position,
    config: PlannerConfig,
) -> Result<u32, Refusal> {
    let io_err = |e: std::io::Error| {
        (
            ErrorCode::IoError,
            format!("cannot read {}: {e}", path.display()),
        )
    };
    let interp = Interpreter::open(path, start).map_err(io_err)?;
    let mut planner = Planner::new(kins, start, config);
    for canon in interp {
        let canon = canon.map_err(|e| (ErrorCode::ProgramError, e.to_string()))?;
        planner
            .plan(&canon)
            .map_err(|e| (ErrorCode::ProgramError, e.to_string()))?;
        while planner.next_segment().is_some() {}
    }
    let file = std::fs::File::open(path).map_err(io_err)?;
    let mut lines = 0u32;
    for line in std::io::BufReader::new(file).split(b'\n') {
        line.map_err(io_err)?;
        lines += 1;
    }
    Ok(lines)
}

/// Interpret and plan just ahead of the servo, feeding its queue.
fn stream_program(
    shared: Arc<Shared>,
    mut producer: rtrb::Producer<Segment>,
    id: u32,
    path: &Path,
    start: Position,
) {
    let mut failure = None;
    let mut end = start;
    let mut last_line = 0;
    match Interpreter::open(path, start) {
        Err(e) => failure = Some(format!("cannot read {}: {e}", path.display())),
        Ok(interp) => {
            let mut planner = Planner::new(&*shared.kins, start, shared.planner);
            'program: for canon in interp {
                let planned = canon.map_err(|e| e.to_string()).and_then(|c| {
                    last_line = c.source.line;
                    planner.plan(&c).map_err(|e| e.to_string())
                });
                if let Err(e) = planned {
                    failure = Some(format!("{e} (the file changed after it was checked?)"));
                    break;
                }
                while let Some(segment) = planner.next_segment() {
                    if let Err(e) = push(&shared, &mut producer, segment) {
                        failure = Some(e);
                        break 'program;
                    }
                }
            }
            planner.finish();
            end = planner.position();
            while failure.is_none() {
                let Some(segment) = planner.next_segment() else {
                    break;
                };
                failure = push(&shared, &mut producer, segment).err();
            }
        }
    }
    // The end marker follows even a failure, so the servo stops there.
    let marker = Segment::marker(SegmentKind::Stop { tag: id }, last_line, end);
    let marker_failure = push(&shared, &mut producer, marker).err();
    let mut programs = shared.programs.lock().expect("program lock poisoned");
    if let (Some(reason), Some(p)) = (failure.or(marker_failure), programs.current.as_mut()) {
        tracing::warn!(program = id, %reason, "program failed");
        p.error = Some(reason);
    }
    programs.producer = Some(producer);
}

/// Push onto the servo queue, waiting while it is full. Gives up if the
/// servo faults, since a faulted servo takes nothing more.
fn push(
    shared: &Shared,
    producer: &mut rtrb::Producer<Segment>,
    mut item: Segment,
) -> Result<(), String> {
    loop {
        match producer.push(item) {
            Ok(()) => return Ok(()),
            Err(rtrb::PushError::Full(back)) => {
                item = back;
                if let Some(fault) = shared.status.read().fault {
                    return Err(format!("stopped by fault: {fault}"));
                }
                // The queue holds seconds of motion; polling at 1 ms keeps it full.
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }
}
