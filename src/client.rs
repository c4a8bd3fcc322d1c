//! A blocking client for the command socket, used by the `kerf` command.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::protocol::{Command, ErrorCode, Event, Fields, ProgramState, ServerLine, Status};

/// What can go wrong talking to kerfd.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot connect to kerfd at {path}: {source} (is kerfd running? start it with `kerfd`, or give --socket PATH)")]
    Connect {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("connection to kerfd failed: {0}")]
    Io(#[from] std::io::Error),
    #[error("kerfd closed the connection")]
    Closed,
    #[error("unexpected message from kerfd: {0}")]
    Protocol(String),
    #[error("kerfd refused: {message}")]
    Refused { code: ErrorCode, message: String },
}

/// Sees every line a [`Client`] sends (`true`) and receives (`false`),
/// without the newline: for protocol debugging and for tests that check
/// real traffic against the schema.
pub type Tap = Box<dyn FnMut(bool, &str) + Send>;

/// A connection to kerfd.
pub struct Client {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    next_id: u64,
    events: VecDeque<Event>,
    line: String,
    tap: Option<Tap>,
}

impl Client {
    /// Connect to the daemon's socket.
    pub fn connect(path: &Path) -> Result<Client, ClientError> {
        let stream = UnixStream::connect(path).map_err(|source| ClientError::Connect {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Client {
            reader: BufReader::new(stream.try_clone()?),
            writer: stream,
            next_id: 1,
            events: VecDeque::new(),
            line: String::new(),
            tap: None,
        })
    }

    /// Show every line sent and received to `tap`.
    pub fn set_tap(&mut self, tap: Tap) {
        self.tap = Some(tap);
    }

    /// Send a request and wait for its reply; returns the `ok` value.
    /// Events that arrive meanwhile are kept for [`next_event`](Self::next_event).
    pub fn request(&mut self, cmd: &Command) -> Result<Value, ClientError> {
        let id = self.next_id;
        self.next_id += 1;
        let mut request =
            serde_json::to_value(cmd).map_err(|e| ClientError::Protocol(e.to_string()))?;
        request["id"] = Value::from(id);
        let mut text = request.to_string();
        if let Some(tap) = self.tap.as_mut() {
            tap(true, &text);
        }
        text.push('\n');
        self.writer.write_all(text.as_bytes())?;
        loop {
            match self.read_line()? {
                ServerLine::Event(e) => self.events.push_back(e),
                ServerLine::Ok { id: got, ok } if got == id => return Ok(ok),
                ServerLine::Error { id: got, error } if got == id => {
                    return Err(ClientError::Refused {
                        code: error.code,
                        message: error.message,
                    })
                }
                other => {
                    return Err(ClientError::Protocol(format!(
                        "reply to another request: {other:?}"
                    )))
                }
            }
        }
    }

    /// The next event, waiting for one.
    pub fn next_event(&mut self) -> Result<Event, ClientError> {
        if let Some(e) = self.events.pop_front() {
            return Ok(e);
        }
        match self.read_line()? {
            ServerLine::Event(e) => Ok(e),
            other => Err(ClientError::Protocol(format!(
                "unrequested reply: {other:?}"
            ))),
        }
    }

    fn read_line(&mut self) -> Result<ServerLine, ClientError> {
        self.line.clear();
        if self.reader.read_line(&mut self.line)? == 0 {
            return Err(ClientError::Closed);
        }
        if let Some(tap) = self.tap.as_mut() {
            tap(false, self.line.trim_end());
        }
        serde_json::from_str(&self.line)
            .map_err(|e| ClientError::Protocol(format!("{e}: {}", self.line.trim_end())))
    }

    /// Send a request and return the reply as a status, for `status`.
    pub fn status(&mut self) -> Result<Status, ClientError> {
        let v = self.request(&Command::Status)?;
        serde_json::from_value(v).map_err(|e| ClientError::Protocol(format!("bad status: {e}")))
    }

    /// Follow status at `rate_hz` until job `id` (as returned by `run`,
    /// `mdi`, `jog` or `home`) has ended; calls `progress` with each status
    /// on the way and returns the last. Leaves the subscription off.
    pub fn wait_job(
        &mut self,
        id: u32,
        rate_hz: f64,
        mut progress: impl FnMut(&Status),
    ) -> Result<Status, ClientError> {
        self.request(&Command::Subscribe {
            rate_hz: Some(rate_hz),
            fields: Fields::Full,
            events: false,
        })?;
        loop {
            let Event::Status { status } = self.next_event()? else {
                continue;
            };
            progress(&status);
            let ended = status
                .job
                .as_ref()
                .is_none_or(|j| j.id > id || (j.id == id && j.state != ProgramState::Running));
            if ended {
                self.request(&Command::Unsubscribe)?;
                // Events sent before the unsubscribe took effect are stale.
                self.events.clear();
                return Ok(status);
            }
        }
    }
}
