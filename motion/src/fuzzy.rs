//! The outer loop: a Mamdani fuzzy controller that moves the feed override
//! to hold the cutting force at a target (seed `002`, sections II.B.1,
//! II.B.3 and III.C).
//!
//! Once per spindle revolution (at least 10 ms) the controller takes the
//! largest cutting force of that revolution, estimated from the spindle
//! motor current (`F = (I − I0) / k`, seed eq. 6 with the spindle at
//! constant speed), and forms
//!
//! ```text
//! E  = (F_d − F) / F_d                 (seed eq. 5: normalised error)
//! CE = E(k') − E(k'−1)                 (its change since the last revolution)
//! ```
//!
//! Both are scaled into the universe [−1, 1] (`gain_e`, `gain_ce`, then
//! clipped), fuzzified with 7 triangular terms each (NB NM NS ZE PS PM PB,
//! centres −1, −2/3, … 1, half-width 1/3), combined by the rule table
//! [`RULES`] with min for "and" and max for aggregation, and defuzzified
//! by the centroid of the clipped output terms (same 7 triangles). The
//! crisp output `du` in [−1, 1] moves the override:
//! `override += gain_out · du`, kept within `[min_override, max_override]`.
//! Because the controller outputs a change, it acts like a PI controller:
//! `gain_e` sets the integral action, `gain_ce` the proportional action.
//!
//! Plain state and arithmetic: no allocation, real-time safe.

/// Number of linguistic terms per variable.
pub const TERMS: usize = 7;

/// Term names, from negative big to positive big.
pub const TERM_NAMES: [&str; TERMS] = ["NB", "NM", "NS", "ZE", "PS", "PM", "PB"];

/// The rule table: `RULES[e][ce]` is the output term (index into
/// [`TERM_NAMES`]) for error term `e` and change-of-error term `ce`.
///
/// Positive E means the force is below target (feed up); positive CE means
/// the force is falling (feed up). The table is the diagonal (MacVicar-
/// Whelan) one: the output term index is `e + ce − 3`, clipped to NB..PB,
/// so the rule surface is close to `du = e + ce` with saturation — a
/// fuzzy PI controller.
pub const RULES: [[usize; TERMS]; TERMS] = {
    let mut table = [[0; TERMS]; TERMS];
    let mut e = 0;
    while e < TERMS {
        let mut ce = 0;
        while ce < TERMS {
            let sum = e + ce;
            table[e][ce] = if sum < 3 {
                0
            } else if sum - 3 > 6 {
                6
            } else {
                sum - 3
            };
            ce += 1;
        }
        e += 1;
    }
    table
};

/// Points the centroid integral samples the output universe at.
const CENTROID_POINTS: usize = 161;

/// Membership of `x` in term `i` (triangle centred at (i − 3)/3, feet
/// 1/3 either side).
fn membership(i: usize, x: f64) -> f64 {
    let centre = (i as f64 - 3.0) / 3.0;
    (1.0 - (x - centre).abs() * 3.0).max(0.0)
}

/// Memberships of `x` (clipped to [−1, 1]) in every term.
fn fuzzify(x: f64) -> [f64; TERMS] {
    let x = x.clamp(-1.0, 1.0);
    std::array::from_fn(|i| membership(i, x))
}

/// Mamdani inference over [`RULES`]: the crisp output in [−1, 1] for
/// scaled inputs `e` and `ce` (each clipped to [−1, 1]).
pub fn infer(e: f64, ce: f64) -> f64 {
    let (me, mce) = (fuzzify(e), fuzzify(ce));
    // Firing strength of each output term: max over its rules of min(μe, μce).
    let mut strength = [0.0f64; TERMS];
    for (i, &a) in me.iter().enumerate() {
        if a == 0.0 {
            continue;
        }
        for (j, &b) in mce.iter().enumerate() {
            let out = RULES[i][j];
            strength[out] = strength[out].max(a.min(b));
        }
    }
    // Centroid of the union of the clipped output triangles, sampled over
    // their whole support [−4/3, 4/3].
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..CENTROID_POINTS {
        let y = -4.0 / 3.0 + 8.0 / 3.0 * k as f64 / (CENTROID_POINTS - 1) as f64;
        let mut mu = 0.0f64;
        for (t, &s) in strength.iter().enumerate() {
            if s > 0.0 {
                mu = mu.max(s.min(membership(t, y)));
            }
        }
        num += mu * y;
        den += mu;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Settings of the force controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FuzzyConfig {
    /// Scale of E = (F_d − F)/F_d into the universe [−1, 1].
    pub gain_e: f64,
    /// Scale of CE (change of E per step) into the universe.
    pub gain_ce: f64,
    /// Override change per step at full output (1.0 = 100 %).
    pub gain_out: f64,
    /// Lowest override the controller sets (0.1 = 10 %).
    pub min_override: f64,
    /// Highest override the controller sets (1.5 = 150 %).
    pub max_override: f64,
    /// Below this fraction of F_d the tool is taken to cut air: the
    /// override is held, so it does not climb to the maximum before the
    /// tool reaches the material.
    pub engage: f64,
}

impl Default for FuzzyConfig {
    fn default() -> Self {
        FuzzyConfig {
            gain_e: 1.0,
            gain_ce: 1.0,
            gain_out: 0.15,
            min_override: 0.1,
            max_override: 1.5,
            engage: 0.2,
        }
    }
}

impl FuzzyConfig {
    /// The first setting that is out of range, by its TOML key, and why.
    pub fn invalid(&self) -> Option<(&'static str, String)> {
        for (key, v) in [
            ("gain_e", self.gain_e),
            ("gain_ce", self.gain_ce),
            ("gain_out", self.gain_out),
            ("engage", self.engage),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((key, format!("must be a number ≥ 0, got {v}")));
            }
        }
        if !(self.min_override > 0.0 && self.min_override <= 1.0) {
            return Some((
                "min_override",
                format!("must be in (0, 1], got {}", self.min_override),
            ));
        }
        if !(self.max_override >= 1.0 && self.max_override <= 2.0) {
            return Some((
                "max_override",
                format!("must be in [1, 2], got {}", self.max_override),
            ));
        }
        None
    }
}

/// Converts spindle motor current to cutting force: `F = (I − I0)/k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentSensor {
    /// Current with the spindle turning and not cutting, A (friction).
    pub idle_current: f64,
    /// Current per newton of cutting force, A/N.
    pub current_per_newton: f64,
}

impl CurrentSensor {
    /// Cutting force for spindle current `amps`, N.
    pub fn force(&self, amps: f64) -> f64 {
        (amps - self.idle_current) / self.current_per_newton
    }
}

/// Servo ticks per controller step: one spindle revolution at `rpm`, or
/// as many whole revolutions as make at least 10 ms, at servo period `dt`.
pub fn ticks_per_step(rpm: f64, dt: f64) -> u32 {
    let revolution = 60.0 / rpm;
    let revolutions = (0.010 / revolution).ceil().max(1.0);
    ((revolutions * revolution / dt).round() as u32).max(1)
}

/// What a controller step decided (for status and plots).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Step {
    /// Largest force estimated over the step, N.
    pub force: f64,
    /// Normalised error E of the step.
    pub e: f64,
    /// Crisp controller output in [−1, 1] (0 while holding).
    pub output: f64,
    /// Override after the step.
    pub feed_override: f64,
}

/// The force controller, ticked every servo period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceControl {
    config: FuzzyConfig,
    sensor: CurrentSensor,
    ticks_per_step: u32,
    /// Target force F_d, N; `None`: off (override 1).
    target: Option<f64>,
    feed_override: f64,
    /// E of the last step, if it acted.
    last_e: Option<f64>,
    /// Ticks into the current step.
    ticks: u32,
    /// Largest force estimate seen in the current step, N.
    peak: f64,
    /// The machine fed at the commanded rate through every tick of the
    /// current step so far.
    feeding: bool,
    last_step: Step,
}

impl ForceControl {
    /// A controller, off, stepping every `ticks_per_step` servo periods.
    pub fn new(config: FuzzyConfig, sensor: CurrentSensor, ticks_per_step: u32) -> ForceControl {
        ForceControl {
            config,
            sensor,
            ticks_per_step: ticks_per_step.max(1),
            target: None,
            feed_override: 1.0,
            last_e: None,
            ticks: 0,
            peak: f64::NEG_INFINITY,
            feeding: true,
            last_step: Step {
                feed_override: 1.0,
                ..Step::default()
            },
        }
    }

    /// Turn force control on with target `newtons` (> 0), or off (`None`:
    /// the override returns to 1). Changing the target keeps the override.
    pub fn set_target(&mut self, newtons: Option<f64>) {
        let newtons = newtons.filter(|f| f.is_finite() && *f > 0.0);
        if newtons.is_none() {
            self.feed_override = 1.0;
        }
        if self.target.is_none() {
            self.last_e = None;
        }
        self.target = newtons;
    }

    /// Target force, N, while on.
    pub fn target(&self) -> Option<f64> {
        self.target
    }

    /// The override the controller asks for (1 while off).
    pub fn feed_override(&self) -> f64 {
        self.feed_override
    }

    /// The last completed step.
    pub fn last_step(&self) -> Step {
        self.last_step
    }

    /// Servo ticks per step.
    pub fn ticks_per_step(&self) -> u32 {
        self.ticks_per_step
    }

    /// One servo period with spindle current `amps`; `feeding` says the
    /// machine moves at the feed the override asks for (not braking for a
    /// stop, a hold or a corner, not on a rapid). Returns the step if one
    /// completed this tick.
    ///
    /// A step that was not feeding throughout holds the override: its
    /// force fell or rose because the machine changed speed, not because
    /// the material did, and acting on it winds the override up (a stop in
    /// the material raised it one step, up to gain_out, for the restart).
    pub fn tick(&mut self, amps: f64, feeding: bool) -> Option<Step> {
        self.peak = self.peak.max(self.sensor.force(amps));
        self.feeding &= feeding;
        self.ticks += 1;
        if self.ticks < self.ticks_per_step {
            return None;
        }
        let (force, fed) = (self.peak, self.feeding);
        self.ticks = 0;
        self.peak = f64::NEG_INFINITY;
        self.feeding = true;
        let mut step = Step {
            force,
            feed_override: self.feed_override,
            ..Step::default()
        };
        if let Some(target) = self.target {
            let e = (target - force) / target;
            step.e = e;
            if force < self.config.engage * target || !fed {
                // Cutting air, or the machine changed speed: hold, and
                // start afresh at the next step cut at the commanded feed.
                self.last_e = None;
            } else {
                let ce = self.last_e.map_or(0.0, |last| e - last);
                let c = &self.config;
                let du = infer(c.gain_e * e, c.gain_ce * ce);
                self.feed_override =
                    (self.feed_override + c.gain_out * du).clamp(c.min_override, c.max_override);
                self.last_e = Some(e);
                step.output = du;
                step.feed_override = self.feed_override;
            }
        }
        self.last_step = step;
        Some(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rule_table_is_the_clipped_diagonal() {
        assert_eq!(RULES[3][3], 3, "ZE, ZE → ZE");
        assert_eq!(RULES[0][0], 0, "NB, NB → NB");
        assert_eq!(RULES[6][6], 6, "PB, PB → PB");
        assert_eq!(RULES[6][0], 3, "PB, NB → ZE");
        assert_eq!(RULES[4][3], 4, "PS, ZE → PS");
        assert_eq!(RULES[1][2], 0, "NM, NS → NB");
    }

    #[test]
    fn single_rule_outputs_its_term_centre() {
        // Inputs on term centres fire one rule fully; the centroid of a
        // whole symmetric triangle is its centre.
        for e in 0..TERMS {
            for ce in 0..TERMS {
                let x = |i: usize| (i as f64 - 3.0) / 3.0;
                let want = x(RULES[e][ce]);
                let got = infer(x(e), x(ce));
                // The outer triangles are cut at ±4/3 where the sampled
                // support ends: still symmetric, so exact up to rounding.
                assert!((got - want).abs() < 1e-9, "{e},{ce}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn output_is_odd_monotone_and_bounded() {
        let mut last = -2.0;
        for k in -30..=30 {
            let e = k as f64 / 30.0;
            let du = infer(e, 0.0);
            assert!((du + infer(-e, 0.0)).abs() < 1e-12, "odd at {e}");
            assert!(du >= last - 1e-12, "monotone at {e}");
            assert!(du.abs() <= 1.0 + 1e-12);
            last = du;
        }
        // Inputs beyond the universe saturate.
        assert_eq!(infer(5.0, 5.0), infer(1.0, 1.0));
    }

    #[test]
    fn halfway_between_terms_blends_two_rules() {
        // e = 1/6 is 0.5 ZE and 0.5 PS; ce = 0 is ZE: rules ZE and PS fire
        // at 0.5. The clipped union is symmetric about 1/6.
        let du = infer(1.0 / 6.0, 0.0);
        assert!((du - 1.0 / 6.0).abs() < 1e-9, "{du}");
    }

    fn sensor() -> CurrentSensor {
        CurrentSensor {
            idle_current: 2.0,
            current_per_newton: 0.01,
        }
    }

    #[test]
    fn steps_once_per_revolution_on_the_largest_force() {
        assert_eq!(ticks_per_step(1000.0, 0.001), 60);
        // 12000 rpm: 5 ms a revolution, two make the 10 ms minimum.
        assert_eq!(ticks_per_step(12000.0, 0.001), 10);
        let mut fc = ForceControl::new(FuzzyConfig::default(), sensor(), 4);
        fc.set_target(Some(100.0));
        // Forces 50, 80, 60, 70 N: the step sees 80 N, E = 0.2.
        let amps = [2.5, 2.8, 2.6, 2.7];
        let steps: Vec<_> = amps.iter().map(|&a| fc.tick(a, true)).collect();
        assert!(steps[..3].iter().all(Option::is_none));
        let step = steps[3].unwrap();
        assert!((step.force - 80.0).abs() < 1e-9);
        assert!((step.e - 0.2).abs() < 1e-12);
        // First step: CE = 0, so du = infer(0.2, 0) > 0, feed goes up.
        let want = 1.0 + 0.15 * infer(0.2, 0.0);
        assert!((step.feed_override - want).abs() < 1e-12);
        assert!(step.feed_override > 1.0);
    }

    #[test]
    fn holds_in_air_keeps_bounds_and_resets_when_off() {
        let config = FuzzyConfig::default();
        let mut fc = ForceControl::new(config, sensor(), 1);
        fc.set_target(Some(200.0));
        // Idle current: no force, below the engage threshold: hold.
        assert_eq!(fc.tick(2.0, true).unwrap().feed_override, 1.0);
        // Far too much force, many steps: down to the lower bound, no further.
        for _ in 0..100 {
            fc.tick(2.0 + 0.01 * 1000.0, true);
        }
        assert_eq!(fc.feed_override(), config.min_override);
        // Too little (but cutting): up to the upper bound.
        for _ in 0..100 {
            fc.tick(2.0 + 0.01 * 100.0, true);
        }
        assert_eq!(fc.feed_override(), config.max_override);
        fc.set_target(None);
        assert_eq!(fc.feed_override(), 1.0);
        assert_eq!(fc.tick(5.0, true).unwrap().output, 0.0);
    }

    /// A revolution that ends with the machine braking to a stop in the
    /// material sees the force fall with the feed, not with the material:
    /// the same forces that raise the override while feeding (the tail of
    /// the sensor's lag, 229 N against 250) leave it where it was, and the
    /// next step cut at the feed acts afresh (CE = 0).
    #[test]
    fn a_step_the_machine_changed_speed_in_holds_the_override() {
        let (target, per_step) = (250.0, 4);
        let amps = |force: f64| 2.0 + 0.01 * force;
        for feeding_through in [true, false] {
            let mut fc = ForceControl::new(FuzzyConfig::default(), sensor(), per_step);
            fc.set_target(Some(target));
            let steady = (0..per_step).map(|_| fc.tick(amps(target), true)).last();
            let before = steady.unwrap().unwrap().feed_override;
            // Feeding for three ticks, braking in the last one.
            let step = [229.0, 200.0, 150.0, 60.0]
                .iter()
                .enumerate()
                .map(|(k, &f)| fc.tick(amps(f), feeding_through || k < 3))
                .last()
                .unwrap()
                .unwrap();
            if feeding_through {
                let want = before + 0.15 * infer(1.0 - 229.0 / 250.0, 1.0 - 229.0 / 250.0);
                assert!((step.feed_override - want).abs() < 1e-12, "{step:?}");
                assert!(step.feed_override > before + 0.01);
            } else {
                assert_eq!((step.feed_override, step.output), (before, 0.0));
                // Back at the feed: E alone, CE from nothing.
                let next = (0..per_step).map(|_| fc.tick(amps(229.0), true)).last();
                let want = before + 0.15 * infer(1.0 - 229.0 / 250.0, 0.0);
                assert!((next.unwrap().unwrap().feed_override - want).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn regulates_a_proportional_process_with_two_steps_of_delay() {
        // Force proportional to the override, seen two steps late (one
        // revolution of sensor lag, one of sampling); the gain doubles
        // (depth of cut 2 → 4 mm) at step 20. The controller must bring
        // the force back to the target and hold it.
        let target = 250.0;
        let mut fc = ForceControl::new(FuzzyConfig::default(), sensor(), 1);
        fc.set_target(Some(target));
        let mut history = [1.0f64; 2];
        let mut force = 0.0;
        for k in 0..60 {
            let gain = if k < 20 { 250.0 } else { 490.0 };
            force = gain * history[1];
            let step = fc.tick(2.0 + 0.01 * force, true).unwrap();
            history = [step.feed_override, history[0]];
            if k >= 40 {
                assert!((force - target).abs() < 0.02 * target, "k {k}: {force}");
            }
        }
        assert!((force - target).abs() < 1.0, "{force}");
    }
}
