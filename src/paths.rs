//! Default file locations.

use std::path::PathBuf;

/// The command socket path used when `--socket` is not given.
///
/// In order: `$KERF_SOCKET`; `$RUNTIME_DIRECTORY/kerfd.sock` (set by systemd's
/// `RuntimeDirectory=`); `$XDG_RUNTIME_DIR/kerf/kerfd.sock`;
/// `/tmp/kerf-$UID/kerfd.sock`.
pub fn default_socket() -> PathBuf {
    if let Some(p) = std::env::var_os("KERF_SOCKET").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    if let Some(dir) = std::env::var_os("RUNTIME_DIRECTORY").filter(|p| !p.is_empty()) {
        // systemd may list several directories separated by ':'; use the first.
        let first = dir
            .to_string_lossy()
            .split(':')
            .next()
            .unwrap_or("")
            .to_string();
        return PathBuf::from(first).join("kerfd.sock");
    }
    if let Some(dir) = std::env::var_os("XDG_RUNTIME_DIR").filter(|p| !p.is_empty()) {
        return PathBuf::from(dir).join("kerf").join("kerfd.sock");
    }
    // SAFETY: getuid cannot fail and has no preconditions.
    let uid = unsafe { libc::getuid() };
    PathBuf::from(format!("/tmp/kerf-{uid}")).join("kerfd.sock")
}
