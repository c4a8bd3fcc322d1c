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
pub const PROTOCOL_VERSION: u32 = 2;

/// Longest request line accepted, bytes.
pub const MAX_LINE: usize = 1 << 20;

/// A joint named by its number (from 0) or by its name in the machine
/// description.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum JointRef {
    Index(usize),
    Name(String),
}

/// What a status subscription sends each period.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Fields {
    /// The whole status every time (`status` events).
    #[default]
    Full,
    /// Only the top-level status fields that changed since the last event
    /// (`changes` events); the first event carries every field.
    Changed,
}

fn yes() -> bool {
    true
}

/// A request's command and its arguments. Units: mm (degrees for rotary
/// axes), mm/min for speeds, percent for overrides.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Protocol version and machine name.
    Hello,
    /// Present the bearer token (TCP connections when a token is configured).
    Auth { token: String },
    /// One status snapshot.
    Status,
    /// Send `status` (or `changes`) events at `rate_hz` (1–1000; none when
    /// absent), and machine events when `events` (default true), until
    /// `unsubscribe`. A new subscription replaces the old one.
    Subscribe {
        #[serde(default)]
        rate_hz: Option<f64>,
        #[serde(default)]
        fields: Fields,
        #[serde(default = "yes")]
        events: bool,
    },
    /// Stop all events to this client.
    Unsubscribe,
    /// Emergency stop: drives off at once, motion and programs abandoned.
    Estop,
    /// Leave e-stop (to `estop_reset`), or clear a fault (to `estop_reset`).
    Reset,
    /// Drives on (from `estop_reset`).
    On,
    /// Drives off (to `estop_reset`); refused while the machine moves.
    Off,
    /// Home every joint, or one joint.
    Home {
        #[serde(default)]
        joint: Option<JointRef>,
    },
    /// Jog an axis (or a joint) in `direction` (1 or -1) at `speed` mm/min:
    /// `distance` mm and stop (incremental), or until `jog_stop`
    /// (continuous, also stopped if this client disconnects).
    Jog {
        #[serde(default)]
        axis: Option<String>,
        #[serde(default)]
        joint: Option<JointRef>,
        direction: i32,
        speed: f64,
        #[serde(default)]
        distance: Option<f64>,
    },
    /// Stop a jog, decelerating.
    JogStop,
    /// Execute one line of G-code.
    Mdi { line: String },
    /// Check a program file and make it the program `run` runs.
    Open { path: String },
    /// Run a program: `path` (opened first), or the opened one; from source
    /// line `line` (default 1).
    Run {
        #[serde(default)]
        path: Option<String>,
        #[serde(default)]
        line: Option<u32>,
    },
    /// Feed hold: decelerate on the path and wait.
    Pause,
    /// Release feed hold, single-block stepping and a program stop (M0,
    /// M1, M60) the tool waits at.
    Resume,
    /// Single-block: run the next source line, then wait (out of a program
    /// stop too). From `idle`, starts the opened program that way.
    Step,
    /// The optional-stop switch: whether M1 stops the program (on when the
    /// daemon starts).
    OptionalStop { enabled: bool },
    /// Stop the program, MDI, jog or homing, decelerating on the path.
    Abort,
    /// Set the feed (0–200), rapid (0–100) and/or spindle speed (0–200)
    /// override, percent.
    Override {
        #[serde(default)]
        feed: Option<f64>,
        #[serde(default)]
        rapid: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        spindle: Option<f64>,
    },
    /// Read the work offsets, G92 offset and G28/G30 positions.
    Offsets,
    /// Set some axes of one offset or stored position: `system` is G54 …
    /// G59.3, G92, G28 or G30; `values` maps axis letters to mm.
    SetOffset {
        system: String,
        values: Map<String, Value>,
    },
    /// Read the tool table.
    Tools,
    /// Add or change a tool; absent fields keep their value (a new tool
    /// starts from zeros, pocket = tool number).
    SetTool {
        tool: u32,
        #[serde(default)]
        pocket: Option<u32>,
        #[serde(default)]
        offsets: Option<Map<String, Value>>,
        #[serde(default)]
        diameter: Option<f64>,
        #[serde(default)]
        comment: Option<String>,
    },
    /// Remove a tool from the table.
    RemoveTool { tool: u32 },
    /// Cutting-force control on (with target force `target_n`, N, or the
    /// machine's configured target) or off.
    ForceControl {
        enabled: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        target_n: Option<f64>,
    },
}

/// Every command name, as sent in `cmd`.
pub const COMMANDS: [&str; 27] = [
    "hello",
    "auth",
    "status",
    "subscribe",
    "unsubscribe",
    "estop",
    "reset",
    "on",
    "off",
    "home",
    "jog",
    "jog_stop",
    "mdi",
    "open",
    "run",
    "pause",
    "resume",
    "step",
    "optional_stop",
    "abort",
    "override",
    "offsets",
    "set_offset",
    "tools",
    "set_tool",
    "remove_tool",
    "force_control",
];

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
    /// The connection must present the bearer token first (`auth`).
    Unauthorized,
    /// The machine is busy (a program, MDI, jog or homing is running).
    Busy,
    /// The command is not allowed in the machine's state; the message says
    /// why and what to do.
    InvalidState,
    /// The machine is in a fault state.
    Fault,
    /// The program was refused: the message says where and why.
    ProgramError,
    /// A file could not be read or written.
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
#[allow(clippy::large_enum_variant)] // status is the common event
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// A full status snapshot (subscription with `fields: full`).
    Status { status: Status },
    /// The status fields that changed (subscription with `fields: changed`).
    Changes { changes: Map<String, Value> },
    /// The machine state (or how a program executes) changed, and why.
    State {
        state: MachineState,
        /// In `auto` and `mdi`: running, paused or stepping.
        execution: Option<Execution>,
        previous: MachineState,
        reason: Option<String>,
    },
    /// A program started, moved to another line, or ended.
    Program { program: ProgramStatus },
    /// An operator message from the program, `(MSG, text)`, shown when the
    /// machine reaches it.
    Message { text: String, line: u32 },
    /// Something went wrong outside any request, e.g. a program failed.
    Error { message: String },
    /// This client read too slowly and `missed` events were dropped.
    Lagged { missed: u64 },
}

/// The machine's overall state.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MachineState {
    /// Emergency stop: drives off; `reset` to leave.
    Estop,
    /// E-stop released, drives off; `on` to power up.
    EstopReset,
    /// Drives on, not every joint homed; `home`.
    On,
    /// Homing.
    Homing,
    /// On, homed and ready.
    Idle,
    /// A program runs (see `execution`).
    Auto,
    /// An MDI line runs.
    Mdi,
    /// Jogging.
    Manual,
    /// Motion stopped by a fault; see `fault`. `reset` to clear.
    Fault,
}

/// How a program or MDI line is executing.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Execution {
    Running,
    /// Feed hold, or waiting at a program stop (M0, M1, M60).
    Paused,
    /// Single-block mode.
    Stepping,
}

/// How a program stands.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ProgramState {
    /// Opened and checked, not run yet.
    Ready,
    Running,
    Finished,
    Failed,
    Aborted,
}

/// The current or last program.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ProgramStatus {
    /// Id of this run (increasing, shared with MDI, jogs and homing); 0
    /// while the program is only opened.
    pub id: u32,
    pub file: String,
    pub state: ProgramState,
    /// Number of lines in the file.
    pub lines: u32,
    /// Line the run started from.
    pub start_line: u32,
    /// Source line reached (0 before the first).
    pub line: u32,
    /// Why it failed, when it did.
    pub error: Option<String>,
}

/// What a job moves for.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum JobType {
    Program,
    Mdi,
    Jog,
    Home,
}

/// The current or last job: a program run, MDI line, jog or homing.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct JobStatus {
    /// The id its command returned.
    pub id: u32,
    /// What the job moves for.
    pub kind: JobType,
    /// `running`, then `finished`, `failed` or `aborted`.
    pub state: ProgramState,
    /// Why it failed or was aborted.
    pub error: Option<String>,
}

/// Override factors in force, percent.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct Overrides {
    /// Feed override, 0 to 200.
    pub feed: f64,
    /// Rapid override, 0 to 100.
    pub rapid: f64,
    /// Spindle speed override, 0 to 200.
    pub spindle: f64,
}

/// Servo thread figures.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
pub struct ServoStatus {
    pub period_us: u32,
    pub ticks: u64,
    /// Wake-ups a whole period or more late.
    pub overruns: u64,
    /// Servo periods in which the executor followed its guard, a checked
    /// way to rest, because the motion its search chose had none.
    #[serde(default)]
    pub guard_takeovers: u64,
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
    /// The machine state (see `docs/protocol.md`).
    pub state: MachineState,
    /// In `auto` and `mdi`: running, paused (feed hold, or waiting at a
    /// program stop) or stepping.
    pub execution: Option<Execution>,
    /// The optional-stop switch: M1 stops the program.
    pub optional_stop: bool,
    /// Per joint, in joint order: homed.
    pub homed: Vec<bool>,
    /// Source line being executed (0 before any).
    pub line: u32,
    /// Tool position in machine coordinates, mm (degrees for A B C), keyed
    /// by lower-case axis letter in axis order: `{"x": .., "y": .., "z": ..}`.
    pub position: Map<String, Value>,
    /// Commanded tool position, same keys.
    pub commanded: Map<String, Value>,
    /// Joint positions in joint order, joint units (mm).
    pub joints: Vec<f64>,
    /// Path speed, mm/min.
    pub velocity: f64,
    /// Overrides in force, percent.
    pub overrides: Overrides,
    /// The current or last job.
    pub job: Option<JobStatus>,
    /// The opened, running or last program.
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
    if !COMMANDS.contains(&cmd.as_str()) {
        return Err(ServerLine::error(
            id,
            ErrorCode::UnknownCommand,
            format!("unknown command {cmd:?}; known: {}", COMMANDS.join(", ")),
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
                path: Some("/p.ngc".into()),
                line: None
            }
        );
        let (_, c) = parse_request(br#"{"id": 1, "cmd": "subscribe", "rate_hz": 5}"#).unwrap();
        assert_eq!(
            c,
            Command::Subscribe {
                rate_hz: Some(5.0),
                fields: Fields::Full,
                events: true
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
            code(parse_request(br#"{"id":3,"cmd":"mdi"}"#)),
            (json!(3), ErrorCode::InvalidRequest)
        );
        assert_eq!(
            code(parse_request(
                br#"{"id":6,"cmd":"jog","axis":"x","direction":"up","speed":1}"#
            )),
            (json!(6), ErrorCode::InvalidRequest)
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
