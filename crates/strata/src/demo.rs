//! `strata demo-runtime`: a small module graph that exercises the three connection policies,
//! run on both hosts, with the statistics table each host reports.

use std::time::Duration;

use anyhow::Result;
use clap::Args;
use rand::RngExt;
use strata_runtime::{
    Context, GraphBuilder, HostConfig, Input, LockstepHost, Module, ModuleError, Output, Policy,
    ProcessingTime, ThreadedHost, Trigger,
};

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Seed for the lockstep run.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds on the lockstep host.
    #[arg(long, default_value_t = 60.0)]
    simulated: f64,
    /// Real seconds on the threaded host.
    #[arg(long, default_value_t = 2.0)]
    real: f64,
    /// Print the statistics as JSON.
    #[arg(long)]
    json: bool,
}

/// An inertial sensor at 83 Hz with noise.
struct Imu {
    reading: Output<f64>,
    step: Output<f64>,
}

impl Module for Imu {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let noise: f64 = ctx.rng().random_range(-0.05..0.05);
        ctx.send(self.reading, 9.81 + noise);
        ctx.send(self.step, 0.003);
        Ok(())
    }
}

/// Sees every reading in order (Queue) and the summed motion (Merge).
struct Estimator {
    readings: Input<f64>,
    steps: Input<f64>,
    estimate: Output<(f64, f64)>,
    mean: f64,
    travelled: f64,
}

impl Module for Estimator {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        for reading in ctx.drain(self.readings) {
            self.mean += 0.05 * (reading.value - self.mean);
        }
        if let Some(step) = ctx.take(self.steps) {
            self.travelled += step.value;
        }
        ctx.send(self.estimate, (self.mean, self.travelled));
        Ok(())
    }
}

/// Acts on the newest estimate (Latest).
struct Controller {
    estimate: Input<(f64, f64)>,
}

impl Module for Controller {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let _ = ctx.latest(self.estimate);
        Ok(())
    }
}

fn graph() -> Result<strata_runtime::Graph> {
    let mut graph = GraphBuilder::new();
    let (reading, step) = graph.add("imu", |p| {
        p.trigger(Trigger::every(Duration::from_millis(12)));
        p.processing_time(ProcessingTime::fixed(Duration::from_micros(300)));
        let reading = p.output("reading");
        let step = p.output("odometry_step");
        (Imu { reading, step }, (reading, step))
    });
    let (readings, steps, estimate) = graph.add("estimator", |p| {
        let readings = p.input("readings", Policy::queue(16));
        let steps = p.input("odometry", Policy::merge(|sum: &mut f64, step| *sum += step));
        let estimate = p.output("estimate");
        p.trigger(Trigger::every(Duration::from_millis(30)));
        p.processing_time(ProcessingTime::Uniform {
            min: Duration::from_millis(2),
            max: Duration::from_millis(8),
        });
        let module = Estimator { readings, steps, estimate, mean: 9.81, travelled: 0.0 };
        (module, (readings, steps, estimate))
    });
    let controller = graph.add("controller", |p| {
        let estimate = p.input("estimate", Policy::Latest);
        p.trigger(Trigger::on_any([estimate.into()]));
        (Controller { estimate }, estimate)
    });
    graph.connect(reading, readings);
    graph.connect(step, steps);
    graph.connect(estimate, controller);
    Ok(graph.build()?)
}

pub fn run(args: DemoArgs) -> Result<()> {
    let mut lockstep = LockstepHost::new(graph()?, HostConfig::with_seed(args.seed));
    lockstep.run_for(Duration::from_secs_f64(args.simulated))?;
    let lockstep_stats = lockstep.stats();
    let threaded = ThreadedHost::new(graph()?, HostConfig::with_seed(args.seed)).start()?;
    threaded.stop_on_interrupt()?;
    let threaded_stats = threaded.run_for(Duration::from_secs_f64(args.real))?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "lockstep": lockstep_stats, "threaded": threaded_stats })
        );
        return Ok(());
    }
    println!(
        "Lockstep host: {:.0} s simulated in {:.3} s wall ({:.0}x real time)",
        lockstep_stats.elapsed_s,
        lockstep_stats.wall_s,
        lockstep_stats.elapsed_s / lockstep_stats.wall_s.max(1e-9)
    );
    print!("{}", lockstep_stats.table());
    println!("\nThreaded host: {:.1} s real time", threaded_stats.elapsed_s);
    print!("{}", threaded_stats.table());
    for stats in [&lockstep_stats, &threaded_stats] {
        if let Some(estimator) = stats.module("estimator") {
            for input in &estimator.inputs {
                println!(
                    "  estimator.{:<10} {:<10} received {:>6}, delivered {:>6}, dropped {:>4}, merged {:>6}",
                    input.port,
                    input.policy.to_string(),
                    input.counters.received,
                    input.counters.delivered,
                    input.counters.dropped,
                    input.counters.merged
                );
            }
        }
    }
    Ok(())
}
