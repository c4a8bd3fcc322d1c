//! kerfd: the kerf controller daemon.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use kerf::daemon::{bind_socket, Daemon, Options};

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
