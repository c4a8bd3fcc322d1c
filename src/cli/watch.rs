//! `kerf watch`: a live terminal view of the machine.

use std::io::{IsTerminal, Write};
use std::path::Path;

use super::{fmt_state, name, Failure};
use crate::client::Client;
use crate::protocol::{Command, Event, Fields, Status};

/// Width of the program progress bar, characters.
const BAR: usize = 40;

/// The screen for one status: DRO, state, line, speed, overrides,
/// program progress bar, and the latest machine messages.
pub fn render(status: &Status, messages: &[String]) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "kerf  {}  {}\n\n",
        status.machine,
        fmt_state(status)
    ));
    for (axis, v) in &status.position {
        let cmd = status.commanded.get(axis).and_then(|c| c.as_f64());
        s.push_str(&format!(
            "  {}  {:>11.4}   (commanded {:>11.4})\n",
            axis.to_uppercase(),
            v.as_f64().unwrap_or(f64::NAN),
            cmd.unwrap_or(f64::NAN)
        ));
    }
    s.push_str(&format!(
        "\n  speed {:>9.1} mm/min   feed {:>3.0} %   rapid {:>3.0} %   spindle {:>3.0} %\n",
        status.velocity, status.overrides.feed, status.overrides.rapid, status.overrides.spindle
    ));
    if let Some(p) = &status.program {
        let done = if p.lines > 0 {
            (status.line.min(p.lines) as f64 / p.lines as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let filled = (done * BAR as f64).round() as usize;
        s.push_str(&format!(
            "\n  {} ({})\n  line {:>6}/{:<6} [{}{}] {:>3.0} %\n",
            p.file,
            name(&p.state),
            status.line,
            p.lines,
            "#".repeat(filled),
            ".".repeat(BAR - filled),
            done * 100.0
        ));
        if let Some(e) = &p.error {
            s.push_str(&format!("  error: {e}\n"));
        }
    }
    if let Some(f) = &status.fault {
        s.push_str(&format!("\n  FAULT: {f}\n"));
    }
    for m in messages {
        s.push_str(&format!("  > {m}\n"));
    }
    s.push_str(&format!(
        "\n  servo {} µs  overruns {}  latest wake-up {:.0} µs late\n",
        status.servo.period_us, status.servo.overruns, status.servo.latency.max_us
    ));
    s
}

/// Show the live view at `rate_hz` until interrupted (Ctrl-C) or kerfd
/// goes away. On a terminal the screen is redrawn in place; otherwise one
/// line per change is printed. With `json`, every event is printed as a
/// JSON line.
pub fn watch(socket: &Path, rate_hz: f64, json: bool) -> Result<(), Failure> {
    let mut client = Client::connect(socket)?;
    client.request(&Command::Subscribe {
        rate_hz: Some(rate_hz),
        fields: Fields::Full,
        events: true,
    })?;
    let tty = std::io::stdout().is_terminal();
    let mut messages: Vec<String> = Vec::new();
    let mut last_line = String::new();
    loop {
        let event = client.next_event()?;
        if json {
            println!(
                "{}",
                serde_json::to_string(&event).expect("events serialise")
            );
            continue;
        }
        match event {
            Event::Status { status } if tty => {
                // Home the cursor and clear the screen, then draw.
                print!("\x1b[H\x1b[2J{}", render(&status, &messages));
                let _ = std::io::stdout().flush();
            }
            Event::Status { status } => {
                let line = format!(
                    "{}  line {}  {}",
                    fmt_state(&status),
                    status.line,
                    super::fmt_position(&status)
                );
                if line != last_line {
                    println!("{line}");
                    last_line = line;
                }
            }
            Event::Message { text, line } => {
                messages.push(format!("line {line}: {text}"));
                if messages.len() > 5 {
                    messages.remove(0);
                }
                if !tty {
                    println!("message: {text}");
                }
            }
            Event::State { state, reason, .. } if !tty => {
                println!(
                    "state {}{}",
                    name(&state),
                    reason.map(|r| format!(": {r}")).unwrap_or_default()
                );
            }
            Event::Error { message } => {
                messages.push(format!("error: {message}"));
                if !tty {
                    println!("error: {message}");
                }
            }
            _ => {}
        }
    }
}
