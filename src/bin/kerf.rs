//! kerf: command-line client of kerfd, and offline tools.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use kerf::client::{Client, ClientError};
use kerf::protocol::{Command, Event, ProgramState, Status};
use kerf_interp::{Interpreter, Position};

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
}

/// Exit status for a failed command; 2 is for usage and connection errors.
const FAILED: u8 = 1;
const CANNOT_CONNECT: u8 = 2;

fn main() -> ExitCode {
    let args = Args::parse();
    let socket = args
        .socket
        .clone()
        .unwrap_or_else(kerf::paths::default_socket);
    let result = match args.command {
        Cmd::Status { json } => status(&socket, json),
        Cmd::Run { file } => run(&socket, &file),
        Cmd::Canon { file } => canon(&file),
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

struct Failure(u8, String);

impl From<ClientError> for Failure {
    fn from(e: ClientError) -> Self {
        let code = if matches!(e, ClientError::Connect { .. }) {
            CANNOT_CONNECT
        } else {
            FAILED
        };
        Failure(code, e.to_string())
    }
}

fn fmt_position(status: &Status) -> String {
    status
        .position
        .iter()
        .map(|(axis, v)| {
            format!(
                "{}{:>10.4}",
                axis.to_uppercase(),
                v.as_f64().unwrap_or(f64::NAN)
            )
        })
        .collect::<Vec<_>>()
        .join("  ")
}

fn status(socket: &std::path::Path, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let value = client.request(&Command::Status)?;
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&value).expect("JSON value")
        );
        return Ok(());
    }
    let status: Status =
        serde_json::from_value(value).map_err(|e| Failure(FAILED, format!("bad status: {e}")))?;
    println!("machine   {}", status.machine);
    println!(
        "state     {}",
        serde_json::to_value(status.state)
            .expect("enum")
            .as_str()
            .unwrap_or("?")
    );
    println!("line      {}", status.line);
    println!("position  {}", fmt_position(&status));
    if let Some(p) = &status.program {
        let state = serde_json::to_value(p.state).expect("enum");
        println!(
            "program   #{} {} ({})",
            p.id,
            p.file,
            state.as_str().unwrap_or("?")
        );
        if let Some(e) = &p.error {
            println!("error     {e}");
        }
    }
    if let Some(f) = &status.fault {
        println!("fault     {f}");
    }
    println!(
        "servo     {} µs, {} ticks, {} overruns",
        status.servo.period_us, status.servo.ticks, status.servo.overruns
    );
    Ok(())
}

fn run(socket: &std::path::Path, file: &std::path::Path) -> Result<(), Failure> {
    let path = std::fs::canonicalize(file)
        .map_err(|e| Failure(FAILED, format!("{}: {e}", file.display())))?;
    let mut client = Client::connect(socket)?;
    let reply = client.request(&Command::Run {
        path: path.display().to_string(),
    })?;
    let id = reply["program"]
        .as_u64()
        .ok_or_else(|| Failure(FAILED, format!("bad run reply: {reply}")))? as u32;
    client.request(&Command::Subscribe { rate_hz: 10.0 })?;
    let tty = std::io::stdout().is_terminal();
    let mut last_line = u32::MAX;
    let started = std::time::Instant::now();
    loop {
        let Event::Status { status } = client.next_event()?;
        let Some(program) = status.program.as_ref().filter(|p| p.id == id) else {
            continue;
        };
        let done = program.state != ProgramState::Running;
        if status.line != last_line || done {
            last_line = status.line;
            let text = format!(
                "line {:>6}/{}  {}",
                status.line,
                program.lines,
                fmt_position(&status)
            );
            if tty {
                print!("\r{text}");
                let _ = std::io::stdout().flush();
            } else {
                println!("{text}");
            }
        }
        if done {
            if tty {
                println!();
            }
            return match program.state {
                ProgramState::Finished => {
                    println!(
                        "program finished in {:.1} s",
                        started.elapsed().as_secs_f64()
                    );
                    Ok(())
                }
                _ => Err(Failure(
                    FAILED,
                    format!(
                        "program failed: {}",
                        program.error.as_deref().unwrap_or("unknown reason")
                    ),
                )),
            };
        }
    }
}

fn canon(file: &std::path::Path) -> Result<(), Failure> {
    let interp = Interpreter::open(file, Position::ZERO)
        .map_err(|e| Failure(FAILED, format!("{}: {e}", file.display())))?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for item in interp {
        match item {
            Ok(c) => {
                if writeln!(out, "{c}").is_err() {
                    return Ok(());
                }
            }
            Err(e) => {
                let _ = out.flush();
                return Err(Failure(FAILED, e.to_string()));
            }
        }
    }
    Ok(())
}
