//! The simulator as a module of the runtime, and the platform and links of the robots it
//! simulates: each step it applies the orders and takes the messages they sent since the
//! previous one, moves the world, and publishes each robot's sensor frame, motion feedback and
//! what its links received (teammates' messages, GameController packets). The robots connect to
//! it like to any platform's and links' edge (`strata_robot::edge::PlatformPorts`,
//! `strata_robot::edge::LinkPorts`), so its place relative to them is an edge of the graph: a
//! robot reads the world only through what the simulator published, whenever it runs.

use std::time::Duration;

use strata_robot::edge::{LinkInbox, LinkOutbox, LinkPorts, PlatformPorts, write_orders};
use strata_runtime::{
    Context, GraphBuilder, Module, ModuleError, ModuleId, Output, PortName, Time, Trigger,
};

use crate::platform::SimHandle;
use crate::truth::{GroundTruth, RobotId};

/// The ports that serve one robot: its platform and its links.
#[derive(Clone, Debug)]
pub struct ServedRobot {
    pub id: RobotId,
    pub platform: PlatformPorts,
    pub links: LinkPorts,
}

/// Steps the simulation periodically, serves its robots and publishes ground truth.
#[derive(Debug)]
pub struct SimulatorModule {
    sim: SimHandle,
    robots: Vec<ServedRobot>,
    ground_truth: Output<GroundTruth>,
    truth_period: Duration,
    next_truth: Time,
    published_events: usize,
}

impl Module for SimulatorModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let mut sim = self.sim.lock();
        // Orders and messages take effect from the next step, as they would between two steps
        // of a world that runs on its own.
        for robot in &self.robots {
            let id = robot.id;
            write_orders(ctx, robot.platform.orders, robot.platform.refusals, |orders| {
                sim.apply_orders(id, orders)
            })?;
            for package in ctx.drain(robot.links.sent) {
                let LinkOutbox { team, external } = package.value;
                // A message the world refuses (too large, a robot out of the game) is the
                // sender's loss, as on a real network: the world counts it.
                if let Some(bytes) = team
                    && let Err(error) = sim.send_team_message(id, &bytes)
                {
                    tracing::debug!(robot = %id, %error, "team message not sent");
                }
                if let Some(bytes) = external {
                    sim.receive_return_packet(id, &bytes)?;
                }
            }
        }
        sim.advance_to(now);
        for robot in &self.robots {
            let ports = &robot.platform;
            if let Some(frame) = sim.take_sensor_frame(robot.id)? {
                let stamp = frame.stamp;
                ctx.send_stamped(ports.frames, frame, stamp);
            }
            let motion = sim.read_motion(robot.id)?;
            ctx.send_stamped(ports.motion, motion, motion.stamp);
            let inbox = LinkInbox {
                team: sim.take_team_messages(robot.id)?,
                external: sim.take_control_packets(robot.id)?,
            };
            if !inbox.team.is_empty() || !inbox.external.is_empty() {
                ctx.send(robot.links.received, inbox);
            }
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
    /// The platform and links of each robot served through the graph, in the order they were
    /// given.
    pub robots: Vec<ServedRobot>,
}

impl SimulatorPorts {
    pub const GROUND_TRUTH: PortName<GroundTruth> = PortName::new("ground_truth");

    /// The platform of `robot`, if the simulator serves it through the graph.
    pub fn platform(&self, robot: RobotId) -> Option<PlatformPorts> {
        self.served(robot).map(|served| served.platform.clone())
    }

    /// The links of `robot` (its team radio and GameController), if the simulator serves it.
    pub fn links(&self, robot: RobotId) -> Option<LinkPorts> {
        self.served(robot).map(|served| served.links)
    }

    fn served(&self, robot: RobotId) -> Option<&ServedRobot> {
        self.robots.iter().find(|served| served.id == robot)
    }
}

/// Adds the simulator module (named `simulator`), triggered at the simulation's sensor period,
/// serving `robots` through the graph ([`SimulatorPorts::platform`], [`SimulatorPorts::links`];
/// connect each robot to its ports or leave them). The module takes what a listed robot's links
/// received each step, so give it no `SimTeamLink` or `SimGameControllerLink` besides. Robots
/// not listed read a `SimPlatform` and links of their own, which read the world whenever they
/// run.
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
        let ground_truth = p.output(SimulatorPorts::GROUND_TRUTH);
        let served: Vec<ServedRobot> = robots
            .iter()
            .map(|&id| {
                let prefix = robot_port_prefix(id);
                ServedRobot {
                    id,
                    platform: PlatformPorts::serve(p, &prefix, info.clone()),
                    links: LinkPorts::serve(p, &prefix),
                }
            })
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
