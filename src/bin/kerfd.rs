//! kerfd: the kerf controller daemon.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use kerf::config::Config;
use kerf::daemon::{bind_socket, Daemon, Options};
use kerf::servo::{Pacing, RealTime};
use kerf::systemd;

/// The kerf CNC controller daemon. With no arguments it runs the embedded
/// simulated 3-axis mill `mill3`. Flags override the configuration file.
#[derive(Parser, Debug)]
#[command(name = "kerfd", version)]
struct Args {
    /// Configuration file [default: /etc/kerf/kerf.toml when it exists].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Command socket path [default: $KERF_SOCKET, $RUNTIME_DIRECTORY/kerfd.sock,
    /// $XDG_RUNTIME_DIR/kerf/kerfd.sock or /tmp/kerf-$UID/kerfd.sock].
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Machine to run: an embedded name (mill3) or a machine TOML file [default: mill3].
    #[arg(long, value_name = "NAME|FILE")]
    machine: Option<String>,
    /// Servo period in microseconds, 250 to 10000 [default: 1000].
    #[arg(long, value_name = "US")]
    period_us: Option<u32>,
    /// Directory of the parameter file and tool table [default:
    /// $STATE_DIRECTORY, $XDG_STATE_HOME/kerf or ~/.local/state/kerf].
    #[arg(long, value_name = "DIR")]
    state_dir: Option<PathBuf>,
    /// Run the servo on a virtual clock: ticks back to back, each one
    /// period of machine time, deterministic (for tests and simulation).
    #[arg(long)]
    virtual_clock: bool,
    /// SCHED_FIFO priority of the servo thread, 1 to 99 [default: the
    /// configuration's `servo.priority`, or 80].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
    /// Pin the servo thread to this CPU [default: the configuration's
    /// `servo.cpu`].
    #[arg(long, value_name = "CPU")]
    servo_cpu: Option<usize>,
    /// Do not ask for SCHED_FIFO or lock memory (the servo runs as an
    /// ordinary thread; wake-ups will be later).
    #[arg(long)]
    no_realtime: bool,
}

fn main() -> ExitCode {
    systemd::init_logging();
    let args = Args::parse();
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            eprintln!("kerfd: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let (config, file) = Config::find(args.config.as_deref())?;
    let config_name = file.map_or_else(
        || "(no configuration file)".to_string(),
        |f| f.display().to_string(),
    );
    let tcp = config.tcp(&config_name)?;
    let socket = args
        .socket
        .or(config.socket.path.clone())
        .unwrap_or_else(kerf::paths::default_socket);
    let options = Options {
        machine: args
            .machine
            .or(config.machine.clone())
            .unwrap_or_else(|| kerf_machines::DEFAULT_MACHINE.into()),
        period_us: args.period_us.or(config.servo.period_us).unwrap_or(1000),
        pacing: if args.virtual_clock {
            Pacing::Virtual
        } else {
            Pacing::Wall
        },
        realtime: (!args.no_realtime).then_some(RealTime {
            fifo_priority: Some(
                args.rt_priority
                    .unwrap_or(config.servo.priority.map_or(80, i32::from)),
            ),
            cpu: args.servo_cpu.or(config.servo.cpu),
        }),
        state_dir: args
            .state_dir
            .or(config.state_dir.clone())
            .unwrap_or_else(kerf::paths::default_state_dir),
        tcp_token: tcp.as_ref().and_then(|t| t.token.clone()),
    };
    tracing::info!(config = %config_name, "starting");
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let mut daemon = Daemon::start(&options)?;
    let result = runtime.block_on(async {
        let unix = bind_socket(&socket, config.socket.group.as_deref())?;
        let tcp_listener =
            match &tcp {
                Some(t) => Some(tokio::net::TcpListener::bind(t.listen).await.with_context(
                    || {
                        format!(
                            "{config_name}: key `tcp.listen`: cannot listen on {}",
                            t.listen
                        )
                    },
                )?),
                None => None,
            };
        if let (Some(t), Some(l)) = (&tcp, &tcp_listener) {
            let address = l.local_addr().unwrap_or(t.listen);
            tracing::info!(%address, token = t.token.is_some(), "listening on TCP");
        }
        tracing::info!(socket = %socket.display(), "listening");
        let status = daemon.status();
        systemd::ready(&format!(
            "machine {} in {:?}; socket {}",
            status.machine,
            status.state,
            socket.display()
        ));
        let watchdog = tokio::spawn(feed_watchdog(daemon_ticks(&daemon)));
        let status_line = tokio::spawn(show_state(daemon.events()));
        daemon.serve(unix, tcp_listener, shutdown_signal()).await;
        watchdog.abort();
        status_line.abort();
        systemd::stopping("stopping: bringing motion to rest");
        tracing::info!("stopping");
        let report = daemon.shutdown(Duration::from_secs(5)).await;
        tracing::info!("{report}");
        anyhow::Ok(())
    });
    daemon.stop();
    let _ = std::fs::remove_file(&socket);
    tracing::info!("stopped");
    result
}

/// A function reading the servo's tick count, for the watchdog.
fn daemon_ticks(daemon: &Daemon) -> impl Fn() -> u64 + Send + 'static {
    let reader = daemon.snapshot_reader();
    move || reader.read().ticks
}

/// Ping the systemd watchdog at half its timeout, but only while the servo
/// keeps ticking: if it stalls, systemd notices and restarts kerfd.
async fn feed_watchdog(ticks: impl Fn() -> u64) {
    let Some(interval) = systemd::watchdog_interval() else {
        return;
    };
    tracing::info!(?interval, "feeding the systemd watchdog");
    let mut last = ticks();
    let mut timer = tokio::time::interval(interval);
    loop {
        timer.tick().await;
        let now = ticks();
        if now != last {
            systemd::watchdog();
        } else {
            tracing::error!("servo thread stalled: not feeding the watchdog");
        }
        last = now;
    }
}

/// Keep systemd's status line (`systemctl status kerfd`) on the machine
/// state and why it last changed.
async fn show_state(mut events: tokio::sync::broadcast::Receiver<std::sync::Arc<str>>) {
    use kerf::protocol::{Event, ServerLine};
    loop {
        let line = match events.recv().await {
            Ok(line) => line,
            Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => continue,
            Err(tokio::sync::broadcast::error::RecvError::Closed) => return,
        };
        if let Ok(ServerLine::Event(Event::State { state, reason, .. })) =
            serde_json::from_str::<ServerLine>(&line)
        {
            systemd::status(&format!(
                "{}{}",
                kerf::machine::state_name(state),
                reason.map(|r| format!(": {r}")).unwrap_or_default()
            ));
        }
    }
}

async fn shutdown_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term.recv() => {}
    }
}
