//! Time inverse and forward kinematics of every embedded machine.
//!
//! Run with `cargo bench -p kerf-machines`. Each machine is timed over a
//! set of poses spread over its axis travel, so the figures include the
//! branches a real path takes; forward kinematics are seeded with the
//! previous pose of the set, as the servo tick seeds them with the last
//! one. Budgets: inverse under 1 µs per call, rfmt5 forward under 20 µs.

use std::hint::black_box;
use std::time::Instant;

use kerf_interp::Position;
use kerf_motion::Kinematics;

/// Calls per timing run; several runs are made and the fastest kept, which
/// is the figure least disturbed by other work on the machine.
const CALLS: usize = 200_000;
const RUNS: usize = 5;

/// Poses on a grid over the machine's axis travel (4 steps per axis).
fn poses(kins: &dyn Kinematics) -> Vec<Position> {
    let axes = kins.axes();
    let mut out = vec![Position::ZERO];
    for spec in axes {
        let mut next = Vec::new();
        for p in &out {
            for k in 0..4 {
                let mut q = *p;
                let f = (k as f64 + 0.5) / 4.0;
                q.set(
                    spec.axis,
                    spec.limits.min + f * (spec.limits.max - spec.limits.min),
                );
                next.push(q);
            }
        }
        out = next;
    }
    out.retain(|p| kins.check_pose(p).is_ok());
    out
}

/// Fastest mean time per call of `f` over `RUNS` runs, ns.
fn time(mut f: impl FnMut(usize)) -> f64 {
    (0..RUNS)
        .map(|_| {
            let start = Instant::now();
            for i in 0..CALLS {
                f(i);
            }
            start.elapsed().as_nanos() as f64 / CALLS as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    println!(
        "{:<10} {:>6} {:>14} {:>14}   budget: inverse < 1000 ns, rfmt5 forward < 20000 ns",
        "machine", "poses", "inverse ns", "forward ns"
    );
    for (name, _) in kerf_machines::EMBEDDED {
        let machine = kerf_machines::load(name).expect("embedded machine loads");
        let kins = &*machine.kinematics;
        let poses = poses(kins);
        let n = kins.joints().len();
        let joints: Vec<Vec<f64>> = poses
            .iter()
            .map(|p| {
                let mut q = vec![0.0; n];
                kins.inverse(p, &mut q).expect("pose inside travel");
                q
            })
            .collect();
        let mut q = vec![0.0; n];
        let inverse = time(|i| {
            let p = &poses[i % poses.len()];
            black_box(kins.inverse(black_box(p), &mut q)).expect("inverse");
        });
        let forward = time(|i| {
            let k = i % poses.len();
            let seed = &poses[(k + poses.len() - 1) % poses.len()];
            black_box(kins.forward(black_box(&joints[k]), seed)).expect("forward");
        });
        println!(
            "{:<10} {:>6} {:>14.1} {:>14.1}",
            name,
            poses.len(),
            inverse,
            forward
        );
    }
}
