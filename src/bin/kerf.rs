//! kerf: command-line client of kerfd, and offline tools.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use kerf::cli::{self, Failure};

#[derive(Parser, Debug)]
#[command(
    name = "kerf",
    version,
    about = "Control kerfd, the kerf CNC controller daemon, and work on G-code offline"
)]
struct Args {
    /// kerfd's command socket [default: as kerfd].
    #[arg(long, value_name = "PATH", global = true)]
    socket: Option<PathBuf>,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Print the machine state, current line and position.
    Status {
        /// Print the status as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Run a G-code program and show its progress until it ends.
    Run {
        /// The program file.
        file: PathBuf,
    },
    /// Interpret a program offline and print its canon commands.
    Canon {
        /// The program file.
        file: PathBuf,
    },
    /// Check a program offline against a machine's travel, reach and
    /// joint strokes; exits non-zero with the list of violations.
    Check {
        /// The program file.
        file: PathBuf,
        /// Machine: embedded name or TOML file.
        #[arg(long, default_value = kerf_machines::DEFAULT_MACHINE)]
        machine: String,
        /// Print the result as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Plan a program offline: cycle time, path deviation, limit use.
    Plan {
        /// The program file.
        file: PathBuf,
        /// Machine: embedded name or TOML file.
        #[arg(long, default_value = kerf_machines::DEFAULT_MACHINE)]
        machine: String,
        /// Write an SVG plot of the path and of position, joints and feed
        /// against time.
        #[arg(long, value_name = "OUT.svg")]
        plot: Option<PathBuf>,
        /// Print the result as JSON.
        #[arg(long)]
        json: bool,
        /// Acceleration-limited (trapezoidal) profiles instead of jerk-limited.
        #[arg(long)]
        trapezoidal: bool,
    },
}

fn main() -> ExitCode {
    let args = Args::parse();
    let socket = args
        .socket
        .clone()
        .unwrap_or_else(kerf::paths::default_socket);
    let result = match args.command {
        Cmd::Status { json } => cli::status::status(&socket, json),
        Cmd::Run { file } => cli::run::run(&socket, &file),
        Cmd::Canon { file } => cli::canon::canon(&file),
        Cmd::Check {
            file,
            machine,
            json,
        } => cli::plan::check(&file, &machine, json),
        Cmd::Plan {
            file,
            machine,
            plot,
            json,
            trapezoidal,
        } => cli::plan::plan(&file, &machine, plot.as_deref(), json, trapezoidal),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure(code, message)) => {
            if !message.is_empty() {
                eprintln!("kerf: {message}");
            }
            ExitCode::from(code)
        }
    }
}
