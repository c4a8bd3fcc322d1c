//! The daemon's configuration file, `/etc/kerf/kerf.toml` (or `--config`).
//!
//! ```toml
//! machine = "mill3"              # embedded name, or a machine TOML path
//!                                # (relative paths: from this file's directory)
//! state_dir = "/var/lib/kerf"    # parameter file and tool table
//!
//! [servo]
//! period_us = 1000               # 250 to 10000
//! priority = 80                  # SCHED_FIFO priority; 0: none
//! cpu = 3                        # pin the servo thread (optional)
//!
//! [socket]
//! path = "/run/kerf/kerfd.sock"
//! group = "kerf"                 # group owning the socket (mode 0660)
//!
//! [tcp]                          # optional
//! listen = "127.0.0.1:7477"      # any non-loopback address needs a token
//! token_file = "/etc/kerf/token" # or token = "..."
//! ```
//!
//! Every key is optional; unknown keys are errors (they are usually typos).
//! Relative paths are taken from the configuration file's directory.
//! Every error names the file, the key and the reason.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// The system-wide configuration file, read when it exists and no
/// `--config` is given.
pub const SYSTEM_CONFIG: &str = "/etc/kerf/kerf.toml";

/// A configuration error: the file, the key (when one is at fault) and why.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {}{reason}", key.as_ref().map(|k| format!("key `{k}`: ")).unwrap_or_default())]
pub struct ConfigError {
    /// The configuration file.
    pub file: String,
    /// The key at fault, dotted (`tcp.listen`), when one is.
    pub key: Option<String>,
    /// What is wrong.
    pub reason: String,
}

/// The contents of `kerf.toml`.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Machine: embedded name or TOML path.
    pub machine: Option<String>,
    /// State directory.
    pub state_dir: Option<PathBuf>,
    #[serde(default)]
    pub servo: ServoConfig,
    #[serde(default)]
    pub socket: SocketConfig,
    /// `[tcp]`, when present.
    pub tcp: Option<TcpConfig>,
}

/// `[servo]`.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ServoConfig {
    /// Servo period, µs.
    pub period_us: Option<u32>,
    /// `SCHED_FIFO` priority of the servo thread, 1 to 99 (default 80);
    /// 0 runs it at normal priority.
    pub priority: Option<u8>,
    /// CPU (from 0) to pin the servo thread to.
    pub cpu: Option<usize>,
}

/// `[socket]`: the Unix command socket.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SocketConfig {
    /// Socket path.
    pub path: Option<PathBuf>,
    /// Group that owns the socket, so its members may connect.
    pub group: Option<String>,
}

/// `[tcp]`: an optional TCP listener.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TcpConfig {
    /// Address and port to listen on.
    pub listen: SocketAddr,
    /// Bearer token clients must present.
    pub token: Option<String>,
    /// File holding the token (first line), so it can be kept unreadable to others.
    pub token_file: Option<PathBuf>,
}

/// The TCP listener with its resolved token.
#[derive(Clone, Debug, PartialEq)]
pub struct Tcp {
    /// Address to listen on.
    pub listen: SocketAddr,
    /// The bearer token, if one is required.
    pub token: Option<String>,
}

impl Config {
    /// The configuration kerfd runs with: `explicit` (its `--config`), else
    /// [`SYSTEM_CONFIG`] when it exists, read and checked; with the file
    /// it came from, or None (and the defaults) when there is none.
    pub fn find(explicit: Option<&Path>) -> Result<(Config, Option<PathBuf>), ConfigError> {
        let system = Path::new(SYSTEM_CONFIG);
        match explicit.or_else(|| system.exists().then_some(system)) {
            Some(path) => Ok((Config::load(path)?, Some(path.to_path_buf()))),
            None => Ok((Config::default(), None)),
        }
    }

    /// Read and check `path`.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: file.clone(),
            key: None,
            reason: format!("cannot read: {e}"),
        })?;
        let mut config = Config::parse(&text, &file)?;
        // Relative paths are relative to the configuration file.
        if let Some(dir) = path.parent() {
            if let Some(m) = config.machine.as_mut() {
                if (m.contains('/') || m.ends_with(".toml")) && Path::new(m).is_relative() {
                    *m = dir.join(&*m).display().to_string();
                }
            }
            for p in [
                config.state_dir.as_mut(),
                config.socket.path.as_mut(),
                config.tcp.as_mut().and_then(|t| t.token_file.as_mut()),
            ]
            .into_iter()
            .flatten()
            {
                if p.is_relative() {
                    *p = dir.join(&*p);
                }
            }
        }
        Ok(config)
    }

    /// Parse and check configuration text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Config, ConfigError> {
        let deserializer = toml::Deserializer::new(text);
        let config: Config = serde_path_to_error::deserialize(deserializer).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            let mut reason = inner.message().to_string();
            if let Some(span) = inner.span() {
                let line = text[..span.start].matches('\n').count() + 1;
                reason.push_str(&format!(" (line {line})"));
            }
            ConfigError {
                file: file.to_string(),
                key: (path != "." && !path.is_empty()).then_some(path),
                reason,
            }
        })?;
        let err = |key: &str, reason: String| ConfigError {
            file: file.to_string(),
            key: Some(key.to_string()),
            reason,
        };
        if let Some(p) = config
            .servo
            .period_us
            .filter(|p| !(250..=10_000).contains(p))
        {
            return Err(err(
                "servo.period_us",
                format!("{p} µs is out of range 250 to 10000"),
            ));
        }
        if let Some(p) = config.servo.priority.filter(|p| *p > 99) {
            return Err(err(
                "servo.priority",
                format!("{p} is out of range: 1 to 99, or 0 for no real-time priority"),
            ));
        }
        // SAFETY: sysconf has no preconditions.
        let cpus = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_CONF) }.max(1) as usize;
        if let Some(c) = config.servo.cpu.filter(|c| *c >= cpus) {
            return Err(err(
                "servo.cpu",
                format!(
                    "CPU {c} does not exist: this machine has CPUs 0 to {}",
                    cpus - 1
                ),
            ));
        }
        if let Some(g) = config.socket.group.as_deref().filter(|g| g.is_empty()) {
            return Err(err("socket.group", format!("{g:?}: empty group name")));
        }
        if let Some(tcp) = &config.tcp {
            if tcp.token.is_some() && tcp.token_file.is_some() {
                return Err(err(
                    "tcp.token",
                    "give `token` or `token_file`, not both".into(),
                ));
            }
            if tcp.token.as_deref().is_some_and(|t| t.len() < 16) {
                return Err(err(
                    "tcp.token",
                    "too short: use at least 16 characters (e.g. `openssl rand -hex 16`)".into(),
                ));
            }
            if !tcp.listen.ip().is_loopback() && tcp.token.is_none() && tcp.token_file.is_none() {
                return Err(err(
                    "tcp.listen",
                    format!(
                        "{} is reachable from other machines: set `tcp.token` or `tcp.token_file`",
                        tcp.listen
                    ),
                ));
            }
        }
        Ok(config)
    }

    /// The TCP listener, reading the token file if there is one; `file`
    /// names the configuration in errors.
    pub fn tcp(&self, file: &str) -> Result<Option<Tcp>, ConfigError> {
        let Some(tcp) = &self.tcp else {
            return Ok(None);
        };
        let token = match (&tcp.token, &tcp.token_file) {
            (Some(t), _) => Some(t.clone()),
            (None, Some(path)) => {
                let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
                    file: file.to_string(),
                    key: Some("tcp.token_file".into()),
                    reason: format!("cannot read {}: {e}", path.display()),
                })?;
                let token = text.lines().next().unwrap_or("").trim().to_string();
                if token.len() < 16 {
                    return Err(ConfigError {
                        file: file.to_string(),
                        key: Some("tcp.token_file".into()),
                        reason: format!(
                            "{}: the token on its first line is shorter than 16 characters",
                            path.display()
                        ),
                    });
                }
                Some(token)
            }
            (None, None) => None,
        };
        Ok(Some(Tcp {
            listen: tcp.listen,
            token,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_configuration_parses() {
        let c = Config::parse(
            "machine = \"mill3\"\nstate_dir = \"/tmp/s\"\n[servo]\nperiod_us = 500\n\
             [socket]\npath = \"/run/kerf/k.sock\"\ngroup = \"kerf\"\n\
             [tcp]\nlisten = \"0.0.0.0:7477\"\ntoken = \"0123456789abcdef\"\n",
            "kerf.toml",
        )
        .unwrap();
        assert_eq!(c.servo.period_us, Some(500));
        assert_eq!(c.socket.group.as_deref(), Some("kerf"));
        let tcp = c.tcp("kerf.toml").unwrap().unwrap();
        assert_eq!(tcp.listen.port(), 7477);
        assert_eq!(tcp.token.as_deref(), Some("0123456789abcdef"));
    }

    #[test]
    fn errors_name_file_key_and_reason() {
        let e = Config::parse("[servo]\nperiod_us = \"fast\"\n", "k.toml").unwrap_err();
        assert_eq!(e.key.as_deref(), Some("servo.period_us"));
        assert!(
            e.to_string().starts_with("k.toml: key `servo.period_us`: "),
            "{e}"
        );
        assert!(e.reason.contains("line 2"), "{e}");

        let e = Config::parse("[servo]\ncpu = 100000\n", "k.toml").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("k.toml: key `servo.cpu`: CPU 100000 does not exist"),
            "{e}"
        );

        let e = Config::parse("[servo]\nperiod_us = 20\n", "k.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "k.toml: key `servo.period_us`: 20 µs is out of range 250 to 10000"
        );

        let e = Config::parse("[socket]\npth = \"/x\"\n", "k.toml").unwrap_err();
        assert!(e.to_string().contains("pth"), "{e}");

        let e = Config::parse("[tcp]\nlisten = \"192.0.2.1:7477\"\n", "k.toml").unwrap_err();
        assert_eq!(e.key.as_deref(), Some("tcp.listen"));
        assert!(e.reason.contains("token"), "{e}");

        let e = Config::parse("[tcp]\nlisten = \"nowhere\"\n", "k.toml").unwrap_err();
        assert_eq!(e.key.as_deref(), Some("tcp.listen"), "{e}");

        // Loopback needs no token.
        assert!(Config::parse("[tcp]\nlisten = \"127.0.0.1:7477\"\n", "k.toml").is_ok());
    }

    #[test]
    fn relative_machine_paths_follow_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("kerf.toml");
        std::fs::write(
            &path,
            "machine = \"machines/m.toml\"\nstate_dir = \"state\"\n[socket]\npath = \"/run/k.sock\"\n",
        )
        .unwrap();
        let c = Config::load(&path).unwrap();
        assert_eq!(
            c.machine.unwrap(),
            dir.path().join("machines/m.toml").display().to_string()
        );
        assert_eq!(c.state_dir.unwrap(), dir.path().join("state"));
        assert_eq!(c.socket.path.unwrap(), Path::new("/run/k.sock"));
        let e = Config::load(&dir.path().join("none.toml")).unwrap_err();
        assert!(e.to_string().contains("none.toml: cannot read"), "{e}");
    }
}
