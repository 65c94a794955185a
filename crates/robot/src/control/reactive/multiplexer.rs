//! A resource multiplexer: holds a resource group's score vector, runs its activation function
//! and activates one primitive behavior.

use std::collections::BTreeSet;
use std::fmt::Debug;

use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use super::activation::Assessment;
use super::policy::{NoActivation, Policy};
use super::{
    ActivationPolicy, ActivationShortcuts, GoalNotes, GoalReport, GoalReports, MuxReport,
    PrimitiveBehavior, ReactiveInput,
};
use crate::command::ResourceGroup;
use crate::control::scores::{Goal, GoalScore, PrimitiveId, ScoreCombination, ScoreVector};

/// Tunables of a multiplexer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MultiplexerConfig {
    pub combination: ScoreCombination,
    /// Added to the final score of the goal currently pursued, so that two goals with nearly
    /// equal scores do not make the resource flicker between them every cycle.
    pub hysteresis: f64,
}

impl Default for MultiplexerConfig {
    fn default() -> Self {
        MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.05 }
    }
}

pub(super) struct Active<G> {
    pub(super) goal: G,
    pub(super) primitive: usize,
}

/// A selection made by the activation function, not yet executed. It names a goal of the
/// multiplexer's current assessment rather than holding a copy of it (goals own strings, and
/// a selection is made every cycle), so it is executed by the multiplexer that made it, before
/// that multiplexer evaluates again or receives another score vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Selection {
    /// The selected goal's place in [`Assessment::goals`].
    pub(super) goal: usize,
    pub final_score: f64,
    pub(super) primitive: usize,
    /// The assessment the selection was made from.
    pub(super) assessment: u64,
}

/// Manages one resource group: holds the deliberative score vector, runs the activation
/// function, activates one primitive behavior.
pub struct Multiplexer<G: Goal, Cmd, W> {
    pub(super) group: ResourceGroup,
    pub(super) config: MultiplexerConfig,
    pub(super) policy: Policy<G, W>,
    pub(super) primitives: Vec<Box<dyn PrimitiveBehavior<G, Cmd, W>>>,
    pub(super) scores: ScoreVector<G>,
    /// Goals the reactive layer always offers this multiplexer (reflexes such as the fall
    /// goal): they must not wait for a slow deliberative layer.
    pub(super) reflexes: ScoreVector<G>,
    /// Labels of the reflexes and offered goals, made once per score vector rather than every
    /// cycle (a reactive cycle must not format strings it already has).
    pub(super) labels: Vec<(std::sync::Arc<str>, std::sync::Arc<[String]>)>,
    /// The policy's notes on each offered goal (reflexes first), emptied with the labels.
    pub(super) notes: Vec<GoalNotes>,
    /// By name: the deliberative layer's output carries one set for all three multiplexers,
    /// and logs hold it as names.
    pub(super) deactivated: BTreeSet<String>,
    /// The primitive each list of ids given by the policy resolves to, under the current
    /// deactivations: the policy answers with a few static lists, so each is resolved once
    /// per score vector rather than by looking each id up for every goal.
    pub(super) resolved: Vec<(&'static [G::Primitive], Option<usize>)>,
    pub(super) assessment: Assessment<G>,
    /// Where the next assessment's reports are gathered (kept for its capacity).
    pub(super) scratch: Vec<GoalReport>,
    pub(super) active: Option<Active<G>>,
    pub(super) report: MuxReport,
}

impl<G: Goal, Cmd, W> Debug for Multiplexer<G, Cmd, W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Multiplexer")
            .field("group", &self.group)
            .field("primitives", &self.primitives.iter().map(|p| p.id().name()).collect::<Vec<_>>())
            .field("scores", &self.scores)
            .finish()
    }
}

impl<G: Goal, Cmd, W> Multiplexer<G, Cmd, W> {
    /// A multiplexer for a resource group the application does not drive: no policy, no
    /// primitives, it never selects a goal and never commands its resources (goal type
    /// [`crate::control::scores::NoGoal`], or any goal the application never offers it).
    pub fn unused(group: ResourceGroup) -> Multiplexer<G, Cmd, W> {
        Self::new(group, MultiplexerConfig::default(), Box::new(NoActivation))
    }

    /// A multiplexer for `group` that asks `policy` its contract every cycle.
    pub fn new(
        group: ResourceGroup,
        config: MultiplexerConfig,
        policy: Box<dyn ActivationPolicy<G, W>>,
    ) -> Multiplexer<G, Cmd, W> {
        Self::with_policy(group, config, Policy::Contract(policy))
    }

    /// A multiplexer for `group` that takes `policy`'s shortcuts ([`ActivationShortcuts`]):
    /// the same selections as [`Multiplexer::new`], found with less work.
    pub fn with_shortcuts(
        group: ResourceGroup,
        config: MultiplexerConfig,
        policy: Box<dyn ActivationShortcuts<G, W>>,
    ) -> Multiplexer<G, Cmd, W> {
        Self::with_policy(group, config, Policy::Shortcuts(policy))
    }

    fn with_policy(
        group: ResourceGroup,
        config: MultiplexerConfig,
        policy: Policy<G, W>,
    ) -> Multiplexer<G, Cmd, W> {
        Multiplexer {
            group,
            config,
            policy,
            primitives: Vec::new(),
            scores: ScoreVector::default(),
            reflexes: ScoreVector::default(),
            labels: Vec::new(),
            notes: Vec::new(),
            deactivated: BTreeSet::new(),
            resolved: Vec::new(),
            assessment: Assessment {
                goals: Vec::new(),
                reports: GoalReports::default(),
                key: None,
                serial: 0,
                pursued_known: false,
            },
            scratch: Vec::new(),
            active: None,
            report: MuxReport { group: Some(group), ..MuxReport::default() },
        }
    }

    /// Registers a primitive behavior; it replaces one registered earlier with the same id.
    pub fn with_primitive(mut self, primitive: Box<dyn PrimitiveBehavior<G, Cmd, W>>) -> Self {
        self.primitives.retain(|p| p.id() != primitive.id());
        self.primitives.push(primitive);
        self.resolved.clear();
        self.assessment.key = None;
        self
    }

    pub fn with_reflexes(mut self, reflexes: ScoreVector<G>) -> Self {
        self.reflexes = reflexes;
        self.relabel();
        self
    }

    /// Labels the offered goals anew; the answers for the previous ones, the policy's notes on
    /// them and the primitives resolved under the previous deactivations no longer hold.
    fn relabel(&mut self) {
        self.labels = self
            .reflexes
            .goals
            .iter()
            .chain(&self.scores.goals)
            .map(|g| {
                (std::sync::Arc::from(g.goal.label()), std::sync::Arc::from(g.objects.as_slice()))
            })
            .collect();
        self.notes.clear();
        self.notes.resize_with(self.labels.len(), GoalNotes::default);
        self.resolved.clear();
        self.assessment.key = None;
    }

    pub fn group(&self) -> ResourceGroup {
        self.group
    }

    /// The ids of the registered primitives, in the order they were registered.
    pub fn primitive_ids(&self) -> impl Iterator<Item = G::Primitive> + '_ {
        self.primitives.iter().map(|p| p.id())
    }

    /// The goal type's primitives ([`PrimitiveId::ALL`]) that are not registered: a policy
    /// that names one gets nothing from it, and a goal only it could pursue is never
    /// selected. An application's tests assert that this is empty for the multiplexers it
    /// uses.
    pub fn unregistered(&self) -> impl Iterator<Item = G::Primitive> + '_ {
        G::Primitive::ALL.iter().copied().filter(|id| self.primitives.iter().all(|p| p.id() != *id))
    }

    /// A new score vector from the deliberative layer replaces the previous one; the
    /// deactivated primitives come with it.
    pub fn set_scores(
        &mut self,
        scores: ScoreVector<G>,
        deactivated: &BTreeSet<String>,
        received: Time,
    ) {
        self.scores = scores;
        self.deactivated = deactivated.clone();
        self.report.scores_received = Some(received);
        self.relabel();
    }

    pub fn scores(&self) -> &ScoreVector<G> {
        &self.scores
    }

    /// The goal a selection names; `None` if the multiplexer assessed its goals again since
    /// the selection was made.
    pub fn selected(&self, selection: &Selection) -> Option<&GoalScore<G>> {
        if selection.assessment != self.assessment.serial {
            return None;
        }
        let assessed = self.assessment.goals.get(selection.goal)?;
        Some(assessed.goal(&self.reflexes, &self.scores))
    }

    /// The activation function: both stages and the selection, without executing anything.
    pub fn evaluate(&mut self, input: &ReactiveInput<'_, W>) -> Option<Selection> {
        self.evaluate_on(input, None)
    }
    /// Activates the selected primitive (deactivating the previous one if it changes) and
    /// steps it. A selection from an earlier assessment executes nothing: the multiplexer
    /// idles.
    pub fn execute(&mut self, selection: &Selection, input: &ReactiveInput<'_, W>) -> Option<Cmd> {
        let assessed = if selection.assessment == self.assessment.serial {
            self.assessment.goals.get(selection.goal)
        } else {
            None
        };
        let Some(assessed) = assessed else {
            self.idle(None);
            return None;
        };
        let goal = &assessed.goal(&self.reflexes, &self.scores).goal;
        // The ranking has just compared the goals with the one pursued.
        let pursued = if self.assessment.pursued_known {
            assessed.pursued
        } else {
            self.active.as_ref().is_some_and(|a| a.goal == *goal)
        };
        let same =
            pursued && self.active.as_ref().is_some_and(|a| a.primitive == selection.primitive);
        if !same {
            if let Some(previous) = self.active.take() {
                self.primitives[previous.primitive].deactivate();
            }
            self.primitives[selection.primitive].activate(goal, input);
            self.active = Some(Active { goal: goal.clone(), primitive: selection.primitive });
            self.assessment.pursued_known = false;
        }
        let primitive = &mut self.primitives[selection.primitive];
        self.report.selected_goal =
            self.assessment.reports.get(selection.goal).map(|r| r.goal.clone());
        self.report.primitive = Some(std::borrow::Cow::Borrowed(primitive.id().name()));
        self.report.inhibited_by = None;
        primitive.step(goal, input)
    }

    /// Nothing selected, or inhibited by another multiplexer: the active primitive stops.
    pub fn idle(&mut self, inhibited_by: Option<ResourceGroup>) {
        if let Some(previous) = self.active.take() {
            self.primitives[previous.primitive].deactivate();
            self.assessment.pursued_known = false;
        }
        self.report.selected_goal = None;
        self.report.primitive = None;
        self.report.inhibited_by = inhibited_by;
    }

    pub fn report(&self) -> &MuxReport {
        &self.report
    }

    /// The cycle's report, moved out (the next evaluation builds a new one).
    pub(super) fn take_report(&mut self) -> MuxReport {
        let fresh = MuxReport {
            group: Some(self.group),
            scores_received: self.report.scores_received,
            ..MuxReport::default()
        };
        std::mem::replace(&mut self.report, fresh)
    }
}
