//! The command socket protocol: newline-delimited JSON.
//!
//! A client sends one request object per line, `{"id": .., "cmd": "..", ..}`.
//! The daemon answers each with `{"id": .., "ok": ..}` or
//! `{"id": .., "error": {"code": "..", "message": ".."}}`, echoing the id
//! (any JSON value; `null` when the request was unreadable). Unsolicited
//! lines carry an `"event"` key instead of an id. See `docs/protocol.md`.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// Protocol version, reported by `hello`.
pub const PROTOCOL_VERSION: u32 = 1;

/// Longest request line accepted, bytes.
pub const MAX_LINE: usize = 1 << 20;

/// A request's command and its arguments.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Protocol version and machine name.
    Hello,
    /// One status snapshot.
    Status,
    /// Check a program file, then run it. `path` must be absolute.
    Run { path: String },
    /// Send `status` events at `rate_hz` (1–1000) until `unsubscribe`.
    Subscribe { rate_hz: f64 },
    /// Stop status events.
    Unsubscribe,
    /// Cutting-force control on (with target force `target_n`, N, or the
    /// machine's configured target) or off.
    ForceControl {
        enabled: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        target_n: Option<f64>,
    },
}

/// Error codes carried in error replies.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// The line is not JSON.
    ParseError,
    /// JSON, but not a valid request (no `cmd`, wrong fields or types).
    InvalidRequest,
    /// `cmd` names no command.
    UnknownCommand,
    /// The request line exceeds [`MAX_LINE`].
    LineTooLong,
    /// The machine is busy (a program is running).
    Busy,
    /// The machine is in a fault state.
    Fault,
    /// The program was refused: the message says where and why.
    ProgramError,
    /// A file could not be read.
    IoError,
    /// An argument is out of range.
    InvalidArgument,
}

/// The error object of an error reply.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ErrorBody {
    pub code: ErrorCode,
    pub message: String,
}

/// A reply or an event, as the daemon writes it.
#[allow(clippy::large_enum_variant)] // a status event is the common line; boxing it buys nothing
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum ServerLine {
    Ok { id: Value, ok: Value },
    Error { id: Value, error: ErrorBody },
    Event(Event),
}

/// An unsolicited message.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    Status { status: Status },
}

/// The machine's overall state.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MachineState {
    /// Ready for a program.
    Idle,
    /// A program is running.
    Running,
    /// Motion stopped by a fault; see `fault`.
    Fault,
}

/// How a program stands.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ProgramState {
    Running,
    Finished,
    Failed,
}

/// The current or last program.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ProgramStatus {
    /// Id returned by `run`, increasing from 1.
    pub id: u32,
    pub file: String,
    pub state: ProgramState,
    /// Number of lines in the file.
    pub lines: u32,
    /// Why it failed, when it did.
    pub error: Option<String>,
}

/// Servo thread figures.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ServoStatus {
    pub period_us: u32,
    pub ticks: u64,
    pub overruns: u64,
    /// `wall` (real time) or `virtual` (`kerfd --virtual-clock`).
    pub clock: String,
    /// Running under SCHED_FIFO.
    pub sched_fifo: bool,
    /// The process's memory is locked (mlockall).
    pub memory_locked: bool,
    /// CPU the servo thread is pinned to.
    pub cpu: Option<usize>,
    /// How late the servo thread woke after its deadlines, µs.
    pub latency: Latency,
}

/// Wake-up latency figures, µs.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
pub struct Latency {
    /// Wake-ups measured (0 on a virtual clock).
    pub samples: u64,
    /// Earliest wake-up.
    pub min_us: f64,
    /// Median (to 1 µs below 1 ms).
    pub median_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// 99.9th percentile.
    pub p999_us: f64,
    /// Latest wake-up.
    pub max_us: f64,
}

/// The cutting-force controller's state.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
pub struct ForceStatus {
    /// Force control is on.
    pub enabled: bool,
    /// Target force F_d, N (null while off).
    pub target_n: Option<f64>,
    /// Largest force of the last spindle revolution, from the spindle
    /// current, N.
    pub force_n: f64,
    /// Feed override the controller sets (1 while off); the feed is
    /// programmed × operator override × this.
    pub feed_override: f64,
}

/// A status snapshot.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct Status {
    /// Machine name, e.g. `mill3`.
    pub machine: String,
    pub state: MachineState,
    /// Source line being executed (0 before any).
    pub line: u32,
    /// Tool position in machine coordinates, mm (degrees for A B C), keyed
    /// by lower-case axis letter in axis order: `{"x": .., "y": .., "z": ..}`.
    pub position: Map<String, Value>,
    /// Joint positions in joint order, joint units (mm).
    pub joints: Vec<f64>,
    pub program: Option<ProgramStatus>,
    /// Why motion stopped, in fault state.
    pub fault: Option<String>,
    /// Commanded minus measured position per joint, joint units (mm).
    pub following_error: Vec<f64>,
    /// The cutting-force controller; null on machines without one.
    pub force: Option<ForceStatus>,
    pub servo: ServoStatus,
}

impl ServerLine {
    /// A success reply.
    pub fn ok(id: Value, ok: Value) -> ServerLine {
        ServerLine::Ok { id, ok }
    }

    /// An error reply.
    pub fn error(id: Value, code: ErrorCode, message: impl Into<String>) -> ServerLine {
        ServerLine::Error {
            id,
            error: ErrorBody {
                code,
                message: message.into(),
            },
        }
    }

    /// The line as sent, newline included.
    pub fn to_line(&self) -> String {
        let mut s = serde_json::to_string(self).expect("protocol types always serialise");
        s.push('\n');
        s
    }
}

/// Parse one request line into its id and command, or the error reply to send.
#[allow(clippy::result_large_err)] // the error is the reply line itself, sent once
pub fn parse_request(line: &[u8]) -> Result<(Value, Command), ServerLine> {
    let value: Value = serde_json::from_slice(line).map_err(|e| {
        ServerLine::error(Value::Null, ErrorCode::ParseError, format!("not JSON: {e}"))
    })?;
    let Value::Object(mut object) = value else {
        return Err(ServerLine::error(
            Value::Null,
            ErrorCode::InvalidRequest,
            "a request is a JSON object: {\"id\": 1, \"cmd\": \"status\"}",
        ));
    };
    let id = object.remove("id").unwrap_or(Value::Null);
    let cmd = match object.get("cmd") {
        Some(Value::String(s)) => s.clone(),
        Some(_) => {
            return Err(ServerLine::error(
                id,
                ErrorCode::InvalidRequest,
                "`cmd` must be a string",
            ));
        }
        None => {
            return Err(ServerLine::error(
                id,
                ErrorCode::InvalidRequest,
                "missing `cmd`",
            ));
        }
    };
    const KNOWN: [&str; 6] = [
        "hello",
        "status",
        "run",
        "subscribe",
        "unsubscribe",
        "force_control",
    ];
    if !KNOWN.contains(&cmd.as_str()) {
        return Err(ServerLine::error(
            id,
            ErrorCode::UnknownCommand,
            format!("unknown command {cmd:?}; known: {}", KNOWN.join(", ")),
        ));
    }
    let command = match serde_json::from_value::<Command>(Value::Object(object.clone())) {
        Ok(c) => c,
        Err(e) => {
            return Err(ServerLine::error(
                id,
                ErrorCode::InvalidRequest,
                format!("{cmd}: {e}"),
            ))
        }
    };
    // serde does not reject extra keys on argument-less commands; a key the
    // command does not serialise back is one it does not take.
    let known = serde_json::to_value(&command).expect("commands serialise");
    if let Some(extra) = object.keys().find(|k| known.get(k.as_str()).is_none()) {
        return Err(ServerLine::error(
            id,
            ErrorCode::InvalidRequest,
            format!("{cmd}: unknown field `{extra}`"),
        ));
    }
    Ok((id, command))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn code(r: Result<(Value, Command), ServerLine>) -> (Value, ErrorCode) {
        match r {
            Err(ServerLine::Error { id, error }) => (id, error.code),
            other => panic!("expected an error, got {other:?}"),
        }
    }

    #[test]
    fn parses_requests_with_any_id() {
        let (id, c) = parse_request(br#"{"id": "a7", "cmd": "run", "path": "/p.ngc"}"#).unwrap();
        assert_eq!(id, json!("a7"));
        assert_eq!(
            c,
            Command::Run {
                path: "/p.ngc".into()
            }
        );
        let (id, c) = parse_request(br#"{"cmd":"status","id":3}"#).unwrap();
        assert_eq!((id, c), (json!(3), Command::Status));
    }

    #[test]
    fn bad_requests_get_the_right_code_and_keep_the_id() {
        assert_eq!(
            code(parse_request(b"{not json")),
            (Value::Null, ErrorCode::ParseError)
        );
        assert_eq!(
            code(parse_request(b"[1,2]")),
            (Value::Null, ErrorCode::InvalidRequest)
        );
        assert_eq!(
            code(parse_request(br#"{"id":1}"#)),
            (json!(1), ErrorCode::InvalidRequest)
        );
        assert_eq!(
            code(parse_request(br#"{"id":2,"cmd":"fly"}"#)),
            (json!(2), ErrorCode::UnknownCommand)
        );
        assert_eq!(
            code(parse_request(br#"{"id":3,"cmd":"run"}"#)),
            (json!(3), ErrorCode::InvalidRequest)
        );
        assert_eq!(
            code(parse_request(br#"{"id":4,"cmd":"status","extra":1}"#)),
            (json!(4), ErrorCode::InvalidRequest)
        );
    }

    #[test]
    fn replies_and_events_round_trip() {
        let line = ServerLine::error(json!(5), ErrorCode::Busy, "a program is running").to_line();
        assert_eq!(
            line,
            "{\"id\":5,\"error\":{\"code\":\"busy\",\"message\":\"a program is running\"}}\n"
        );
        let back: ServerLine = serde_json::from_str(&line).unwrap();
        assert!(matches!(
            back,
            ServerLine::Error {
                error: ErrorBody {
                    code: ErrorCode::Busy,
                    ..
                },
                ..
            }
        ));
    }
}
