//! Helpers for end-to-end tests: a kerfd child process on a private socket
//! and state directory, and clients whose every line is checked against
//! the protocol's JSON Schema (`docs/protocol.schema.json`).

#![allow(dead_code)]

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, OnceLock};

use kerf::client::Client;
use kerf::protocol::{Command as Cmd, MachineState, Status};
use serde_json::Value;

/// A kerfd process on a socket in its own temporary directory; killed on drop.
pub struct Kerfd {
    pub child: Child,
    pub socket: PathBuf,
    pub dir: Arc<tempfile::TempDir>,
    /// kerfd's log up to and including its `listening` line.
    pub startup_log: String,
    /// kerfd's log lines after `listening`, as they come.
    pub log: std::sync::mpsc::Receiver<String>,
}

impl Kerfd {
    /// Start kerfd with `args` in a new temporary directory (socket and
    /// state directory inside it) and wait until it reports that it listens.
    pub fn start(args: &[&str]) -> Kerfd {
        Kerfd::start_in(Arc::new(tempfile::tempdir().expect("temp dir")), args, &[])
    }

    /// Start kerfd in `dir` (reusing its state directory), with extra
    /// environment `env`.
    ///
    /// Waiting reads kerfd's log line by line until the `listening` line,
    /// so there is no sleep and no polling.
    pub fn start_in(dir: Arc<tempfile::TempDir>, args: &[&str], env: &[(&str, &str)]) -> Kerfd {
        let socket = dir.path().join("kerfd.sock");
        let mut command = Command::new(env!("CARGO_BIN_EXE_kerfd"));
        command
            .arg("--socket")
            .arg(&socket)
            .arg("--state-dir")
            .arg(dir.path().join("state"))
            .args(args)
            .env("KERF_LOG", "info")
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .env_remove("JOURNAL_STREAM")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        for (k, v) in env {
            command.env(k, v);
        }
        let mut child = command.spawn().expect("start kerfd");
        let mut log = BufReader::new(child.stderr.take().expect("stderr"));
        let mut seen = String::new();
        loop {
            let mut line = String::new();
            if log.read_line(&mut line).expect("read kerfd log") == 0 {
                panic!("kerfd exited before listening; its log:\n{seen}");
            }
            seen.push_str(&line);
            if line.contains("listening") && !line.contains("TCP") {
                break;
            }
        }
        // Keep draining the log so kerfd never blocks on a full pipe, and
        // pass it on for tests that look for a line.
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            while log.read_line(&mut line).map(|n| n > 0).unwrap_or(false) {
                let _ = tx.send(std::mem::take(&mut line));
            }
        });
        Kerfd {
            child,
            socket,
            dir,
            startup_log: seen,
            log: rx,
        }
    }

    /// Write a program into the temporary directory and return its path.
    pub fn program(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.path().join(name);
        std::fs::write(&path, text).expect("write program");
        path
    }

    /// A client whose traffic is checked against the schema.
    pub fn client(&self) -> Client {
        let mut c = Client::connect(&self.socket).expect("connect to kerfd");
        c.set_tap(schema_tap());
        c
    }

    /// A client, with the machine out of e-stop, on and homed.
    pub fn ready_client(&self) -> Client {
        let mut c = self.client();
        ready(&mut c);
        c
    }

    /// Wait for kerfd's log to show a line containing `text`; returns it.
    pub fn wait_log(&self, text: &str) -> String {
        loop {
            let line = self.log.recv().expect("kerfd's log ended");
            if line.contains(text) {
                return line;
            }
        }
    }
}

impl Drop for Kerfd {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Reset, turn on and home, waiting for the homing to end.
pub fn ready(c: &mut Client) {
    c.request(&Cmd::Reset).expect("reset");
    c.request(&Cmd::On).expect("on");
    let reply = c.request(&Cmd::Home { joint: None }).expect("home");
    let id = reply["home"].as_u64().unwrap() as u32;
    let end = c.wait_job(id, 100.0, |_| {}).expect("homing");
    assert_eq!(end.state, MachineState::Idle, "{end:?}");
}

/// Start the program at `path` from its first line; returns its job id.
pub fn start_program(c: &mut Client, path: &std::path::Path) -> u32 {
    let reply = c
        .request(&Cmd::Run {
            path: Some(path.display().to_string()),
            line: None,
        })
        .expect("run");
    reply["program"].as_u64().expect("a program id") as u32
}

/// Status now.
pub fn status(c: &mut Client) -> Status {
    c.status().expect("status")
}

/// One axis of a status position.
pub fn axis(status: &Status, key: &str) -> f64 {
    status.position[key].as_f64().unwrap()
}

/// The protocol schema and validators for its parts.
pub struct Schema {
    root: Value,
    validators: Mutex<HashMap<String, Arc<jsonschema::Validator>>>,
    /// `$defs` names that validated at least one real line.
    pub seen: Mutex<std::collections::BTreeSet<String>>,
}

/// The schema in `docs/`.
pub fn schema() -> &'static Schema {
    static SCHEMA: OnceLock<Schema> = OnceLock::new();
    SCHEMA.get_or_init(|| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/protocol.schema.json");
        let text = std::fs::read_to_string(&path).expect("read the protocol schema");
        let root: Value = serde_json::from_str(&text).expect("the schema is JSON");
        jsonschema::validator_for(&root).expect("the schema is a valid JSON Schema");
        Schema {
            root,
            validators: Mutex::new(HashMap::new()),
            seen: Mutex::new(Default::default()),
        }
    })
}

impl Schema {
    /// Check `value` against `$defs/NAME`; panics with the reasons if it fails.
    pub fn check(&self, name: &str, value: &Value) {
        let validator = {
            let mut v = self.validators.lock().unwrap();
            v.entry(name.to_string())
                .or_insert_with(|| {
                    let mut sub = self.root.clone();
                    let obj = sub.as_object_mut().unwrap();
                    obj.remove("oneOf");
                    assert!(
                        self.root["$defs"].get(name).is_some(),
                        "the schema has no $defs/{name}"
                    );
                    obj.insert("$ref".into(), Value::from(format!("#/$defs/{name}")));
                    Arc::new(jsonschema::validator_for(&sub).expect("sub-schema compiles"))
                })
                .clone()
        };
        let errors: Vec<String> = validator
            .iter_errors(value)
            .map(|e| format!("{} at {}", e, e.instance_path()))
            .collect();
        assert!(
            errors.is_empty(),
            "{value} does not match $defs/{name}:\n{}",
            errors.join("\n")
        );
        self.seen.lock().unwrap().insert(name.to_string());
    }

    /// Check one line the daemon sent; `cmd` is the command of the request
    /// it answers, when known.
    pub fn check_server_line(&self, line: &str, cmd: Option<&str>) {
        let value: Value = serde_json::from_str(line).expect("kerfd sent JSON");
        self.check("server_line", &value);
        if let (Some(ok), Some(cmd)) = (value.get("ok"), cmd) {
            self.check(&format!("result_{cmd}"), ok);
        }
        if let Some(e) = value.get("event").and_then(|e| e.as_str()) {
            self.seen.lock().unwrap().insert(format!("event_{e}"));
        }
    }
}

/// A client tap checking each request, reply and event against the schema.
pub fn schema_tap() -> kerf::client::Tap {
    let mut pending: HashMap<String, String> = HashMap::new();
    Box::new(move |outgoing, line| {
        let schema = schema();
        let value: Value = serde_json::from_str(line).expect("a JSON line");
        if outgoing {
            schema.check("request", &value);
            pending.insert(
                value["id"].to_string(),
                value["cmd"].as_str().unwrap_or_default().to_string(),
            );
        } else {
            let cmd = value
                .get("id")
                .and_then(|id| pending.remove(&id.to_string()));
            schema.check_server_line(line, cmd.as_deref());
        }
    })
}
