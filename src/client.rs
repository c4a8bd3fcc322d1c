//! A blocking client for the command socket, used by the `kerf` command.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::protocol::{Command, ErrorCode, Event, ServerLine};

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

/// A connection to kerfd.
pub struct Client {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    next_id: u64,
    events: VecDeque<Event>,
    line: String,
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
        })
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
        serde_json::from_str(&self.line)
            .map_err(|e| ClientError::Protocol(format!("{e}: {}", self.line.trim_end())))
    }
}
