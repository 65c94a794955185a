//! Goals and score vectors: how the deliberative layer configures the resource multiplexers
//! (paper 3.4, Fig. 3).

use std::fmt::Debug;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// A goal of one resource multiplexer (paper Table 3): "observe ball", "go to position (x, y)".
/// Its parameters are part of the value (an enum variant's fields).
pub trait Goal:
    Clone + Debug + PartialEq + Serialize + DeserializeOwned + Send + Sync + 'static
{
    /// The primitive behaviors that can pursue goals of this type: a closed set, so that an
    /// activation policy names them by values the compiler checks and a misspelt primitive
    /// cannot make a goal inapplicable for ever.
    type Primitive: PrimitiveId;

    /// A short human-readable name for reports and plots, parameters included.
    fn label(&self) -> String;
}

/// Which primitive behavior, among those of one goal type ([`Goal::Primitive`]): usually a
/// field-less enum declared with [`crate::primitive_ids!`]. Activation policies, primitive
/// behaviors and multiplexers refer to primitives by these values; reports, logs and the
/// deliberative layer's deactivations by [`PrimitiveId::name`].
pub trait PrimitiveId: Copy + Eq + Debug + Send + Sync + 'static {
    /// Every primitive of the set, so that a multiplexer can tell which it lacks
    /// ([`crate::control::reactive::Multiplexer::unregistered`]).
    const ALL: &'static [Self];

    /// The name reports and logs show, and deactivations name: unique within the set.
    fn name(self) -> &'static str;
}

/// The primitive ids of a goal type no primitive can pursue ([`NoGoal`]'s): there are none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NoPrimitive {}

impl PrimitiveId for NoPrimitive {
    const ALL: &'static [NoPrimitive] = &[];

    fn name(self) -> &'static str {
        match self {}
    }
}

/// Declares a goal type's primitive ids: a field-less enum and its [`PrimitiveId`], each
/// variant with the name reports and logs show. The macro writes [`PrimitiveId::ALL`] from
/// the same list as the variants, so that no primitive is left out of it (one left out would
/// escape [`crate::control::reactive::Multiplexer::unregistered`]).
///
/// ```
/// strata_robot::primitive_ids! {
///     /// The head's primitive behaviors.
///     pub enum HeadPrimitive {
///         Scan => "scan",
///         /// Keeps the goal's object in the middle of the image.
///         ObjectTracking => "object tracking",
///     }
/// }
/// use strata_robot::control::scores::PrimitiveId;
/// assert_eq!(HeadPrimitive::ObjectTracking.name(), "object tracking");
/// assert_eq!(HeadPrimitive::ALL, [HeadPrimitive::Scan, HeadPrimitive::ObjectTracking]);
/// ```
#[macro_export]
macro_rules! primitive_ids {
    (
        $(#[$meta:meta])*
        $vis:vis enum $id:ident {
            $($(#[$variant_meta:meta])* $variant:ident => $name:expr),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        $vis enum $id {
            $($(#[$variant_meta])* $variant),*
        }

        impl $crate::control::scores::PrimitiveId for $id {
            const ALL: &'static [$id] = &[$($id::$variant),*];

            fn name(self) -> &'static str {
                match self {
                    $($id::$variant => $name),*
                }
            }
        }
    };
}

/// The goal type of a resource group an application does not use (a robot without a head, or
/// one whose head and body are never driven together): there is no such goal, so its
/// multiplexer, [`crate::control::reactive::Multiplexer::unused`], never selects one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NoGoal {}

impl Goal for NoGoal {
    type Primitive = NoPrimitive;

    fn label(&self) -> String {
        match *self {}
    }
}

/// One entry of a score vector: a goal, its deliberative score S_d, and the objects of interest
/// it concerns (Fig. 3). The objects are world-model object names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "G: Goal")]
pub struct GoalScore<G> {
    pub goal: G,
    /// S_d, in [0, 1]. Unchanged until the deliberative layer sends a new score vector.
    pub deliberative: f64,
    pub objects: Vec<String>,
}

impl<G: Goal> GoalScore<G> {
    pub fn new(goal: G, deliberative: f64) -> GoalScore<G> {
        GoalScore { goal, deliberative: deliberative.clamp(0.0, 1.0), objects: Vec::new() }
    }

    pub fn about(mut self, object: impl Into<String>) -> GoalScore<G> {
        self.objects.push(object.into());
        self
    }
}

/// The goals the deliberative layer offers one multiplexer, with their scores. Its size
/// depends on run-time information (Fig. 3: "this data structure is dynamic").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "G: Goal")]
pub struct ScoreVector<G> {
    pub goals: Vec<GoalScore<G>>,
}

impl<G> Default for ScoreVector<G> {
    fn default() -> Self {
        ScoreVector { goals: Vec::new() }
    }
}

impl<G: Goal> ScoreVector<G> {
    pub fn single(goal: G) -> ScoreVector<G> {
        ScoreVector { goals: vec![GoalScore::new(goal, 1.0)] }
    }

    pub fn with(mut self, score: GoalScore<G>) -> ScoreVector<G> {
        self.goals.push(score);
        self
    }

    pub fn push(&mut self, score: GoalScore<G>) {
        self.goals.push(score);
    }

    pub fn is_empty(&self) -> bool {
        self.goals.is_empty()
    }
}

/// How a multiplexer combines the deliberative score S_d with the reactive score S_r (the
/// second stage of the activation function). The paper averages them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ScoreCombination {
    /// (S_d + S_r) / 2, as in the paper.
    #[default]
    Average,
    /// w S_d + (1 - w) S_r.
    Weighted { deliberative_weight: f64 },
    /// S_d S_r: a goal needs both layers' support.
    Product,
    /// Only S_d: the reactive layer does not rescale (a baseline for experiments).
    DeliberativeOnly,
}

impl ScoreCombination {
    pub fn combine(&self, deliberative: f64, reactive: f64) -> f64 {
        match self {
            ScoreCombination::Average => 0.5 * (deliberative + reactive),
            ScoreCombination::Weighted { deliberative_weight } => {
                let w = deliberative_weight.clamp(0.0, 1.0);
                w * deliberative + (1.0 - w) * reactive
            }
            ScoreCombination::Product => deliberative * reactive,
            ScoreCombination::DeliberativeOnly => deliberative,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn combinations() {
        assert_eq!(ScoreCombination::Average.combine(0.2, 0.6), 0.4);
        assert_eq!(ScoreCombination::Product.combine(0.5, 0.5), 0.25);
        assert_eq!(ScoreCombination::DeliberativeOnly.combine(0.3, 1.0), 0.3);
        let w = ScoreCombination::Weighted { deliberative_weight: 0.75 };
        assert!((w.combine(1.0, 0.0) - 0.75).abs() < 1e-12);
    }
}
