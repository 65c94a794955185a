//! Cost of the T1 walking policy per 20 ms control step: the network alone, and one whole
//! `WalkPolicy::step` (smoothing, observation, network, clipping, targets), each printed as a
//! share of the control period it has to fit in.
//!
//! Run: `cargo bench -p strata-rcssmj --bench policy`

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::Criterion;
use strata_rcssmj::policy::{
    LEG_JOINTS, LegState, OBSERVATION_LEN, WalkCommand, WalkNetwork, WalkPolicy,
};

/// A slightly tilted, moving robot near its default pose, varying with `k` so no two steps see
/// the same input.
fn state(policy: &WalkPolicy, k: u32) -> LegState {
    let defaults = policy.config().default_targets();
    let wobble = (f64::from(k) * 0.37).sin();
    LegState {
        torso_orientation: [0.998, 0.02 * wobble, 0.05, 0.01],
        torso_angular_velocity: [0.1 * wobble, -0.2, 0.05],
        joint_positions: LEG_JOINTS.map(|i| defaults[i].q + 0.05 * wobble),
        joint_velocities: std::array::from_fn(|i| (i as f64 - 6.0) * 0.3 * wobble),
    }
}

/// Median time per call of `f`, in nanoseconds, over the samples criterion took.
fn median(samples: &mut [f64]) -> f64 {
    samples.sort_by(f64::total_cmp);
    samples.get(samples.len() / 2).copied().unwrap_or(f64::NAN)
}

fn time_per_call(criterion: &mut Criterion, name: &str, mut f: impl FnMut(u32)) -> f64 {
    let mut per_call = Vec::new();
    criterion.bench_function(name, |b| {
        b.iter_custom(|iters| {
            let start = Instant::now();
            for k in 0..iters {
                f(k as u32);
            }
            let wall = start.elapsed();
            per_call.push(wall.as_nanos() as f64 / iters.max(1) as f64);
            wall
        })
    });
    median(&mut per_call)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut policy = WalkPolicy::shipped()?;
    let network = WalkNetwork::shipped()?;
    let period = Duration::from_secs_f64(policy.config().policy_period());
    let walk = WalkCommand { vx: 0.5, vy: 0.0, yaw_rate: 0.2 };
    let states: Vec<LegState> = (0..64).map(|k| state(&policy, k)).collect();
    let observation: [f32; OBSERVATION_LEN] = std::array::from_fn(|i| (i as f32 * 0.1).sin());

    if !std::env::args().any(|a| a == "--bench") {
        for s in &states {
            let targets = policy.step(s, walk);
            if targets.iter().any(|t| !t.q.is_finite()) {
                return Err("the policy produced a non-finite target".into());
            }
        }
        println!("policy: smoke run ok");
        return Ok(());
    }

    let mut criterion = Criterion::default().configure_from_args();
    let network_ns = time_per_call(&mut criterion, "T1 walk network forward", |_| {
        black_box(network.forward(black_box(&observation)));
    });
    let step_ns = time_per_call(&mut criterion, "T1 WalkPolicy step", |k| {
        let s = &states[k as usize % states.len()];
        black_box(policy.step(black_box(s), walk));
    });
    let period_ns = period.as_nanos() as f64;
    println!();
    println!("T1 walking policy per control step (median per call; control period {period:?})");
    println!(
        "  network forward:  {:>8.2} us   {:.5} of the period",
        network_ns / 1e3,
        network_ns / period_ns
    );
    println!(
        "  WalkPolicy step:  {:>8.2} us   {:.5} of the period",
        step_ns / 1e3,
        step_ns / period_ns
    );
    Ok(())
}
