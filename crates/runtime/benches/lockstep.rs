//! Overhead of the lockstep host per module cycle, with 100 trivial periodic modules, against a
//! bare discrete-event loop (a binary heap of due times calling a closure) in the same run.
//!
//! Run: `cargo bench -p strata-runtime --bench lockstep`

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::Criterion;
use strata_runtime::{
    Context, GraphBuilder, HostConfig, LockstepHost, Module, ModuleError, Trigger,
};

const MODULES: usize = 100;

struct Trivial(u64);

impl Module for Trivial {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        self.0 = black_box(self.0.wrapping_add(1));
        Ok(())
    }
}

fn host() -> LockstepHost {
    let mut graph = GraphBuilder::new();
    for i in 0..MODULES {
        graph.add(&format!("m{i}"), |p| {
            // Periods from 5 to 15 ms, so events interleave as a robot's modules do.
            p.trigger(Trigger::every(Duration::from_micros(5_000 + 100 * i as u64)));
            (Trivial(0), ())
        });
    }
    LockstepHost::new(graph.build().expect("valid"), HostConfig::default())
}

/// Runs the host for `sim` of simulated time; returns (cycles, wall time).
fn run_host(sim: Duration) -> (u64, Duration) {
    let mut host = host();
    let start = Instant::now();
    host.run_for(sim).expect("runs");
    let elapsed = start.elapsed();
    let cycles = host.stats().modules.iter().map(|m| m.cycles).sum();
    (cycles, elapsed)
}

/// The same schedule without the host: what any discrete-event loop must pay.
fn run_bare(sim: Duration) -> (u64, Duration) {
    let periods: Vec<u64> = (0..MODULES).map(|i| 5_000_000 + 100_000 * i as u64).collect();
    let mut state = vec![0u64; MODULES];
    let mut heap: BinaryHeap<Reverse<(u64, usize)>> =
        (0..MODULES).map(|i| Reverse((0, i))).collect();
    let end = sim.as_nanos() as u64;
    let start = Instant::now();
    let mut cycles = 0;
    while let Some(Reverse((t, i))) = heap.pop() {
        if t > end {
            break;
        }
        state[i] = black_box(state[i].wrapping_add(1));
        cycles += 1;
        heap.push(Reverse((t + periods[i], i)));
    }
    (cycles, start.elapsed())
}

fn main() {
    let quick = !std::env::args().any(|a| a == "--bench");
    let sim = if quick { Duration::from_secs(1) } else { Duration::from_secs(600) };
    if quick {
        let (cycles, _) = run_host(sim);
        assert!(cycles > MODULES as u64 * 60);
        println!("lockstep: smoke run ok");
        return;
    }
    let mut criterion = Criterion::default().configure_from_args().sample_size(10);
    let mut host_ns = Vec::new();
    let mut bare_ns = Vec::new();
    criterion.bench_function("lockstep host, 100 modules, 10 s simulated", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let (cycles, wall) = run_host(Duration::from_secs(10));
                host_ns.push(wall.as_nanos() as f64 / cycles as f64);
                total += wall;
            }
            total
        })
    });
    criterion.bench_function("bare event loop, same schedule", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let (cycles, wall) = run_bare(Duration::from_secs(10));
                bare_ns.push(wall.as_nanos() as f64 / cycles as f64);
                total += wall;
            }
            total
        })
    });
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let host = median(&mut host_ns);
    let bare = median(&mut bare_ns);
    let (cycles, wall) = run_host(sim);
    println!();
    println!("LockstepHost overhead per module cycle ({MODULES} trivial periodic modules)");
    println!("  bare event loop (baseline): {bare:>8.1} ns/cycle   1.00x");
    println!("  lockstep host:              {host:>8.1} ns/cycle   {:.2}x", host / bare);
    println!(
        "  {} s simulated: {cycles} cycles in {:.3} s wall = {:.1} ns/cycle, {:.0}x real time",
        sim.as_secs(),
        wall.as_secs_f64(),
        wall.as_nanos() as f64 / cycles as f64,
        sim.as_secs_f64() / wall.as_secs_f64()
    );
}
