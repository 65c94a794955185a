//! The hybrid control layers as runtime modules: thin shells around the pure layers, so the
//! layers themselves are tested without threads and the shells only move packages.

use strata_runtime::{
    Context, Input, Message, Module, ModuleError, Output, Policy, PortName, Ports, Trigger,
};

use crate::command::{ActuationMessage, MotionCommands};
use crate::control::deliberative::{DeliberativeInput, DeliberativeOutput, DeliberativePolicy};
use crate::control::reactive::{ReactiveLayer, ReactiveReport, Stability};
use crate::control::scores::Goal;
use crate::percept::Percepts;

/// The reactive layer's ports.
#[derive(Debug)]
pub struct ReactivePorts<H, B, X, W> {
    pub percepts: Input<Percepts>,
    pub world: Input<W>,
    pub deliberative: Input<DeliberativeOutput<H, B, X>>,
    pub actuation: Input<ActuationMessage>,
    pub commands: Output<MotionCommands>,
    pub report: Output<ReactiveReport>,
    pub stability: Output<Stability>,
}

impl<H, B, X, W> Clone for ReactivePorts<H, B, X, W> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<H, B, X, W> Copy for ReactivePorts<H, B, X, W> {}

impl<H, B, X, W> ReactivePorts<H, B, X, W>
where
    W: Message,
    DeliberativeOutput<H, B, X>: Message,
{
    pub const PERCEPTS: PortName<Percepts> = PortName::new("percepts");
    pub const WORLD: PortName<W> = PortName::new("world");
    pub const DELIBERATIVE: PortName<DeliberativeOutput<H, B, X>> = PortName::new("deliberative");
    pub const ACTUATION: PortName<ActuationMessage> = PortName::new("actuation");
    pub const COMMANDS: PortName<MotionCommands> = PortName::new("commands");
    pub const REPORT: PortName<ReactiveReport> = PortName::new("report");
    pub const STABILITY: PortName<Stability> = PortName::new("stability");

    /// Declares the ports, once for the assembly and for replay; the layer runs on every
    /// percept.
    pub fn declare(p: &mut Ports<'_>) -> Self {
        let ports = ReactivePorts {
            percepts: p.input(Self::PERCEPTS, Policy::Latest),
            world: p.input(Self::WORLD, Policy::Latest),
            deliberative: p.input(Self::DELIBERATIVE, Policy::Latest),
            actuation: p.input(Self::ACTUATION, Policy::queue(64)),
            commands: p.output(Self::COMMANDS),
            report: p.output(Self::REPORT),
            stability: p.output(Self::STABILITY),
        };
        p.trigger(Trigger::on_any([ports.percepts.into()]));
        ports
    }
}

/// Runs a reactive cycle on every new percept (the fastest layer, at the sensor rate).
pub struct ReactiveModule<H: Goal, B: Goal, X: Goal, W> {
    layer: ReactiveLayer<H, B, X, W>,
    ports: ReactivePorts<H, B, X, W>,
    world: Option<W>,
    /// How many world states have arrived: the number of the one in `world`, so the layer can
    /// tell a cycle on a new world state from one on the previous cycle's.
    world_revision: u64,
    last_stability: Option<Stability>,
}

impl<H: Goal, B: Goal, X: Goal, W> std::fmt::Debug for ReactiveModule<H, B, X, W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReactiveModule").field("layer", &self.layer).finish_non_exhaustive()
    }
}

impl<H: Goal, B: Goal, X: Goal, W> ReactiveModule<H, B, X, W> {
    pub fn new(layer: ReactiveLayer<H, B, X, W>, ports: ReactivePorts<H, B, X, W>) -> Self {
        ReactiveModule { layer, ports, world: None, world_revision: 0, last_stability: None }
    }
}

impl<H: Goal, B: Goal, X: Goal, W: strata_runtime::Message> Module for ReactiveModule<H, B, X, W> {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        if let Some(output) = ctx.latest(self.ports.deliberative) {
            let received = output.stamp;
            let output = output.value;
            self.layer.head.set_scores(output.head, &output.deactivated, received);
            self.layer.body.set_scores(output.body, &output.deactivated, received);
            self.layer.whole_body.set_scores(output.whole_body, &output.deactivated, received);
        }
        for message in ctx.drain(self.ports.actuation) {
            self.layer.actuation_message(&message.value);
        }
        if let Some(world) = ctx.latest(self.ports.world) {
            self.world = Some(world.value);
            self.world_revision += 1;
        }
        let Some(percepts) = ctx.latest(self.ports.percepts) else { return Ok(()) };
        let stamp = percepts.stamp;
        let report = self.layer.step_on_revision(
            ctx.now(),
            &percepts.value,
            self.world.as_ref(),
            self.world_revision,
        );
        // Commands go out every cycle, empty or not: they are what paces actuation.
        ctx.send_stamped(self.ports.commands, report.commands, stamp);
        if self.last_stability != Some(report.stability) {
            self.last_stability = Some(report.stability);
            ctx.send_stamped(self.ports.stability, report.stability, stamp);
        }
        ctx.send_stamped(self.ports.report, report, stamp);
        Ok(())
    }
}

/// The deliberative layer's ports.
#[derive(Debug)]
pub struct DeliberativePorts<H, B, X, W, A> {
    pub world: Input<W>,
    pub assignment: Input<A>,
    pub stability: Input<Stability>,
    pub output: Output<DeliberativeOutput<H, B, X>>,
}

impl<H, B, X, W, A> Clone for DeliberativePorts<H, B, X, W, A> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<H, B, X, W, A> Copy for DeliberativePorts<H, B, X, W, A> {}

impl<H, B, X, W, A> DeliberativePorts<H, B, X, W, A>
where
    W: Message,
    A: Message,
    DeliberativeOutput<H, B, X>: Message,
{
    pub const WORLD: PortName<W> = PortName::new("world");
    pub const ASSIGNMENT: PortName<A> = PortName::new("assignment");
    pub const STABILITY: PortName<Stability> = PortName::new("stability");
    pub const SCORES: PortName<DeliberativeOutput<H, B, X>> = PortName::new("scores");

    /// Declares the ports, once for the assembly and for replay (the layer's period is the
    /// caller's: it is configured).
    pub fn declare(p: &mut Ports<'_>) -> Self {
        DeliberativePorts {
            world: p.input(Self::WORLD, Policy::Latest),
            assignment: p.input(Self::ASSIGNMENT, Policy::Latest),
            stability: p.input(Self::STABILITY, Policy::Latest),
            output: p.output(Self::SCORES),
        }
    }
}

/// The ports of the deliberative layer of a given policy.
pub type PolicyPorts<P> = DeliberativePorts<
    <P as DeliberativePolicy>::HeadGoal,
    <P as DeliberativePolicy>::BodyGoal,
    <P as DeliberativePolicy>::WholeBodyGoal,
    <P as DeliberativePolicy>::World,
    <P as DeliberativePolicy>::Assignment,
>;

/// Ticks the application's deliberative behaviors at the layer's rate.
pub struct DeliberativeModule<P: DeliberativePolicy> {
    policy: P,
    ports: PolicyPorts<P>,
    world: Option<P::World>,
    assignment: Option<P::Assignment>,
    stability: Stability,
}

impl<P: DeliberativePolicy> std::fmt::Debug for DeliberativeModule<P> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeliberativeModule")
            .field("stability", &self.stability)
            .finish_non_exhaustive()
    }
}

impl<P: DeliberativePolicy> DeliberativeModule<P> {
    pub fn new(policy: P, ports: PolicyPorts<P>) -> Self {
        DeliberativeModule {
            policy,
            ports,
            world: None,
            assignment: None,
            stability: Stability::Stable,
        }
    }
}

impl<P> Module for DeliberativeModule<P>
where
    P: DeliberativePolicy + 'static,
    P::World: strata_runtime::Message,
    P::Assignment: strata_runtime::Message,
{
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        if let Some(world) = ctx.latest(self.ports.world) {
            self.world = Some(world.value);
        }
        if let Some(assignment) = ctx.latest(self.ports.assignment) {
            self.assignment = Some(assignment.value);
        }
        if let Some(stability) = ctx.latest(self.ports.stability) {
            self.stability = stability.value;
        }
        let input = DeliberativeInput {
            now: ctx.now(),
            world: self.world.as_ref(),
            assignment: self.assignment.as_ref(),
            stability: self.stability,
        };
        let output = self.policy.tick(&input);
        ctx.send(self.ports.output, output);
        Ok(())
    }
}
