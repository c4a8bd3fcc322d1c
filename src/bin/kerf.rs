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
        /// Print the servo thread's wake-up latency (min, median, p99,
        /// p99.9, max) and real-time settings.
        #[arg(long)]
        latency: bool,
    },
    /// Turn cutting-force control on (with a target force) or off.
    Force {
        #[command(subcommand)]
        action: ForceAction,
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
        #[command(flatten)]
        run: OfflineRun,
        /// Acceleration-limited (trapezoidal) profiles instead of jerk-limited.
        #[arg(long)]
        trapezoidal: bool,
        /// List the planned segments and their limits (speeds in mm/min,
        /// acceleration mm/s², jerk mm/s³) instead of running the plan.
        #[arg(long)]
        segments: bool,
    },
    /// Run a program on the simulated machine (servo loops, plant and
    /// cutting process) on a virtual clock: cycle time, following and
    /// contour error, cutting force and the force controller.
    Sim {
        #[command(flatten)]
        run: OfflineRun,
        /// The seed's pure PD: no velocity or acceleration feedforward.
        #[arg(long)]
        no_feedforward: bool,
        /// Plant of the simulated joints [default: identified].
        #[arg(long, value_enum, default_value = "identified")]
        plant: PlantArg,
        /// Force control on from the start with this target, N (as the
        /// program's force-control M-code will do).
        #[arg(long, value_name = "N")]
        force: Option<f64>,
        /// Servo period in microseconds (250 to 10000).
        #[arg(long, value_name = "US", default_value_t = 1000,
              value_parser = clap::value_parser!(u32).range(250..=10000))]
        period_us: u32,
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

/// A program run offline on a machine (`plan`, `sim`).
#[derive(clap::Args, Debug)]
struct OfflineRun {
    /// The program file.
    file: PathBuf,
    /// Machine: embedded name or TOML file.
    #[arg(long, default_value = kerf_machines::DEFAULT_MACHINE)]
    machine: String,
    /// Write an SVG plot: the path, and position, joints, feed (plan) or
    /// following error, feed, force and override (sim) against time.
    #[arg(long, value_name = "OUT.svg")]
    plot: Option<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum PlantArg {
    /// Each joint sits on its command (no servo dynamics).
    Ideal,
    /// The seed's identified feed drive, driven by the position loop.
    Identified,
}

#[derive(Subcommand, Debug)]
enum ForceAction {
    /// On, holding the cutting force at TARGET newtons (default: the
    /// current or configured target).
    On {
        #[arg(value_name = "TARGET_N")]
        target: Option<f64>,
    },
    /// Off: the controller's feed override returns to 100 %.
    Off,
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

fn main() -> ExitCode {
    let args = Args::parse();
    let socket = args
        .socket
        .clone()
        .unwrap_or_else(kerf::paths::default_socket);
    let result = match args.command {
        Cmd::Status { json, latency } => cli::status::status(&socket, json, latency),
        Cmd::Force { action } => match action {
            ForceAction::On { target } => cli::status::force(&socket, true, target),
            ForceAction::Off => cli::status::force(&socket, false, None),
        },
        Cmd::Run { file } => cli::run::run(&socket, &file),
        Cmd::Canon { file } => cli::canon::canon(&file),
        Cmd::Check {
            file,
            machine,
            json,
        } => cli::plan::check(&file, &machine, json),
        Cmd::Plan {
            run:
                OfflineRun {
                    file,
                    machine,
                    plot,
                    json,
                },
            trapezoidal,
            segments,
        } => {
            if segments {
                cli::plan::segments(&file, &machine)
            } else {
                cli::plan::plan(&file, &machine, plot.as_deref(), json, trapezoidal)
            }
        }
        Cmd::Sim {
            run:
                OfflineRun {
                    file,
                    machine,
                    plot,
                    json,
                },
            no_feedforward,
            plant,
            force,
            period_us,
        } => {
            if force.is_some_and(|f| !(f.is_finite() && f > 0.0)) {
                Err(Failure(
                    cli::CANNOT_CONNECT,
                    "--force takes a force in N above 0".into(),
                ))
            } else {
                let options = kerf::simulate::SimOptions {
                    period: period_us as f64 * 1e-6,
                    feedforward: !no_feedforward,
                    plant: Some(match plant {
                        PlantArg::Ideal => kerf_io::sim::Plant::Ideal,
                        PlantArg::Identified => kerf_io::sim::Plant::Identified,
                    }),
                    force_target: force,
                    ..Default::default()
                };
                cli::sim::sim(&file, &machine, options, plot.as_deref(), json)
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
