//! The simulator alone: physics and sensor generation for 14 robots at the 83 Hz sensor rate
//! with 30 Hz camera images, as a real-time factor (simulated seconds per second; real time is
//! 1x). Robots walk, turn and scan with their heads; the ball rolls; the referee runs. A last
//! variant adds what 14 robot platforms cost when they read every sensor frame and the motion
//! state at every step.
//!
//! Run: `cargo bench -p strata-sim --bench sim`
//! (`STRATA_SIM_BENCH_SECONDS` shortens the runs, `STRATA_SIM_BENCH_ONLY=<label prefix>`
//! selects variants — a whole label selects only that one —, `STRATA_SIM_BENCH_RUNS` sets
//! the number of runs per variant, 5 by default, and `STRATA_SIM_BENCH_SEED` the world's seed
//! instead of the default configuration's.)

use std::hint::black_box;
use std::time::{Duration, Instant};

use strata_robot::Velocity;
use strata_robot::platform::{ActuatorOrders, BodyOrder, HeadAngles, HeadOrder};
use strata_sim::{GameState, NoiseConfig, NoiseLevel, SimConfig, Simulation};

fn world(noise: NoiseLevel, camera: bool) -> Simulation {
    let mut config = SimConfig { noise: NoiseConfig::level(noise), ..SimConfig::default() };
    if let Some(seed) = std::env::var("STRATA_SIM_BENCH_SEED").ok().and_then(|s| s.parse().ok()) {
        config.seed = seed;
    }
    if !camera {
        // Effectively never: isolates the cost of everything else.
        config.timing.camera_period = 1e6;
    }
    let mut sim = Simulation::new(config).expect("the default config is valid");
    sim.set_game_state(GameState::Playing);
    sim
}

/// Gives every robot a new walk and head order, varying with time and robot.
fn command(sim: &mut Simulation, t: f64) {
    let ids: Vec<_> = sim.robot_ids().collect();
    for (i, id) in ids.into_iter().enumerate() {
        let phase = t * 0.7 + i as f64;
        let orders = ActuatorOrders {
            head: Some(HeadOrder {
                target: HeadAngles { yaw: 1.0 * (phase * 1.3).sin(), pitch: 0.2 },
                max_speed: 2.0,
            }),
            body: Some(BodyOrder::Walk {
                velocity: Velocity::new(0.2, 0.05 * phase.cos(), 0.6 * phase.sin()),
            }),
        };
        let _ = sim.apply_orders(id, &orders);
    }
}

/// CPU time this thread has run, from Linux's scheduler statistics: on a shared machine wall
/// time depends on other processes. It may be counted in scheduler ticks: runs must be long.
fn thread_cpu_time() -> Option<Duration> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanos = text.split_whitespace().next()?.parse::<u64>().ok()?;
    Some(Duration::from_nanos(nanos))
}

/// What a run cost: CPU time (wall time where the platform does not report it) and wall time.
struct Cost {
    cpu: Duration,
    wall: Duration,
}

/// Runs `seconds` of simulated time; returns its cost and the detections counted.
fn run(noise: NoiseLevel, camera: bool, readers: bool, seconds: f64) -> (Cost, u64) {
    let mut sim = world(noise, camera);
    let tick = Duration::from_millis(12);
    let steps = (seconds / 0.012).round() as u64;
    let ids: Vec<_> = sim.robot_ids().collect();
    let mut detections = 0u64;
    let start = Instant::now();
    let cpu_start = thread_cpu_time();
    for step in 0..steps {
        if step % 10 == 0 {
            command(&mut sim, step as f64 * 0.012);
        }
        sim.step(tick);
        if readers || step % 100 == 0 {
            // What platforms do with each frame: take it (and recycle its buffer), read the
            // motion. Without readers, only a sample is taken, to count detections.
            for &id in &ids {
                if let Ok(Some(frame)) = sim.take_sensor_frame(id) {
                    detections += frame.camera.as_ref().map_or(0, |c| c.detections.len() as u64);
                    sim.recycle(id, black_box(frame));
                    let _ = black_box(sim.read_motion(id));
                }
            }
        }
    }
    let wall = start.elapsed();
    let cpu = match (cpu_start, thread_cpu_time()) {
        (Some(a), Some(b)) => b.saturating_sub(a),
        _ => wall,
    };
    (Cost { cpu, wall }, detections)
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn main() {
    let quick = !std::env::args().any(|a| a == "--bench");
    if quick {
        let (_, detections) = run(NoiseLevel::Default, true, true, 2.0);
        assert!(detections > 0);
        println!("sim: smoke run ok");
        return;
    }
    let seconds = std::env::var("STRATA_SIM_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(600.0);
    let only = std::env::var("STRATA_SIM_BENCH_ONLY").unwrap_or_default();
    let runs = std::env::var("STRATA_SIM_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(5);
    println!(
        "Simulator real-time factor: 14 robots, 83 Hz sensors, 30 Hz camera, {seconds} s simulated per run, {runs} runs"
    );
    println!(
        "(baseline: real time = 1x; target >= 5000x on one core; median over runs of the thread's CPU time, and the best wall time)"
    );
    let variants = [
        ("alone, default noise", NoiseLevel::Default, true, false),
        ("alone, no noise", NoiseLevel::None, true, false),
        ("alone, high noise", NoiseLevel::High, true, false),
        ("alone, default noise, no camera", NoiseLevel::Default, false, false),
        ("with 14 readers, default noise", NoiseLevel::Default, true, true),
    ];
    let exact = variants.iter().any(|v| v.0 == only);
    for (label, noise, camera, readers) in variants {
        if !label.starts_with(only.as_str()) || (exact && label != only) {
            continue;
        }
        let mut cpu = Vec::new();
        let mut wall = Vec::new();
        let mut detections = 0;
        for _ in 0..runs {
            let (cost, d) = run(noise, camera, readers, seconds);
            detections = d;
            cpu.push(seconds / cost.cpu.as_secs_f64());
            wall.push(seconds / cost.wall.as_secs_f64());
        }
        let cpu = median(cpu);
        let best = wall.iter().copied().fold(0.0, f64::max);
        println!(
            "  {label:<32} {cpu:>6.0}x (CPU) {best:>6.0}x (best wall)  {:>5.2} us per 12 ms step  ({detections} detections counted)",
            12.0e3 / cpu,
        );
    }
}
