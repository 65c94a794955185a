//! The planning layer as a runtime module: the robot's only contact with its teammates and with
//! external devices (paper 3.3: a robot that loses the network loses no ability of its own).

use serde::{Deserialize, Serialize};
use strata_runtime::{
    Context, Input, Message, Module, ModuleError, Output, Policy, PortName, Ports, Time,
};

use crate::control::planning::{
    Assignment, Label, MessageBudget, OwnState, Planner, PlanningPolicy, PlanningStats,
    SharedObject, SharedSignal, StandingStatus, TeamMessage, Urgency,
};
use crate::control::reactive::Stability;
use crate::edge::{LinkInbox, LinkOutbox};
use crate::geometry::Pose;
use crate::percept::Signal;
use crate::world::{
    ObjectCategory, SharedObject as WorldSharedObject, TeammateEstimate, WorldCommand, WorldState,
};

/// Turns team messages into bytes and back (the application's wire format, e.g. the SPL's
/// 128-byte limit). Decoding must reject malformed and foreign messages, never panic.
pub trait TeamCodec<M: Label, R: Label>: Send {
    fn encode(&self, message: &TeamMessage<M, R>) -> Result<Vec<u8>, String>;
    fn decode(&self, bytes: &[u8]) -> Result<TeamMessage<M, R>, String>;
}

/// The codec of a robot without teammates: every message encodes to nothing (the robot has no
/// one to tell; its links carry no team link to send it on) and no bytes decode.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCodec;

impl<M: Label, R: Label> TeamCodec<M, R> for NoCodec {
    fn encode(&self, _message: &TeamMessage<M, R>) -> Result<Vec<u8>, String> {
        Ok(Vec::new())
    }

    fn decode(&self, bytes: &[u8]) -> Result<TeamMessage<M, R>, String> {
        Err(format!("a team message of {} bytes for a robot without teammates", bytes.len()))
    }
}

/// The application's side of an external device that directs the robot (paper 3.3: the
/// planning layer uses "information coming from other robots and eventually external devices";
/// in soccer the GameController, in `examples/patrol` an operator's console). Only `receive`
/// and `directive` are required: a device that never takes a robot out of play, publishes no
/// message budget, wants no status packets or knows no signals leaves those methods at their
/// defaults, and a robot without any device uses [`NoDevice`].
pub trait ExternalDevice: Send {
    /// What the deliberative layer needs from the device (in soccer: the game state).
    type Directive: Message + PartialEq + Default + std::fmt::Debug;

    /// A packet from the device; malformed packets are an error the module counts and skips.
    fn receive(&mut self, now: Time, packet: &[u8]) -> Result<(), String>;
    fn directive(&self) -> Self::Directive;
    /// Whether the device took the robot out of play.
    fn penalized(&self) -> bool {
        false
    }
    /// The team's message budget, when the device publishes one.
    fn budget(&self) -> Option<MessageBudget> {
        None
    }
    /// A status packet for the device, when one is due.
    fn status_packet(
        &mut self,
        _now: Time,
        _own: &OwnState,
        _world: Option<&WorldState>,
    ) -> Option<Vec<u8>> {
        None
    }
    /// Pose resets and hints the device's events imply (placed at a kick-off position, back
    /// from a penalty).
    fn world_commands(&mut self) -> Vec<WorldCommand> {
        Vec::new()
    }

    /// A signal this robot perceived (the referee's whistle or gesture): what a device whose
    /// packets lag the game (GameController3's delays) lets the robot act on before they
    /// catch up.
    fn perceive(&mut self, _now: Time, _signal: &Signal) {}

    /// A signal a teammate's message reports.
    fn teammate_signal(&mut self, _now: Time, _sender: u8, _signal: &SharedSignal) {}

    /// The signal this robot's messages report, while teammates should act on it.
    fn shared_signal(&self, _now: Time) -> Option<SharedSignal> {
        None
    }

    /// Whether a signal was perceived since the last call that teammates should hear of at
    /// once.
    fn take_signal_news(&mut self) -> bool {
        false
    }

    /// Called every planning cycle before [`ExternalDevice::directive`], with the newest world
    /// state: beliefs that expire with time (a whistle the packets never confirmed) or read
    /// the world (where the ball went before a goal's whistle).
    fn update(&mut self, _now: Time, _world: Option<&WorldState>) {}
}

/// The device of a robot that has none: its directive is `()` and every packet is refused.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoDevice;

impl ExternalDevice for NoDevice {
    type Directive = ();

    fn receive(&mut self, _now: Time, packet: &[u8]) -> Result<(), String> {
        Err(format!("a packet of {} bytes for a robot without an external device", packet.len()))
    }

    fn directive(&self) {}
}

/// A teammate as the deliberative layer sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct TeammateView<M, R> {
    pub member: u8,
    pub mission: M,
    pub role: R,
    pub pose: Pose,
    pub available: bool,
    /// Why MAMC considers it unavailable (silent, fallen, penalized, not localized...).
    pub unavailable: Option<String>,
    /// Seconds since it was last heard.
    pub age: f64,
}

/// What the planning layer sends the deliberative layer: the mission and role, the
/// application's directive, and the teammates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label, D: Message")]
pub struct PlanningDecision<M, R, D> {
    pub assignment: Assignment<M, R>,
    pub directive: D,
    pub teammates: Vec<TeammateView<M, R>>,
    pub stats: PlanningStats,
}

/// The planning module's ports.
#[derive(Debug)]
pub struct PlanningPorts<M, R, D> {
    /// What the links received since the previous cycle; each inbox is a cycle.
    pub inbox: Input<LinkInbox>,
    pub world: Input<WorldState>,
    pub stability: Input<Stability>,
    /// Perception's signals, every one (a Queue): a whistle is one frame long.
    pub signals: Input<Signal>,
    pub decision: Output<PlanningDecision<M, R, D>>,
    pub team_estimates: Output<TeammateEstimate>,
    pub world_commands: Output<WorldCommand>,
    /// The team message and the external device's packet of the cycle, for the links.
    pub outbox: Output<LinkOutbox>,
}

impl<M, R, D> Clone for PlanningPorts<M, R, D> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M, R, D> Copy for PlanningPorts<M, R, D> {}

impl<M, R, D> PlanningPorts<M, R, D>
where
    PlanningDecision<M, R, D>: Message,
{
    pub const INBOX: PortName<LinkInbox> = PortName::new("inbox");
    pub const WORLD: PortName<WorldState> = PortName::new("world");
    pub const STABILITY: PortName<Stability> = PortName::new("stability");
    pub const SIGNALS: PortName<Signal> = PortName::new("signals");
    pub const DECISION: PortName<PlanningDecision<M, R, D>> = PortName::new("decision");
    pub const TEAM_ESTIMATES: PortName<TeammateEstimate> = PortName::new("team_estimates");
    pub const WORLD_COMMANDS: PortName<WorldCommand> = PortName::new("world_commands");
    pub const OUTBOX: PortName<LinkOutbox> = PortName::new("outbox");

    /// Declares the ports, once for the assembly and for replay; the layer runs on every
    /// inbox, which the links' source sends at the layer's rate.
    pub fn declare(p: &mut Ports<'_>) -> Self {
        let ports = PlanningPorts {
            inbox: p.input(Self::INBOX, Policy::queue(8)),
            world: p.input(Self::WORLD, Policy::Latest),
            stability: p.input(Self::STABILITY, Policy::Latest),
            signals: p.input(Self::SIGNALS, Policy::queue(32)),
            decision: p.output(Self::DECISION),
            team_estimates: p.output(Self::TEAM_ESTIMATES),
            world_commands: p.output(Self::WORLD_COMMANDS),
            outbox: p.output(Self::OUTBOX),
        };
        p.trigger(strata_runtime::Trigger::on_any([ports.inbox.into()]));
        ports
    }
}

/// Runs the planner on the robot's links.
pub struct PlanningModule<P: PlanningPolicy, C, F: ExternalDevice> {
    member: u8,
    planner: Planner<P>,
    codec: C,
    device: F,
    ports: PlanningPorts<P::Mission, P::Role, F::Directive>,
    world: Option<WorldState>,
    stability: Stability,
    last_sent: Option<PlanningDecision<P::Mission, P::Role, F::Directive>>,
    /// Shared-object names this robot puts in its messages, most important first.
    shared_objects: Vec<String>,
    /// When each shared object was last seen, remembered after world modeling forgets it:
    /// teammates judge a striker by how long ago it saw the ball (MAMC), and a striker that
    /// is searching for a ball lost a few seconds ago is still accomplishing its mission.
    last_seen: Vec<Option<Time>>,
}

impl<P: PlanningPolicy, C, F: ExternalDevice> std::fmt::Debug for PlanningModule<P, C, F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlanningModule")
            .field("member", &self.member)
            .field("assignment", self.planner.assignment())
            .finish_non_exhaustive()
    }
}

impl<P, C, F> PlanningModule<P, C, F>
where
    P: PlanningPolicy,
    C: TeamCodec<P::Mission, P::Role>,
    F: ExternalDevice,
{
    pub fn new(
        member: u8,
        planner: Planner<P>,
        codec: C,
        device: F,
        ports: PlanningPorts<P::Mission, P::Role, F::Directive>,
        shared_objects: Vec<String>,
    ) -> Self {
        PlanningModule {
            member,
            planner,
            codec,
            device,
            ports,
            world: None,
            stability: Stability::Stable,
            last_sent: None,
            last_seen: vec![None; shared_objects.len()],
            shared_objects,
        }
    }

    fn own_state(&self) -> OwnState {
        let status = match self.stability {
            Stability::Stable => StandingStatus::Stable,
            Stability::Unstable(_) => StandingStatus::Unstable,
            Stability::Fallen(_) => StandingStatus::Fallen,
        };
        let penalized = self.device.penalized();
        match &self.world {
            None => OwnState {
                id: self.member,
                status,
                penalized,
                localized: false,
                pose: Pose::default(),
                pose_confidence: 0.0,
                objects: Vec::new(),
            },
            Some(world) => OwnState {
                id: self.member,
                status,
                penalized,
                localized: !world.pose.lost,
                pose: world.pose.pose,
                pose_confidence: world.pose.confidence,
                objects: self
                    .shared_objects
                    .iter()
                    .zip(&self.last_seen)
                    .filter_map(|(name, remembered)| {
                        let o = world.object(name)?;
                        // Shared with its age and confidence even when uncertain or forgotten:
                        // teammates judge from how long ago it was seen (MAMC), not from its
                        // absence; a forgotten object has no confidence, so nobody uses its
                        // position.
                        let seen = o.last_seen.or(*remembered)?;
                        (o.category != ObjectCategory::Landmark).then(|| SharedObject {
                            name: o.name.to_string(),
                            position: o.global_position,
                            sigma: o.global_covariance.trace().max(0.0).sqrt(),
                            confidence: o.confidence,
                            age: (world.stamp - seen).as_secs_f64().max(0.0),
                        })
                    })
                    .collect(),
            },
        }
    }

    /// What world modeling's team fusion needs from a teammate's message.
    fn estimate_of(
        &self,
        now: Time,
        message: &TeamMessage<P::Mission, P::Role>,
    ) -> Option<TeammateEstimate> {
        let world = self.world.as_ref()?;
        // Confidence 1 means a few centimetres; 0 means anywhere on the field.
        let sigma = 0.05 + 3.0 * (1.0 - message.pose_confidence.clamp(0.0, 1.0));
        let heading_sigma = 0.05 + 1.5 * (1.0 - message.pose_confidence.clamp(0.0, 1.0));
        let objects = message
            .objects
            .iter()
            .filter_map(|shared| {
                let own = world.object(&shared.name)?;
                let s = shared.sigma.max(0.01);
                Some(WorldSharedObject {
                    class: own.class,
                    variant: own.variant,
                    position: shared.position,
                    velocity: None,
                    covariance: nalgebra::Matrix2::new(s * s, 0.0, 0.0, s * s),
                    confidence: shared.confidence,
                    age: shared.age,
                })
            })
            .collect();
        Some(TeammateEstimate {
            member: message.sender,
            stamp: now,
            pose: message.pose,
            pose_covariance: nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(
                sigma * sigma,
                sigma * sigma,
                heading_sigma * heading_sigma,
            )),
            pose_confidence: message.pose_confidence,
            objects,
        })
    }

    pub fn planner(&self) -> &Planner<P> {
        &self.planner
    }
}

impl<P, C, F> Module for PlanningModule<P, C, F>
where
    P: PlanningPolicy + 'static,
    C: TeamCodec<P::Mission, P::Role> + 'static,
    F: ExternalDevice + 'static,
{
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        if let Some(world) = ctx.latest(self.ports.world) {
            for (name, seen) in self.shared_objects.iter().zip(&mut self.last_seen) {
                if let Some(t) = world.value.object(name).and_then(|o| o.last_seen) {
                    *seen = Some(t);
                }
            }
            self.world = Some(world.value);
        }
        if let Some(stability) = ctx.latest(self.ports.stability) {
            self.stability = stability.value;
        }
        for signal in ctx.drain(self.ports.signals) {
            self.device.perceive(signal.stamp, &signal.value);
        }
        let mut inbox = LinkInbox::default();
        for package in ctx.drain(self.ports.inbox) {
            inbox.team.extend(package.value.team);
            inbox.external.extend(package.value.external);
        }
        // External device (GameController).
        for packet in inbox.external {
            if let Err(error) = self.device.receive(packet.received, &packet.bytes) {
                tracing::debug!(module = ctx.module_name(), %error, "external packet rejected");
            }
        }
        for command in self.device.world_commands() {
            ctx.send(self.ports.world_commands, command);
        }
        if let Some(budget) = self.device.budget() {
            self.planner.budget = budget;
        }
        // Teammates: evaluation is asynchronous, on every message received.
        for packet in inbox.team {
            match self.codec.decode(&packet.bytes) {
                Ok(message) if message.sender == self.member => {}
                Ok(message) => {
                    if let Some(estimate) = self.estimate_of(packet.received, &message) {
                        ctx.send(self.ports.team_estimates, estimate);
                    }
                    if let Some(signal) = &message.signal {
                        self.device.teammate_signal(packet.received, message.sender, signal);
                    }
                    self.planner.receive(packet.received, message);
                }
                Err(error) => {
                    // A teammate sending garbage costs that message only.
                    self.planner.reject();
                    tracing::debug!(module = ctx.module_name(), %error, "team message rejected");
                }
            }
        }
        self.device.update(now, self.world.as_ref());
        if self.device.take_signal_news() {
            // Teammates that missed the signal follow this robot: the sooner the better, so
            // it may use the team's whole reserve.
            self.planner.request_instant(Urgency::Vital);
        }
        let own = self.own_state();
        self.planner.evaluate(now, own.clone());
        let decision = PlanningDecision {
            assignment: self.planner.assignment().clone(),
            directive: self.device.directive(),
            teammates: self
                .planner
                .teammates()
                .map(|t| TeammateView {
                    member: t.message.sender,
                    mission: t.message.mission,
                    role: t.message.role,
                    pose: t.message.pose,
                    available: t.unavailable.is_none(),
                    unavailable: t.unavailable.clone(),
                    age: (now - t.last_heard).as_secs_f64(),
                })
                .collect(),
            stats: self.planner.stats.clone(),
        };
        // The deliberative layer hears only of changes (ages and counters do not count).
        let changed = self.last_sent.as_ref().is_none_or(|last| {
            last.assignment != decision.assignment
                || last.directive != decision.directive
                || last.teammates.len() != decision.teammates.len()
                || last.teammates.iter().zip(&decision.teammates).any(|(a, b)| {
                    a.member != b.member
                        || a.role != b.role
                        || a.available != b.available
                        || a.pose != b.pose
                })
        });
        if changed {
            self.last_sent = Some(decision.clone());
            ctx.send(self.ports.decision, decision);
        }
        // The links' sink sends what this robot has links for: a robot without teammates
        // composes its messages all the same, so its planning is the same with or without.
        let mut outbox = LinkOutbox::default();
        if let Some(kind) = self.planner.message_due(now)
            && let Some(mut message) = self.planner.compose(now, kind)
        {
            message.signal = self.device.shared_signal(now);
            match self.codec.encode(&message) {
                Ok(bytes) => outbox.team = Some(bytes),
                Err(error) => {
                    tracing::warn!(module = ctx.module_name(), %error, "team message not encoded")
                }
            }
        }
        outbox.external = self.device.status_packet(now, &own, self.world.as_ref());
        if outbox.team.is_some() || outbox.external.is_some() {
            ctx.send(self.ports.outbox, outbox);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot without a device: nothing to take it out of play, no budget, no status packet,
    /// and a packet that arrives anyway is an error the module counts, not a crash.
    #[test]
    fn a_robot_without_a_device_keeps_the_defaults_and_refuses_packets() {
        let mut device = NoDevice;
        let now = Time::from_secs_f64(1.0);
        assert!(!device.penalized());
        assert!(device.budget().is_none());
        let own = OwnState {
            id: 1,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            pose: Pose::default(),
            pose_confidence: 1.0,
            objects: Vec::new(),
        };
        assert!(device.status_packet(now, &own, None).is_none());
        assert!(device.world_commands().is_empty());
        let error = device.receive(now, b"RGme").expect_err("no device to read it");
        assert!(error.contains("4 bytes"), "{error}");
    }
}
