//! Default file locations.

use std::path::PathBuf;

/// The socket of the system service (`deploy/kerfd.service`:
/// `RuntimeDirectory=kerf`).
pub const SYSTEM_SOCKET: &str = "/run/kerf/kerfd.sock";

/// The command socket path used when `--socket` is not given.
///
/// In order: `$KERF_SOCKET`; `$RUNTIME_DIRECTORY/kerfd.sock` (set by systemd's
/// `RuntimeDirectory=`); [`SYSTEM_SOCKET`] when that socket exists (the
/// system service is running); `$XDG_RUNTIME_DIR/kerf/kerfd.sock`;
/// `/tmp/kerf-$UID/kerfd.sock`.
pub fn default_socket() -> PathBuf {
    if let Some(p) = std::env::var_os("KERF_SOCKET").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    if let Some(dir) = systemd_directory("RUNTIME_DIRECTORY") {
        return dir.join("kerfd.sock");
    }
    if std::path::Path::new(SYSTEM_SOCKET).exists() {
        return PathBuf::from(SYSTEM_SOCKET);
    }
    if let Some(dir) = std::env::var_os("XDG_RUNTIME_DIR").filter(|p| !p.is_empty()) {
        return PathBuf::from(dir).join("kerf").join("kerfd.sock");
    }
    // SAFETY: getuid cannot fail and has no preconditions.
    let uid = unsafe { libc::getuid() };
    PathBuf::from(format!("/tmp/kerf-{uid}")).join("kerfd.sock")
}

/// A directory systemd passes in `var` (`RUNTIME_DIRECTORY`,
/// `STATE_DIRECTORY`, …), when set. systemd may list several, separated by
/// `:`; the first is ours.
pub fn systemd_directory(var: &str) -> Option<PathBuf> {
    let dir = std::env::var_os(var).filter(|p| !p.is_empty())?;
    let first = dir.to_string_lossy().split(':').next()?.to_string();
    Some(PathBuf::from(first))
}

/// The state directory used when neither `--state-dir` nor the
/// configuration names one: `$STATE_DIRECTORY` (systemd's `StateDirectory=`,
/// i.e. `/var/lib/kerf`), else `$XDG_STATE_HOME/kerf`, else
/// `~/.local/state/kerf`, else `/var/lib/kerf`.
pub fn default_state_dir() -> PathBuf {
    if let Some(dir) = systemd_directory("STATE_DIRECTORY") {
        return dir;
    }
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
    if let Some(dir) = var("XDG_STATE_HOME") {
        return PathBuf::from(dir).join("kerf");
    }
    if let Some(home) = var("HOME") {
        return PathBuf::from(home).join(".local/state/kerf");
    }
    PathBuf::from("/var/lib/kerf")
}
