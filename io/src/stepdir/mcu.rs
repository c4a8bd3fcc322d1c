//! A simulated step-generator MCU: the firmware's logic, without pins.
//!
//! It answers the host's frames exactly as the protocol says, keeps a
//! queue of step runs, and "executes" them on its clock: every step edge
//! it would make is handed to a recorder with its time in ticks and the
//! level of the direction pin. The clock is virtual: it is the host time
//! stamped in each [`Command::Clock`] request, scaled to the MCU's
//! frequency with an offset and a crystal error (so a host on a virtual
//! clock makes the whole simulation deterministic), or, with
//! [`ClockSource::Monotonic`], this process's own monotonic clock.
//!
//! The `kerf-sim-mcu` binary (`io/src/bin/kerf-sim-mcu.rs`) serves this on
//! a pseudo-terminal.

use std::collections::VecDeque;

use super::protocol::{
    ChannelTiming, Command, FrameError, NakReason, RawFrame, Reply, Status, StepRun, MAX_CHANNELS,
    VERSION,
};
use super::stepgen::{check_run, LastStep};

/// Where the simulated MCU's clock comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClockSource {
    /// From the host's `host_ns` stamps in clock requests.
    HostStamps,
    /// From this process's `CLOCK_MONOTONIC`.
    Monotonic,
}

/// Settings of the simulated MCU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct McuSettings {
    /// Step channels.
    pub channels: u8,
    /// Clock frequency, Hz.
    pub clock_hz: u32,
    /// Step queue size (commands).
    pub queue_slots: u16,
    /// Clock source.
    pub clock: ClockSource,
    /// MCU clock at the first clock reading, ticks.
    pub offset: u64,
    /// Crystal error, parts per million (positive: the MCU clock runs fast).
    pub drift_ppm: f64,
}

impl Default for McuSettings {
    fn default() -> Self {
        McuSettings {
            channels: 4,
            clock_hz: 10_000_000,
            queue_slots: 1024,
            clock: ClockSource::HostStamps,
            offset: 1_000_000,
            drift_ppm: 0.0,
        }
    }
}

/// What the simulated MCU reports to its recorder.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A step edge (rising edge of the step pin).
    Edge {
        /// Channel.
        channel: u8,
        /// Time, ticks.
        time: u64,
        /// Level of the direction pin.
        dir_pin: bool,
    },
    /// A step command arrived: its first step is `slack` ticks after the
    /// MCU clock at arrival (negative: late).
    Slack {
        /// Ticks.
        slack: i64,
    },
    /// The MCU status changed.
    Status(Status),
}

#[derive(Clone, Copy, Debug, Default)]
struct ChannelState {
    invert: bool,
    timing: ChannelTiming,
    /// Net steps of runs fully executed.
    position: i64,
    last: LastStep,
}

struct Queued {
    channel: u8,
    forward: bool,
    run: StepRun,
    last: u64,
}

/// The simulated MCU.
pub struct SimMcu {
    settings: McuSettings,
    channels: [ChannelState; MAX_CHANNELS],
    queue: VecDeque<Queued>,
    status: Status,
    expect_seq: Option<u8>,
    now: u64,
    host_origin: Option<u64>,
    mono_origin: Option<u64>,
}

impl SimMcu {
    /// A simulated MCU; `Hello` must come first. At most
    /// [`MAX_CHANNELS`] channels and one queue slot or more.
    pub fn new(mut settings: McuSettings) -> SimMcu {
        settings.channels = settings.channels.min(MAX_CHANNELS as u8);
        settings.queue_slots = settings.queue_slots.max(1);
        SimMcu {
            settings,
            channels: [ChannelState::default(); MAX_CHANNELS],
            queue: VecDeque::new(),
            status: Status::Stopped,
            expect_seq: None,
            now: settings.offset,
            host_origin: None,
            mono_origin: None,
        }
    }

    /// The MCU clock, ticks.
    pub fn now(&self) -> u64 {
        self.now
    }

    fn free(&self) -> u16 {
        self.settings.queue_slots - self.queue.len() as u16
    }

    fn set_status(&mut self, s: Status, record: &mut impl FnMut(Event)) {
        if self.status != s {
            self.status = s;
            record(Event::Status(s));
        }
    }

    /// Move the clock to `now` (never back), executing the runs that end by
    /// then and freeing their slots.
    fn advance(&mut self, now: u64) {
        self.now = self.now.max(now);
        let now = self.now;
        let channels = &mut self.channels;
        self.queue.retain(|q| {
            if q.last <= now {
                let ch = &mut channels[q.channel as usize];
                ch.position += if q.forward { 1 } else { -1 } * q.run.count as i64;
                false
            } else {
                true
            }
        });
    }

    /// Steps taken per channel by the current time.
    fn positions(&self) -> [i32; MAX_CHANNELS] {
        let mut p = [0i64; MAX_CHANNELS];
        for (i, ch) in self.channels.iter().enumerate() {
            p[i] = ch.position;
        }
        for q in &self.queue {
            let done = q
                .run
                .times()
                .take_while(|t| t.is_some_and(|t| t <= self.now))
                .count() as i64;
            p[q.channel as usize] += if q.forward { done } else { -done };
        }
        p.map(|v| v as i32)
    }

    fn clock_from_host(&mut self, host_ns: u64) -> u64 {
        let ns = match self.settings.clock {
            ClockSource::HostStamps => {
                let origin = *self.host_origin.get_or_insert(host_ns);
                host_ns.saturating_sub(origin)
            }
            ClockSource::Monotonic => {
                let mono = super::clock::Clock::now_ns(&super::clock::Monotonic);
                let origin = *self.mono_origin.get_or_insert(mono);
                mono - origin
            }
        };
        let ticks = ns as f64
            * self.settings.clock_hz as f64
            * 1e-9
            * (1.0 + self.settings.drift_ppm * 1e-6);
        self.settings.offset + ticks as u64
    }

    /// Handle one received frame (or framing error); returns the answer to
    /// send, if any, and reports edges and events to `record`.
    pub fn handle(
        &mut self,
        frame: Result<RawFrame<'_>, FrameError>,
        mut record: impl FnMut(Event),
    ) -> Option<(u8, Reply)> {
        if self.settings.clock == ClockSource::Monotonic && self.mono_origin.is_some() {
            let now = self.clock_from_host(0);
            self.advance(now);
        }
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                // A damaged frame's sequence number cannot be trusted: answer
                // with the one expected so the host sees what was lost.
                let reason = if e == FrameError::Crc {
                    NakReason::Crc
                } else {
                    NakReason::Malformed
                };
                return Some((self.expect_seq.unwrap_or(0), Reply::Nak { reason }));
            }
        };
        let seq = frame.seq;
        let cmd = match Command::decode(frame.kind, frame.payload) {
            Ok(c) => c,
            Err(_) => {
                return Some((
                    seq,
                    Reply::Nak {
                        reason: NakReason::Malformed,
                    },
                ))
            }
        };
        if let Command::Hello = cmd {
            self.queue.clear();
            self.channels = [ChannelState::default(); MAX_CHANNELS];
            self.expect_seq = Some(seq.wrapping_add(1));
            self.set_status(Status::Ok, &mut record);
            return Some((
                seq,
                Reply::Ident {
                    version: VERSION,
                    channels: self.settings.channels,
                    clock_hz: self.settings.clock_hz,
                    queue_slots: self.settings.queue_slots,
                },
            ));
        }
        if self.expect_seq != Some(seq) {
            return Some((
                seq,
                Reply::Nak {
                    reason: NakReason::Sequence,
                },
            ));
        }
        self.expect_seq = Some(seq.wrapping_add(1));
        match cmd {
            Command::Hello => unreachable!("handled above"),
            Command::Clock { host_ns } => {
                let now = self.clock_from_host(host_ns);
                self.advance(now);
                let positions = self.positions();
                return Some((
                    seq,
                    Reply::Clock {
                        clock: self.now,
                        free: self.free(),
                        status: self.status as u8,
                        positions,
                        channels: self.settings.channels,
                    },
                ));
            }
            Command::Config {
                channel,
                invert_dir,
                timing,
            } => {
                if channel >= self.settings.channels {
                    self.set_status(Status::BadCommand, &mut record);
                } else {
                    let ch = &mut self.channels[channel as usize];
                    ch.invert = invert_dir;
                    ch.timing = timing;
                }
            }
            Command::Steps {
                channel,
                forward,
                run,
            } => self.queue_steps(channel, forward, run, &mut record),
            Command::Stop => {
                self.queue.clear();
                self.set_status(Status::Stopped, &mut record);
            }
        }
        Some((
            seq,
            Reply::Ack {
                free: self.free(),
                status: self.status as u8,
            },
        ))
    }

    fn queue_steps(
        &mut self,
        channel: u8,
        forward: bool,
        run: StepRun,
        record: &mut impl FnMut(Event),
    ) {
        if self.status != Status::Ok {
            return;
        }
        if self.queue.len() >= self.settings.queue_slots as usize {
            self.set_status(Status::Overflow, record);
            return;
        }
        record(Event::Slack {
            slack: run.first as i64 - self.now as i64,
        });
        if run.first <= self.now {
            self.set_status(Status::Late, record);
            return;
        }
        if channel >= self.settings.channels || run.count == 0 {
            self.set_status(Status::BadCommand, record);
            return;
        }
        let ch = &mut self.channels[channel as usize];
        let Some(last) = run.last() else {
            self.set_status(Status::BadCommand, record);
            return;
        };
        if check_run(&mut ch.last, forward, &run, &ch.timing).is_err() {
            self.set_status(Status::BadCommand, record);
            return;
        }
        let dir_pin = forward != ch.invert;
        for t in run.times().flatten() {
            record(Event::Edge {
                channel,
                time: t,
                dir_pin,
            });
        }
        self.queue.push_back(Queued {
            channel,
            forward,
            run,
            last,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stepdir::protocol::Deframer;

    fn exchange(mcu: &mut SimMcu, seq: u8, cmd: Command, events: &mut Vec<Event>) -> Reply {
        let frame = cmd.encode(seq);
        let mut d = Deframer::default();
        let mut reply = None;
        for &b in frame.bytes() {
            if let Some(f) = d.push(b) {
                reply = mcu.handle(f, |e| events.push(e));
            }
        }
        let (s, r) = reply.expect("an answer");
        assert_eq!(s, seq);
        r
    }

    #[test]
    fn executes_runs_on_its_clock_and_reports_faults() {
        let mut mcu = SimMcu::new(McuSettings {
            channels: 2,
            queue_slots: 2,
            ..Default::default()
        });
        let mut ev = Vec::new();
        assert!(matches!(
            exchange(&mut mcu, 7, Command::Hello, &mut ev),
            Reply::Ident { channels: 2, .. }
        ));
        exchange(
            &mut mcu,
            8,
            Command::Config {
                channel: 1,
                invert_dir: true,
                timing: ChannelTiming {
                    pulse: 10,
                    space: 10,
                    dir_setup: 5,
                    dir_hold: 5,
                },
            },
            &mut ev,
        );
        // Host clock 0 ns → MCU clock = offset.
        let Reply::Clock { clock, .. } =
            exchange(&mut mcu, 9, Command::Clock { host_ns: 5_000 }, &mut ev)
        else {
            panic!()
        };
        assert_eq!(clock, 1_000_000);
        let run = StepRun {
            first: 1_000_100,
            interval: 50,
            count: 3,
            add: 0,
        };
        let r = exchange(
            &mut mcu,
            10,
            Command::Steps {
                channel: 1,
                forward: true,
                run,
            },
            &mut ev,
        );
        assert_eq!(r, Reply::Ack { free: 1, status: 0 });
        let edges: Vec<_> = ev
            .iter()
            .filter_map(|e| match e {
                Event::Edge { time, dir_pin, .. } => Some((*time, *dir_pin)),
                _ => None,
            })
            .collect();
        // Direction inverted: forward steps drive the pin low.
        assert_eq!(
            edges,
            vec![(1_000_100, false), (1_000_150, false), (1_000_200, false)]
        );
        // 15 µs of host time later (150 ticks at 10 MHz) two steps are done.
        let Reply::Clock {
            positions, free, ..
        } = exchange(&mut mcu, 11, Command::Clock { host_ns: 20_000 }, &mut ev)
        else {
            panic!()
        };
        assert_eq!((positions[1], free), (2, 1));
        // A run whose first step is already past is an underrun.
        let late = StepRun {
            first: 1_000_140,
            interval: 50,
            count: 1,
            add: 0,
        };
        let r = exchange(
            &mut mcu,
            12,
            Command::Steps {
                channel: 0,
                forward: true,
                run: late,
            },
            &mut ev,
        );
        assert_eq!(
            r,
            Reply::Ack {
                free: 1,
                status: Status::Late as u8
            }
        );
        // A skipped sequence number is refused.
        let r = exchange(&mut mcu, 14, Command::Stop, &mut ev);
        assert_eq!(
            r,
            Reply::Nak {
                reason: NakReason::Sequence
            }
        );
    }
}
