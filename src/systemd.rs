//! systemd integration: readiness and watchdog notifications, and logging
//! to the journal when systemd started us.
//!
//! Notifications go to `$NOTIFY_SOCKET` (a no-op without it, so kerfd runs
//! the same from a terminal). The watchdog is fed only while the servo
//! thread is ticking: a hung servo stops the pings and systemd restarts the
//! service, which is the point of having one.

use std::time::Duration;

use sd_notify::NotifyState;

/// Tell systemd the daemon is ready, with a status line.
pub fn ready(status: &str) {
    send(&[NotifyState::Ready, NotifyState::Status(status)]);
}

/// Update the status line `systemctl status` shows.
pub fn status(status: &str) {
    send(&[NotifyState::Status(status)]);
}

/// Tell systemd the daemon is stopping.
pub fn stopping(status: &str) {
    send(&[NotifyState::Stopping, NotifyState::Status(status)]);
}

/// Feed the watchdog.
pub fn watchdog() {
    send(&[NotifyState::Watchdog]);
}

/// How often to feed the watchdog: half its timeout (`WatchdogSec=`), as
/// systemd recommends; `None` when no watchdog is set for this process.
pub fn watchdog_interval() -> Option<Duration> {
    sd_notify::watchdog_enabled().map(|t| t / 2)
}

fn send(states: &[NotifyState]) {
    if let Err(e) = sd_notify::notify(states) {
        tracing::warn!("cannot notify systemd: {e}");
    }
}

/// True when stderr is connected to the journal: systemd sets
/// `$JOURNAL_STREAM` to the device and inode of that stream, and a child
/// that inherited the variable but not the stream must not trust it.
pub fn stderr_is_journal() -> bool {
    use std::os::fd::AsFd;
    let Some(value) = std::env::var_os("JOURNAL_STREAM") else {
        return false;
    };
    let Some((dev, ino)) = value.to_str().and_then(|v| v.split_once(':')) else {
        return false;
    };
    match nix::sys::stat::fstat(std::io::stderr().as_fd()) {
        Ok(st) => dev.parse::<u64>() == Ok(st.st_dev) && ino.parse::<u64>() == Ok(st.st_ino),
        Err(_) => false,
    }
}

/// Set up logging: to the journal (structured fields, levels as
/// priorities) under systemd, else to stderr. `KERF_LOG` filters, e.g.
/// `KERF_LOG=debug` (default `info`).
pub fn init_logging() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let filter =
        tracing_subscriber::EnvFilter::try_from_env("KERF_LOG").unwrap_or_else(|_| "info".into());
    let journald = if stderr_is_journal() {
        tracing_journald::layer().ok()
    } else {
        None
    };
    match journald {
        Some(layer) => tracing_subscriber::registry()
            .with(filter)
            .with(layer.with_syslog_identifier("kerfd".into()))
            .init(),
        None => tracing_subscriber::registry()
            .with(filter)
            .with(
                tracing_subscriber::fmt::layer()
                    .with_writer(std::io::stderr)
                    .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())),
            )
            .init(),
    }
}
