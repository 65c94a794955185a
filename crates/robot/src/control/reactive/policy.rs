//! The application's part of the reactive layer: what a primitive behavior sees, the
//! primitive behaviors and the activation policies of the multiplexers.

use std::fmt::Debug;

use strata_runtime::Time;

use super::{ActuationStatus, Stability};
use crate::control::scores::{Goal, GoalScore};
use crate::percept::Percepts;

/// What a primitive behavior sees each cycle: the newest data, never older (paper 3.5).
#[derive(Debug)]
pub struct ReactiveInput<'a, W> {
    pub now: Time,
    pub percepts: &'a Percepts,
    /// The newest world state, if world modeling has published one.
    pub world: Option<&'a W>,
    pub actuation: &'a ActuationStatus,
    pub stability: Stability,
}

/// A primitive behavior (paper 3.5.1): a short-term policy for one resource group, pursuing a
/// goal set by the deliberative layer. It knows nothing of the consequences of its actions.
pub trait PrimitiveBehavior<G: Goal, Cmd, W>: Send {
    /// Which of the goal type's primitives this is: what activation policies name it by.
    fn id(&self) -> G::Primitive;

    /// The multiplexer activated this primitive (it was not active in the previous cycle, or
    /// its goal changed).
    fn activate(&mut self, _goal: &G, _input: &ReactiveInput<'_, W>) {}

    /// This cycle's command toward `goal`; `None` leaves actuation doing what it does.
    fn step(&mut self, goal: &G, input: &ReactiveInput<'_, W>) -> Option<Cmd>;

    /// Another primitive took over the resource, or the primitive was inhibited.
    fn deactivate(&mut self) {}
}

/// The application's part of a multiplexer's activation function.
pub trait ActivationPolicy<G: Goal, W>: Send {
    /// Stage 1: a goal that cannot be executed now as one (several objects that do not fit in
    /// one gaze) is divided into goals that can (`Some`, possibly empty: the goal cannot be
    /// pursued at all). `None`, the default, keeps the goal as offered — the common case, which
    /// the reactive cycle runs without copying the goal.
    fn split(
        &self,
        _goal: &GoalScore<G>,
        _input: &ReactiveInput<'_, W>,
    ) -> Option<Vec<GoalScore<G>>> {
        None
    }

    /// Stage 2: the reactive score S_r in [0, 1], refreshed on every percept.
    fn reactive_score(&self, goal: &GoalScore<G>, input: &ReactiveInput<'_, W>) -> f64;

    /// The primitive behaviors that can pursue `goal` given the percepts, preferred first.
    /// Empty: the goal cannot be pursued now (e.g. a fall goal while stable). A static list:
    /// the choice among a fixed catalogue, made every cycle without allocating.
    fn primitives_for(&self, goal: &G, input: &ReactiveInput<'_, W>) -> &'static [G::Primitive];
}

/// The activation policy of an idle multiplexer: no goal applies, no primitive is named.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoActivation;

impl<G: Goal, W> ActivationPolicy<G, W> for NoActivation {
    fn reactive_score(&self, _goal: &GoalScore<G>, _input: &ReactiveInput<'_, W>) -> f64 {
        0.0
    }

    fn primitives_for(&self, _goal: &G, _input: &ReactiveInput<'_, W>) -> &'static [G::Primitive] {
        &[]
    }
}

/// Shortcuts an activation policy may take to the answers of its [`ActivationPolicy`]: never
/// other answers, the same ones sooner (a reactive cycle has a few hundred microseconds). A
/// multiplexer built with [`Multiplexer::with_shortcuts`] asks these; one built with
/// [`Multiplexer::new`] asks the contract only. Every method has a default in terms of the
/// contract, so a policy overrides only the shortcuts it takes.
///
/// [`Multiplexer::with_shortcuts`]: super::Multiplexer::with_shortcuts
/// [`Multiplexer::new`]: super::Multiplexer::new
pub trait ActivationShortcuts<G: Goal, W>: ActivationPolicy<G, W> {
    /// Stage 2 and the choice of primitives at once: what the multiplexer asks of every goal
    /// each cycle. The default asks [`ActivationPolicy::reactive_score`] and
    /// [`ActivationPolicy::primitives_for`]; a policy whose two answers read the same percepts
    /// (the objects a goal is about) can read them once, with the same results.
    fn assess(
        &self,
        goal: &GoalScore<G>,
        input: &ReactiveInput<'_, W>,
    ) -> (f64, &'static [G::Primitive]) {
        (self.reactive_score(goal, input), self.primitives_for(&goal.goal, input))
    }

    /// What the answers above depend on besides the goal and `input.world`, if that is little:
    /// `Some(key)` promises that they depend on the goal, the world state and whatever `key`
    /// sums up of the rest of the input (equal keys, equal answers: `Some(0)` for a policy that
    /// reads nothing else). The world state changes more slowly than percepts arrive (about
    /// 30 Hz against 83 Hz in a match), so the multiplexer of such a policy asks again only
    /// when the world state, the score vector or the key has changed, and reuses the answers —
    /// the same answers — in between (see [`ReactiveLayer::step_on_revision`]). `None`, the
    /// default, asks every cycle.
    ///
    /// [`ReactiveLayer::step_on_revision`]: super::ReactiveLayer::step_on_revision
    fn reuse_key(&self, _input: &ReactiveInput<'_, W>) -> Option<u64> {
        None
    }

    /// [`ActivationPolicy::split`] with the goal's notes ([`GoalNotes`]). The multiplexer
    /// asks this; the default ignores the notes.
    fn split_noted(
        &self,
        goal: &GoalScore<G>,
        _notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
    ) -> Option<Vec<GoalScore<G>>> {
        self.split(goal, input)
    }

    /// [`ActivationShortcuts::assess`] with the goal's notes ([`GoalNotes`]). The multiplexer
    /// asks this; the default ignores the notes.
    fn assess_noted(
        &self,
        goal: &GoalScore<G>,
        _notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
    ) -> (f64, &'static [G::Primitive]) {
        self.assess(goal, input)
    }
}

/// What an activation policy keeps about one offered goal while the score vector stands —
/// the objects the goal names, found by name once rather than every time it is asked. The
/// multiplexer keeps one per offered goal and empties them when another score vector (or
/// reflex vector) arrives; a goal made by a split gets empty notes each time. A policy's
/// answers with its notes must be the answers without them.
#[derive(Default)]
pub struct GoalNotes(Option<Box<dyn std::any::Any + Send>>);

impl GoalNotes {
    /// The notes, made by `make` if there are none of type `T` yet.
    pub fn get_or_insert_with<T: std::any::Any + Send>(
        &mut self,
        make: impl FnOnce() -> T,
    ) -> &mut T {
        if !self.0.as_ref().is_some_and(|notes| notes.is::<T>()) {
            self.0 = Some(Box::new(make()));
        }
        self.0
            .as_mut()
            .and_then(|notes| notes.downcast_mut::<T>())
            .expect("notes of type T were just put in")
    }
}

impl Debug for GoalNotes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("GoalNotes").field(&self.0.is_some()).finish()
    }
}

/// A multiplexer's policy: the contract alone, or with its shortcuts.
pub(super) enum Policy<G: Goal, W> {
    Contract(Box<dyn ActivationPolicy<G, W>>),
    Shortcuts(Box<dyn ActivationShortcuts<G, W>>),
}

impl<G: Goal, W> Policy<G, W> {
    pub(super) fn reuse_key(&self, input: &ReactiveInput<'_, W>) -> Option<u64> {
        match self {
            Policy::Contract(_) => None,
            Policy::Shortcuts(policy) => policy.reuse_key(input),
        }
    }

    pub(super) fn split_noted(
        &self,
        goal: &GoalScore<G>,
        notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
    ) -> Option<Vec<GoalScore<G>>> {
        match self {
            Policy::Contract(policy) => policy.split(goal, input),
            Policy::Shortcuts(policy) => policy.split_noted(goal, notes, input),
        }
    }

    pub(super) fn assess_noted(
        &self,
        goal: &GoalScore<G>,
        notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
    ) -> (f64, &'static [G::Primitive]) {
        match self {
            Policy::Contract(policy) => {
                (policy.reactive_score(goal, input), policy.primitives_for(&goal.goal, input))
            }
            Policy::Shortcuts(policy) => policy.assess_noted(goal, notes, input),
        }
    }
}
