//! The simulator as a module of the runtime: on the lockstep host it steps the world at the
//! sensor period, before the robots' modules that run at the same instant read their platforms.

use std::time::Duration;

use strata_runtime::{Context, GraphBuilder, Module, ModuleError, ModuleId, Output, Time, Trigger};

use crate::platform::SimHandle;
use crate::truth::GroundTruth;

/// The lockstep host runs lower priorities first at one instant: the world moves before any
/// robot reads it.
pub const SIMULATOR_PRIORITY: i32 = -100;

/// Steps the simulation periodically and publishes ground truth.
#[derive(Debug)]
pub struct SimulatorModule {
    sim: SimHandle,
    ground_truth: Output<GroundTruth>,
    truth_period: Duration,
    next_truth: Time,
    published_events: usize,
}

impl Module for SimulatorModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let truth = {
            let mut sim = self.sim.lock();
            sim.advance_to(now);
            if now >= self.next_truth {
                // On the schedule, not `period` after each publication: the sensor period does
                // not divide the publication period.
                self.next_truth += self.truth_period;
                if self.next_truth <= now {
                    self.next_truth = now + self.truth_period;
                }
                let mut truth = sim.snapshot();
                truth.events = sim.events_since(self.published_events).to_vec();
                self.published_events += truth.events.len();
                Some(truth)
            } else {
                None
            }
        };
        if let Some(truth) = truth {
            ctx.send(self.ground_truth, truth);
        }
        Ok(())
    }
}

/// What [`add_simulator`] added.
#[derive(Clone, Copy, Debug)]
pub struct SimulatorPorts {
    pub module: ModuleId,
    /// Ground truth at `timing.ground_truth_period`, with the events since the previous one.
    /// Leave it unconnected if nothing logs it.
    pub ground_truth: Output<GroundTruth>,
}

/// Adds the simulator module (named `simulator`), triggered at the simulation's sensor period
/// with priority [`SIMULATOR_PRIORITY`]. Robot modules read their `SimPlatform` in their own
/// cycles.
pub fn add_simulator(graph: &mut GraphBuilder, sim: SimHandle) -> SimulatorPorts {
    let (period, truth_period) = {
        let world = sim.lock();
        let timing = &world.config().timing;
        (
            Duration::from_nanos((timing.sensor_period * 1e9).round().max(1.0) as u64),
            Duration::from_nanos((timing.ground_truth_period * 1e9).round().max(1.0) as u64),
        )
    };
    let mut id = ModuleId(0);
    let ground_truth = graph.add("simulator", |p| {
        id = p.id();
        p.trigger(Trigger::every(period));
        p.priority(SIMULATOR_PRIORITY);
        let ground_truth = p.output::<GroundTruth>("ground_truth");
        let module = SimulatorModule {
            sim,
            ground_truth,
            truth_period,
            next_truth: Time::ZERO,
            published_events: 0,
        };
        (module, ground_truth)
    });
    SimulatorPorts { module: id, ground_truth }
}
