//! The identified feed-drive model of seed `002`, eq. (2).
//!
//! The seed identifies the y-axis feed drive of a machining centre, from
//! drive input voltage u to table position y, at 1 ms:
//!
//! ```text
//! G(z) = (0.00257 z⁻¹ + 0.00241 z⁻²) / (1 − 1.820 z⁻¹ + 0.820 z⁻²)
//! ```
//!
//! The denominator is (1 − z⁻¹)(1 − 0.82 z⁻¹): an integrator and a lag.
//! That is the zero-order-hold sampling of `K / (s (τ s + 1))` (a velocity
//! drive: speed settles at K·u with time constant τ) with
//! `τ = −1 ms / ln 0.82 = 5.039 ms` and `K = (b1 + b2) / ((1 − 0.82)·1 ms)
//! = 27.67` per second per volt. Sampled at 1 ms that model has
//! b1 = 0.002572 and b2 = 0.002408, the seed's coefficients to every digit
//! printed. kerf simulates the continuous model exactly between ticks, so
//! the plant is right at any servo period, not only at 1 ms.
//!
//! Units: the seed's PD gains (eq. 3) only give a sensible loop if y is in
//! mm while their error is in µm (a 100 µm step then settles in about
//! 0.1 s without overshoot, and the following error at 1000 mm/min is
//! 0.46 mm); with y in µm or e in mm the loop is a thousand times too slow.
//! So K is in mm/s per volt: 27.67 mm/s at 1 V.

/// A velocity drive and axis: `Y(s)/U(s) = K / (s (τ s + 1))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveModel {
    /// Settled speed per unit of drive input, mm/s per volt.
    pub gain: f64,
    /// Time constant of the speed response, s.
    pub time_constant: f64,
}

impl DriveModel {
    /// The model of seed eq. (2).
    pub const SEED: DriveModel = DriveModel {
        gain: 0.00498 / (0.18 * 0.001),
        // −T / ln(0.82), T = 1 ms.
        time_constant: 0.005_039_028_822_088_8,
    };

    /// Advance position `y` (mm) and velocity `v` (mm/s) by `dt` seconds
    /// with input `u` held constant (zero-order hold), exactly.
    pub fn step(&self, y: f64, v: f64, u: f64, dt: f64) -> (f64, f64) {
        let (k, tau) = (self.gain, self.time_constant);
        let decay = (-dt / tau).exp();
        let settle = k * u;
        let y = y + settle * dt + (v - settle) * tau * (1.0 - decay);
        let v = settle + (v - settle) * decay;
        (y, v)
    }

    /// The discrete transfer function at period `dt`:
    /// `([b1, b2], [a1, a2])` of `(b1 z⁻¹ + b2 z⁻²) / (1 + a1 z⁻¹ + a2 z⁻²)`.
    pub fn discrete(&self, dt: f64) -> ([f64; 2], [f64; 2]) {
        let (k, tau) = (self.gain, self.time_constant);
        let a = (-dt / tau).exp();
        let b1 = k * (dt - tau * (1.0 - a));
        let b2 = k * (tau * (1.0 - a) - a * dt);
        ([b1, b2], [-(1.0 + a), a])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampled_at_1ms_it_is_the_seed_equation_to_the_printed_digits() {
        let ([b1, b2], [a1, a2]) = DriveModel::SEED.discrete(0.001);
        let round5 = |x: f64| (x * 1e5).round() / 1e5;
        assert_eq!(round5(b1), 0.00257);
        assert_eq!(round5(b2), 0.00241);
        assert!((a1 + 1.820).abs() < 1e-12 && (a2 - 0.820).abs() < 1e-12);
    }

    #[test]
    fn stepping_equals_the_difference_equation() {
        // Any input sequence: the exact ZOH step and the discrete transfer
        // function must give the same positions.
        let m = DriveModel::SEED;
        for dt in [0.00025, 0.001, 0.004] {
            let ([b1, b2], [a1, a2]) = m.discrete(dt);
            let (mut y, mut v) = (0.0, 0.0);
            let (mut hist_y, mut last_u) = ([0.0f64; 2], 0.0);
            for k in 0..500 {
                let u = (k as f64 * 0.037).sin() * 3.0 + if k > 200 { 1.0 } else { 0.0 };
                (y, v) = m.step(y, v, u, dt);
                let d = -a1 * hist_y[0] - a2 * hist_y[1] + b1 * u + b2 * last_u;
                hist_y = [d, hist_y[0]];
                last_u = u;
                assert!(
                    (y - d).abs() < 1e-9 * (1.0 + d.abs()),
                    "dt {dt} k {k}: {y} vs {d}"
                );
            }
        }
    }

    #[test]
    fn unit_step_response_is_the_closed_form() {
        // u = 1 V from rest: y(t) = K (t − τ (1 − e^(−t/τ))).
        let m = DriveModel::SEED;
        let (mut y, mut v) = (0.0, 0.0);
        for k in 1..=100 {
            (y, v) = m.step(y, v, 1.0, 0.001);
            let t = k as f64 * 0.001;
            let want = m.gain * (t - m.time_constant * (1.0 - (-t / m.time_constant).exp()));
            assert!((y - want).abs() < 1e-12, "k {k}: {y} vs {want}");
        }
        // After 20 time constants the speed has settled at K = 27.67 mm/s.
        assert!((v - 27.666_666).abs() < 1e-3, "{v}");
    }
}
