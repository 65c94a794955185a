//! The simulator as a module of the runtime, and the platform of the robots it simulates: each
//! step it applies the orders they sent since the previous one, moves the world, and publishes
//! each robot's sensor frame and motion feedback. The robots' perception and actuation are
//! connected to it like to any platform's edge (`strata_robot::edge::PlatformPorts`), so its
//! place before them is an edge of the graph.

use std::time::Duration;

use strata_robot::edge::{PlatformPorts, write_orders};
use strata_runtime::{
    Context, GraphBuilder, Module, ModuleError, ModuleId, Output, PortName, Time, Trigger,
};

use crate::platform::SimHandle;
use crate::truth::{GroundTruth, RobotId};

/// The lockstep host runs lower priorities first at one instant: the world moves before the
/// robots' links read it (`SimTeamLink`, `SimGameControllerLink`), and before any robot that
/// reads it as a platform object (`SimPlatform`) rather than through the simulator's ports.
pub const SIMULATOR_PRIORITY: i32 = -100;

/// Steps the simulation periodically, serves its robots and publishes ground truth.
#[derive(Debug)]
pub struct SimulatorModule {
    sim: SimHandle,
    robots: Vec<(RobotId, PlatformPorts)>,
    ground_truth: Output<GroundTruth>,
    truth_period: Duration,
    next_truth: Time,
    published_events: usize,
}

impl Module for SimulatorModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let mut sim = self.sim.lock();
        // Orders take effect from the next step, as on the platform object.
        for (robot, ports) in &self.robots {
            write_orders(ctx, ports.orders, ports.refusals, |orders| {
                sim.apply_orders(*robot, orders)
            })?;
        }
        sim.advance_to(now);
        for (robot, ports) in &self.robots {
            if let Some(frame) = sim.take_sensor_frame(*robot)? {
                let stamp = frame.stamp;
                ctx.send_stamped(ports.frames, frame, stamp);
            }
            let motion = sim.read_motion(*robot)?;
            ctx.send_stamped(ports.motion, motion, motion.stamp);
        }
        let truth = if now >= self.next_truth {
            // On the schedule, not `period` after each publication: the sensor period does not
            // divide the publication period.
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
        };
        drop(sim);
        if let Some(truth) = truth {
            ctx.send(self.ground_truth, truth);
        }
        Ok(())
    }
}

/// What [`add_simulator`] added.
#[derive(Clone, Debug)]
pub struct SimulatorPorts {
    pub module: ModuleId,
    /// Ground truth at `timing.ground_truth_period`, with the events since the previous one.
    /// Leave it unconnected if nothing logs it.
    pub ground_truth: Output<GroundTruth>,
    /// The platform of each robot served through the graph, in the order they were given.
    pub robots: Vec<(RobotId, PlatformPorts)>,
}

impl SimulatorPorts {
    pub const GROUND_TRUTH: PortName<GroundTruth> = PortName::new("ground_truth");

    /// The platform of `robot`, if the simulator serves it through the graph.
    pub fn platform(&self, robot: RobotId) -> Option<PlatformPorts> {
        self.robots.iter().find(|(id, _)| *id == robot).map(|(_, ports)| ports.clone())
    }
}

/// Adds the simulator module (named `simulator`), triggered at the simulation's sensor period
/// with priority [`SIMULATOR_PRIORITY`], serving `robots` through the graph
/// ([`SimulatorPorts::platform`]; connect each robot to its ports or leave them). Robots not
/// listed read a `SimPlatform` of their own.
pub fn add_simulator(
    graph: &mut GraphBuilder,
    sim: SimHandle,
    robots: &[RobotId],
) -> SimulatorPorts {
    let (period, truth_period, info) = {
        let world = sim.lock();
        let timing = &world.config().timing;
        (
            Duration::from_nanos((timing.sensor_period * 1e9).round().max(1.0) as u64),
            Duration::from_nanos((timing.ground_truth_period * 1e9).round().max(1.0) as u64),
            world.platform_info(),
        )
    };
    let mut id = ModuleId(0);
    let (ground_truth, served) = graph.add("simulator", |p| {
        id = p.id();
        p.trigger(Trigger::every(period));
        p.priority(SIMULATOR_PRIORITY);
        let ground_truth = p.output(SimulatorPorts::GROUND_TRUTH);
        let served: Vec<(RobotId, PlatformPorts)> = robots
            .iter()
            .map(|&robot| (robot, PlatformPorts::serve(p, &robot_port_prefix(robot), info.clone())))
            .collect();
        let module = SimulatorModule {
            sim,
            robots: served.clone(),
            ground_truth,
            truth_period,
            next_truth: Time::ZERO,
            published_events: 0,
        };
        (module, (ground_truth, served))
    });
    SimulatorPorts { module: id, ground_truth, robots: served }
}

/// The prefix of a robot's ports on the simulator module: `home_3` for home player 3 (its
/// topics in a log are `simulator/home_3/frames`, ...).
pub fn robot_port_prefix(robot: RobotId) -> String {
    let team = if robot.team == 0 { "home" } else { "away" };
    format!("{team}_{}", robot.player)
}
