//! The simulator as a module of the runtime, and the platform of the robots it serves: each
//! step it applies the orders they sent since the previous one, moves the world, and publishes
//! each robot's sensor frame and motion feedback. The robots' perception and actuation connect
//! to its ports as to any platform's edge (`strata_robot::edge::PlatformPorts`, given to
//! `add_robot` as `RobotPlatform::Module`), so a robot runs after the world moved because the
//! world's step is what triggers its perception: an edge of the graph, not a priority.

use strata_robot::edge::{OrderRefused, PlatformPorts};
use strata_robot::platform::{ActuatorOrders, MotionFeedback, PlatformError, SensorFrame};
use strata_runtime::{
    Context, GraphBuilder, Input, Module, ModuleError, ModuleId, Output, Policy, Trigger,
};

use crate::handle::WorldHandle;
use crate::sim::{Script, WorldSimError};

/// Orders a robot may send between two steps (a few per step at most).
const ORDER_QUEUE: usize = 16;

/// One served robot's side of the module.
#[derive(Clone, Copy, Debug)]
struct RobotPorts {
    robot: usize,
    frames: Output<SensorFrame>,
    motion: Output<MotionFeedback>,
    orders: Input<ActuatorOrders>,
    refusals: Output<OrderRefused>,
}

/// Steps the simulation every sensor period and serves its robots.
pub struct WorldSimModule<S> {
    handle: WorldHandle<S>,
    robots: Vec<RobotPorts>,
}

impl<S> std::fmt::Debug for WorldSimModule<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorldSimModule").field("robots", &self.robots).finish_non_exhaustive()
    }
}

impl<S: Script + 'static> Module for WorldSimModule<S> {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let mut simulation = self.handle.lock();
        // Orders act from the next step: actuation decided them on the previous frame.
        for ports in &self.robots {
            for package in ctx.drain(ports.orders) {
                let orders = package.value;
                match simulation.sim.apply_orders(ports.robot, &orders) {
                    Ok(()) => {}
                    Err(PlatformError::Unsupported(reason)) => {
                        ctx.send(ports.refusals, OrderRefused::of(&orders, reason));
                    }
                    Err(other) => return Err(Box::new(other)),
                }
            }
        }
        simulation.advance_to(now);
        for ports in &self.robots {
            if let Some(frame) = simulation.sim.take_frame(ports.robot)? {
                let stamp = frame.stamp;
                ctx.send_stamped(ports.frames, frame, stamp);
            }
            let motion = simulation.sim.take_feedback(ports.robot)?;
            ctx.send_stamped(ports.motion, motion, motion.stamp);
        }
        Ok(())
    }
}

/// What [`add_world_sim`] added.
#[derive(Clone, Debug)]
pub struct WorldSimPorts {
    pub module: ModuleId,
    /// The platform of each served robot, in the order they were given.
    pub robots: Vec<(usize, PlatformPorts)>,
}

impl WorldSimPorts {
    /// The platform of robot `robot`, if the module serves it.
    pub fn platform(&self, robot: usize) -> Option<PlatformPorts> {
        self.robots.iter().find(|(id, _)| *id == robot).map(|(_, ports)| ports.clone())
    }
}

/// The prefix of robot `robot`'s ports on the module: `robot_0` (topics `{module}/robot_0/frames`,
/// `/motion`, `/orders`, `/refusals`).
pub fn robot_port_prefix(robot: usize) -> String {
    format!("robot_{robot}")
}

/// Adds the simulator's module, named `name` and triggered every sensor period, serving
/// `robots` (indices into the world's robots) through the graph.
pub fn add_world_sim<S: Script + 'static>(
    graph: &mut GraphBuilder,
    name: &str,
    handle: WorldHandle<S>,
    robots: &[usize],
) -> Result<WorldSimPorts, WorldSimError> {
    let (period, info, count) = {
        let simulation = handle.lock();
        (simulation.sim.period(), simulation.sim.platform_info(), simulation.sim.robots())
    };
    if let Some(&missing) = robots.iter().find(|&&robot| robot >= count) {
        return Err(WorldSimError::NoRobot(missing));
    }
    let mut id = ModuleId(0);
    let served = graph.add(name, |p| {
        id = p.id();
        p.trigger(Trigger::every(period));
        let served: Vec<RobotPorts> = robots
            .iter()
            .map(|&robot| {
                let prefix = robot_port_prefix(robot);
                RobotPorts {
                    robot,
                    frames: p.output(&format!("{prefix}/frames")),
                    motion: p.output(&format!("{prefix}/motion")),
                    // Not a trigger: orders wait for the next step.
                    orders: p
                        .optional_input(&format!("{prefix}/orders"), Policy::queue(ORDER_QUEUE)),
                    refusals: p.output(&format!("{prefix}/refusals")),
                }
            })
            .collect();
        (WorldSimModule { handle, robots: served.clone() }, served)
    });
    let robots = served
        .into_iter()
        .map(|ports| {
            let platform = PlatformPorts {
                info: info.clone(),
                frames: ports.frames,
                motion: ports.motion,
                orders: ports.orders,
                refusals: ports.refusals,
            };
            (ports.robot, platform)
        })
        .collect();
    Ok(WorldSimPorts { module: id, robots })
}
