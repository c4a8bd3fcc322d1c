//! Helpers for end-to-end tests: a kerfd child process on a private socket.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

/// A kerfd process on a socket in its own temporary directory; killed on drop.
pub struct Kerfd {
    pub child: Child,
    pub socket: PathBuf,
    pub dir: tempfile::TempDir,
}

impl Kerfd {
    /// Start kerfd with `args` and wait until it reports that it listens.
    ///
    /// Waiting reads kerfd's log line by line until the `listening` line,
    /// so there is no sleep and no polling.
    pub fn start(args: &[&str]) -> Kerfd {
        let dir = tempfile::tempdir().expect("temp dir");
        let socket = dir.path().join("kerfd.sock");
        let mut child = Command::new(env!("CARGO_BIN_EXE_kerfd"))
            .arg("--socket")
            .arg(&socket)
            .args(args)
            .env("KERF_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start kerfd");
        let mut log = BufReader::new(child.stderr.take().expect("stderr"));
        let mut seen = String::new();
        loop {
            let mut line = String::new();
            if log.read_line(&mut line).expect("read kerfd log") == 0 {
                panic!("kerfd exited before listening; its log:\n{seen}");
            }
            seen.push_str(&line);
            if line.contains("listening") {
                break;
            }
        }
        // Keep draining the log so kerfd never blocks on a full pipe.
        std::thread::spawn(move || {
            let mut sink = String::new();
            while log.read_line(&mut sink).map(|n| n > 0).unwrap_or(false) {
                sink.clear();
            }
        });
        Kerfd { child, socket, dir }
    }

    /// Write a program into the temporary directory and return its path.
    pub fn program(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.path().join(name);
        std::fs::write(&path, text).expect("write program");
        path
    }
}

impl Drop for Kerfd {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
