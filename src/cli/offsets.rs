//! `kerf offsets` and `kerf tools`: the persistent work offsets and tool table.

use std::path::Path;

use serde_json::{Map, Value};

use super::{print_json, Failure, CANNOT_CONNECT};
use crate::client::Client;
use crate::protocol::Command;

fn axes_line(v: &Value) -> String {
    v.as_object().map(super::fmt_axes).unwrap_or_default()
}

/// `AXIS=VALUE` words (`x=10`, `Z=-2.5`) into a JSON object.
pub fn parse_axis_values(words: &[String]) -> Result<Map<String, Value>, Failure> {
    let mut m = Map::new();
    for w in words {
        let (k, v) = w.split_once('=').ok_or_else(|| {
            Failure(
                CANNOT_CONNECT,
                format!("{w:?}: write AXIS=VALUE, e.g. x=10"),
            )
        })?;
        let v: f64 = v
            .parse()
            .map_err(|_| Failure(CANNOT_CONNECT, format!("{w:?}: {v:?} is not a number")))?;
        m.insert(k.to_ascii_lowercase(), Value::from(v));
    }
    Ok(m)
}

/// Print the offsets, or set some axes of one: `set` is `(SYSTEM, AXIS=VALUE…)`.
pub fn offsets(socket: &Path, set: Option<(&str, &[String])>, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    let v = match set {
        Some((system, words)) => client.request(&Command::SetOffset {
            system: system.into(),
            values: parse_axis_values(words)?,
        })?,
        None => client.request(&Command::Offsets)?,
    };
    if json {
        print_json(&v);
        return Ok(());
    }
    let active = v["active"].as_str().unwrap_or("?");
    if let Some(systems) = v["systems"].as_object() {
        for (name, axes) in systems {
            let mark = if name == active { '*' } else { ' ' };
            println!("{mark}{name:<6} {}", axes_line(axes));
        }
    }
    let g92 = if v["g92_active"].as_bool() == Some(true) {
        "G92"
    } else {
        "G92 (off)"
    };
    println!(" {g92:<6} {}", axes_line(&v["g92"]));
    println!(" {:<6} {}", "G28", axes_line(&v["g28"]));
    println!(" {:<6} {}", "G30", axes_line(&v["g30"]));
    Ok(())
}

/// What `kerf tools set` changes.
pub struct ToolChange {
    /// Tool number.
    pub tool: u32,
    /// New pocket.
    pub pocket: Option<u32>,
    /// `AXIS=VALUE` offsets, e.g. `z=12.5`.
    pub offsets: Vec<String>,
    /// New diameter, mm.
    pub diameter: Option<f64>,
    /// New comment.
    pub comment: Option<String>,
}

/// Print the tool table, change a tool, or remove one.
pub fn tools(
    socket: &Path,
    change: Option<ToolChange>,
    remove: Option<u32>,
    json: bool,
) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    if let Some(t) = change {
        let offsets = (!t.offsets.is_empty())
            .then(|| parse_axis_values(&t.offsets))
            .transpose()?;
        let v = client.request(&Command::SetTool {
            tool: t.tool,
            pocket: t.pocket,
            offsets,
            diameter: t.diameter,
            comment: t.comment,
        })?;
        if json {
            print_json(&v);
            return Ok(());
        }
    }
    if let Some(tool) = remove {
        client.request(&Command::RemoveTool { tool })?;
    }
    let v = client.request(&Command::Tools)?;
    if json {
        print_json(&v);
        return Ok(());
    }
    let tools = v["tools"].as_array().cloned().unwrap_or_default();
    if tools.is_empty() {
        println!("the tool table is empty");
    }
    for t in tools {
        println!(
            "T{:<4} P{:<4} {}  D{:.4}  {}",
            t["tool"].as_u64().unwrap_or(0),
            t["pocket"].as_u64().unwrap_or(0),
            axes_line(&t["offsets"]),
            t["diameter"].as_f64().unwrap_or(0.0),
            t["comment"].as_str().unwrap_or("")
        );
    }
    Ok(())
}
