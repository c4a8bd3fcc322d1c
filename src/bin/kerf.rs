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
