//! The simulator as a module of the runtime, and the platform of the robots it serves: each
//! step it applies the orders they sent since the previous one, moves the world, and publishes
//! each robot's sensor frame and motion feedback. The robots' perception and actuation connect
//! to its ports as to any platform's edge (`strata_robot::edge::PlatformPorts`, given to
//! `add_robot` as `RobotPlatform::Module`), so a robot runs after the world moved because the
//! world's step is what triggers its perception: an edge of the graph, not a priority.

use strata_robot::edge::{PlatformPorts, write_orders};
use strata_runtime::{Context, GraphBuilder, Module, ModuleError, ModuleId, Trigger};

use crate::handle::WorldHandle;
use crate::sim::{Script, WorldSimError};

/// Steps the simulation every sensor period and serves its robots.
pub struct WorldSimModule<S> {
    handle: WorldHandle<S>,
    robots: Vec<(usize, PlatformPorts)>,
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
        for (robot, ports) in &self.robots {
            write_orders(ctx, ports.orders, ports.refusals, |orders| {
                simulation.sim.apply_orders(*robot, orders)
            })?;
        }
        simulation.advance_to(now);
        for (robot, ports) in &self.robots {
            if let Some(frame) = simulation.sim.take_frame(*robot)? {
                let stamp = frame.stamp;
                ctx.send_stamped(ports.frames, frame, stamp);
            }
            let motion = simulation.sim.take_feedback(*robot)?;
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
        let served: Vec<(usize, PlatformPorts)> = robots
            .iter()
            .map(|&robot| (robot, PlatformPorts::serve(p, &robot_port_prefix(robot), info.clone())))
            .collect();
        (WorldSimModule { handle, robots: served.clone() }, served)
    });
    Ok(WorldSimPorts { module: id, robots: served })
}
