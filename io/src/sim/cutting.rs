//! The simulated cutting process: two-flute end milling with the force
//! model of seed `002`, eq. (1), a stock with a stepped top, and the
//! spindle motor current as the force sensor (seed section III.C).
//!
//! Per servo period the tool tip moves from the joint positions of the
//! X, Y and Z joints (`joints`, which must drive those axes directly). The
//! process then takes:
//!
//! * feed f (mm/min): the tool's speed in the XY plane;
//! * feed per tooth `f_t = f / (N_s · M)` (mm), N_s the spindle speed
//!   (rpm), M the flutes;
//! * axial depth of cut d (mm): the stock top under the tool axis minus the
//!   tool tip Z, if the tool axis is over the stock (0 otherwise);
//! * flute angle θ = 2π N_s t / 60.
//!
//! Eq. (1), full immersion, one flute engaged (h is the helix lead
//! πD / tan β, ψ = atan(1/K_rt)):
//!
//! ```text
//! F_x = K_s K_rt f_t d / 2 + (K_s f_t h / 4π) sin(2πd/h) √(1 + K_rt²) sin(2θ − 2πd/h + ψ)
//! F_y = K_s f_t d / 2      + (K_s f_t h / 4π) sin(2πd/h) √(1 + K_rt²) sin(2θ − 2πd/h + ψ)
//! ```
//!
//! The force is the magnitude √(F_x² + F_y²); the simulator reports its
//! largest value over each period exactly (not just at the sample), since
//! the flutes pass many times per period at high spindle speeds.
//!
//! Spindle current (eq. 6 for the spindle: at constant speed the motor
//! torque balances friction plus the cutting torque, so I = I0 + k·F).
//! The belt drive and the drive's current loop pass only slow changes
//! (the seed: below 5 Hz), so the model reports the largest force of each
//! spindle revolution during the next one — a lag of one revolution —
//! plus white noise: `I = I0 + k · F_max(previous revolution) + n`.

use serde::Deserialize;

use super::noise::Noise;
use crate::HalConfigError;

/// A step in the stock top: from `x` (mm) on, the top is at `top` (mm).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StockStep {
    /// X where the step is, mm.
    pub x: f64,
    /// Z of the stock top from there on, mm.
    pub top: f64,
}

/// `[hal.sim.cutting]`: the tool, the material, the stock and the spindle
/// current sensor.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CuttingConfig {
    /// Tangential specific cutting force K_s, N/mm² (aluminium ≈ 800).
    #[serde(default = "defaults::ks")]
    pub ks: f64,
    /// Radial-to-tangential force ratio K_rt.
    #[serde(default = "defaults::krt")]
    pub krt: f64,
    /// Number of flutes M.
    #[serde(default = "defaults::flutes")]
    pub flutes: u32,
    /// Tool diameter D, mm.
    #[serde(default = "defaults::diameter")]
    pub diameter: f64,
    /// Helix angle β, degrees; the helix lead is h = πD / tan β.
    #[serde(default = "defaults::helix_angle")]
    pub helix_angle: f64,
    /// Joints that move the tool in X, Y and Z (they must drive those axes
    /// directly, as with trivial kinematics).
    #[serde(default = "defaults::joints")]
    pub joints: [usize; 3],
    /// Z of the stock top before the first step, mm.
    pub stock_top: f64,
    /// Where the stock starts along X, mm; unbounded when not given.
    #[serde(default)]
    pub x_min: Option<f64>,
    /// Where the stock ends along X, mm; unbounded when not given.
    #[serde(default)]
    pub x_max: Option<f64>,
    /// Steps in the stock top along X, in increasing `x`.
    #[serde(default)]
    pub steps: Vec<StockStep>,
    /// Spindle current turning without cutting, I0, A.
    #[serde(default = "defaults::idle_current")]
    pub idle_current: f64,
    /// Spindle current per newton of cutting force, k, A/N.
    #[serde(default = "defaults::current_per_newton")]
    pub current_per_newton: f64,
    /// Standard deviation of the white noise on the current, A.
    #[serde(default = "defaults::current_noise")]
    pub current_noise: f64,
    /// Seed of the noise.
    #[serde(default = "defaults::seed")]
    pub seed: u64,
}

mod defaults {
    pub fn ks() -> f64 {
        800.0
    }
    pub fn krt() -> f64 {
        0.3
    }
    pub fn flutes() -> u32 {
        2
    }
    pub fn diameter() -> f64 {
        10.0
    }
    pub fn helix_angle() -> f64 {
        30.0
    }
    pub fn joints() -> [usize; 3] {
        [0, 1, 2]
    }
    pub fn idle_current() -> f64 {
        2.0
    }
    pub fn current_per_newton() -> f64 {
        0.01
    }
    pub fn current_noise() -> f64 {
        0.005
    }
    pub fn seed() -> u64 {
        1
    }
}

impl CuttingConfig {
    /// Check every value; errors name the key under `hal.sim.cutting`.
    pub fn validate(&self, joints: usize) -> Result<(), HalConfigError> {
        let key = |k: &str, reason: String| HalConfigError::key(format!("sim.cutting.{k}"), reason);
        for (k, v) in [
            ("ks", self.ks),
            ("diameter", self.diameter),
            ("current_per_newton", self.current_per_newton),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(key(k, format!("must be a positive number, got {v}")));
            }
        }
        for (k, v) in [
            ("krt", self.krt),
            ("idle_current", self.idle_current),
            ("current_noise", self.current_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(key(k, format!("must be a number ≥ 0, got {v}")));
            }
        }
        if !(self.helix_angle > 0.0 && self.helix_angle < 90.0) {
            return Err(key(
                "helix_angle",
                format!("must be between 0 and 90 degrees, got {}", self.helix_angle),
            ));
        }
        if self.flutes == 0 {
            return Err(key("flutes", "must be at least 1".into()));
        }
        if let Some(&j) = self.joints.iter().find(|&&j| j >= joints) {
            return Err(key(
                "joints",
                format!(
                    "joint {j} does not exist: the simulator drives joints 0 to {}",
                    joints - 1
                ),
            ));
        }
        if !self.stock_top.is_finite() {
            return Err(key("stock_top", "must be a number".into()));
        }
        let mut last = f64::NEG_INFINITY;
        for (i, s) in self.steps.iter().enumerate() {
            if !(s.x.is_finite() && s.top.is_finite() && s.x > last) {
                return Err(key(
                    &format!("steps[{i}]"),
                    format!(
                        "x = {}, top = {}: steps need numbers in increasing x",
                        s.x, s.top
                    ),
                ));
            }
            last = s.x;
        }
        if let (Some(a), Some(b)) = (self.x_min, self.x_max) {
            if a >= b || a.is_nan() || b.is_nan() {
                return Err(key(
                    "x_min",
                    format!("x_min ({a}) must be below x_max ({b})"),
                ));
            }
        }
        Ok(())
    }

    /// Helix lead h = πD / tan β, mm.
    pub fn lead(&self) -> f64 {
        std::f64::consts::PI * self.diameter / self.helix_angle.to_radians().tan()
    }

    /// Stock top at `x`, or `None` where there is no stock.
    pub fn top_at(&self, x: f64) -> Option<f64> {
        if self.x_min.is_some_and(|a| x < a) || self.x_max.is_some_and(|b| x > b) {
            return None;
        }
        Some(
            self.steps
                .iter()
                .take_while(|s| s.x <= x)
                .last()
                .map_or(self.stock_top, |s| s.top),
        )
    }

    /// The force of eq. (1), N, for feed per tooth `ft` (mm), depth `d`
    /// (mm) and `s` = sin(2θ − 2πd/h + ψ).
    pub fn force(&self, ft: f64, d: f64, s: f64) -> f64 {
        let h = self.lead();
        let ripple = self.ks * ft * h / (4.0 * std::f64::consts::PI)
            * (2.0 * std::f64::consts::PI * d / h).sin()
            * (1.0 + self.krt * self.krt).sqrt()
            * s;
        let fx = self.ks * self.krt * ft * d / 2.0 + ripple;
        let fy = self.ks * ft * d / 2.0 + ripple;
        fx.hypot(fy)
    }
}

/// The state of the simulated cutting process and spindle.
#[derive(Clone, Debug)]
pub struct Cutting {
    config: CuttingConfig,
    /// Flute angle θ, rad, in [0, 2π).
    theta: f64,
    /// Largest force of the revolution in progress, N.
    peak: f64,
    /// Largest force of the last complete revolution, N.
    last_peak: f64,
    noise: Noise,
}

/// What the process did over one period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cut {
    /// Largest cutting force over the period, N.
    pub force: f64,
    /// Spindle motor current at the end of the period, A.
    pub current: f64,
}

impl Cutting {
    /// The process for a checked `config`, spindle angle 0.
    pub fn new(config: CuttingConfig) -> Cutting {
        let noise = Noise::new(config.seed);
        Cutting {
            config,
            theta: 0.0,
            peak: 0.0,
            last_peak: 0.0,
            noise,
        }
    }

    /// The settings.
    pub fn config(&self) -> &CuttingConfig {
        &self.config
    }

    /// One period of `dt` s ending with the tool tip at `tip` (X Y Z, mm)
    /// moving at `velocity` (mm/s), spindle at `rpm`.
    pub fn step(&mut self, tip: [f64; 3], velocity: [f64; 3], rpm: f64, dt: f64) -> Cut {
        use std::f64::consts::{PI, TAU};
        let c = &self.config;
        if rpm <= 0.0 {
            // Spindle off: no cutting (a real tool would break), no current.
            self.peak = 0.0;
            self.last_peak = 0.0;
            return Cut::default();
        }
        let feed = velocity[0].hypot(velocity[1]) * 60.0;
        let ft = feed / (rpm * c.flutes as f64);
        let depth = c.top_at(tip[0]).map_or(0.0, |top| (top - tip[2]).max(0.0));
        let h = c.lead();
        let psi = (1.0 / c.krt).atan();
        let start = self.theta;
        let sweep = TAU * rpm / 60.0 * dt;
        let force = if ft > 0.0 && depth > 0.0 {
            // Extremes of sin over the phase swept this period; |F| is
            // convex in s, so its largest value is at one of them.
            let phase = 2.0 * start - 2.0 * PI * depth / h + psi;
            let (lo, hi) = sin_range(phase, phase + 2.0 * sweep);
            c.force(ft, depth, lo).max(c.force(ft, depth, hi))
        } else {
            0.0
        };
        self.peak = self.peak.max(force);
        self.theta += sweep;
        if self.theta >= TAU {
            self.theta %= TAU;
            self.last_peak = self.peak;
            self.peak = force;
        }
        let current = c.idle_current
            + c.current_per_newton * self.last_peak
            + c.current_noise * self.noise.normal();
        Cut { force, current }
    }
}

/// Smallest and largest value of sin over [a, b] (radians, a ≤ b).
fn sin_range(a: f64, b: f64) -> (f64, f64) {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let (sa, sb) = (a.sin(), b.sin());
    let (mut lo, mut hi) = (sa.min(sb), sa.max(sb));
    // Is there a crest (π/2 + 2πn) or a trough (−π/2 + 2πn) inside?
    let contains = |centre: f64| {
        let n = ((a - centre) / TAU).ceil();
        centre + n * TAU <= b
    };
    if b - a >= TAU || contains(FRAC_PI_2) {
        hi = 1.0;
    }
    if b - a >= TAU || contains(-FRAC_PI_2) {
        lo = -1.0;
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn aluminium() -> CuttingConfig {
        toml::from_str("stock_top = 0.0\ncurrent_noise = 0.0").unwrap()
    }

    #[test]
    fn mean_force_over_a_revolution_is_the_constant_terms() {
        // The ripple is a sinusoid in 2θ: over a revolution F_x and F_y
        // average to K_s K_rt f_t d / 2 and K_s f_t d / 2.
        let c = aluminium();
        let (ft, d, n) = (0.1, 2.0, 3600);
        let h = c.lead();
        let psi = (1.0 / c.krt).atan();
        let ripple = |s: f64| {
            c.ks * ft * h / (4.0 * std::f64::consts::PI)
                * (2.0 * std::f64::consts::PI * d / h).sin()
                * (1.0 + c.krt * c.krt).sqrt()
                * s
        };
        let (mut fx, mut fy) = (0.0, 0.0);
        for k in 0..n {
            let theta = std::f64::consts::TAU * k as f64 / n as f64;
            let s = (2.0 * theta - 2.0 * std::f64::consts::PI * d / h + psi).sin();
            fx += c.ks * c.krt * ft * d / 2.0 + ripple(s);
            fy += c.ks * ft * d / 2.0 + ripple(s);
        }
        assert!((fx / n as f64 - 800.0 * 0.3 * 0.1).abs() < 1e-9);
        assert!((fy / n as f64 - 800.0 * 0.1).abs() < 1e-9);
        // Magnitude at a crest, checked by hand: ripple amplitude for
        // h = π·10/tan 30° = 54.41 mm.
        let a = ripple(1.0);
        let want = (24.0 + a).hypot(80.0 + a);
        assert!((c.force(ft, d, 1.0) - want).abs() < 1e-9);
    }

    #[test]
    fn doubling_the_depth_nearly_doubles_the_peak_force() {
        let c = aluminium();
        let ratio = c.force(0.1, 4.0, 1.0) / c.force(0.1, 2.0, 1.0);
        assert!(ratio > 1.9 && ratio < 2.0, "{ratio}");
    }

    #[test]
    fn stock_steps_and_extent() {
        let c: CuttingConfig = toml::from_str(
            "stock_top = -1.0\nx_min = 10.0\nx_max = 100.0\nsteps = [{ x = 50.0, top = 1.0 }, { x = 80.0, top = 0.0 }]",
        )
        .unwrap();
        c.validate(3).unwrap();
        assert_eq!(c.top_at(5.0), None);
        assert_eq!(c.top_at(10.0), Some(-1.0));
        assert_eq!(c.top_at(50.0), Some(1.0));
        assert_eq!(c.top_at(79.9), Some(1.0));
        assert_eq!(c.top_at(90.0), Some(0.0));
        assert_eq!(c.top_at(100.1), None);
    }

    #[test]
    fn current_reports_the_last_revolutions_peak() {
        // 1000 rpm at 1 ms: 60 periods a revolution. Feeding 240 mm/min in
        // X at depth 2 mm: f_t = 0.12 mm.
        let c = aluminium();
        let peak = c.force(0.12, 2.0, 1.0);
        let mut cut = Cutting::new(c);
        let v = [4.0, 0.0, 0.0];
        let mut seen = Vec::new();
        for k in 0..180 {
            let out = cut.step([k as f64 * 0.004, 0.0, -2.0], v, 1000.0, 0.001);
            assert!(out.force <= peak + 1e-9);
            seen.push(out);
        }
        // First revolution: nothing measured yet, only the idle current.
        assert!(seen[..59].iter().all(|c| c.current == 2.0));
        // From the second on, I0 + k·peak of the revolution before.
        let largest = seen[..60].iter().map(|c| c.force).fold(0.0, f64::max);
        assert!((largest - peak).abs() < 1e-9, "{largest} vs {peak}");
        assert!((seen[100].current - (2.0 + 0.01 * peak)).abs() < 1e-9);
    }

    #[test]
    fn no_cut_in_air_when_stopped_or_spindle_off() {
        let mut cut = Cutting::new(aluminium());
        assert_eq!(
            cut.step([0.0, 0.0, 1.0], [4.0, 0.0, 0.0], 1000.0, 0.001)
                .force,
            0.0
        );
        assert_eq!(
            cut.step([0.0, 0.0, -2.0], [0.0; 3], 1000.0, 0.001).force,
            0.0
        );
        assert_eq!(
            cut.step([0.0, 0.0, -2.0], [4.0, 0.0, 0.0], 0.0, 0.001),
            Cut::default()
        );
    }

    #[test]
    fn sin_range_finds_crests_inside_the_interval() {
        let (lo, hi) = sin_range(0.0, 1.0);
        assert_eq!((lo, hi), (0.0, 1.0f64.sin()));
        assert_eq!(sin_range(1.0, 2.0).1, 1.0);
        assert_eq!(sin_range(4.0, 5.0).0, -1.0);
        assert_eq!(sin_range(0.0, 7.0), (-1.0, 1.0));
        assert_eq!(
            sin_range(
                1.0 + std::f64::consts::TAU * 3.0,
                2.0 + std::f64::consts::TAU * 3.0
            )
            .1,
            1.0
        );
    }

    #[test]
    fn bad_values_name_their_key() {
        let mut c = aluminium();
        c.helix_angle = 90.0;
        assert!(c
            .validate(3)
            .unwrap_err()
            .to_string()
            .contains("sim.cutting.helix_angle"));
        let mut c = aluminium();
        c.joints = [0, 1, 5];
        assert!(c
            .validate(3)
            .unwrap_err()
            .to_string()
            .contains("joint 5 does not exist"));
        let mut c = aluminium();
        c.steps = vec![
            StockStep { x: 5.0, top: 0.0 },
            StockStep { x: 1.0, top: 0.0 },
        ];
        assert!(c
            .validate(3)
            .unwrap_err()
            .to_string()
            .contains("sim.cutting.steps[1]"));
    }
}
