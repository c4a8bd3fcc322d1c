//! The inner loop: one position controller per joint, run every servo
//! period on the host (seed `002`, section II.B.2, eq. 3).
//!
//! ```text
//! u = kp·e + ki·∫e dt + kd·ė + kvff·v + kaff·a,   clamped to ±max_output
//! ```
//!
//! * `e` is the following error **now**: where the joint should be at the
//!   start of this period minus where it is measured to be, mm (joint units).
//! * `ė` is its change over the last period divided by the period, mm/s.
//! * `v` is the mean commanded velocity over the coming period (the
//!   setpoint for the end of the period minus the one for now, over the
//!   period), mm/s.
//! * `a` is the mean commanded acceleration over the coming period, mm/s²,
//!   extrapolated from the last three mean velocities so that it is exact
//!   while the jerk is constant (the executor's profiles are piecewise
//!   constant jerk).
//! * `u` is the drive input (effort) held over the coming period, in the
//!   drive's units: "V" for the analogue velocity drive of the seed.
//!
//! Units: every gain is per mm of joint motion and per second, so gains do
//! not change with the servo period. The seed's eq. (3),
//! `u(k) = 0.001396·e(k) − 0.0001·e(k−1)`, takes the error in µm: as
//! `(kp + kd/T)·e − (kd/T)·e(k−1)` with `e` in mm and `T` = 1 ms it is
//! `kp = 1.296 V/mm` and `kd = 1.0e-4 V·s/mm` ([`LoopGains::SEED`]).
//!
//! Everything here is plain state and arithmetic: no allocation, no I/O.

use crate::kinematics::MAX_JOINTS;

/// Gains and output limit of one joint's position loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopGains {
    /// Proportional gain, drive units per mm of following error.
    pub kp: f64,
    /// Integral gain, drive units per mm·s of accumulated error.
    pub ki: f64,
    /// Derivative gain, drive units per mm/s of error change.
    pub kd: f64,
    /// Velocity feedforward, drive units per mm/s of commanded velocity.
    /// For a plant that settles at `K` mm/s per drive unit it is `1/K`.
    pub kvff: f64,
    /// Acceleration feedforward, drive units per mm/s² of commanded
    /// acceleration. For a plant `K/(s(τs + 1))` it is `τ/K`.
    pub kaff: f64,
    /// Largest drive input either way, drive units (the drive's ±10 V, say).
    pub max_output: f64,
}

impl LoopGains {
    /// The seed's PD gains (eq. 3, converted to mm and seconds at its 1 ms
    /// period) with the feedforward that inverts its identified plant
    /// (eq. 2: K = 27.67 mm/s per V, τ = 5.04 ms), output ±10 V.
    pub const SEED: LoopGains = LoopGains {
        kp: 1.296,
        ki: 0.0,
        kd: 1.0e-4,
        kvff: 1.0 / 27.666_666_666_666_67,
        kaff: 0.005_039_028_822_088_8 / 27.666_666_666_666_67,
        max_output: 10.0,
    };

    /// No feedback and no feedforward: the loop outputs zero. Used for
    /// drives that close the position loop themselves.
    pub const NONE: LoopGains = LoopGains {
        kp: 0.0,
        ki: 0.0,
        kd: 0.0,
        kvff: 0.0,
        kaff: 0.0,
        max_output: 0.0,
    };

    /// The same gains without velocity and acceleration feedforward (the
    /// seed's pure PD).
    pub fn without_feedforward(self) -> LoopGains {
        LoopGains {
            kvff: 0.0,
            kaff: 0.0,
            ..self
        }
    }

    /// The first gain that is not a finite number ≥ 0, by its TOML key,
    /// with the offending value.
    pub fn invalid(&self) -> Option<(&'static str, f64)> {
        [
            ("kp", self.kp),
            ("ki", self.ki),
            ("kd", self.kd),
            ("kvff", self.kvff),
            ("kaff", self.kaff),
            ("max_output", self.max_output),
        ]
        .into_iter()
        .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
    }
}

/// What one period of the loop computed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LoopOutput {
    /// Drive input for the coming period, clamped to ±`max_output`.
    pub effort: f64,
    /// Following error used this period (setpoint now − measured), mm.
    pub error: f64,
    /// The unclamped output exceeded `max_output`.
    pub saturated: bool,
}

/// The state of one joint's position loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLoop {
    gains: LoopGains,
    /// Setpoint for now (the end of the last period), mm.
    setpoint: f64,
    /// Following error of the last period, mm.
    last_error: f64,
    /// ∫e dt, mm·s.
    integral: f64,
    /// Mean commanded velocities of the last two periods, newest first, mm/s.
    past_velocity: [f64; 2],
}

impl JointLoop {
    /// A loop at rest at `position` (mm).
    pub fn new(gains: LoopGains, position: f64) -> JointLoop {
        JointLoop {
            gains,
            setpoint: position,
            last_error: 0.0,
            integral: 0.0,
            past_velocity: [0.0; 2],
        }
    }

    /// The gains in force.
    pub fn gains(&self) -> LoopGains {
        self.gains
    }

    /// Change the gains; the loop's history is kept.
    pub fn set_gains(&mut self, gains: LoopGains) {
        self.gains = gains;
    }

    /// Forget all history and rest at `position`: the drive was off, or
    /// the machine was moved by something other than this loop.
    pub fn reset(&mut self, position: f64) {
        *self = JointLoop::new(self.gains, position);
    }

    /// One period of `dt` seconds: `next` is the setpoint for the end of
    /// the period, `measured` the joint position measured now (both mm).
    pub fn update(&mut self, next: f64, measured: f64, dt: f64) -> LoopOutput {
        let g = &self.gains;
        let error = self.setpoint - measured;
        let d_error = (error - self.last_error) / dt;
        let velocity = (next - self.setpoint) / dt;
        // Mean acceleration over the coming period: the second differences
        // give the acceleration at the start of this period and the last;
        // extrapolating half a period is exact for constant jerk.
        let [v1, v2] = self.past_velocity;
        let acceleration = (1.5 * velocity - 2.0 * v1 + 0.5 * v2) / dt;
        let integral = self.integral + error * dt;
        let raw = g.kp * error
            + g.ki * integral
            + g.kd * d_error
            + g.kvff * velocity
            + g.kaff * acceleration;
        let saturated = raw.abs() > g.max_output;
        // Anti-windup: stop integrating while the output is clamped.
        if !saturated {
            self.integral = integral;
        }
        self.last_error = error;
        self.setpoint = next;
        self.past_velocity = [velocity, v1];
        LoopOutput {
            effort: raw.clamp(-g.max_output, g.max_output),
            error,
            saturated,
        }
    }
}

/// The position loops of every joint of a machine.
#[derive(Clone, Debug, PartialEq)]
pub struct JointLoops {
    loops: [JointLoop; MAX_JOINTS],
    /// The gains as configured (with feedforward).
    gains: [LoopGains; MAX_JOINTS],
    count: usize,
    feedforward: bool,
}

impl JointLoops {
    /// Loops for `gains.len()` joints resting at `positions`.
    ///
    /// # Panics
    /// If the two slices differ in length or hold more than [`MAX_JOINTS`].
    pub fn new(gains: &[LoopGains], positions: &[f64]) -> JointLoops {
        assert!(gains.len() == positions.len() && gains.len() <= MAX_JOINTS);
        let mut loops = [JointLoop::new(LoopGains::NONE, 0.0); MAX_JOINTS];
        let mut configured = [LoopGains::NONE; MAX_JOINTS];
        for (j, (g, p)) in gains.iter().zip(positions).enumerate() {
            loops[j] = JointLoop::new(*g, *p);
            configured[j] = *g;
        }
        JointLoops {
            loops,
            gains: configured,
            count: gains.len(),
            feedforward: true,
        }
    }

    /// Velocity and acceleration feedforward on (the default) or off (the
    /// seed's pure PD).
    pub fn set_feedforward(&mut self, on: bool) {
        self.feedforward = on;
        for (l, g) in self.loops[..self.count].iter_mut().zip(&self.gains) {
            l.set_gains(if on { *g } else { g.without_feedforward() });
        }
    }

    /// Feedforward is on.
    pub fn feedforward(&self) -> bool {
        self.feedforward
    }

    /// The loop of joint `j`.
    pub fn joint(&self, j: usize) -> &JointLoop {
        &self.loops[j]
    }

    /// Reset every loop to rest at `positions` (drives off).
    pub fn reset(&mut self, positions: &[f64]) {
        for (l, p) in self.loops[..self.count].iter_mut().zip(positions) {
            l.reset(*p);
        }
    }

    /// One period for every joint: `next[j]` is joint j's setpoint for the
    /// end of the period, `measured[j]` its position now; the drive inputs
    /// go to `effort[j]`. Returns how many outputs were clamped.
    pub fn update(&mut self, next: &[f64], measured: &[f64], dt: f64, effort: &mut [f64]) -> usize {
        let mut clamped = 0;
        for (j, l) in self.loops[..self.count].iter_mut().enumerate() {
            let out = l.update(next[j], measured[j], dt);
            effort[j] = out.effort;
            clamped += out.saturated as usize;
        }
        clamped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The seed's eq. (2) as printed: y(k) = 1.820·y(k−1) − 0.820·y(k−2)
    /// + 0.00257·u(k−1) + 0.00241·u(k−2), y in mm, u in V, 1 ms.
    #[derive(Default)]
    struct SeedPlant {
        y: [f64; 2],
        u: f64,
    }

    impl SeedPlant {
        /// Hold `u` over the coming period; returns y at its end.
        fn step(&mut self, u: f64) -> f64 {
            let y = 1.820 * self.y[0] - 0.820 * self.y[1] + 0.00257 * u + 0.00241 * self.u;
            self.y = [y, self.y[0]];
            self.u = u;
            y
        }
    }

    #[test]
    fn seed_gains_reproduce_equation_3() {
        // u(k) = 0.001396·e(k) − 0.0001·e(k−1) with e in µm.
        let mut l = JointLoop::new(LoopGains::SEED.without_feedforward(), 0.0);
        let errors_um = [100.0, 80.0, -30.0, 5.0];
        let mut last = 0.0;
        for e in errors_um {
            // Setpoint held at 0, measured −e: error = e (converted to mm).
            let out = l.update(0.0, -e / 1000.0, 0.001);
            let want = 0.001396 * e - 0.0001 * last;
            assert!(
                (out.effort - want).abs() < 1e-12,
                "{} vs {want}",
                out.effort
            );
            last = e;
        }
    }

    #[test]
    fn pd_on_the_seed_plant_follows_a_ramp_at_v_over_kv() {
        // Ramp at 1000 mm/min: the steady following error of a type-1 loop
        // with PD is v / (K·kp): the plant's velocity gain K = 0.00498/0.18
        // mm per ms per V, so 16.667 / (27.667 · 1.296) = 0.4648 mm.
        let v = 1000.0 / 60.0;
        let k = 0.00498 / 0.18 / 0.001;
        let want = v / (k * 1.296);
        let mut l = JointLoop::new(LoopGains::SEED.without_feedforward(), 0.0);
        let mut plant = SeedPlant::default();
        let mut y = 0.0;
        let mut error = 0.0;
        for k in 1..=2000 {
            let out = l.update(v * k as f64 * 0.001, y, 0.001);
            error = out.error;
            y = plant.step(out.effort);
        }
        assert!((error - want).abs() < 1e-6, "{error} vs {want}");
    }

    #[test]
    fn step_of_100_um_rises_without_overshoot() {
        // The seed designed kd so that a 100 µm step does not overshoot.
        let mut l = JointLoop::new(LoopGains::SEED.without_feedforward(), 0.0);
        let mut plant = SeedPlant::default();
        let mut y = 0.0;
        let mut peak: f64 = 0.0;
        for _ in 0..1000 {
            let out = l.update(0.1, y, 0.001);
            y = plant.step(out.effort);
            peak = peak.max(y);
        }
        assert!(peak <= 0.1 + 1e-9, "overshoot to {peak}");
        assert!((y - 0.1).abs() < 1e-6, "settled at {y}");
    }

    #[test]
    fn acceleration_feedforward_is_exact_for_constant_jerk() {
        // r = j t³/6: mean acceleration over [t, t+T] is j (t + T/2).
        let g = LoopGains {
            kaff: 1.0,
            max_output: f64::INFINITY,
            ..LoopGains::NONE
        };
        let (dt, j) = (0.001, 5000.0);
        let mut l = JointLoop::new(g, 0.0);
        for k in 0..20 {
            let t = k as f64 * dt;
            let next = j * (t + dt).powi(3) / 6.0;
            let out = l.update(next, 0.0, dt);
            if k >= 2 {
                let want = j * (t + dt / 2.0);
                assert!(
                    (out.effort - want).abs() < 1e-6,
                    "k {k}: {} vs {want}",
                    out.effort
                );
            }
        }
    }

    #[test]
    fn output_is_clamped_and_the_integral_does_not_wind_up() {
        let g = LoopGains {
            kp: 1.0,
            ki: 10.0,
            max_output: 2.0,
            ..LoopGains::NONE
        };
        let mut l = JointLoop::new(g, 0.0);
        for _ in 0..100 {
            let out = l.update(5.0, 0.0, 0.001);
            assert!(out.effort <= 2.0);
        }
        // Saturated all along (error 5 mm → 5 V > 2 V): nothing integrated.
        let out = l.update(0.0, 5.0 - 0.1, 0.001);
        assert!((out.effort - 0.1).abs() < 0.01, "{}", out.effort);
    }

    #[test]
    fn bad_gains_are_named() {
        let g = LoopGains {
            kd: -1.0,
            ..LoopGains::SEED
        };
        assert_eq!(g.invalid(), Some(("kd", -1.0)));
        assert_eq!(LoopGains::SEED.invalid(), None);
    }
}
