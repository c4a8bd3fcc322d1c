//! kerf-shm: watch kerf's status and pins in shared memory, or drive an
//! input pin from the command line.
//!
//! ```text
//! kerf-shm watch INSTANCE [--pin NAME]... [--frames N]
//!     Print every status frame (`status tick=.. state=.. line=.. fault=..
//!     pos=a,b,c`) and every value of the named pins (`pin NAME VALUE`),
//!     until N status frames and a value of every named pin have been
//!     printed (default: forever).
//! kerf-shm set INSTANCE PIN VALUE
//!     Publish VALUE (a number; 0/1 for digital pins) on an input pin, print
//!     `set`, and keep it published until standard input closes.
//! ```
//!
//! INSTANCE is the name kerf exports under (the machine's name).

use std::io::{Read, Write};
use std::process::ExitCode;
use std::time::Duration;

use kerf_io::shm::{PinSample, Services};

fn usage() -> ExitCode {
    eprintln!(
        "usage: kerf-shm watch INSTANCE [--pin NAME]... [--frames N]\n       kerf-shm set INSTANCE PIN VALUE"
    );
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("watch") if args.len() >= 2 => watch(&args[1], &args[2..]),
        Some("set") if args.len() == 4 => match args[3].parse::<f64>() {
            Ok(v) => set(&args[1], &args[2], v),
            Err(_) => Err(format!("{:?} is not a number", args[3])),
        },
        _ => return usage(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("kerf-shm: {e}");
            ExitCode::FAILURE
        }
    }
}

fn watch(instance: &str, rest: &[String]) -> Result<(), String> {
    let mut pins = Vec::new();
    let mut frames: Option<u64> = None;
    let mut it = rest.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--pin" => pins.push(it.next().ok_or("--pin needs a name")?.clone()),
            "--frames" => {
                let n = it.next().ok_or("--frames needs a count")?;
                frames = Some(
                    n.parse()
                        .map_err(|_| format!("--frames: {n:?} is not a count"))?,
                );
            }
            other => return Err(format!("unknown option {other:?}")),
        }
    }
    let s = Services::new().map_err(|e| e.to_string())?;
    let status = s.status_subscriber(instance).map_err(|e| e.to_string())?;
    let subs = pins
        .iter()
        .map(|p| s.pin_subscriber(instance, p).map(|sub| (p.clone(), sub)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut seen = 0u64;
    let mut pin_seen = vec![false; subs.len()];
    loop {
        for ((name, sub), seen) in subs.iter().zip(&mut pin_seen) {
            while let Some(sample) = sub.receive().map_err(|e| format!("{name}: {e:?}"))? {
                let PinSample { value, .. } = *sample;
                writeln!(out, "pin {name} {value}").map_err(|e| e.to_string())?;
                *seen = true;
            }
        }
        while let Some(f) = status.receive().map_err(|e| format!("status: {e:?}"))? {
            let n = (f.joint_count as usize).min(f.position.len());
            let pos: Vec<String> = f.position[..n].iter().map(|p| format!("{p}")).collect();
            writeln!(
                out,
                "status tick={} state={} line={} fault={} pos={}",
                f.tick,
                f.state,
                f.line,
                f.fault,
                pos.join(",")
            )
            .map_err(|e| e.to_string())?;
            seen += 1;
        }
        if frames.is_some_and(|n| seen >= n) && pin_seen.iter().all(|&s| s) {
            out.flush().map_err(|e| e.to_string())?;
            return Ok(());
        }
        out.flush().map_err(|e| e.to_string())?;
        // A terminal tool polling at 1 kHz: iceoryx2's subscribers have no
        // blocking receive without an event service.
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn set(instance: &str, pin: &str, value: f64) -> Result<(), String> {
    let s = Services::new().map_err(|e| e.to_string())?;
    let publisher = s.pin_publisher(instance, pin).map_err(|e| e.to_string())?;
    publisher
        .send_copy(PinSample { value, tick: 0 })
        .map_err(|e| format!("{pin}: {e:?}"))?;
    println!("set");
    std::io::stdout().flush().map_err(|e| e.to_string())?;
    // Keep the sample (it lives in this process's shared memory) until told
    // to go.
    let mut sink = Vec::new();
    let _ = std::io::stdin().read_to_end(&mut sink);
    Ok(())
}
