//! The world-modeling module (paper 3.1 and 3.7): percepts arrive queued (every observation, in
//! order), odometry merged (increments composed), teammates' estimates and commands queued; the
//! world state leaves as the newest value (Latest at the readers). A thin shell: all the
//! filtering is in [`WorldModel`].

use strata_runtime::{
    Context, GraphBuilder, Input, Module, ModuleError, Output, Policy, PortName, Trigger,
};

use super::config::{ConfigError, WorldModelConfig};
use super::model::{WorldCommand, WorldModel};
use super::state::WorldState;
use super::team::TeammateEstimate;
use crate::geometry::Odometry;
use crate::percept::Percepts;

/// Capacity of the percept queue: a second of frames at 30 Hz, with room to spare.
pub const PERCEPT_QUEUE: usize = 64;
const TEAM_QUEUE: usize = 32;
const COMMAND_QUEUE: usize = 16;

/// The world-modeling module's ports.
#[derive(Clone, Copy, Debug)]
pub struct WorldPorts {
    /// Perception's percepts (Queue); every package triggers a cycle.
    pub percepts: Input<Percepts>,
    /// Actuation's odometry increments (Merge: composed with [`Odometry::then`]).
    pub odometry: Input<Odometry>,
    /// Teammates' estimates from the planning layer (Queue; optional).
    pub team: Input<TeammateEstimate>,
    /// Commands from the application (Queue; optional).
    pub commands: Input<WorldCommand>,
    /// The world state, stamped with the newest percepts' measurement time.
    pub world_state: Output<WorldState>,
}

impl WorldPorts {
    pub const PERCEPTS: PortName<Percepts> = PortName::new("percepts");
    pub const ODOMETRY: PortName<Odometry> = PortName::new("odometry");
    pub const TEAM: PortName<TeammateEstimate> = PortName::new("team");
    pub const COMMANDS: PortName<WorldCommand> = PortName::new("commands");
    pub const WORLD_STATE: PortName<WorldState> = PortName::new("world_state");
}

/// Between camera images only odometry changes the estimates, so the world state is published
/// when an image was processed, or at least this often (readers still see the robot's own
/// motion between images).
pub const MIN_PUBLISH_PERIOD: std::time::Duration = std::time::Duration::from_millis(50);

/// Runs a [`WorldModel`] on the module's inputs.
#[derive(Debug)]
pub struct WorldModule {
    model: WorldModel,
    ports: WorldPorts,
    last_published: Option<strata_runtime::Time>,
    /// Odometry of frames whose filtering was deferred to the next image or publication.
    pending_odometry: Odometry,
}

impl WorldModule {
    pub fn model(&self) -> &WorldModel {
        &self.model
    }
}

impl Module for WorldModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        for command in ctx.drain(self.ports.commands) {
            if let Err(error) = self.model.command(command.value) {
                tracing::warn!(module = ctx.module_name(), %error, "world command refused");
            }
        }
        for estimate in ctx.drain(self.ports.team) {
            if let Err(error) = self.model.add_teammate_estimate(estimate.value) {
                tracing::warn!(module = ctx.module_name(), %error, "teammate estimate refused");
            }
        }
        // Merged odometry covers the motion up to the newest percepts: it is applied before
        // the first of them (odometry packages carry no finer timing after merging).
        let mut odometry = ctx.take(self.ports.odometry).map_or(Odometry::ZERO, |p| p.value);
        // Between images only odometry moves the estimates: frames without one are folded into
        // the next image or publication instead of running every filter at the sensor rate.
        let mut published = None;
        while let Some(package) = ctx.take(self.ports.percepts) {
            let frame = &package.value;
            self.pending_odometry = self.pending_odometry.then(odometry);
            odometry = Odometry::ZERO;
            let due = self.last_published.is_none_or(|t| package.stamp - t >= MIN_PUBLISH_PERIOD);
            // A placement is filtered at once: the odometry before it was made where the robot
            // was, the odometry after it where it is.
            if frame.camera.is_some() || due || frame.placed {
                let motion = std::mem::replace(&mut self.pending_odometry, Odometry::ZERO);
                self.model.process(motion, frame);
                published = Some(package.stamp);
            } else {
                self.model.note_frame_without_image(frame);
            }
        }
        if odometry != Odometry::ZERO {
            self.pending_odometry = self.pending_odometry.then(odometry);
        }
        if let Some(stamp) = published {
            self.last_published = Some(stamp);
            let state = self.model.publish();
            ctx.send_stamped(self.ports.world_state, state, stamp);
        }
        Ok(())
    }
}

/// Adds a world-modeling module named `name` to `graph`; the configuration is checked first.
pub fn add_world_module(
    graph: &mut GraphBuilder,
    name: &str,
    config: WorldModelConfig,
) -> Result<WorldPorts, ConfigError> {
    let model = WorldModel::new(config)?;
    Ok(graph.add(name, move |p| {
        let percepts = p.input(WorldPorts::PERCEPTS, Policy::queue(PERCEPT_QUEUE));
        let odometry =
            p.input(WorldPorts::ODOMETRY, Policy::merge(|a: &mut Odometry, b| *a = a.then(b)));
        let team = p.optional_input(WorldPorts::TEAM, Policy::queue(TEAM_QUEUE));
        let commands = p.optional_input(WorldPorts::COMMANDS, Policy::queue(COMMAND_QUEUE));
        let world_state = p.output(WorldPorts::WORLD_STATE);
        p.trigger(Trigger::on_any([percepts.into()]));
        let ports = WorldPorts { percepts, odometry, team, commands, world_state };
        (
            WorldModule { model, ports, last_published: None, pending_odometry: Odometry::ZERO },
            ports,
        )
    }))
}
