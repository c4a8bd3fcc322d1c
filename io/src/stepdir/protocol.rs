//! The serial protocol between the host and the step-generator MCU.
//!
//! Every message travels in a frame:
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 1 | start byte `0x7E` |
//! | 1 | 1 | `len`: bytes of `seq`, `type` and payload (2 to [`MAX_BODY`]) |
//! | 2 | 1 | `seq`: host frames count up by one (mod 256); the MCU answers each with the same `seq` |
//! | 3 | 1 | `type`: the message type |
//! | 4 | len − 2 | payload, little-endian fields |
//! | 2 + len | 2 | CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of bytes 1 .. 2 + len, little-endian |
//!
//! The host sends one frame per message and the MCU answers every host
//! frame with exactly one frame carrying the same `seq`; a frame it cannot
//! accept is answered with [`Reply::Nak`]. Times are MCU clock ticks
//! (frequency in [`Reply::Ident`]). The full specification, with the
//! meaning of each field, is in `docs/hal.md`.

use std::fmt;

/// First byte of every frame.
pub const START: u8 = 0x7E;
/// Largest `len` (sequence byte, type byte and payload).
pub const MAX_BODY: usize = 64;
/// Largest frame on the wire.
pub const MAX_FRAME: usize = MAX_BODY + 4;
/// Protocol version the MCU reports in [`Reply::Ident`].
pub const VERSION: u8 = 1;
/// Most step channels a protocol frame can describe (positions in
/// [`Reply::Clock`] must fit a frame).
pub const MAX_CHANNELS: usize = 8;

/// CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no
/// reflection, no final XOR. Its check value ("123456789") is 0x29B1.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// MCU status codes (in every [`Reply::Ack`] and [`Reply::Clock`]).
/// Anything but [`Status::Ok`] is latched by the MCU until the next
/// [`Command::Hello`], and makes the host stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Status {
    /// Running normally.
    Ok = 0,
    /// A step command arrived after its first step was due: the host fell
    /// behind (buffer underrun). The MCU stopped stepping.
    Late = 1,
    /// A step command arrived with the queue full: flow control broken.
    Overflow = 2,
    /// A command was malformed (unknown channel, zero count, steps closer
    /// than the configured pulse and space, time going backwards).
    BadCommand = 3,
    /// Stopped by [`Command::Stop`]; no steps are taken until a new
    /// [`Command::Hello`].
    Stopped = 4,
}

impl Status {
    /// Decode a status byte.
    pub fn from_u8(b: u8) -> Option<Status> {
        Some(match b {
            0 => Status::Ok,
            1 => Status::Late,
            2 => Status::Overflow,
            3 => Status::BadCommand,
            4 => Status::Stopped,
            _ => return None,
        })
    }

    /// What the status means, for the operator.
    pub fn reason(self) -> &'static str {
        match self {
            Status::Ok => "running",
            Status::Late => "the MCU ran out of steps: a command arrived after its time (underrun)",
            Status::Overflow => "the MCU's step queue overflowed",
            Status::BadCommand => "the MCU refused a malformed step command",
            Status::Stopped => "the MCU is stopped",
        }
    }
}

/// Why the MCU refused a frame ([`Reply::Nak`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum NakReason {
    /// The frame's CRC did not match.
    Crc = 1,
    /// `seq` was not the one expected: a frame was lost.
    Sequence = 2,
    /// Unknown message type or wrong payload length.
    Malformed = 3,
}

impl NakReason {
    fn from_u8(b: u8) -> Option<NakReason> {
        Some(match b {
            1 => NakReason::Crc,
            2 => NakReason::Sequence,
            3 => NakReason::Malformed,
            _ => return None,
        })
    }

    /// What the refusal means.
    pub fn reason(self) -> &'static str {
        match self {
            NakReason::Crc => "the MCU received a frame with a bad CRC",
            NakReason::Sequence => "the MCU saw a gap in sequence numbers (lost frame)",
            NakReason::Malformed => "the MCU could not parse a frame",
        }
    }
}

/// Per-channel timing limits, in MCU ticks ([`Command::Config`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ChannelTiming {
    /// Step pulse width (high time).
    pub pulse: u16,
    /// Least low time between pulses.
    pub space: u16,
    /// Least time from a direction change to the next step edge.
    pub dir_setup: u16,
    /// Least time from the end of a step pulse to a direction change.
    pub dir_hold: u16,
}

impl ChannelTiming {
    /// Least time between two step edges in the same direction.
    pub fn min_interval(&self) -> u64 {
        self.pulse as u64 + self.space as u64
    }

    /// Least time between two step edges on either side of a reversal.
    pub fn min_reversal(&self) -> u64 {
        self.pulse as u64 + self.dir_hold as u64 + self.dir_setup as u64
    }
}

/// A compressed run of steps in one direction ([`Command::Steps`]).
///
/// Step `i` (from 0) is at `first + i·interval + add·i·(i−1)/2`: each gap
/// is the previous one plus `add`. [`StepRun::times`] is the one decoder
/// both ends use, in exact integer arithmetic.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepRun {
    /// Time of the first step edge, MCU ticks.
    pub first: u64,
    /// Gap from the first step to the second, ticks.
    pub interval: u32,
    /// Number of steps (1 or more).
    pub count: u16,
    /// Change of the gap from one step to the next, ticks.
    pub add: i32,
}

impl StepRun {
    /// The step times of the run, or `None` if a gap would not be positive
    /// (such a run is malformed).
    pub fn times(&self) -> impl Iterator<Item = Option<u64>> + '_ {
        let mut t = self.first as i128;
        let mut gap = self.interval as i128;
        (0..self.count).map(move |i| {
            if i > 0 {
                if gap < 1 {
                    return None;
                }
                t += gap;
                gap += self.add as i128;
            }
            u64::try_from(t).ok()
        })
    }

    /// Time of the last step, or `None` for a malformed run.
    pub fn last(&self) -> Option<u64> {
        let n = self.count as i128 - 1;
        if n < 0 {
            return None;
        }
        // The smallest gap is at one end of the run (gaps change linearly).
        let first_gap = self.interval as i128;
        let last_gap = first_gap + (n - 1).max(0) * self.add as i128;
        if n > 0 && (first_gap < 1 || last_gap < 1) {
            return None;
        }
        let t = self.first as i128 + n * self.interval as i128 + self.add as i128 * n * (n - 1) / 2;
        u64::try_from(t).ok()
    }
}

/// Host → MCU messages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `0x01`: reset the MCU's state (queues empty, status Ok, expected
    /// sequence = this frame's + 1) and ask for [`Reply::Ident`].
    Hello,
    /// `0x02`: ask for the MCU clock ([`Reply::Clock`]). `host_ns` is the
    /// host's clock when sending, nanoseconds (for logs and simulators).
    Clock {
        /// Host monotonic clock at sending, ns.
        host_ns: u64,
    },
    /// `0x03`: set a channel's direction polarity and timing limits.
    Config {
        /// Step channel (0 ..).
        channel: u8,
        /// Drive the direction pin low for positive steps.
        invert_dir: bool,
        /// Timing limits, ticks.
        timing: ChannelTiming,
    },
    /// `0x04`: queue a run of steps on a channel. Uses one queue slot.
    Steps {
        /// Step channel.
        channel: u8,
        /// Direction: true counts the position up.
        forward: bool,
        /// The run.
        run: StepRun,
    },
    /// `0x05`: drop all queued steps and stop until [`Command::Hello`].
    Stop,
}

/// MCU → host messages; each answers the host frame with the same `seq`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reply {
    /// `0x81`: answer to [`Command::Hello`].
    Ident {
        /// Protocol version ([`VERSION`]).
        version: u8,
        /// Number of step channels.
        channels: u8,
        /// Clock frequency, Hz.
        clock_hz: u32,
        /// Step queue size, in [`Command::Steps`] commands (all channels).
        queue_slots: u16,
    },
    /// `0x82`: answer to [`Command::Clock`].
    Clock {
        /// MCU clock when the request was handled, ticks.
        clock: u64,
        /// Free step queue slots.
        free: u16,
        /// MCU status.
        status: u8,
        /// Steps taken so far per channel (signed count), first `channels`.
        positions: [i32; MAX_CHANNELS],
        /// Number of channels reported.
        channels: u8,
    },
    /// `0x83`: answer to every other accepted command.
    Ack {
        /// Free step queue slots.
        free: u16,
        /// MCU status.
        status: u8,
    },
    /// `0x84`: the frame with this `seq` (or the one expected, for a CRC
    /// error) was refused.
    Nak {
        /// Why.
        reason: NakReason,
    },
}

/// A frame that could not be decoded, and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// CRC mismatch.
    Crc,
    /// `len` out of range.
    Length,
    /// Unknown type or payload size wrong for the type.
    Malformed,
}

impl FrameError {
    /// The error as a fault reason.
    pub fn reason(self) -> &'static str {
        match self {
            FrameError::Crc => "CRC error on a frame from the MCU",
            FrameError::Length => "bad frame length from the MCU",
            FrameError::Malformed => "malformed frame from the MCU",
        }
    }
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.reason())
    }
}

/// Frame bytes being built: fixed capacity, no allocation.
#[derive(Clone, Copy)]
pub struct Frame {
    buf: [u8; MAX_FRAME],
    len: usize,
}

impl Frame {
    fn new(seq: u8, kind: u8) -> Frame {
        let mut f = Frame {
            buf: [0; MAX_FRAME],
            len: 4,
        };
        f.buf[0] = START;
        f.buf[2] = seq;
        f.buf[3] = kind;
        f
    }

    fn put(&mut self, bytes: &[u8]) -> &mut Frame {
        self.buf[self.len..self.len + bytes.len()].copy_from_slice(bytes);
        self.len += bytes.len();
        self
    }

    fn finish(mut self) -> Frame {
        self.buf[1] = (self.len - 2) as u8;
        let crc = crc16(&self.buf[1..self.len]);
        let at = self.len;
        self.buf[at..at + 2].copy_from_slice(&crc.to_le_bytes());
        self.len += 2;
        self
    }

    /// The encoded bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }
}

impl Command {
    /// Encode the command as a frame with sequence number `seq`.
    pub fn encode(&self, seq: u8) -> Frame {
        match *self {
            Command::Hello => Frame::new(seq, 0x01).finish(),
            Command::Clock { host_ns } => {
                Frame::new(seq, 0x02).put(&host_ns.to_le_bytes()).finish()
            }
            Command::Config {
                channel,
                invert_dir,
                timing,
            } => Frame::new(seq, 0x03)
                .put(&[channel, invert_dir as u8])
                .put(&timing.pulse.to_le_bytes())
                .put(&timing.space.to_le_bytes())
                .put(&timing.dir_setup.to_le_bytes())
                .put(&timing.dir_hold.to_le_bytes())
                .finish(),
            Command::Steps {
                channel,
                forward,
                run,
            } => Frame::new(seq, 0x04)
                .put(&[channel, forward as u8])
                .put(&run.first.to_le_bytes())
                .put(&run.interval.to_le_bytes())
                .put(&run.count.to_le_bytes())
                .put(&run.add.to_le_bytes())
                .finish(),
            Command::Stop => Frame::new(seq, 0x05).finish(),
        }
    }

    /// Decode a command from a frame's type and payload.
    pub fn decode(kind: u8, p: &[u8]) -> Result<Command, FrameError> {
        let mut r = Cursor(p);
        let c = match kind {
            0x01 => Command::Hello,
            0x02 => Command::Clock { host_ns: r.u64()? },
            0x03 => Command::Config {
                channel: r.u8()?,
                invert_dir: r.u8()? != 0,
                timing: ChannelTiming {
                    pulse: r.u16()?,
                    space: r.u16()?,
                    dir_setup: r.u16()?,
                    dir_hold: r.u16()?,
                },
            },
            0x04 => Command::Steps {
                channel: r.u8()?,
                forward: r.u8()? != 0,
                run: StepRun {
                    first: r.u64()?,
                    interval: r.u32()?,
                    count: r.u16()?,
                    add: r.u32()? as i32,
                },
            },
            0x05 => Command::Stop,
            _ => return Err(FrameError::Malformed),
        };
        r.end()?;
        Ok(c)
    }
}

impl Reply {
    /// Encode the reply as a frame answering `seq`.
    pub fn encode(&self, seq: u8) -> Frame {
        match *self {
            Reply::Ident {
                version,
                channels,
                clock_hz,
                queue_slots,
            } => Frame::new(seq, 0x81)
                .put(&[version, channels])
                .put(&clock_hz.to_le_bytes())
                .put(&queue_slots.to_le_bytes())
                .finish(),
            Reply::Clock {
                clock,
                free,
                status,
                positions,
                channels,
            } => {
                let mut f = Frame::new(seq, 0x82);
                f.put(&clock.to_le_bytes())
                    .put(&free.to_le_bytes())
                    .put(&[status, channels]);
                for p in &positions[..(channels as usize).min(MAX_CHANNELS)] {
                    f.put(&p.to_le_bytes());
                }
                f.finish()
            }
            Reply::Ack { free, status } => Frame::new(seq, 0x83)
                .put(&free.to_le_bytes())
                .put(&[status])
                .finish(),
            Reply::Nak { reason } => Frame::new(seq, 0x84).put(&[reason as u8]).finish(),
        }
    }

    /// Decode a reply from a frame's type and payload.
    pub fn decode(kind: u8, p: &[u8]) -> Result<Reply, FrameError> {
        let mut r = Cursor(p);
        let reply = match kind {
            0x81 => Reply::Ident {
                version: r.u8()?,
                channels: r.u8()?,
                clock_hz: r.u32()?,
                queue_slots: r.u16()?,
            },
            0x82 => {
                let clock = r.u64()?;
                let free = r.u16()?;
                let status = r.u8()?;
                let channels = r.u8()?;
                if channels as usize > MAX_CHANNELS {
                    return Err(FrameError::Malformed);
                }
                let mut positions = [0; MAX_CHANNELS];
                for p in &mut positions[..channels as usize] {
                    *p = r.u32()? as i32;
                }
                Reply::Clock {
                    clock,
                    free,
                    status,
                    positions,
                    channels,
                }
            }
            0x83 => Reply::Ack {
                free: r.u16()?,
                status: r.u8()?,
            },
            0x84 => Reply::Nak {
                reason: NakReason::from_u8(r.u8()?).ok_or(FrameError::Malformed)?,
            },
            _ => return Err(FrameError::Malformed),
        };
        r.end()?;
        Ok(reply)
    }
}

struct Cursor<'a>(&'a [u8]);

impl Cursor<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], FrameError> {
        if self.0.len() < N {
            return Err(FrameError::Malformed);
        }
        let (head, rest) = self.0.split_at(N);
        self.0 = rest;
        Ok(head.try_into().expect("length checked"))
    }
    fn u8(&mut self) -> Result<u8, FrameError> {
        Ok(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, FrameError> {
        Ok(u16::from_le_bytes(self.take()?))
    }
    fn u32(&mut self) -> Result<u32, FrameError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn u64(&mut self) -> Result<u64, FrameError> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    fn end(&self) -> Result<(), FrameError> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(FrameError::Malformed)
        }
    }
}

/// One received frame: sequence number, type and payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawFrame<'a> {
    /// Sequence number.
    pub seq: u8,
    /// Message type.
    pub kind: u8,
    /// Payload bytes.
    pub payload: &'a [u8],
}

/// Reassembles frames from a byte stream.
///
/// Bytes before a start byte are skipped (counted in
/// [`Deframer::skipped`]): a link that has just opened may begin mid-frame.
/// A frame with a bad length or CRC is reported as an error; both ends
/// treat that as a link fault rather than guessing where the next frame
/// starts.
pub struct Deframer {
    buf: [u8; MAX_FRAME],
    len: usize,
    /// Bytes skipped while looking for a start byte.
    pub skipped: u64,
}

impl Default for Deframer {
    fn default() -> Self {
        Deframer {
            buf: [0; MAX_FRAME],
            len: 0,
            skipped: 0,
        }
    }
}

impl Deframer {
    /// Feed one byte; returns a frame when one is complete. The frame
    /// borrows the deframer's buffer until the next call.
    pub fn push(&mut self, byte: u8) -> Option<Result<RawFrame<'_>, FrameError>> {
        if self.len == 0 {
            if byte != START {
                self.skipped += 1;
                return None;
            }
            self.buf[0] = byte;
            self.len = 1;
            return None;
        }
        if self.len == 1 && !(2..=MAX_BODY).contains(&(byte as usize)) {
            self.len = 0;
            return Some(Err(FrameError::Length));
        }
        self.buf[self.len] = byte;
        self.len += 1;
        let body = self.buf[1] as usize;
        if self.len < body + 4 {
            return None;
        }
        let total = self.len;
        self.len = 0;
        let crc = u16::from_le_bytes([self.buf[total - 2], self.buf[total - 1]]);
        if crc16(&self.buf[1..total - 2]) != crc {
            return Some(Err(FrameError::Crc));
        }
        Some(Ok(RawFrame {
            seq: self.buf[2],
            kind: self.buf[3],
            payload: &self.buf[4..total - 2],
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip_command(c: Command) {
        let f = c.encode(42);
        let mut d = Deframer::default();
        let mut got = None;
        for &b in f.bytes() {
            if let Some(r) = d.push(b) {
                let raw = r.unwrap();
                assert_eq!(raw.seq, 42);
                got = Some(Command::decode(raw.kind, raw.payload).unwrap());
            }
        }
        assert_eq!(got, Some(c));
    }

    #[test]
    fn crc_matches_the_published_check_value() {
        // CRC-16/CCITT-FALSE of "123456789" is 0x29B1 (catalogue check value).
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn commands_and_replies_round_trip() {
        roundtrip_command(Command::Hello);
        roundtrip_command(Command::Clock {
            host_ns: u64::MAX - 3,
        });
        roundtrip_command(Command::Config {
            channel: 2,
            invert_dir: true,
            timing: ChannelTiming {
                pulse: 20,
                space: 30,
                dir_setup: 40,
                dir_hold: 50,
            },
        });
        roundtrip_command(Command::Steps {
            channel: 1,
            forward: false,
            run: StepRun {
                first: 1 << 40,
                interval: 12345,
                count: 77,
                add: -3,
            },
        });
        roundtrip_command(Command::Stop);
        let mut positions = [0; MAX_CHANNELS];
        positions[..3].copy_from_slice(&[-5, 0, i32::MAX]);
        for reply in [
            Reply::Ident {
                version: 1,
                channels: 3,
                clock_hz: 10_000_000,
                queue_slots: 512,
            },
            Reply::Clock {
                clock: 99,
                free: 7,
                status: 0,
                positions,
                channels: 3,
            },
            Reply::Ack { free: 3, status: 1 },
            Reply::Nak {
                reason: NakReason::Sequence,
            },
        ] {
            let f = reply.encode(9);
            let mut d = Deframer::default();
            let mut got = None;
            for &b in f.bytes() {
                if let Some(r) = d.push(b) {
                    let raw = r.unwrap();
                    got = Some(Reply::decode(raw.kind, raw.payload).unwrap());
                }
            }
            assert_eq!(got, Some(reply));
        }
    }

    #[test]
    fn garbage_is_skipped_and_corruption_is_an_error() {
        let f = Command::Stop.encode(1);
        let mut d = Deframer::default();
        // Leading noise without a start byte is skipped.
        for b in [0x00, 0x13, 0xFF] {
            assert!(d.push(b).is_none());
        }
        assert_eq!(d.skipped, 3);
        // Every single-bit flip after the start byte is caught.
        for byte in 1..f.bytes().len() {
            for bit in 0..8 {
                let mut bad = f.bytes().to_vec();
                bad[byte] ^= 1 << bit;
                let mut d = Deframer::default();
                let mut results = Vec::new();
                for &b in &bad {
                    if let Some(r) = d.push(b) {
                        results.push(r.map(|raw| (raw.seq, raw.kind)));
                    }
                }
                assert!(
                    results.iter().any(|r| r.is_err()) || results.is_empty(),
                    "flip of bit {bit} in byte {byte} went unnoticed: {results:?}"
                );
            }
        }
        assert_eq!(
            Command::decode(0x04, &[0, 1, 2]),
            Err(FrameError::Malformed)
        );
        assert_eq!(Command::decode(0x77, &[]), Err(FrameError::Malformed));
    }

    #[test]
    fn run_decoding_is_exact_and_refuses_non_positive_gaps() {
        let run = StepRun {
            first: 100,
            interval: 10,
            count: 4,
            add: 2,
        };
        let t: Vec<_> = run.times().map(Option::unwrap).collect();
        assert_eq!(t, vec![100, 110, 122, 136]);
        assert_eq!(run.last(), Some(136));
        let bad = StepRun {
            first: 0,
            interval: 2,
            count: 5,
            add: -1,
        };
        assert!(bad.times().any(|t| t.is_none()));
        assert_eq!(bad.last(), None);
    }
}
