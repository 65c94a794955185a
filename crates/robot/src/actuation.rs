//! The actuation module (paper 3.5.1): keeps a command queue per resource, applies the three
//! command policies, turns commands into platform orders, and tells the reactive layer what it
//! needs to know — the odometry of the current command, that a command is about to finish (the
//! resource will be released), and that a cyclic command is in its execution stage (it can be
//! changed now without disturbing the robot).
//!
//! Policies:
//! - Queue: appended behind what is queued; a walk followed by a queued walk continues the gait
//!   without its end and initialization stages.
//! - Non-queue: clears the resource's queue and replaces the current command at once.
//! - Special: a non-parametric sequence. It takes its resources until the platform reports it
//!   done; commands for them are rejected meanwhile. A protective fall preempts anything.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};
use strata_runtime::{
    Context, Input, Module, ModuleError, Output, Policy, PortName, Ports, Time, Trigger,
};

use crate::command::{
    ActuationMessage, BodyCommand, BodyMotion, HeadCommand, HeadMotion, MotionCommands, Resource,
    WholeBodyCommand,
};
use crate::edge::OrderRefused;
use crate::geometry::{Odometry, Velocity};
use crate::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, HeadOrder, MotionFeedback, MotionName,
    SpecialMotion,
};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActuationConfig {
    /// How long before a command ends actuation announces it (asks for the next action), s.
    pub finishing_lead: f64,
}

impl Default for ActuationConfig {
    fn default() -> Self {
        ActuationConfig { finishing_lead: 0.15 }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum BodyExecution {
    Idle,
    Standing,
    Walking {
        velocity: Velocity,
        remaining: f64,
    },
    /// `waited`: how long it has waited for the platform to start it, s.
    Special {
        motion: SpecialMotion,
        started: bool,
        waited: f64,
    },
}

/// A special sequence the platform has not started within this is given up, its resources
/// released, s: a platform that accepts an order and never runs it (a T1 told to fall while
/// it lies already) would otherwise hold the body for good, and a fallen robot would never be
/// told to stand up.
const SPECIAL_START_DEADLINE: f64 = 1.0;

/// The command queues and the state of execution; pure, so it can be tested without a
/// platform or threads.
#[derive(Clone, Debug)]
pub struct ActuationState {
    config: ActuationConfig,
    head_queue: VecDeque<HeadMotion>,
    head_current: Option<HeadMotion>,
    head_announced: bool,
    /// The stamp of the newest feedback when the current head motion was ordered: feedback
    /// no newer than it was measured before the order reached the platform, and its
    /// "settled" is about the previous target.
    head_ordered_after: Option<Time>,
    body_queue: VecDeque<BodyMotion>,
    body: BodyExecution,
    body_announced: bool,
    /// A whole-body sequence holds the head too.
    head_held_by_special: bool,
    last_stage: Option<CycleStage>,
    last_time: Option<Time>,
    messages: Vec<ActuationMessage>,
    orders: ActuatorOrders,
}

impl ActuationState {
    pub fn new(config: ActuationConfig) -> ActuationState {
        ActuationState {
            config,
            head_queue: VecDeque::new(),
            head_current: None,
            head_announced: false,
            head_ordered_after: None,
            body_queue: VecDeque::new(),
            body: BodyExecution::Idle,
            body_announced: false,
            head_held_by_special: false,
            last_stage: None,
            last_time: None,
            messages: Vec::new(),
            orders: ActuatorOrders::default(),
        }
    }

    fn reject(&mut self, resource: Resource, reason: &str) {
        self.messages
            .push(ActuationMessage::CommandRejected { resource, reason: reason.to_owned() });
    }

    fn body_busy(&self) -> bool {
        matches!(self.body, BodyExecution::Special { .. })
    }

    fn start_special(&mut self, motion: SpecialMotion) {
        self.body_queue.clear();
        self.body = BodyExecution::Special { motion, started: false, waited: 0.0 };
        self.orders.body = Some(BodyOrder::Special { motion });
        self.messages.push(ActuationMessage::ResourceBusy { resource: Resource::Body });
        if motion.head {
            self.head_queue.clear();
            self.head_current = None;
            self.head_held_by_special = true;
            self.messages.push(ActuationMessage::ResourceBusy { resource: Resource::Head });
        }
    }

    fn start_body(&mut self, motion: BodyMotion) {
        self.body_announced = false;
        match motion {
            BodyMotion::Stand => {
                self.body = BodyExecution::Standing;
                self.orders.body = Some(BodyOrder::Stand);
            }
            BodyMotion::Walk { velocity, duration } => {
                self.body = BodyExecution::Walking { velocity, remaining: duration.max(0.0) };
                self.orders.body = Some(BodyOrder::Walk { velocity });
            }
        }
    }

    fn start_head(&mut self, motion: HeadMotion) {
        self.head_current = Some(motion);
        self.head_announced = false;
        self.head_ordered_after = self.last_time;
        self.orders.head = Some(HeadOrder { target: motion.target, max_speed: motion.max_speed });
    }

    /// Applies one cycle's commands from the reactive layer.
    pub fn command(&mut self, commands: &MotionCommands) {
        match *commands {
            MotionCommands::WholeBody { command: WholeBodyCommand::Coordinated { head, body } } => {
                self.command(&MotionCommands::PerResource { head: Some(head), body: Some(body) });
            }
            MotionCommands::WholeBody { command: WholeBodyCommand::Special { motion } } => {
                let preempts = motion.is(MotionName::FALL);
                let already =
                    matches!(self.body, BodyExecution::Special { motion: m, .. } if m == motion);
                if already {
                    return;
                }
                if self.body_busy() && !preempts {
                    self.reject(Resource::Body, "a special sequence is running");
                    return;
                }
                self.start_special(motion);
            }
            MotionCommands::PerResource { head, body } => {
                if let Some(head) = head {
                    if self.head_held_by_special {
                        self.reject(Resource::Head, "a whole-body sequence holds the head");
                    } else {
                        match head {
                            HeadCommand::NonQueue(motion) => {
                                self.head_queue.clear();
                                self.start_head(motion);
                            }
                            HeadCommand::Queue(motion) => {
                                if self.head_current.is_none() {
                                    self.start_head(motion);
                                } else {
                                    self.head_queue.push_back(motion);
                                }
                            }
                        }
                    }
                }
                if let Some(body) = body {
                    if self.body_busy() {
                        self.reject(Resource::Body, "a special sequence is running");
                    } else {
                        match body {
                            BodyCommand::Special(motion) => self.start_special(motion),
                            BodyCommand::NonQueue(motion) => {
                                self.body_queue.clear();
                                self.start_body(motion);
                            }
                            BodyCommand::Queue(motion) => {
                                if matches!(self.body, BodyExecution::Idle) {
                                    self.start_body(motion);
                                } else {
                                    self.body_queue.push_back(motion);
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Advances execution with the platform's feedback; returns the orders to write (if any
    /// changed) and the messages for the reactive layer.
    pub fn update(
        &mut self,
        feedback: &MotionFeedback,
    ) -> (Option<ActuatorOrders>, Vec<ActuationMessage>) {
        let now = feedback.stamp;
        let dt = self.last_time.map_or(0.0, |t| (now - t).as_secs_f64());
        self.last_time = Some(now);

        if feedback.odometry != Odometry::ZERO {
            self.messages.push(ActuationMessage::CommandOdometry { odometry: feedback.odometry });
        }

        // Body.
        match (&mut self.body, feedback.body) {
            (BodyExecution::Special { started, .. }, BodyMotionState::Special { .. }) => {
                *started = true;
            }
            (BodyExecution::Special { started: true, .. }, _) => {
                // The sequence ended (standing, or lying after a fall): the resources are free.
                self.release_special();
            }
            (BodyExecution::Special { motion, started: false, waited }, state) => {
                *waited += dt;
                let (motion, late) = (*motion, *waited > SPECIAL_START_DEADLINE);
                // A fall ordered as the robot came to lie is over before it began.
                let fall_over =
                    motion.is(MotionName::FALL) && matches!(state, BodyMotionState::Fallen { .. });
                if !fall_over && late {
                    self.reject(
                        Resource::Body,
                        &format!(
                            "the platform did not start {motion} within {SPECIAL_START_DEADLINE} s"
                        ),
                    );
                }
                if fall_over || late {
                    self.release_special();
                }
            }
            (BodyExecution::Walking { remaining, .. }, state) => {
                let stage = match state {
                    BodyMotionState::Walking { stage, .. } => Some(stage),
                    _ => None,
                };
                if stage == Some(CycleStage::Execution) {
                    *remaining -= dt;
                }
                let remaining = *remaining;
                if stage == Some(CycleStage::Execution)
                    && self.last_stage != Some(CycleStage::Execution)
                {
                    self.messages
                        .push(ActuationMessage::CommandCyclicPart { resource: Resource::Body });
                }
                self.last_stage = stage;
                if remaining <= self.config.finishing_lead
                    && self.body_queue.is_empty()
                    && !self.body_announced
                {
                    self.body_announced = true;
                    self.messages.push(ActuationMessage::CommandFinishing {
                        resource: Resource::Body,
                        remaining: remaining.max(0.0),
                    });
                }
                if remaining <= 0.0 {
                    match self.body_queue.pop_front() {
                        // A queued walk continues the gait: only the velocity changes.
                        Some(next) => self.start_body(next),
                        None => {
                            self.body = BodyExecution::Standing;
                            self.orders.body = Some(BodyOrder::Stand);
                        }
                    }
                }
            }
            (BodyExecution::Standing, _) | (BodyExecution::Idle, _) => {
                if let Some(next) = self.body_queue.pop_front() {
                    self.start_body(next);
                }
            }
        }
        if !matches!(self.body, BodyExecution::Walking { .. }) {
            self.last_stage = None;
        }

        // Head.
        if let Some(current) = self.head_current {
            let error = (feedback.head.yaw - current.target.yaw)
                .abs()
                .max((feedback.head.pitch - current.target.pitch).abs());
            let eta = if current.max_speed > 0.0 { error / current.max_speed } else { 0.0 };
            // The feedback describes the previous target until the platform has received the
            // order: a queued motion must wait for its own settling. A platform whose feedback
            // comes from another thread can hand over a sample taken before the order a cycle
            // or two later (the T1 in rcssservermj under load), so feedback stamped no later
            // than the order is not heard on settling.
            let ordered_this_cycle = self.orders.head.is_some();
            let fresh = self.head_ordered_after.is_none_or(|t| feedback.stamp > t);
            let ended = !ordered_this_cycle && ((fresh && feedback.head_settled) || error < 0.01);
            // Every motion with nothing queued behind it is announced once, at the latest when
            // it ends: a head path waits for the announcement to go on, and a motion that ended
            // unannounced (a sample taken before the order and stamped after the last one)
            // would stop it for good.
            if self.head_queue.is_empty()
                && !self.head_announced
                && (eta <= self.config.finishing_lead || ended)
            {
                self.head_announced = true;
                self.messages.push(ActuationMessage::CommandFinishing {
                    resource: Resource::Head,
                    remaining: if ended { 0.0 } else { eta },
                });
            }
            if ended {
                match self.head_queue.pop_front() {
                    Some(next) => self.start_head(next),
                    None => self.head_current = None,
                }
            }
        }

        let orders = std::mem::take(&mut self.orders);
        let messages = std::mem::take(&mut self.messages);
        let changed = orders.head.is_some() || orders.body.is_some();
        (changed.then_some(orders), messages)
    }

    fn release_special(&mut self) {
        self.body = BodyExecution::Idle;
        self.orders.body = None;
        self.messages.push(ActuationMessage::ResourceReleased { resource: Resource::Body });
        if self.head_held_by_special {
            self.head_held_by_special = false;
            self.messages.push(ActuationMessage::ResourceReleased { resource: Resource::Head });
        }
    }

    /// The platform refused the last body order (a motion not in its catalogue, say): a special
    /// sequence that never started must not hold its resources.
    pub fn body_order_refused(&mut self) -> Vec<ActuationMessage> {
        let mut messages = Vec::new();
        if let BodyExecution::Special { started: false, .. } = self.body {
            self.body = BodyExecution::Idle;
            messages.push(ActuationMessage::ResourceReleased { resource: Resource::Body });
            if self.head_held_by_special {
                self.head_held_by_special = false;
                messages.push(ActuationMessage::ResourceReleased { resource: Resource::Head });
            }
        } else if let BodyExecution::Walking { .. } = self.body {
            self.body = BodyExecution::Idle;
        }
        self.body_queue.clear();
        messages
    }

    pub fn head_queue_len(&self) -> usize {
        self.head_queue.len()
    }

    pub fn body_queue_len(&self) -> usize {
        self.body_queue.len()
    }
}

/// The ports of the actuation module, declared once for the assembly and for replay.
#[derive(Clone, Copy, Debug)]
pub struct ActuationPorts {
    pub commands: Input<MotionCommands>,
    /// The platform's motion state and odometry, merged: the newest state, the odometry since
    /// the last cycle composed.
    pub motion: Input<MotionFeedback>,
    /// Orders the platform refused, handled with the next commands (the reactive layer sends
    /// commands every cycle; a refusal waking actuation would close a loop of same-instant
    /// triggers through the actuator sink).
    pub refusals: Input<OrderRefused>,
    pub orders: Output<ActuatorOrders>,
    pub odometry: Output<Odometry>,
    pub messages: Output<ActuationMessage>,
    pub feedback: Output<MotionFeedback>,
}

impl ActuationPorts {
    pub const COMMANDS: PortName<MotionCommands> = PortName::new("commands");
    pub const MOTION: PortName<MotionFeedback> = PortName::new("motion");
    pub const REFUSALS: PortName<OrderRefused> = PortName::new("refusals");
    pub const ORDERS: PortName<ActuatorOrders> = PortName::new("orders");
    pub const ODOMETRY: PortName<Odometry> = PortName::new("odometry");
    pub const MESSAGES: PortName<ActuationMessage> = PortName::new("messages");
    pub const FEEDBACK: PortName<MotionFeedback> = PortName::new("feedback");

    /// Declares the ports; actuation runs on every command.
    pub fn declare(p: &mut Ports<'_>) -> ActuationPorts {
        let ports = ActuationPorts {
            commands: p.input(Self::COMMANDS, Policy::queue(16)),
            motion: p.input(Self::MOTION, Policy::merge(merge_feedback)),
            refusals: p.input(Self::REFUSALS, Policy::queue(16)),
            orders: p.output(Self::ORDERS),
            odometry: p.output(Self::ODOMETRY),
            messages: p.output(Self::MESSAGES),
            feedback: p.output(Self::FEEDBACK),
        };
        p.trigger(Trigger::on_any([ports.commands.into()]));
        ports
    }
}

/// Folds a newer motion feedback into a pending one: the newer state, both odometries.
fn merge_feedback(pending: &mut MotionFeedback, newer: MotionFeedback) {
    let odometry = pending.odometry.then(newer.odometry);
    *pending = MotionFeedback { odometry, ..newer };
}

/// The actuation module: runs on every command package from the reactive layer, with the
/// platform's newest motion feedback.
pub struct ActuationModule {
    state: ActuationState,
    ports: ActuationPorts,
    /// The newest feedback, for commands that arrive before the next one (its odometry is
    /// spent).
    last_feedback: Option<MotionFeedback>,
}

impl std::fmt::Debug for ActuationModule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActuationModule").field("state", &self.state).finish_non_exhaustive()
    }
}

impl ActuationModule {
    pub fn new(config: ActuationConfig, ports: ActuationPorts) -> ActuationModule {
        ActuationModule { state: ActuationState::new(config), ports, last_feedback: None }
    }
}

impl Module for ActuationModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        // An unsupported order (a NAO without a gait engine asked to walk) is reported to the
        // reactive layer instead of stopping the robot.
        for refused in ctx.drain(self.ports.refusals) {
            let OrderRefused { resource, reason } = refused.value;
            ctx.send(self.ports.messages, ActuationMessage::CommandRejected { resource, reason });
            // A refused special sequence never starts: its resources must not stay held
            // waiting for it to end.
            if resource == Resource::Body {
                for released in self.state.body_order_refused() {
                    ctx.send(self.ports.messages, released);
                }
            }
        }
        for package in ctx.drain(self.ports.commands) {
            self.state.command(&package.value);
        }
        let feedback = match ctx.take(self.ports.motion) {
            Some(package) => package.value,
            None => match self.last_feedback {
                Some(last) => MotionFeedback { odometry: Odometry::ZERO, ..last },
                // Nothing measured yet: the commands wait in their queues.
                None => return Ok(()),
            },
        };
        self.last_feedback = Some(feedback);
        let (orders, messages) = self.state.update(&feedback);
        if let Some(orders) = orders {
            ctx.send(self.ports.orders, orders);
        }
        if feedback.odometry != Odometry::ZERO {
            ctx.send_stamped(self.ports.odometry, feedback.odometry, feedback.stamp);
        }
        for message in messages {
            ctx.send_stamped(self.ports.messages, message, feedback.stamp);
        }
        ctx.send_stamped(self.ports.feedback, feedback, feedback.stamp);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::HeadAngles;

    /// An application's sequence of the body alone: the head stays free.
    const WAVE: SpecialMotion = SpecialMotion::new(MotionName::from_static("wave"), 0, false);

    fn feedback(t: f64, body: BodyMotionState) -> MotionFeedback {
        MotionFeedback {
            stamp: Time::from_secs_f64(t),
            body,
            head: HeadAngles::default(),
            head_settled: true,
            odometry: Odometry::ZERO,
        }
    }

    fn walk(vx: f64, duration: f64) -> BodyMotion {
        BodyMotion::Walk { velocity: Velocity::new(vx, 0.0, 0.0), duration }
    }

    fn executing(vx: f64) -> BodyMotionState {
        BodyMotionState::Walking {
            stage: CycleStage::Execution,
            velocity: Velocity::new(vx, 0.0, 0.0),
        }
    }

    #[test]
    fn queued_walks_continue_without_stopping_and_non_queue_overwrites() {
        let mut a = ActuationState::new(ActuationConfig { finishing_lead: 0.1 });
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Queue(walk(0.1, 0.5))),
        });
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Queue(walk(0.2, 0.5))),
        });
        let (orders, messages) = a.update(&feedback(0.0, BodyMotionState::Standing));
        assert_eq!(
            orders.and_then(|o| o.body),
            Some(BodyOrder::Walk { velocity: Velocity::new(0.1, 0.0, 0.0) })
        );
        assert!(messages.is_empty());
        let (_, messages) = a.update(&feedback(0.1, executing(0.1)));
        assert!(
            messages.contains(&ActuationMessage::CommandCyclicPart { resource: Resource::Body })
        );
        // After the first walk's 0.5 s the second follows with no stand in between.
        let (orders, _) = a.update(&feedback(0.65, executing(0.1)));
        assert_eq!(
            orders.and_then(|o| o.body),
            Some(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) })
        );
        // The second walk is the last: actuation announces its end before it comes.
        let (_, messages) = a.update(&feedback(1.1, executing(0.2)));
        assert!(messages.iter().any(|m| matches!(
            m,
            ActuationMessage::CommandFinishing { resource: Resource::Body, .. }
        )));
        let (orders, _) = a.update(&feedback(1.2, executing(0.2)));
        assert_eq!(orders.and_then(|o| o.body), Some(BodyOrder::Stand));

        // Non-queue clears the queue and replaces the current command at once.
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Queue(walk(0.1, 5.0))),
        });
        let _ = a.update(&feedback(1.3, BodyMotionState::Standing));
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Queue(walk(0.3, 5.0))),
        });
        assert_eq!(a.body_queue_len(), 1);
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::NonQueue(walk(-0.1, 1.0))),
        });
        assert_eq!(a.body_queue_len(), 0);
        let (orders, _) = a.update(&feedback(1.4, executing(0.1)));
        assert_eq!(
            orders.and_then(|o| o.body),
            Some(BodyOrder::Walk { velocity: Velocity::new(-0.1, 0.0, 0.0) })
        );
    }

    #[test]
    fn special_sequences_hold_their_resources_until_done_and_a_fall_preempts() {
        let mut a = ActuationState::new(ActuationConfig::default());
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Special(WAVE)),
        });
        let (orders, messages) = a.update(&feedback(0.0, BodyMotionState::Standing));
        assert_eq!(orders.and_then(|o| o.body), Some(BodyOrder::Special { motion: WAVE }));
        assert!(messages.contains(&ActuationMessage::ResourceBusy { resource: Resource::Body }));
        let waving = BodyMotionState::Special { motion: WAVE, elapsed: 0.1, duration: 1.0 };
        let _ = a.update(&feedback(0.1, waving));
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::NonQueue(walk(0.1, 1.0))),
        });
        let (_, messages) = a.update(&feedback(0.2, waving));
        assert!(messages.iter().any(|m| matches!(
            m,
            ActuationMessage::CommandRejected { resource: Resource::Body, .. }
        )));
        // A sequence of the body alone leaves the head to head commands.
        a.command(&MotionCommands::PerResource {
            head: Some(HeadCommand::NonQueue(HeadMotion {
                target: HeadAngles { yaw: 0.5, pitch: 0.0 },
                max_speed: 2.0,
            })),
            body: None,
        });
        let (orders, _) = a.update(&feedback(0.3, waving));
        assert!(orders.and_then(|o| o.head).is_some());
        // A fall preempts it and takes the head too.
        a.command(&MotionCommands::WholeBody {
            command: WholeBodyCommand::Special { motion: SpecialMotion::fall(0) },
        });
        let (orders, messages) = a.update(&feedback(0.35, waving));
        assert_eq!(
            orders.and_then(|o| o.body),
            Some(BodyOrder::Special { motion: SpecialMotion::fall(0) })
        );
        assert!(messages.contains(&ActuationMessage::ResourceBusy { resource: Resource::Head }));
        let falling = BodyMotionState::Special {
            motion: SpecialMotion::fall(0),
            elapsed: 0.1,
            duration: 0.5,
        };
        let _ = a.update(&feedback(0.4, falling));
        let (_, messages) = a.update(&feedback(
            1.0,
            BodyMotionState::Fallen { direction: crate::platform::FallDirection::Front },
        ));
        assert!(
            messages.contains(&ActuationMessage::ResourceReleased { resource: Resource::Body })
        );
        assert!(
            messages.contains(&ActuationMessage::ResourceReleased { resource: Resource::Head })
        );
    }

    #[test]
    fn a_fall_ordered_while_the_robot_lies_ends_at_once_and_a_stand_up_follows() {
        let mut a = ActuationState::new(ActuationConfig::default());
        let lying = BodyMotionState::Fallen { direction: crate::platform::FallDirection::Back };
        a.command(&MotionCommands::WholeBody {
            command: WholeBodyCommand::Special { motion: SpecialMotion::fall(0) },
        });
        // The T1 takes the order and goes on lying: the fall is over before it began.
        let (_, messages) = a.update(&feedback(0.0, lying));
        assert!(
            messages.contains(&ActuationMessage::ResourceReleased { resource: Resource::Body })
        );
        let stand_up = SpecialMotion::stand_up(1);
        a.command(&MotionCommands::WholeBody {
            command: WholeBodyCommand::Special { motion: stand_up },
        });
        let (orders, messages) = a.update(&feedback(0.02, lying));
        assert_eq!(orders.and_then(|o| o.body), Some(BodyOrder::Special { motion: stand_up }));
        assert!(messages.iter().all(|m| !matches!(m, ActuationMessage::CommandRejected { .. })));
    }

    #[test]
    fn a_special_sequence_the_platform_never_starts_is_given_up() {
        let mut a = ActuationState::new(ActuationConfig::default());
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Special(WAVE)),
        });
        let mut released_at = None;
        let mut rejected = false;
        for k in 0..100 {
            let at = 0.02 * f64::from(k);
            let (_, messages) = a.update(&feedback(at, BodyMotionState::Standing));
            rejected |=
                messages.iter().any(|m| matches!(m, ActuationMessage::CommandRejected { .. }));
            if messages.contains(&ActuationMessage::ResourceReleased { resource: Resource::Body }) {
                released_at.get_or_insert(at);
            }
        }
        let Some(at) = released_at else { panic!("the body stays held") };
        assert!(
            (SPECIAL_START_DEADLINE..SPECIAL_START_DEADLINE + 0.05).contains(&(at + 1e-9)),
            "{at}"
        );
        assert!(rejected, "the reason is reported");
    }

    #[test]
    fn a_refused_special_sequence_releases_its_resources() {
        let mut a = ActuationState::new(ActuationConfig::default());
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::Special(WAVE)),
        });
        let _ = a.update(&feedback(0.0, BodyMotionState::Standing));
        let released = a.body_order_refused();
        assert_eq!(released, vec![ActuationMessage::ResourceReleased { resource: Resource::Body }]);
        a.command(&MotionCommands::PerResource {
            head: None,
            body: Some(BodyCommand::NonQueue(walk(0.1, 1.0))),
        });
        let (orders, messages) = a.update(&feedback(0.1, BodyMotionState::Standing));
        assert!(messages.iter().all(|m| !matches!(m, ActuationMessage::CommandRejected { .. })));
        assert!(matches!(orders.and_then(|o| o.body), Some(BodyOrder::Walk { .. })));
    }

    #[test]
    fn a_queued_head_motion_waits_for_its_predecessor_even_when_the_head_was_settled() {
        let mut a = ActuationState::new(ActuationConfig::default());
        let target = |yaw| HeadMotion { target: HeadAngles { yaw, pitch: 0.0 }, max_speed: 1.0 };
        for yaw in [0.5, -0.5] {
            a.command(&MotionCommands::PerResource {
                head: Some(HeadCommand::Queue(target(yaw))),
                body: None,
            });
        }
        // The feedback still says "settled" about the resting head: it must not count as the
        // end of the motion just ordered.
        let fb = feedback(0.0, BodyMotionState::Standing);
        let (orders, _) = a.update(&fb);
        assert_eq!(orders.and_then(|o| o.head).map(|h| h.target.yaw), Some(0.5));
        assert_eq!(a.head_queue_len(), 1);
    }

    #[test]
    fn head_queue_follows_a_path_and_announces_its_end() {
        let mut a = ActuationState::new(ActuationConfig { finishing_lead: 0.1 });
        let target = |yaw| HeadMotion { target: HeadAngles { yaw, pitch: 0.0 }, max_speed: 1.0 };
        for yaw in [0.5, -0.5] {
            a.command(&MotionCommands::PerResource {
                head: Some(HeadCommand::Queue(target(yaw))),
                body: None,
            });
        }
        let mut fb = feedback(0.0, BodyMotionState::Standing);
        fb.head_settled = false;
        let (orders, _) = a.update(&fb);
        assert_eq!(orders.and_then(|o| o.head).map(|h| h.target.yaw), Some(0.5));
        fb.head = HeadAngles { yaw: 0.5, pitch: 0.0 };
        fb.head_settled = true;
        fb.stamp = Time::from_secs_f64(0.5);
        let (orders, _) = a.update(&fb);
        assert_eq!(orders.and_then(|o| o.head).map(|h| h.target.yaw), Some(-0.5));
        fb.head = HeadAngles { yaw: -0.45, pitch: 0.0 };
        fb.head_settled = false;
        fb.stamp = Time::from_secs_f64(1.4);
        let (_, messages) = a.update(&fb);
        assert!(messages.iter().any(|m| matches!(
            m,
            ActuationMessage::CommandFinishing { resource: Resource::Head, .. }
        )));
    }

    #[test]
    fn a_stale_settled_feedback_does_not_end_the_head_motion_just_ordered() {
        let mut a = ActuationState::new(ActuationConfig { finishing_lead: 0.1 });
        let target = |yaw| HeadMotion { target: HeadAngles { yaw, pitch: 0.0 }, max_speed: 1.0 };
        a.command(&MotionCommands::PerResource {
            head: Some(HeadCommand::NonQueue(target(-1.0))),
            body: None,
        });
        a.command(&MotionCommands::PerResource {
            head: Some(HeadCommand::Queue(target(0.5))),
            body: None,
        });
        let mut fb = feedback(0.9, BodyMotionState::Standing);
        fb.head_settled = false;
        let (orders, _) = a.update(&fb);
        assert_eq!(orders.and_then(|o| o.head).map(|h| h.target.yaw), Some(-1.0));
        // The first target reached: the queued one is ordered in this update.
        fb.stamp = Time::from_secs_f64(1.0);
        fb.head = HeadAngles { yaw: -1.0, pitch: 0.0 };
        fb.head_settled = true;
        let (orders, _) = a.update(&fb);
        assert_eq!(orders.and_then(|o| o.head).map(|h| h.target.yaw), Some(0.5));
        // The same sample again, a cycle later: measured before the order reached the platform.
        let (orders, messages) = a.update(&fb);
        assert!(orders.is_none() && messages.is_empty(), "{orders:?} {messages:?}");
        // The head on its way, then near the target: the end is announced.
        fb.stamp = Time::from_secs_f64(1.02);
        fb.head_settled = false;
        assert!(a.update(&fb).1.is_empty());
        fb.stamp = Time::from_secs_f64(2.4);
        fb.head = HeadAngles { yaw: 0.45, pitch: 0.0 };
        let (_, messages) = a.update(&fb);
        assert!(
            messages.iter().any(|m| matches!(
                m,
                ActuationMessage::CommandFinishing { resource: Resource::Head, .. }
            )),
            "{messages:?}"
        );
    }

    #[test]
    fn a_head_motion_that_ends_unannounced_is_announced_as_it_ends() {
        let mut a = ActuationState::new(ActuationConfig { finishing_lead: 0.1 });
        let mut fb = feedback(1.0, BodyMotionState::Standing);
        fb.head_settled = true;
        a.update(&fb);
        a.command(&MotionCommands::PerResource {
            head: Some(HeadCommand::Queue(HeadMotion {
                target: HeadAngles { yaw: 1.0, pitch: 0.0 },
                max_speed: 1.0,
            })),
            body: None,
        });
        let (orders, _) = a.update(&fb);
        assert!(orders.is_some_and(|o| o.head.is_some()));
        // Taken before the order reached the platform, stamped after the last sample: it
        // ends the motion far from its target, but the end is announced.
        fb.stamp = Time::from_secs_f64(1.02);
        let (_, messages) = a.update(&fb);
        assert!(
            messages.iter().any(|m| matches!(
                m,
                ActuationMessage::CommandFinishing { resource: Resource::Head, remaining }
                    if *remaining == 0.0
            )),
            "{messages:?}"
        );
    }

    /// A platform that refuses every special sequence (its catalogue is empty).
    struct RefusesSpecialMotions {
        wrote: u32,
    }

    impl crate::platform::Platform for RefusesSpecialMotions {
        fn info(&self) -> crate::platform::PlatformInfo {
            crate::platform::PlatformInfo {
                name: "refuses special motions".into(),
                sensor_period: std::time::Duration::from_millis(12),
                camera_fov: 1.06,
                camera_range: 5.0,
                head_yaw_limits: (-2.0, 2.0),
                head_pitch_limits: (-0.6, 0.5),
                max_head_speed: 3.0,
                max_velocity: Velocity::new(0.25, 0.15, 1.2),
                motions: Vec::new(),
                can_walk: true,
            }
        }

        fn read_sensors(
            &mut self,
            _: Time,
        ) -> Result<Option<crate::platform::SensorFrame>, crate::platform::PlatformError> {
            Ok(None)
        }

        fn read_motion(
            &mut self,
            now: Time,
        ) -> Result<MotionFeedback, crate::platform::PlatformError> {
            Ok(feedback(now.as_secs_f64(), BodyMotionState::Standing))
        }

        fn write(
            &mut self,
            _: Time,
            orders: &ActuatorOrders,
        ) -> Result<(), crate::platform::PlatformError> {
            self.wrote += 1;
            match orders.body {
                Some(BodyOrder::Special { .. }) => {
                    Err(crate::platform::PlatformError::Unsupported("no wave".into()))
                }
                _ => Ok(()),
            }
        }
    }

    #[test]
    fn the_module_releases_the_resources_of_a_sequence_the_platform_refused() {
        use strata_runtime::{GraphBuilder, HostConfig, LockstepHost, Policy};

        let platform: crate::platform::SharedPlatform =
            std::sync::Arc::new(std::sync::Mutex::new(RefusesSpecialMotions { wrote: 0 }));
        let mut graph = GraphBuilder::new();
        let ports = graph.add("actuation", |p| {
            let ports = ActuationPorts::declare(p);
            (ActuationModule::new(ActuationConfig::default(), ports), ports)
        });
        let (sensors, actuators) = crate::edge::add_platform_edge(
            &mut graph,
            "robot",
            platform,
            std::time::Duration::from_millis(12),
        );
        graph.connect(sensors.motion, ports.motion);
        graph.connect(ports.orders, actuators.orders);
        graph.connect(actuators.refusals, ports.refusals);
        let (commands, messages) = (ports.commands, ports.messages);
        let received = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let sink = graph.add("sink", |p| {
            let input = p.input::<ActuationMessage>("messages", Policy::queue(64));
            (Collect { input, received: std::sync::Arc::clone(&received) }, input)
        });
        graph.connect(messages, sink);
        graph.external(commands);
        let mut host =
            LockstepHost::new(graph.build().expect("valid graph"), HostConfig::with_seed(1));
        let at = Time::from_secs_f64(0.1);
        let wave =
            MotionCommands::PerResource { head: None, body: Some(BodyCommand::Special(WAVE)) };
        host.inject(commands, wave, at, at).expect("external input");
        // The refusal is handled with the next commands, as the reactive layer sends every cycle.
        let next = Time::from_secs_f64(0.2);
        let none = MotionCommands::PerResource { head: None, body: None };
        host.inject(commands, none, next, next).expect("external input");
        host.run_for(std::time::Duration::from_millis(500)).expect("runs");

        let received = received.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        assert!(
            received.iter().any(|m| matches!(
                m,
                ActuationMessage::CommandRejected { resource: Resource::Body, .. }
            )),
            "{received:?}"
        );
        assert!(
            received.iter().any(|m| matches!(
                m,
                ActuationMessage::ResourceReleased { resource: Resource::Body }
            )),
            "the refused sequence must not keep the body busy: {received:?}"
        );
    }

    struct Collect {
        input: strata_runtime::Input<ActuationMessage>,
        received: std::sync::Arc<std::sync::Mutex<Vec<ActuationMessage>>>,
    }

    impl Module for Collect {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let mut received =
                self.received.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            received.extend(ctx.drain(self.input).into_iter().map(|p| p.value));
            Ok(())
        }
    }
}
