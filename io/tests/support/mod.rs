//! Helpers for the step/dir tests: a simulated MCU process on a
//! pseudo-terminal, and a lock-step driver for the backend on a virtual
//! clock.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant};

use kerf_io::stepdir::clock::VirtualClock;
use kerf_io::stepdir::{Options, StepDirConfig, StepDirHal, StepJointConfig, TracePoint};
use kerf_io::{Feedback, Hal, HalFault, Setpoints};

/// A running `kerf-sim-mcu`.
pub struct Mcu {
    pub child: Child,
    pub port: String,
    pub record: PathBuf,
    _dir: tempdir::Dir,
}

mod tempdir {
    use std::path::{Path, PathBuf};

    /// A directory removed on drop.
    pub struct Dir(PathBuf);

    impl Dir {
        pub fn new(tag: &str) -> Dir {
            let p = std::env::temp_dir().join(format!(
                "kerf-io-{tag}-{}-{:?}",
                std::process::id(),
                std::thread::current().id()
            ));
            let _ = std::fs::remove_dir_all(&p);
            std::fs::create_dir_all(&p).unwrap();
            Dir(p)
        }
        pub fn path(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl Mcu {
    /// Start the simulated MCU with extra arguments; waits for the line
    /// naming its port.
    pub fn start(tag: &str, args: &[&str]) -> Mcu {
        let dir = tempdir::Dir::new(tag);
        let record = dir.path().join("record.txt");
        let mut child = Command::new(env!("CARGO_BIN_EXE_kerf-sim-mcu"))
            .args(args)
            .arg("--record")
            .arg(&record)
            .stdout(Stdio::piped())
            .spawn()
            .expect("start kerf-sim-mcu");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let port = line.trim().to_string();
        assert!(port.starts_with("/dev/"), "sim MCU printed {line:?}");
        Mcu {
            child,
            port,
            record,
            _dir: dir,
        }
    }

    /// Wait for the MCU to exit (it does when the host closes the port)
    /// and read its record.
    pub fn finish(mut self) -> Record {
        let status = self.child.wait().unwrap();
        assert!(status.success(), "sim MCU exited with {status}");
        Record::parse(&std::fs::read_to_string(&self.record).unwrap())
    }
}

impl Drop for Mcu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What the simulated MCU recorded.
#[derive(Debug, Default)]
pub struct Record {
    /// (channel, time in ticks, direction pin level), in arrival order.
    pub edges: Vec<(u8, u64, bool)>,
    pub slacks: Vec<i64>,
    pub statuses: Vec<u8>,
    /// Line kinds in order: 'e', 's', 't' (status).
    pub order: Vec<char>,
}

impl Record {
    fn parse(text: &str) -> Record {
        let mut r = Record::default();
        for line in text.lines() {
            let f: Vec<&str> = line.split_whitespace().collect();
            match f[0] {
                "edge" => {
                    r.edges
                        .push((f[1].parse().unwrap(), f[2].parse().unwrap(), f[3] == "1"));
                    r.order.push('e');
                }
                "slack" => {
                    r.slacks.push(f[1].parse().unwrap());
                    r.order.push('s');
                }
                "status" => {
                    r.statuses.push(f[1].parse().unwrap());
                    r.order.push('t');
                }
                other => panic!("unexpected record line {other:?}"),
            }
        }
        r
    }
}

/// A step joint entry with the default timing.
pub fn joint(joint: usize, steps_per_mm: f64, invert: bool) -> StepJointConfig {
    StepJointConfig {
        joint,
        steps_per_mm,
        invert_direction: invert,
        max_step_rate: 0.0,
        min_pulse_us: 2.0,
        min_space_us: 2.0,
        dir_setup_us: 1.0,
        dir_hold_us: 1.0,
    }
}

/// A configuration for `port`.
pub fn config(port: &str, joints: Vec<StepJointConfig>) -> StepDirConfig {
    StepDirConfig {
        port: port.to_string(),
        baud: 1_000_000,
        lead_ms: 60.0,
        ack_timeout_ms: 50.0,
        sync_interval_ms: 10.0,
        max_error_us: 2.0,
        joints,
    }
}

/// The backend on a virtual clock, driven one servo period at a time, each
/// period only once the link thread has dealt with the previous one.
pub struct Driver {
    pub hal: StepDirHal,
    pub clock: VirtualClock,
    pub trace: Receiver<TracePoint>,
    pub period: f64,
    pub ticks: u64,
    pub out: Setpoints,
    pub fb: Feedback,
}

impl Driver {
    pub fn open(config: &StepDirConfig, initial: &[f64]) -> Driver {
        let clock = VirtualClock::at(1_000_000_000);
        let (tx, rx) = std::sync::mpsc::channel();
        let hal = StepDirHal::open_with(
            config,
            initial,
            Options {
                clock: Arc::new(clock.clone()),
                trace: Some(tx),
            },
        )
        .expect("open the step link");
        let mut out = Setpoints {
            enable: true,
            ..Default::default()
        };
        for (c, &p) in out.joints.iter_mut().zip(initial) {
            c.position = p;
        }
        Driver {
            hal,
            clock,
            trace: rx,
            period: 0.001,
            ticks: 0,
            out,
            fb: Feedback::default(),
        }
    }

    /// One servo period with the joints commanded to `positions`. With
    /// `settle`, waits (bounded) until the link thread has taken the
    /// setpoint and every frame is answered, or a fault is latched.
    pub fn tick(&mut self, positions: &[f64], settle: bool) -> Result<(), HalFault> {
        self.clock.advance((self.period * 1e9) as u64);
        for (c, &p) in self.out.joints.iter_mut().zip(positions) {
            c.position = p;
        }
        let r = self.hal.exchange(self.period, &self.out, &mut self.fb);
        self.ticks += 1;
        if r.is_ok() {
            self.wait(settle);
        }
        r
    }

    fn wait(&self, settle: bool) {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let s = self.hal.stats();
            if self.hal.fault().is_some() || (s.processed >= self.ticks && (!settle || s.busy == 0))
            {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "the link thread did not settle: {s:?}"
            );
            std::thread::yield_now();
        }
    }
}
