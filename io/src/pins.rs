//! Digital and analog I/O pins: the state M62–M68 act on.
//!
//! A [`PinBank`] lives in the servo tick and never allocates. Outputs are
//! set either at once (M64/M65 digital, M68 analog) or synchronised with
//! motion (M62/M63 digital, M67 analog): a synchronised change waits in
//! the bank until the servo calls [`PinBank::motion_started`] at the tick
//! the next motion segment begins, so the output changes in the same
//! period as the motion starts. Inputs are read with
//! [`PinBank::digital_in`] and [`PinBank::analog_in`]; [`InputWait`] is
//! M66's wait-on-input with timeout, whose result goes to #5399.
//!
//! Pins are numbered as in the G-code (`P` for digital, `E` for analog)
//! and named in `[hal.pins]`; [`crate::shm`] publishes outputs and reads
//! inputs under those names over shared memory.

use serde::Deserialize;

use crate::HalConfigError;

/// Most digital pins in each direction (bits of a `u64`).
pub const MAX_DIGITAL: usize = 64;
/// Most analog pins in each direction.
pub const MAX_ANALOG: usize = 16;

/// `[hal.pins]`: the pins' names, in pin-number order.
///
/// ```toml
/// [hal.pins]
/// digital_out = ["coolant-mist", "clamp"]   # M62-M65 P0, P1
/// digital_in = ["door-closed"]              # M66 P0
/// analog_out = ["laser-power"]              # M67/M68 E0
/// analog_in = ["probe-volts"]               # M66 E0
/// ```
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PinConfig {
    /// Digital outputs.
    #[serde(default)]
    pub digital_out: Vec<String>,
    /// Digital inputs.
    #[serde(default)]
    pub digital_in: Vec<String>,
    /// Analog outputs.
    #[serde(default)]
    pub analog_out: Vec<String>,
    /// Analog inputs.
    #[serde(default)]
    pub analog_in: Vec<String>,
}

impl PinConfig {
    /// Check counts and names (names become shared-memory service names:
    /// letters, digits, `-` and `_`, unique across all pins).
    pub fn validate(&self) -> Result<(), HalConfigError> {
        let groups: [(&str, &Vec<String>, usize); 4] = [
            ("digital_out", &self.digital_out, MAX_DIGITAL),
            ("digital_in", &self.digital_in, MAX_DIGITAL),
            ("analog_out", &self.analog_out, MAX_ANALOG),
            ("analog_in", &self.analog_in, MAX_ANALOG),
        ];
        let mut seen: Vec<&str> = Vec::new();
        for (key, names, max) in groups {
            if names.len() > max {
                return Err(HalConfigError::key(
                    format!("pins.{key}"),
                    format!("at most {max} pins, found {}", names.len()),
                ));
            }
            for (i, n) in names.iter().enumerate() {
                let ok = !n.is_empty()
                    && n.len() <= 64
                    && n.chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
                if !ok {
                    return Err(HalConfigError::key(
                        format!("pins.{key}[{i}]"),
                        format!("{n:?}: use 1 to 64 letters, digits, '-' or '_'"),
                    ));
                }
                if seen.contains(&n.as_str()) {
                    return Err(HalConfigError::key(
                        format!("pins.{key}[{i}]"),
                        format!("{n:?} names another pin already"),
                    ));
                }
                seen.push(n);
            }
        }
        Ok(())
    }
}

/// A pin number out of range for the bank.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("no {kind} pin {number}: the machine has {count}")]
pub struct NoSuchPin {
    /// `digital output`, `analog input`, ...
    pub kind: &'static str,
    /// The number asked for.
    pub number: usize,
    /// How many the machine has.
    pub count: usize,
}

/// The pins' values, owned by the servo tick. `Copy`, no allocation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinBank {
    counts: [usize; 4],
    digital_out: u64,
    analog_out: [f64; MAX_ANALOG],
    digital_in: u64,
    analog_in: [f64; MAX_ANALOG],
    /// Digital outputs waiting for motion: which, and their values.
    pending_mask: u64,
    pending_bits: u64,
    pending_analog: [Option<f64>; MAX_ANALOG],
}

impl PinBank {
    /// A bank with as many pins as `config` names, all off / zero.
    pub fn new(config: &PinConfig) -> PinBank {
        PinBank {
            counts: [
                config.digital_out.len(),
                config.digital_in.len(),
                config.analog_out.len(),
                config.analog_in.len(),
            ],
            digital_out: 0,
            analog_out: [0.0; MAX_ANALOG],
            digital_in: 0,
            analog_in: [0.0; MAX_ANALOG],
            pending_mask: 0,
            pending_bits: 0,
            pending_analog: [None; MAX_ANALOG],
        }
    }

    fn check(&self, group: usize, n: usize) -> Result<(), NoSuchPin> {
        const KINDS: [&str; 4] = [
            "digital output",
            "digital input",
            "analog output",
            "analog input",
        ];
        if n < self.counts[group] {
            Ok(())
        } else {
            Err(NoSuchPin {
                kind: KINDS[group],
                number: n,
                count: self.counts[group],
            })
        }
    }

    /// M64/M65 P`n`: set a digital output now.
    pub fn set_digital(&mut self, n: usize, on: bool) -> Result<(), NoSuchPin> {
        self.check(0, n)?;
        self.digital_out = (self.digital_out & !(1 << n)) | ((on as u64) << n);
        // An immediate change overrides a synchronised one still waiting.
        self.pending_mask &= !(1 << n);
        Ok(())
    }

    /// M62/M63 P`n`: set a digital output when the next motion starts.
    pub fn set_digital_synced(&mut self, n: usize, on: bool) -> Result<(), NoSuchPin> {
        self.check(0, n)?;
        self.pending_mask |= 1 << n;
        self.pending_bits = (self.pending_bits & !(1 << n)) | ((on as u64) << n);
        Ok(())
    }

    /// M68 E`n` Q`value`: set an analog output now.
    pub fn set_analog(&mut self, n: usize, value: f64) -> Result<(), NoSuchPin> {
        self.check(2, n)?;
        self.analog_out[n] = value;
        self.pending_analog[n] = None;
        Ok(())
    }

    /// M67 E`n` Q`value`: set an analog output when the next motion starts.
    pub fn set_analog_synced(&mut self, n: usize, value: f64) -> Result<(), NoSuchPin> {
        self.check(2, n)?;
        self.pending_analog[n] = Some(value);
        Ok(())
    }

    /// The servo calls this in the tick where a motion segment starts:
    /// synchronised changes take effect.
    pub fn motion_started(&mut self) {
        self.digital_out =
            (self.digital_out & !self.pending_mask) | (self.pending_bits & self.pending_mask);
        self.pending_mask = 0;
        for (out, pending) in self.analog_out.iter_mut().zip(&mut self.pending_analog) {
            if let Some(v) = pending.take() {
                *out = v;
            }
        }
    }

    /// Digital output `n` (false if out of range).
    pub fn digital_out(&self, n: usize) -> bool {
        n < MAX_DIGITAL && self.digital_out >> n & 1 == 1
    }

    /// All digital outputs, bit `n` = output `n`.
    pub fn digital_outputs(&self) -> u64 {
        self.digital_out
    }

    /// Analog output `n` (0 if out of range).
    pub fn analog_out(&self, n: usize) -> f64 {
        self.analog_out.get(n).copied().unwrap_or(0.0)
    }

    /// Digital input `n`.
    pub fn digital_in(&self, n: usize) -> Result<bool, NoSuchPin> {
        self.check(1, n)?;
        Ok(self.digital_in >> n & 1 == 1)
    }

    /// Analog input `n`.
    pub fn analog_in(&self, n: usize) -> Result<f64, NoSuchPin> {
        self.check(3, n)?;
        Ok(self.analog_in[n])
    }

    /// Store an input value read from the hardware or shared memory.
    pub fn store_digital_in(&mut self, n: usize, on: bool) {
        if n < self.counts[1] {
            self.digital_in = (self.digital_in & !(1 << n)) | ((on as u64) << n);
        }
    }

    /// Store an analog input value.
    pub fn store_analog_in(&mut self, n: usize, value: f64) {
        if n < self.counts[3] {
            self.analog_in[n] = value;
        }
    }

    /// Number of pins: (digital out, digital in, analog out, analog in).
    pub fn counts(&self) -> (usize, usize, usize, usize) {
        (
            self.counts[0],
            self.counts[1],
            self.counts[2],
            self.counts[3],
        )
    }
}

/// M66's wait type (`L` word).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitMode {
    /// L0: read at once, no waiting.
    Immediate,
    /// L1: wait for a rising edge.
    Rise,
    /// L2: wait for a falling edge.
    Fall,
    /// L3: wait for the input to be high.
    High,
    /// L4: wait for the input to be low.
    Low,
}

/// Which input M66 reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitInput {
    /// `P`: a digital input.
    Digital(usize),
    /// `E`: an analog input (only [`WaitMode::Immediate`]).
    Analog(usize),
}

/// M66: wait on an input, one servo period at a time, with a timeout.
/// The result is what #5399 receives: the input's value (0/1 for digital
/// inputs) when the condition is met, or −1 on timeout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputWait {
    input: WaitInput,
    mode: WaitMode,
    left: f64,
    last: Option<bool>,
}

impl InputWait {
    /// A wait on `input` in `mode` for at most `timeout` seconds. Checks
    /// the pin exists; analog inputs only allow `Immediate` (as in
    /// RS274NGC).
    pub fn new(
        bank: &PinBank,
        input: WaitInput,
        mode: WaitMode,
        timeout: f64,
    ) -> Result<InputWait, String> {
        match input {
            WaitInput::Digital(n) => {
                bank.digital_in(n).map_err(|e| e.to_string())?;
            }
            WaitInput::Analog(n) => {
                bank.analog_in(n).map_err(|e| e.to_string())?;
                if mode != WaitMode::Immediate {
                    return Err("M66 with an analog input (E) only reads immediately (L0)".into());
                }
            }
        }
        if !(timeout >= 0.0 && timeout.is_finite()) {
            return Err(format!("M66 timeout Q{timeout} is not a time in seconds"));
        }
        Ok(InputWait {
            input,
            mode,
            left: timeout,
            last: None,
        })
    }

    /// Check once per servo period of `dt` seconds: `Some(#5399 value)`
    /// when done. Never allocates.
    pub fn poll(&mut self, bank: &PinBank, dt: f64) -> Option<f64> {
        let level = match self.input {
            WaitInput::Analog(n) => return Some(bank.analog_in[n]),
            WaitInput::Digital(n) => bank.digital_in >> n & 1 == 1,
        };
        let met = match self.mode {
            WaitMode::Immediate => true,
            WaitMode::High => level,
            WaitMode::Low => !level,
            WaitMode::Rise => self.last == Some(false) && level,
            WaitMode::Fall => self.last == Some(true) && !level,
        };
        self.last = Some(level);
        if met {
            return Some(level as u8 as f64);
        }
        if self.left <= 0.0 {
            return Some(-1.0);
        }
        self.left -= dt;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bank() -> PinBank {
        PinBank::new(&PinConfig {
            digital_out: vec!["a".into(), "b".into()],
            digital_in: vec!["door".into()],
            analog_out: vec!["power".into()],
            analog_in: vec!["volts".into()],
        })
    }

    #[test]
    fn synchronised_outputs_wait_for_motion_and_immediate_ones_do_not() {
        let mut b = bank();
        b.set_digital_synced(1, true).unwrap();
        b.set_analog_synced(0, 0.75).unwrap();
        b.set_digital(0, true).unwrap();
        assert_eq!(b.digital_outputs(), 0b01);
        assert_eq!(b.analog_out(0), 0.0);
        b.motion_started();
        assert_eq!(b.digital_outputs(), 0b11);
        assert_eq!(b.analog_out(0), 0.75);
        // Nothing left pending: a second motion start changes nothing.
        b.set_digital(1, false).unwrap();
        b.motion_started();
        assert_eq!(b.digital_outputs(), 0b01);
        assert_eq!(
            b.set_digital(2, true),
            Err(NoSuchPin {
                kind: "digital output",
                number: 2,
                count: 2
            })
        );
    }

    #[test]
    fn m66_waits_for_an_edge_or_times_out_with_minus_one() {
        let mut b = bank();
        let mut w = InputWait::new(&b, WaitInput::Digital(0), WaitMode::Rise, 0.0105).unwrap();
        // Input high from the start is not a rising edge.
        b.store_digital_in(0, true);
        assert_eq!(w.poll(&b, 0.001), None);
        b.store_digital_in(0, false);
        assert_eq!(w.poll(&b, 0.001), None);
        b.store_digital_in(0, true);
        assert_eq!(w.poll(&b, 0.001), Some(1.0));
        // Waiting for low while it stays high: −1 after the timeout
        // (10.5 ms at 1 ms per poll: the 12th poll reports it).
        let mut w = InputWait::new(&b, WaitInput::Digital(0), WaitMode::Low, 0.0105).unwrap();
        let polls = (1..=100).find(|_| w.poll(&b, 0.001).is_some()).unwrap();
        assert_eq!(polls, 12);
        assert_eq!(w.poll(&b, 0.001), Some(-1.0));
        b.store_analog_in(0, 2.5);
        let mut w = InputWait::new(&b, WaitInput::Analog(0), WaitMode::Immediate, 0.0).unwrap();
        assert_eq!(w.poll(&b, 0.001), Some(2.5));
        assert!(InputWait::new(&b, WaitInput::Analog(0), WaitMode::Rise, 1.0).is_err());
        assert!(InputWait::new(&b, WaitInput::Digital(3), WaitMode::High, 1.0).is_err());
    }

    #[test]
    fn pin_names_are_checked() {
        let mut c = PinConfig {
            digital_out: vec!["ok-name".into(), "bad name".into()],
            ..Default::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("hal.pins.digital_out[1]"), "{e}");
        c.digital_out = vec!["x".into()];
        c.analog_in = vec!["x".into()];
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("hal.pins.analog_in[0]") && e.contains("another pin"),
            "{e}"
        );
    }
}
