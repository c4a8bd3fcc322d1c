//! kerfd: the kerf controller daemon.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use kerf::daemon::{bind_socket, Daemon, Options};
use kerf::servo::{Pacing, RealTime};

/// The kerf CNC controller daemon. With no arguments it runs the embedded
/// simulated 3-axis mill `mill3`.
#[derive(Parser, Debug)]
#[command(name = "kerfd", version)]
struct Args {
    /// Command socket path [default: $KERF_SOCKET, $RUNTIME_DIRECTORY/kerfd.sock,
    /// $XDG_RUNTIME_DIR/kerf/kerfd.sock or /tmp/kerf-$UID/kerfd.sock].
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Machine to run: an embedded name (mill3) or a machine TOML file.
    #[arg(long, value_name = "NAME|FILE", default_value = kerf_machines::DEFAULT_MACHINE)]
    machine: String,
    /// Servo period in microseconds (250 to 10000).
    #[arg(long, value_name = "US", default_value_t = 1000)]
    period_us: u32,
    /// Run the servo on a virtual clock: ticks back to back, each one
    /// period of machine time, deterministic (for tests and simulation).
    #[arg(long)]
    virtual_clock: bool,
    /// SCHED_FIFO priority of the servo thread (1-99).
    #[arg(long, value_name = "N", default_value_t = 80,
          value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: i32,
    /// Pin the servo thread to this CPU.
    #[arg(long, value_name = "CPU")]
    servo_cpu: Option<usize>,
    /// Do not ask for SCHED_FIFO or lock memory (the servo runs as an
    /// ordinary thread; wake-ups will be later).
    #[arg(long)]
    no_realtime: bool,
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("KERF_LOG")
                .unwrap_or_else(|_| "info".into()),
        )
        .init();
    let args = Args::parse();
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("kerfd: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let socket = args.socket.unwrap_or_else(kerf::paths::default_socket);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let mut daemon = Daemon::start(&Options {
        machine: args.machine,
        period_us: args.period_us,
        pacing: if args.virtual_clock {
            Pacing::Virtual
        } else {
            Pacing::Wall
        },
        realtime: (!args.no_realtime).then_some(RealTime {
            fifo_priority: Some(args.rt_priority),
            cpu: args.servo_cpu,
        }),
    })?;
    let result = runtime.block_on(async {
        let listener = bind_socket(&socket)?;
        tracing::info!(socket = %socket.display(), "listening");
        daemon.serve(listener, shutdown_signal()).await;
        anyhow::Ok(())
    });
    tracing::info!("stopping");
    daemon.stop();
    let _ = std::fs::remove_file(&socket);
    result
}

async fn shutdown_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term.recv() => {}
    }
}
