//! Velocity profiles along a path: distance as a function of time.

/// A trapezoidal velocity profile that starts and ends at rest: accelerate
/// at `acceleration` to `peak_velocity`, cruise, decelerate to a stop.
///
/// Units: mm (or degrees), mm/s, mm/s², seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trapezoid {
    pub length: f64,
    /// Highest speed actually reached (lower than the requested one on a
    /// short move, which becomes a triangle).
    pub peak_velocity: f64,
    pub acceleration: f64,
    /// Time spent accelerating (equal to the time decelerating).
    pub ramp_time: f64,
    /// Time at peak velocity.
    pub cruise_time: f64,
}

impl Trapezoid {
    /// The fastest rest-to-rest profile over `length` under `max_velocity`
    /// and `max_acceleration` (both > 0).
    pub fn new(length: f64, max_velocity: f64, max_acceleration: f64) -> Trapezoid {
        let length = length.max(0.0);
        // Distance to reach max_velocity and stop again.
        let ramp_distance = max_velocity * max_velocity / max_acceleration;
        let peak_velocity = if ramp_distance > length {
            (max_acceleration * length).sqrt()
        } else {
            max_velocity
        };
        let ramp_time = if peak_velocity > 0.0 {
            peak_velocity / max_acceleration
        } else {
            0.0
        };
        let cruise_time = if peak_velocity > 0.0 {
            ((length - peak_velocity * ramp_time) / peak_velocity).max(0.0)
        } else {
            0.0
        };
        Trapezoid {
            length,
            peak_velocity,
            acceleration: max_acceleration,
            ramp_time,
            cruise_time,
        }
    }

    /// A profile that stays at rest for `seconds` (a dwell).
    pub fn rest(seconds: f64) -> Trapezoid {
        Trapezoid {
            length: 0.0,
            peak_velocity: 0.0,
            acceleration: 0.0,
            ramp_time: 0.0,
            cruise_time: seconds.max(0.0),
        }
    }

    /// Total duration in seconds.
    pub fn duration(&self) -> f64 {
        2.0 * self.ramp_time + self.cruise_time
    }

    /// Distance travelled at time `t` (clamped to the profile).
    pub fn distance_at(&self, t: f64) -> f64 {
        if self.length == 0.0 {
            return 0.0;
        }
        let (a, v, tr) = (self.acceleration, self.peak_velocity, self.ramp_time);
        let t = t.clamp(0.0, self.duration());
        let s = if t < tr {
            0.5 * a * t * t
        } else if t < tr + self.cruise_time {
            0.5 * v * tr + v * (t - tr)
        } else {
            let td = self.duration() - t;
            self.length - 0.5 * a * td * td
        };
        s.clamp(0.0, self.length)
    }

    /// Speed at time `t`.
    pub fn velocity_at(&self, t: f64) -> f64 {
        let tr = self.ramp_time;
        if t <= 0.0 || t >= self.duration() || self.length == 0.0 {
            0.0
        } else if t < tr {
            self.acceleration * t
        } else if t < tr + self.cruise_time {
            self.peak_velocity
        } else {
            self.acceleration * (self.duration() - t)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_move_cruises_at_max_velocity() {
        // 100 mm at 50 mm/s, 500 mm/s²: ramps of 0.1 s covering 2.5 mm each,
        // 95 mm cruise taking 1.9 s.
        let p = Trapezoid::new(100.0, 50.0, 500.0);
        assert!((p.ramp_time - 0.1).abs() < 1e-12);
        assert!((p.duration() - 2.1).abs() < 1e-12);
        assert!((p.distance_at(0.1) - 2.5).abs() < 1e-12);
        assert!((p.distance_at(1.05) - 50.0).abs() < 1e-9);
        assert_eq!(p.distance_at(10.0), 100.0);
    }

    #[test]
    fn short_move_is_a_triangle() {
        // 1 mm at 500 mm/s²: peak sqrt(500) mm/s, two ramps of 1/sqrt(500) s.
        let p = Trapezoid::new(1.0, 50.0, 500.0);
        assert!((p.peak_velocity - 500f64.sqrt()).abs() < 1e-12);
        assert!((p.duration() - 2.0 / 500f64.sqrt()).abs() < 1e-12);
        assert!((p.distance_at(p.ramp_time) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn distance_is_monotonic_and_velocity_matches_its_derivative() {
        let p = Trapezoid::new(7.0, 20.0, 300.0);
        let dt = 1e-5;
        let mut last = 0.0;
        let mut t = 0.0;
        while t < p.duration() {
            let s = p.distance_at(t);
            assert!(s >= last);
            let numeric = (p.distance_at(t + dt) - p.distance_at(t - dt)) / (2.0 * dt);
            assert!(
                (numeric - p.velocity_at(t)).abs() < 300.0 * dt * 2.0,
                "t={t}"
            );
            last = s;
            t += 0.0007;
        }
    }
}
