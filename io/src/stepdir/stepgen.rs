//! Step generation: from joint setpoints to compressed step runs.
//!
//! **The trajectory.** The servo gives one position setpoint per period.
//! Setpoint `k` is assigned an MCU time `T_k` (see the link's time base);
//! between `T_{k−1}` and `T_k` the joint moves linearly from `p_{k−1}` to
//! `p_k` (constant velocity over the period, the same model the sim
//! backend's finite-difference velocity uses).
//!
//! **The steps.** With `u = p · steps_per_mm` the position in steps, the
//! step counter is `floor(u + 0.5)`: the joint takes a step at the instant
//! `u` crosses a half-integer, so the motor is never more than half a step
//! from the trajectory. The exact crossing instant is rounded to the
//! nearest MCU tick.
//!
//! **Compression.** Runs of steps are sent as `(first, interval, count,
//! add)` ([`StepRun`]). [`next_run`] only admits a run if every decoded
//! step time is within `tol` ticks of its exact (rounded) time, checked
//! step by step in the same integer arithmetic the MCU uses. So every edge
//! the MCU makes is within `tol + ½` tick of the trajectory's crossing:
//! that is the bound, by construction, whatever the heuristic that picks
//! the run length.

use super::protocol::{ChannelTiming, StepRun};

/// One step: MCU time (ticks) and direction (true: counting up).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// Exact crossing time rounded to the nearest tick.
    pub time: u64,
    /// Direction.
    pub forward: bool,
}

/// The step counter at position `u` (in steps): `floor(u + 0.5)`.
pub fn count_at(u: f64) -> i64 {
    (u + 0.5).floor() as i64
}

/// The steps of the linear move from `u0` at `t0` to `u1` at `t1` (positions
/// in steps, times in ticks, `t1 > t0`), starting from counter `count`
/// (which must equal `count_at(u0)`). Calls `emit` for each step in time
/// order and returns the new counter.
pub fn crossings(
    count: i64,
    (t0, u0): (f64, f64),
    (t1, u1): (f64, f64),
    mut emit: impl FnMut(Step),
) -> i64 {
    let target = count_at(u1);
    let mut c = count;
    let at = |x: f64| -> u64 {
        let t = t0 + (x - u0) / (u1 - u0) * (t1 - t0);
        t.round().max(0.0) as u64
    };
    while c < target {
        // Counter c → c + 1 when u reaches c + ½.
        emit(Step {
            time: at(c as f64 + 0.5),
            forward: true,
        });
        c += 1;
    }
    while c > target {
        // Counter c → c − 1 when u drops below c − ½.
        emit(Step {
            time: at(c as f64 - 0.5),
            forward: false,
        });
        c -= 1;
    }
    c
}

/// The longest run starting at `times[0]` whose decoded times are all
/// within `tol` ticks of `times` (a strictly increasing list of step
/// times in one direction). Always returns a run of at least one step.
pub fn next_run(times: &[u64], tol: u64) -> StepRun {
    let first = times[0];
    let mut best = StepRun {
        first,
        interval: 0,
        count: 1,
        add: 0,
    };
    let limit = times.len().min(u16::MAX as usize);
    if limit < 2 {
        return best;
    }
    // Candidate `add`s come from second differences over ever wider
    // windows of the run found so far; each is tried with its neighbours.
    let second_diff = |h: usize| -> i64 {
        let h = h.max(1);
        if 2 * h >= limit {
            return 0;
        }
        let d = times[2 * h] as i64 - 2 * times[h] as i64 + first as i64;
        let hh = (h * h) as i64;
        // Nearest integer to d / h².
        (2 * d + hh).div_euclid(2 * hh)
    };
    let mut tried: Vec<i64> = Vec::new();
    let mut candidates = vec![0i64, second_diff(1)];
    while let Some(add) = candidates.pop() {
        if tried.contains(&add) || tried.len() >= 16 {
            continue;
        }
        tried.push(add);
        if let Some(run) = longest_with_add(times, limit, tol, add) {
            if run.count > best.count {
                best = run;
                let a = second_diff(best.count as usize / 2);
                candidates.extend([a - 1, a + 1, a]);
            }
        }
    }
    best
}

/// The longest run from `times[0]` with this `add`, if it has two or more
/// steps. The feasible intervals for the first `n` steps form an integer
/// range (one linear constraint pair per step); it is narrowed step by step
/// and the run ends where it would become empty.
fn longest_with_add(times: &[u64], limit: usize, tol: u64, add: i64) -> Option<StepRun> {
    if add < i32::MIN as i64 || add > i32::MAX as i64 {
        return None;
    }
    let first = times[0] as i128;
    let (tol, add) = (tol as i128, add as i128);
    let mut lo: i128 = 1;
    let mut hi: i128 = u32::MAX as i128;
    let mut n = 1;
    for (i, &t) in times.iter().enumerate().take(limit).skip(1) {
        let i = i as i128;
        let tri = add * i * (i - 1) / 2;
        // |first + i·I + tri − t| ≤ tol  ⇔  I ∈ [(t − tol − first − tri)/i, (t + tol − first − tri)/i]
        let l = (t as i128 - tol - first - tri).div_euclid(i)
            + ((t as i128 - tol - first - tri).rem_euclid(i) != 0) as i128;
        let h = (t as i128 + tol - first - tri).div_euclid(i);
        // Every gap stays positive: I + (i − 1)·add ≥ 1.
        let g = 1 - (i - 1) * add;
        let (nlo, nhi) = (lo.max(l).max(g), hi.min(h));
        if nlo > nhi {
            break;
        }
        lo = nlo;
        hi = nhi;
        n = i as usize + 1;
    }
    (n >= 2).then(|| StepRun {
        first: times[0],
        interval: lo as u32,
        count: n as u16,
        add: add as i32,
    })
}

/// Why a step schedule cannot be sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScheduleError {
    /// Two steps in one direction closer than pulse + space.
    TooFast,
    /// A reversal closer than pulse + direction hold + setup.
    ReversalTooFast,
}

impl ScheduleError {
    /// The error as a fault reason.
    pub fn reason(self) -> &'static str {
        match self {
            ScheduleError::TooFast => {
                "step rate above the drive's limit (steps closer than min_pulse_us + min_space_us)"
            }
            ScheduleError::ReversalTooFast => {
                "direction reversal faster than dir_hold_us + dir_setup_us allow"
            }
        }
    }
}

/// The last step sent on a channel, for checking the next one's spacing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LastStep {
    /// Time of the last step edge, if any step was made.
    pub time: Option<u64>,
    /// Its direction.
    pub forward: bool,
}

/// Check a run against the channel's timing, following `last`; updates
/// `last` on success.
pub fn check_run(
    last: &mut LastStep,
    forward: bool,
    run: &StepRun,
    timing: &ChannelTiming,
) -> Result<(), ScheduleError> {
    if let Some(prev) = last.time {
        let need = if forward == last.forward {
            timing.min_interval()
        } else {
            timing.min_reversal()
        };
        if run.first < prev + need {
            return Err(if forward == last.forward {
                ScheduleError::TooFast
            } else {
                ScheduleError::ReversalTooFast
            });
        }
    }
    if run.count > 1 {
        // Gaps change linearly along a run, so the smallest is at an end.
        let n = run.count as i64 - 1;
        let g0 = run.interval as i64;
        let g1 = g0 + (n - 1) * run.add as i64;
        if g0.min(g1) < timing.min_interval() as i64 {
            return Err(ScheduleError::TooFast);
        }
    }
    last.time = run.last();
    last.forward = forward;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact crossing times of u(t) = a t² (t ≥ 0, in ticks), rounded.
    fn accelerating(a: f64, n: usize, t0: u64) -> Vec<u64> {
        (0..n)
            .map(|c| t0 + (((c as f64 + 0.5) / a).sqrt()).round() as u64)
            .collect()
    }

    fn check_within(times: &[u64], run: &StepRun, tol: u64) {
        for (i, t) in run.times().enumerate() {
            let t = t.expect("well-formed run");
            assert!(
                t.abs_diff(times[i]) <= tol,
                "step {i}: {t} vs exact {}",
                times[i]
            );
        }
    }

    #[test]
    fn constant_rate_compresses_to_one_run() {
        // 1000 steps every 123.4 ticks (rounded exact times). The interval
        // is a whole number of ticks, so with the first step exact the
        // run lasts while 0.4 ticks per step of drift stays within the
        // tolerance: 19 / 0.4 = 47.5 more steps with interval 123, give or
        // take the ±½ tick rounding of the exact times.
        let times: Vec<u64> = (0..1000)
            .map(|i| (1e6 + i as f64 * 123.4).round() as u64)
            .collect();
        let run = next_run(&times, 19);
        check_within(&times, &run, 19);
        assert_eq!(run.interval, 123);
        assert!((48..=49).contains(&run.count), "{} steps", run.count);
        // Exactly periodic steps are one run, whatever the length.
        let exact: Vec<u64> = (0..5000).map(|i| 77 + 250 * i).collect();
        let run = next_run(&exact, 0);
        assert_eq!((run.count, run.interval, run.add), (5000, 250, 0));
    }

    #[test]
    fn every_run_is_within_tolerance_and_covers_all_steps() {
        // Acceleration from rest: intervals shrink like 1/sqrt(t).
        let times = accelerating(1e-6, 3000, 500);
        for tol in [0u64, 2, 10, 45] {
            let mut at = 0;
            let mut runs = 0;
            while at < times.len() {
                let run = next_run(&times[at..], tol);
                check_within(&times[at..], &run, tol);
                at += run.count as usize;
                runs += 1;
            }
            assert_eq!(at, times.len());
            if tol == 0 {
                assert!(runs > 1);
            }
            if tol >= 10 {
                assert!(runs * 10 < times.len(), "tol {tol}: {runs} runs");
            }
        }
    }

    #[test]
    fn crossings_are_at_half_steps() {
        // 0 → 3.2 steps over 1000 ticks: crossings at 0.5, 1.5, 2.5.
        let mut steps = Vec::new();
        let c = crossings(0, (0.0, 0.0), (1000.0, 3.2), |s| steps.push(s));
        assert_eq!(c, 3);
        let times: Vec<u64> = steps.iter().map(|s| s.time).collect();
        assert_eq!(times, vec![156, 469, 781]);
        assert!(steps.iter().all(|s| s.forward));
        // Back down to -0.5 exactly: counter floor(-0.5 + 0.5) = 0, so the
        // crossings are 2.5, 1.5, 0.5 (counter 3 → 0).
        steps.clear();
        let c = crossings(3, (1000.0, 3.2), (2000.0, -0.5), |s| steps.push(s));
        assert_eq!(c, 0);
        assert_eq!(steps.len(), 3);
        assert!(steps.iter().all(|s| !s.forward));
    }

    #[test]
    fn spacing_limits_are_enforced() {
        let timing = ChannelTiming {
            pulse: 20,
            space: 20,
            dir_setup: 10,
            dir_hold: 10,
        };
        let mut last = LastStep::default();
        let run = |first, interval, count| StepRun {
            first,
            interval,
            count,
            add: 0,
        };
        check_run(&mut last, true, &run(100, 40, 3), &timing).unwrap();
        assert_eq!(last.time, Some(180));
        assert_eq!(
            check_run(&mut last, true, &run(210, 40, 1), &timing),
            Err(ScheduleError::TooFast)
        );
        assert_eq!(
            check_run(&mut last, false, &run(219, 40, 1), &timing),
            Err(ScheduleError::ReversalTooFast)
        );
        check_run(&mut last, false, &run(220, 40, 1), &timing).unwrap();
        assert_eq!(
            check_run(&mut last, false, &run(1000, 39, 2), &timing),
            Err(ScheduleError::TooFast)
        );
    }
}
