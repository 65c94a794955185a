//! The reactive layer of a humanoid: its three multiplexers and the fall detector, one cycle
//! per percept.

use std::fmt::Debug;

use strata_runtime::Time;

use super::{
    ActuationStatus, FallDetector, FallDetectorConfig, Multiplexer, ReactiveInput, ReactiveReport,
    Stability,
};
use crate::command::{
    ActuationMessage, BodyCommand, HeadCommand, MotionCommands, ResourceGroup, WholeBodyCommand,
};
use crate::control::scores::{Goal, PrimitiveId};
use crate::percept::Percepts;

/// The three multiplexers of a humanoid and the fall detector. `H`, `B`, `X`: the
/// application's head, body and head+body goal types; `W`: the world state type.
pub struct ReactiveLayer<H: Goal, B: Goal, X: Goal, W> {
    pub head: Multiplexer<H, HeadCommand, W>,
    pub body: Multiplexer<B, BodyCommand, W>,
    pub whole_body: Multiplexer<X, WholeBodyCommand, W>,
    fall_detector: FallDetector,
    actuation: ActuationStatus,
}

impl<H: Goal, B: Goal, X: Goal, W> Debug for ReactiveLayer<H, B, X, W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReactiveLayer")
            .field("head", &self.head)
            .field("body", &self.body)
            .field("whole_body", &self.whole_body)
            .finish()
    }
}

impl<H: Goal, B: Goal, X: Goal, W> ReactiveLayer<H, B, X, W> {
    pub fn new(
        head: Multiplexer<H, HeadCommand, W>,
        body: Multiplexer<B, BodyCommand, W>,
        whole_body: Multiplexer<X, WholeBodyCommand, W>,
        fall_detector: FallDetectorConfig,
    ) -> ReactiveLayer<H, B, X, W> {
        ReactiveLayer {
            head,
            body,
            whole_body,
            fall_detector: FallDetector::new(fall_detector),
            actuation: ActuationStatus::default(),
        }
    }

    /// A layer whose three multiplexers are unused ([`Multiplexer::unused`]): an application adds
    /// those it uses with [`ReactiveLayer::with_head`], [`ReactiveLayer::with_body`] and
    /// [`ReactiveLayer::with_whole_body`]; the others never select a goal.
    pub fn empty(fall_detector: FallDetectorConfig) -> ReactiveLayer<H, B, X, W> {
        ReactiveLayer::new(
            Multiplexer::unused(ResourceGroup::Head),
            Multiplexer::unused(ResourceGroup::Body),
            Multiplexer::unused(ResourceGroup::HeadAndBody),
            fall_detector,
        )
    }

    pub fn with_head(mut self, head: Multiplexer<H, HeadCommand, W>) -> Self {
        self.head = head;
        self
    }

    pub fn with_body(mut self, body: Multiplexer<B, BodyCommand, W>) -> Self {
        self.body = body;
        self
    }

    pub fn with_whole_body(mut self, whole_body: Multiplexer<X, WholeBodyCommand, W>) -> Self {
        self.whole_body = whole_body;
        self
    }

    /// Each primitive of the three goal types that its multiplexer lacks
    /// ([`Multiplexer::unregistered`]), by group and name: empty for a layer that registers
    /// every primitive its policies can name. An unused multiplexer's goal type
    /// ([`crate::control::scores::NoGoal`]) has none.
    pub fn unregistered(&self) -> Vec<(ResourceGroup, &'static str)> {
        let head = self.head.unregistered().map(|id| (self.head.group(), id.name()));
        let body = self.body.unregistered().map(|id| (self.body.group(), id.name()));
        let whole = self.whole_body.unregistered().map(|id| (self.whole_body.group(), id.name()));
        head.chain(body).chain(whole).collect()
    }

    pub fn actuation_message(&mut self, message: &ActuationMessage) {
        self.actuation.apply(message);
    }

    pub fn actuation(&self) -> &ActuationStatus {
        &self.actuation
    }

    pub fn stability(&self) -> Stability {
        self.fall_detector.status()
    }

    /// One reactive cycle on the newest percepts. Every call is taken to bring a new world
    /// state: all activation policies are asked.
    pub fn step(&mut self, now: Time, percepts: &Percepts, world: Option<&W>) -> ReactiveReport {
        self.cycle(now, percepts, world, None)
    }

    /// One reactive cycle on the newest percepts, for a caller that numbers the world states
    /// it receives: `world` is the one numbered `revision`. A cycle on the revision of the
    /// previous cycle reuses the answers of activation policies with a reuse key
    /// ([`ActivationShortcuts::reuse_key`]) if their key is the same too: they are the answers
    /// the policies would give again. The fall detector, the ranking with its hysteresis and
    /// the primitives run every cycle.
    ///
    /// [`ActivationShortcuts::reuse_key`]: super::ActivationShortcuts::reuse_key
    pub fn step_on_revision(
        &mut self,
        now: Time,
        percepts: &Percepts,
        world: Option<&W>,
        revision: u64,
    ) -> ReactiveReport {
        self.cycle(now, percepts, world, Some(revision))
    }

    fn cycle(
        &mut self,
        now: Time,
        percepts: &Percepts,
        world: Option<&W>,
        revision: Option<u64>,
    ) -> ReactiveReport {
        let stability = self.fall_detector.update(percepts);
        let input = ReactiveInput { now, percepts, world, actuation: &self.actuation, stability };
        let whole = self.whole_body.evaluate_on(&input, revision);
        let head = self.head.evaluate_on(&input, revision);
        let body = self.body.evaluate_on(&input, revision);
        let best_separate = head
            .as_ref()
            .map(|s| s.final_score)
            .into_iter()
            .chain(body.as_ref().map(|s| s.final_score))
            .fold(f64::NEG_INFINITY, f64::max);
        let commands = match whole {
            Some(selection) if selection.final_score >= best_separate => {
                self.head.idle(Some(ResourceGroup::HeadAndBody));
                self.body.idle(Some(ResourceGroup::HeadAndBody));
                match self.whole_body.execute(&selection, &input) {
                    Some(command) => MotionCommands::WholeBody { command },
                    None => MotionCommands::default(),
                }
            }
            _ => {
                self.whole_body.idle(None);
                let head = match head {
                    Some(selection) => self.head.execute(&selection, &input),
                    None => {
                        self.head.idle(None);
                        None
                    }
                };
                let body = match body {
                    Some(selection) => self.body.execute(&selection, &input),
                    None => {
                        self.body.idle(None);
                        None
                    }
                };
                MotionCommands::PerResource { head, body }
            }
        };
        // A finishing notification asks for one next action; it has been answered.
        self.actuation.finishing.clear();
        ReactiveReport {
            stamp: percepts.stamp,
            stability,
            head: self.head.take_report(),
            body: self.body.take_report(),
            whole_body: self.whole_body.take_report(),
            commands,
        }
    }
}
