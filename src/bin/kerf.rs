//! kerf: command-line client of kerfd, and offline tools.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use kerf::cli::{self, control, offsets, Failure};
use kerf::protocol::Command;

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
    /// Print replies and statuses as JSON, for scripts.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Print the machine state, current line and position.
    Status {
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
    /// Live view: DRO, state, line, speed, overrides, program progress.
    Watch {
        /// Refresh rate, Hz (1 to 1000).
        #[arg(long, default_value_t = 10.0)]
        rate: f64,
    },
    /// Run a G-code program and show its progress until it ends.
    Run {
        /// The program file.
        file: PathBuf,
        /// Start at this source line (earlier lines only set modes).
        #[arg(long, value_name = "LINE")]
        from: Option<u32>,
    },
    /// Check a program and make it the one `step` (and `run` without a
    /// file, over the socket) runs.
    Open {
        /// The program file.
        file: PathBuf,
    },
    /// Feed hold: decelerate on the path and wait.
    Pause,
    /// Release feed hold, single-block stepping or a program stop (M0, M1).
    Resume,
    /// Single-block: run the next line (from idle, starts the opened program).
    Step,
    /// Turn the optional-stop switch on or off: whether M1 stops the program.
    OptionalStop {
        /// `on` or `off`.
        #[arg(value_parser = ["on", "off"])]
        state: String,
    },
    /// Stop the program, MDI, jog or homing, decelerating on the path.
    Abort,
    /// Emergency stop: drives off at once.
    Estop,
    /// Leave e-stop, or clear a fault.
    Reset,
    /// Drives on.
    On,
    /// Drives off.
    Off,
    /// Execute one line of G-code, e.g. `kerf mdi "G0 X10"`.
    Mdi {
        /// The G-code line.
        line: String,
    },
    /// Jog an axis (or a joint with --joint): `kerf jog x + --distance 1`.
    Jog {
        /// Axis letter (or joint name or number with --joint).
        target: String,
        /// Direction: + or -.
        #[arg(value_parser = ["+", "-"])]
        direction: String,
        /// Move this far, mm, and stop; without it, jog until Enter.
        #[arg(long, value_name = "MM")]
        distance: Option<f64>,
        /// Speed, mm/min.
        #[arg(long, value_name = "MM_PER_MIN", default_value_t = 600.0)]
        speed: f64,
        /// TARGET names a joint rather than an axis.
        #[arg(long)]
        joint: bool,
    },
    /// Home every joint, or one joint.
    Home {
        /// Joint name or number.
        joint: Option<String>,
    },
    /// Set the feed (0–200), rapid (0–100) or spindle speed (0–200)
    /// override, percent.
    Override {
        /// `feed`, `rapid` or `spindle`.
        #[arg(value_parser = ["feed", "rapid", "spindle"])]
        which: String,
        /// Percent.
        percent: f64,
    },
    /// Show work offsets (G54–G59.3), G92 and G28/G30, or set one:
    /// `kerf offsets set G54 x=10 y=20`.
    Offsets {
        #[command(subcommand)]
        action: Option<OffsetAction>,
    },
    /// Show the tool table, or change it.
    Tools {
        #[command(subcommand)]
        action: Option<ToolAction>,
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
        #[command(flatten)]
        on: MachineArgs,
        /// LinuxCNC tool table file (.tbl) for the program's T words.
        #[arg(long, value_name = "FILE")]
        tool_table: Option<PathBuf>,
    },
    /// Plan a program offline: cycle time, path deviation, limit use.
    Plan {
        /// The program file.
        file: PathBuf,
        #[command(flatten)]
        on: MachineArgs,
        /// LinuxCNC tool table file (.tbl) for the program's T words.
        #[arg(long, value_name = "FILE")]
        tool_table: Option<PathBuf>,
        /// Write an SVG plot of the path and of position, joints and feed
        /// against time.
        #[arg(long, value_name = "OUT.svg")]
        plot: Option<PathBuf>,
        /// Acceleration-limited (trapezoidal) profiles instead of jerk-limited.
        #[arg(long, conflicts_with = "follow")]
        trapezoidal: bool,
        /// Follow a jerk-limited schedule solved alongside the planner
        /// where one is ready, as third-order planning would (machines
        /// whose joints are their axes; see docs/motion.md, "Following a
        /// schedule"). Slower to plan: about half the motion's time on
        /// dense CAM paths, many times it where the feed sets the speed.
        #[arg(long)]
        follow: bool,
        /// With --follow: the share of every acceleration and jerk limit
        /// the schedule keeps back for feed override and hold (0 to below
        /// 1; more is a quicker hold and a slower schedule).
        #[arg(long, value_name = "SHARE", default_value_t = 0.1, requires = "follow")]
        reserve: f64,
        /// List the planned segments and their limits (speeds in mm/min,
        /// acceleration mm/s², jerk mm/s³) instead of running the plan.
        #[arg(long)]
        segments: bool,
        /// Servo period in microseconds (250 to 10000), as the daemon will
        /// run it: limit use is measured on samples this far apart
        /// [default: kerfd's configuration's, else 1000].
        #[arg(long, value_name = "US",
              value_parser = clap::value_parser!(u32).range(250..=10000))]
        period_us: Option<u32>,
    },
    /// Run a program on the simulated machine (virtual clock): following
    /// and contour error, and the cutting force under force control.
    Sim {
        /// The program file.
        file: PathBuf,
        #[command(flatten)]
        on: MachineArgs,
        /// LinuxCNC tool table file (.tbl) for the program's T words.
        #[arg(long, value_name = "FILE")]
        tool_table: Option<PathBuf>,
        /// Write an SVG plot: the path, and following error, feed, force and
        /// override against time.
        #[arg(long, value_name = "OUT.svg")]
        plot: Option<PathBuf>,
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
        /// Servo period in microseconds (250 to 10000) [default: kerfd's
        /// configuration's, else 1000].
        #[arg(long, value_name = "US",
              value_parser = clap::value_parser!(u32).range(250..=10000))]
        period_us: Option<u32>,
    },
    /// Joints for a pose (inverse) or the pose for joints (forward), offline.
    Kins {
        #[command(flatten)]
        on: MachineArgs,
        /// Do not check axis travel and joint strokes (reach is still checked).
        #[arg(long)]
        no_limits: bool,
        #[command(subcommand)]
        direction: KinsDirection,
    },
    /// Compute and plot the reachable workspace of a machine, offline.
    Workspace {
        #[command(flatten)]
        on: MachineArgs,
        /// Draw the workspace into this SVG file.
        #[arg(long, value_name = "FILE")]
        plot: Option<PathBuf>,
    },
}

/// Which machine an offline tool works on, and where kerfd's settings are.
#[derive(clap::Args, Debug)]
struct MachineArgs {
    /// Machine: an embedded name (mill3, oxglide-x, oxglide-o, rfmt5, ...)
    /// or a TOML file [default: kerfd's configuration's, else mill3].
    #[arg(long, value_name = "NAME|FILE")]
    machine: Option<String>,
    /// kerfd's configuration file, for the machine and, where the tool
    /// runs the servo, its period [default: /etc/kerf/kerf.toml when it
    /// exists].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

impl MachineArgs {
    /// The machine and servo period these flags, the configuration and
    /// the defaults give ([`cli::Target::resolve`]).
    fn resolve(self, period_us: Option<u32>, runs_servo: bool) -> Result<cli::Target, Failure> {
        cli::Target::resolve(self.machine, period_us, runs_servo, self.config.as_deref())
    }
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

/// Output formats of `kerf canon`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum CanonFormat {
    Readable,
    Linuxcnc,
}

#[derive(Subcommand, Debug)]
enum OffsetAction {
    /// Set axes of an offset: G54 … G59.3, G92, G28 or G30.
    Set {
        system: String,
        /// AXIS=VALUE, mm (degrees for A B C).
        #[arg(required = true)]
        values: Vec<String>,
    },
}

#[derive(Subcommand, Debug)]
enum ToolAction {
    /// Add or change a tool.
    Set {
        tool: u32,
        #[arg(long)]
        pocket: Option<u32>,
        /// Diameter, mm.
        #[arg(long)]
        diameter: Option<f64>,
        #[arg(long)]
        comment: Option<String>,
        /// Offsets AXIS=VALUE, mm; z is the tool length.
        offsets: Vec<String>,
    },
    /// Remove a tool.
    Remove { tool: u32 },
}

fn main() -> ExitCode {
    // A reader that stops early (`kerf canon big.ngc | head`) should end
    // kerf quietly, as it does any Unix tool, not make the next print
    // panic. Rust starts programs with SIGPIPE ignored; restore the
    // default. Writes to kerfd's socket still fail with an error, not the
    // signal: std sends on Unix sockets with MSG_NOSIGNAL.
    // SAFETY: called first thing in main, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = Args::parse();
    let socket = args
        .socket
        .clone()
        .unwrap_or_else(kerf::paths::default_socket);
    let socket = socket.as_path();
    let json = args.json;
    let simple = |cmd: Command, done: &str| cli::simple(socket, &cmd, json, done);
    let result = match args.command {
        Cmd::Status { latency } => cli::status::status(socket, json, latency),
        Cmd::Force { action } => match action {
            ForceAction::On { target } => cli::status::force(socket, true, target),
            ForceAction::Off => cli::status::force(socket, false, None),
        },
        Cmd::Sim {
            file,
            on,
            tool_table,
            plot,
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
                on.resolve(period_us, true).and_then(|target| {
                    let options = kerf::simulate::SimOptions {
                        period: target.period(),
                        feedforward: !no_feedforward,
                        plant: Some(match plant {
                            PlantArg::Ideal => kerf_io::sim::Plant::Ideal,
                            PlantArg::Identified => kerf_io::sim::Plant::Identified,
                        }),
                        force_target: force,
                        ..Default::default()
                    };
                    cli::sim::sim(
                        &file,
                        &target.machine,
                        tool_table.as_deref(),
                        options,
                        plot.as_deref(),
                        json,
                    )
                })
            }
        }
        Cmd::Watch { rate } => cli::watch::watch(socket, rate, json),
        Cmd::Run { file, from } => cli::run::run(socket, &file, from, json),
        Cmd::Open { file } => match std::fs::canonicalize(&file) {
            Ok(path) => simple(
                Command::Open {
                    path: path.display().to_string(),
                },
                "opened",
            ),
            Err(e) => Err(Failure::new(format!("{}: {e}", file.display()))),
        },
        Cmd::Pause => simple(Command::Pause, "paused"),
        Cmd::Resume => simple(Command::Resume, "resumed"),
        Cmd::Step => simple(Command::Step, "stepping"),
        Cmd::OptionalStop { state } => {
            let enabled = state == "on";
            simple(
                Command::OptionalStop { enabled },
                if enabled {
                    "optional stop on: M1 stops the program"
                } else {
                    "optional stop off: M1 is passed"
                },
            )
        }
        Cmd::Abort => simple(Command::Abort, "aborted"),
        Cmd::Estop => simple(Command::Estop, "e-stop"),
        Cmd::Reset => simple(Command::Reset, "reset: the machine is off; `kerf on` next"),
        Cmd::On => simple(Command::On, "on"),
        Cmd::Off => simple(Command::Off, "off"),
        Cmd::Mdi { line } => control::mdi(socket, &line, json),
        Cmd::Jog {
            target,
            direction,
            distance,
            speed,
            joint,
        } => control::jog(
            socket,
            &control::Jog {
                target: &target,
                joint,
                direction: if direction == "+" { 1 } else { -1 },
                speed,
                distance,
            },
            json,
        ),
        Cmd::Home { joint } => control::home(socket, joint.as_deref(), json),
        Cmd::Override { which, percent } => control::set_override(socket, &which, percent, json),
        Cmd::Offsets { action } => match action {
            None => offsets::offsets(socket, None, json),
            Some(OffsetAction::Set { system, values }) => {
                offsets::offsets(socket, Some((&system, &values)), json)
            }
        },
        Cmd::Tools { action } => match action {
            None => offsets::tools(socket, None, None, json),
            Some(ToolAction::Set {
                tool,
                pocket,
                diameter,
                comment,
                offsets: o,
            }) => offsets::tools(
                socket,
                Some(offsets::ToolChange {
                    tool,
                    pocket,
                    offsets: o,
                    diameter,
                    comment,
                }),
                None,
                json,
            ),
            Some(ToolAction::Remove { tool }) => offsets::tools(socket, None, Some(tool), json),
        },
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
            on,
            tool_table,
        } => on
            .resolve(None, false)
            .and_then(|t| cli::plan::check(&file, &t.machine, tool_table.as_deref(), json)),
        Cmd::Plan {
            file,
            on,
            tool_table,
            plot,
            trapezoidal,
            follow,
            reserve,
            segments,
            period_us,
        } => on.resolve(period_us, true).and_then(|target| {
            let tools = tool_table.as_deref();
            let (machine, period) = (&target.machine, target.period());
            if segments {
                cli::plan::segments(&file, machine, tools, period)
            } else {
                cli::plan::plan(
                    &file,
                    machine,
                    tools,
                    plot.as_deref(),
                    json,
                    trapezoidal,
                    follow.then_some(reserve),
                    period,
                )
            }
        }),
        Cmd::Kins {
            on,
            no_limits,
            direction,
        } => on.resolve(None, false).and_then(|target| {
            let (direction, values) = match direction {
                KinsDirection::Inverse { values } => (cli::kins::Direction::Inverse, values),
                KinsDirection::Forward { values } => (cli::kins::Direction::Forward, values),
            };
            cli::kins::kins(&cli::kins::Request {
                machine: target.machine,
                direction,
                values,
                json,
                no_limits,
            })
        }),
        Cmd::Workspace { on, plot } => on
            .resolve(None, false)
            .and_then(|t| cli::workspace::workspace(&t.machine, plot.as_deref())),
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
