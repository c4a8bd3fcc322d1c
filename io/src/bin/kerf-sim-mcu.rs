//! kerf-sim-mcu: a simulated step-generator MCU on a pseudo-terminal.
//!
//! It opens a pseudo-terminal, prints the path of its serial end (e.g.
//! `/dev/pts/7`) on the first line of stdout, and then speaks the kerf
//! step protocol on it (see `docs/hal.md`) until the host closes the port.
//! Put the printed path in `[hal.stepdir] port` to run kerfd against it.
//!
//! Every step edge, the slack of every step command and every status
//! change can be recorded to a file (`--record`), one per line:
//! `edge CHANNEL TICKS DIR_PIN`, `slack TICKS`, `status CODE`.
//!
//! Options:
//!   --channels N        step channels (default 4)
//!   --clock-hz N        clock frequency (default 10000000)
//!   --slots N           step queue size in commands (default 1024)
//!   --clock host|monotonic
//!                       virtual clock from the host's clock-request
//!                       stamps (default), or this process's own clock
//!   --offset TICKS      clock value at the first reading (default 1000000)
//!   --drift-ppm X       crystal error (default 0)
//!   --record PATH       write edges and events to PATH
//!   --corrupt-reply N   flip a CRC bit of the Nth reply (fault injection)
//!   --mute-after N      answer only the first N frames (fault injection)
//!   --exit-after N      exit after answering N frames (fault injection)
//!   --persist           keep running when the host closes the port, for
//!                       the host to reconnect (end it with a signal)

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::fd::{FromRawFd, OwnedFd, RawFd};
use std::process::ExitCode;

use kerf_io::stepdir::mcu::{ClockSource, Event, McuSettings, SimMcu};
use kerf_io::stepdir::protocol::Deframer;

struct Args {
    settings: McuSettings,
    record: Option<String>,
    corrupt_reply: Option<u64>,
    mute_after: Option<u64>,
    exit_after: Option<u64>,
    persist: bool,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        settings: McuSettings::default(),
        record: None,
        corrupt_reply: None,
        mute_after: None,
        exit_after: None,
        persist: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        fn num<T: std::str::FromStr>(flag: &str, v: String) -> Result<T, String> {
            v.parse()
                .map_err(|_| format!("{flag}: {v:?} is not a valid number"))
        }
        match flag.as_str() {
            "--channels" => {
                a.settings.channels = num(&flag, value()?)?;
                if a.settings.channels == 0
                    || a.settings.channels as usize > kerf_io::stepdir::protocol::MAX_CHANNELS
                {
                    return Err(format!(
                        "--channels: 1 to {}",
                        kerf_io::stepdir::protocol::MAX_CHANNELS
                    ));
                }
            }
            "--clock-hz" => a.settings.clock_hz = num(&flag, value()?)?,
            "--slots" => a.settings.queue_slots = num(&flag, value()?)?,
            "--offset" => a.settings.offset = num(&flag, value()?)?,
            "--drift-ppm" => a.settings.drift_ppm = num(&flag, value()?)?,
            "--clock" => {
                a.settings.clock = match value()?.as_str() {
                    "host" => ClockSource::HostStamps,
                    "monotonic" => ClockSource::Monotonic,
                    other => return Err(format!("--clock: {other:?} is not host or monotonic")),
                }
            }
            "--record" => a.record = Some(value()?),
            "--corrupt-reply" => a.corrupt_reply = Some(num(&flag, value()?)?),
            "--mute-after" => a.mute_after = Some(num(&flag, value()?)?),
            "--exit-after" => a.exit_after = Some(num(&flag, value()?)?),
            "--persist" => a.persist = true,
            "-h" | "--help" => {
                return Err(
                    "usage: kerf-sim-mcu [--channels N] [--clock-hz N] [--slots N] \
                     [--clock host|monotonic] [--offset TICKS] [--drift-ppm X] [--record PATH] \
                     [--corrupt-reply N] [--mute-after N] [--exit-after N] [--persist]"
                        .into(),
                )
            }
            other => return Err(format!("unknown option {other:?} (see --help)")),
        }
    }
    Ok(a)
}

/// Open a pseudo-terminal in raw mode; returns (controller, serial end, path).
fn open_pty() -> std::io::Result<(OwnedFd, OwnedFd, String)> {
    let (mut master, mut slave): (RawFd, RawFd) = (-1, -1);
    // SAFETY: out-pointers are valid; name, termios and winsize may be null.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: openpty returned two fresh descriptors that we now own.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    use std::os::fd::AsRawFd;
    // SAFETY: termios is plain data filled in by tcgetattr on a valid fd.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        if libc::tcgetattr(slave.as_raw_fd(), &mut t) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        libc::cfmakeraw(&mut t);
        if libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t) != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: the buffer is valid for its length.
    let rc = unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) };
    if rc != 0 {
        return Err(std::io::Error::from_raw_os_error(rc));
    }
    // SAFETY: ttyname_r wrote a NUL-terminated string.
    let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
        .to_string_lossy()
        .into_owned();
    Ok((master, slave, path))
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("kerf-sim-mcu: {e}");
            return ExitCode::from(2);
        }
    };
    match serve(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("kerf-sim-mcu: {e}");
            ExitCode::FAILURE
        }
    }
}

fn serve(args: Args) -> std::io::Result<()> {
    let mut record: Option<BufWriter<File>> = match &args.record {
        Some(p) => Some(BufWriter::new(File::create(p).map_err(|e| {
            std::io::Error::new(e.kind(), format!("cannot create record file {p}: {e}"))
        })?)),
        None => None,
    };
    let (master, slave, path) = open_pty()?;
    let mut slave = Some(slave);
    println!("{path}");
    std::io::stdout().flush()?;
    let mut port = File::from(master);
    let mut mcu = SimMcu::new(args.settings);
    let mut deframer = Deframer::default();
    let mut buf = [0u8; 512];
    let mut answered = 0u64;
    let mut write_err: Option<std::io::Error> = None;
    loop {
        let n = match std::io::Read::read(&mut port, &mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            // EIO: every serial-end descriptor closed, i.e. the host is gone.
            Err(e) if e.raw_os_error() == Some(libc::EIO) => break,
            Err(e) => return Err(e),
        };
        // The host has the port open: drop our own serial-end descriptor so
        // that its close reads as end of file here (unless it may come back).
        if !args.persist {
            slave.take();
        }
        for &b in &buf[..n] {
            let Some(frame) = deframer.push(b) else {
                continue;
            };
            let reply = mcu.handle(frame, |e| {
                if let Some(w) = record.as_mut() {
                    let r = match e {
                        Event::Edge {
                            channel,
                            time,
                            dir_pin,
                        } => writeln!(w, "edge {channel} {time} {}", dir_pin as u8),
                        Event::Slack { slack } => writeln!(w, "slack {slack}"),
                        Event::Status(s) => writeln!(w, "status {}", s as u8),
                    };
                    if let Err(e) = r {
                        write_err.get_or_insert(e);
                    }
                }
            });
            if let Some(e) = write_err.take() {
                return Err(e);
            }
            let Some((seq, reply)) = reply else { continue };
            answered += 1;
            if args.mute_after.is_some_and(|m| answered > m) {
                continue;
            }
            let frame = reply.encode(seq);
            let mut bytes = frame.bytes().to_vec();
            if args.corrupt_reply == Some(answered) {
                let last = bytes.len() - 1;
                bytes[last] ^= 0x01;
            }
            port.write_all(&bytes)?;
            if args.exit_after.is_some_and(|m| answered >= m) {
                if let Some(w) = record.as_mut() {
                    w.flush()?;
                }
                return Ok(());
            }
        }
    }
    if let Some(w) = record.as_mut() {
        w.flush()?;
    }
    Ok(())
}
