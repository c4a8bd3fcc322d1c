//! `kerf mdi`, `jog`, `home`: commands that move the machine and wait for
//! the move to end; and `override`.

use std::io::BufRead;
use std::path::Path;

use super::{fmt_position, fmt_state, name, print_json, Failure};
use crate::client::Client;
use crate::protocol::{Command, JointRef, ProgramState, Status};

/// Send a command that starts a job (its reply carries the job id under
/// `key`), wait for the job to end, and report where the machine is.
fn start_and_wait(
    client: &mut Client,
    cmd: &Command,
    key: &str,
    json: bool,
    stopped_is_success: bool,
    before_wait: impl FnOnce(&mut Client) -> Result<(), Failure>,
) -> Result<Status, Failure> {
    let reply = client.request(cmd)?;
    let id = reply[key]
        .as_u64()
        .ok_or_else(|| Failure::new(format!("bad reply: {reply}")))? as u32;
    before_wait(client)?;
    let end = client.wait_job(id, 20.0, |_| {})?;
    if json {
        print_json(&serde_json::to_value(&end).expect("status serialises"));
    } else {
        println!("{}  {}", fmt_state(&end), fmt_position(&end));
    }
    match end.job.as_ref().filter(|j| j.id == id) {
        Some(j) if j.state == ProgramState::Aborted && stopped_is_success => Ok(end),
        Some(j) if j.state == ProgramState::Failed || j.state == ProgramState::Aborted => {
            Err(Failure::new(format!(
                "{} {}: {}",
                key,
                name(&j.state),
                j.error.as_deref().unwrap_or("no reason given")
            )))
        }
        _ => Ok(end),
    }
}

/// `kerf mdi LINE`: run one line of G-code and wait for it.
pub fn mdi(socket: &Path, line: &str, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let cmd = Command::Mdi { line: line.into() };
    start_and_wait(&mut client, &cmd, "mdi", json, false, |_| Ok(())).map(|_| ())
}

/// `kerf home [JOINT]`: home every joint, or one.
pub fn home(socket: &Path, joint: Option<&str>, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let cmd = Command::Home {
        joint: joint.map(joint_ref),
    };
    start_and_wait(&mut client, &cmd, "home", json, false, |_| Ok(())).map(|_| ())
}

/// A joint given on the command line: a number or a name.
pub fn joint_ref(s: &str) -> JointRef {
    s.parse()
        .map(JointRef::Index)
        .unwrap_or_else(|_| JointRef::Name(s.into()))
}

/// How `kerf jog` was asked to move.
pub struct Jog<'a> {
    /// Axis letter, or joint name/number when `joint`.
    pub target: &'a str,
    /// `target` names a joint.
    pub joint: bool,
    /// `+` or `-`.
    pub direction: i32,
    /// mm/min.
    pub speed: f64,
    /// Incremental distance, mm; continuous when absent.
    pub distance: Option<f64>,
}

/// `kerf jog`: an incremental jog waits for the move; a continuous one
/// runs until Enter (or end of input). If this command dies, kerfd stops
/// the jog when the connection drops.
pub fn jog(socket: &Path, jog: &Jog, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let (axis, joint) = if jog.joint {
        (None, Some(joint_ref(jog.target)))
    } else {
        (Some(jog.target.to_string()), None)
    };
    let cmd = Command::Jog {
        axis,
        joint,
        direction: jog.direction,
        speed: jog.speed,
        distance: jog.distance,
    };
    let continuous = jog.distance.is_none();
    // A continuous jog ends by being stopped: that is success.
    start_and_wait(&mut client, &cmd, "jog", json, continuous, |client| {
        if continuous {
            eprintln!(
                "jogging {}{} at {} mm/min: press Enter to stop",
                jog.target,
                if jog.direction > 0 { '+' } else { '-' },
                jog.speed
            );
            let mut line = String::new();
            let _ = std::io::stdin().lock().read_line(&mut line);
            client.request(&Command::JogStop)?;
        }
        Ok(())
    })
    .map(|_| ())
}

/// `kerf override feed|rapid|spindle PERCENT`.
pub fn set_override(socket: &Path, which: &str, percent: f64, json: bool) -> Result<(), Failure> {
    let cmd = match which {
        "feed" => Command::Override {
            feed: Some(percent),
            rapid: None,
            spindle: None,
        },
        "rapid" => Command::Override {
            feed: None,
            rapid: Some(percent),
            spindle: None,
        },
        "spindle" => Command::Override {
            feed: None,
            rapid: None,
            spindle: Some(percent),
        },
        other => {
            return Err(Failure(
                super::CANNOT_CONNECT,
                format!("override {other:?}: use `feed`, `rapid` or `spindle`"),
            ))
        }
    };
    super::simple(socket, &cmd, json, &format!("{which} override {percent} %"))
}
