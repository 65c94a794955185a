//! The deliberative layer (paper 3.4): executes the mission the planning layer chose, through
//! deliberative behaviors organised as state machines whose states are behaviors or behavior
//! trees ([`crate::control::hsm`], [`crate::control::bt`]). It configures the resource
//! multiplexers with score vectors — directly, or through value functions when several
//! objectives compete ([`crate::control::active_vision`]) — and may deactivate primitive
//! behaviors.
//!
//! The layer runs at its own, slow rate (the paper: 0.5 to 2 Hz; the mission's time
//! requirements set the minimum). Each tick produces a complete [`DeliberativeOutput`], which
//! replaces the previous one in the reactive layer: S_d stays as sent until the next tick.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use crate::control::reactive::Stability;
use crate::control::scores::{Goal, PrimitiveId, ScoreVector};

/// What one deliberative tick hands the reactive layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "H: Goal, B: Goal, X: Goal")]
pub struct DeliberativeOutput<H, B, X> {
    pub head: ScoreVector<H>,
    pub body: ScoreVector<B>,
    pub whole_body: ScoreVector<X>,
    /// Primitive behaviors that must not be activated for now (e.g. "kick ball" while
    /// dribbling is wanted), by [`PrimitiveId::name`]: a name applies to every multiplexer
    /// with a primitive of that name. [`DeliberativeOutput::deactivate`] names one by its id.
    pub deactivated: BTreeSet<String>,
    /// The active state and behavior-tree path, e.g. "Goalie playing/Goal covering/cover".
    pub behavior_path: String,
}

impl<H, B, X> DeliberativeOutput<H, B, X> {
    /// Deactivates `primitive` until the next tick.
    pub fn deactivate(&mut self, primitive: impl PrimitiveId) {
        self.deactivated.insert(primitive.name().to_owned());
    }
}

impl<H, B, X> Default for DeliberativeOutput<H, B, X> {
    fn default() -> Self {
        DeliberativeOutput {
            head: ScoreVector::default(),
            body: ScoreVector::default(),
            whole_body: ScoreVector::default(),
            deactivated: BTreeSet::new(),
            behavior_path: String::new(),
        }
    }
}

/// Everything a deliberative tick may look at.
#[derive(Debug)]
pub struct DeliberativeInput<'a, W, A> {
    pub now: Time,
    /// The newest world state (None until world modeling has published one).
    pub world: Option<&'a W>,
    /// The newest assignment from the planning layer (mission, role and the application's
    /// directive, e.g. the game state).
    pub assignment: Option<&'a A>,
    /// The reactive layer's newest stability estimate.
    pub stability: Stability,
}

/// The application's deliberative behaviors for one robot.
pub trait DeliberativePolicy: Send {
    type HeadGoal: Goal;
    type BodyGoal: Goal;
    type WholeBodyGoal: Goal;
    /// The world state type (the world-modeling module's output).
    type World;
    /// What the planning layer sends (mission, role, directive).
    type Assignment;

    fn tick(
        &mut self,
        input: &DeliberativeInput<'_, Self::World, Self::Assignment>,
    ) -> DeliberativeOutput<Self::HeadGoal, Self::BodyGoal, Self::WholeBodyGoal>;
}
