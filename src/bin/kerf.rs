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
        /// Output format: `readable` (machine mm, one command per line) or
        /// `linuxcnc` (the text of LinuxCNC's stand-alone interpreter rs274).
        #[arg(long, value_name = "FORMAT", default_value = "readable")]
        format: CanonFormat,
        /// LinuxCNC tool table file (.tbl).
        #[arg(long, value_name = "FILE")]
        tool_table: Option<PathBuf>,
        /// Parameter file (.var): read at start, written back at program end.
        #[arg(long, value_name = "FILE")]
        params: Option<PathBuf>,
        /// LinuxCNC INI file for [RS274NGC] settings (subroutine path, remaps).
        #[arg(long, value_name = "FILE")]
        ini: Option<PathBuf>,
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
        /// List the planned segments and their limits (speeds in mm/min,
        /// acceleration mm/s², jerk mm/s³) instead of running the plan.
        #[arg(long)]
        segments: bool,
    },
    /// Joints for a pose (inverse) or the pose for joints (forward), offline.
    Kins {
        /// Machine: an embedded name (mill3, oxglide-x, oxglide-o, rfmt5) or a TOML file.
        #[arg(long, value_name = "NAME|FILE", default_value = kerf_machines::DEFAULT_MACHINE)]
        machine: String,
        /// Print JSON: {"joints": [...]}, {"pose": {...}} or {"error": "..."}.
        #[arg(long)]
        json: bool,
        /// Do not check axis travel and joint strokes (reach is still checked).
        #[arg(long)]
        no_limits: bool,
        #[command(subcommand)]
        direction: KinsDirection,
    },
    /// Compute and plot the reachable workspace of a machine, offline.
    Workspace {
        /// Machine: an embedded name or a TOML file.
        #[arg(long, value_name = "NAME|FILE", default_value = kerf_machines::DEFAULT_MACHINE)]
        machine: String,
        /// Draw the workspace into this SVG file.
        #[arg(long, value_name = "FILE")]
        plot: Option<PathBuf>,
    },
}

#[derive(Subcommand, Debug)]
enum KinsDirection {
    /// Pose to joints: X Y Z, then the machine's other axes (A B ...; mm, degrees).
    Inverse {
        #[arg(allow_hyphen_values = true, num_args = 1.., value_name = "COORD")]
        values: Vec<String>,
    },
    /// Joints to pose: one value per joint, in joint order.
    Forward {
        #[arg(allow_hyphen_values = true, num_args = 1.., value_name = "JOINT")]
        values: Vec<String>,
    },
}

/// Output formats of `kerf canon`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum CanonFormat {
    Readable,
    Linuxcnc,
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
        Cmd::Canon {
            format,
            tool_table,
            params,
            ini,
            file,
        } => cli::canon::canon(
            &file,
            &cli::canon::CanonOptions {
                format: match format {
                    CanonFormat::Readable => cli::canon::Format::Readable,
                    CanonFormat::Linuxcnc => cli::canon::Format::Linuxcnc,
                },
                tool_table,
                params,
                ini,
            },
        ),
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
            segments,
        } => {
            if segments {
                cli::plan::segments(&file, &machine)
            } else {
                cli::plan::plan(&file, &machine, plot.as_deref(), json, trapezoidal)
            }
        }
        Cmd::Kins {
            machine,
            json,
            no_limits,
            direction,
        } => {
            let (direction, values) = match direction {
                KinsDirection::Inverse { values } => (cli::kins::Direction::Inverse, values),
                KinsDirection::Forward { values } => (cli::kins::Direction::Forward, values),
            };
            cli::kins::kins(&cli::kins::Request {
                machine,
                direction,
                values,
                json,
                no_limits,
            })
        }
        Cmd::Workspace { machine, plot } => cli::workspace::workspace(&machine, plot.as_deref()),
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
