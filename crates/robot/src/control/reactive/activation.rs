//! The multiplexer's activation function: both stages for every offered goal, the answers kept
//! while they hold, and the ranking.

use super::{GoalNotes, GoalReport, GoalReports, Multiplexer, ReactiveInput, Selection};
use crate::control::scores::{Goal, GoalScore, PrimitiveId, ScoreVector};

/// One goal as the activation function assessed it: everything that holds until the score
/// vector or (for a world-only policy) the world state changes.
pub(super) struct Assessed<G> {
    /// The offered goal (reflexes first, then the score vector) it comes from.
    pub(super) offered: usize,
    /// The goal a split made, if the offered goal was split.
    pub(super) split: Option<GoalScore<G>>,
    pub(super) final_score: f64,
    /// The first primitive (by index) that may pursue it; `None`: not applicable.
    pub(super) primitive: Option<usize>,
    /// It is the goal the multiplexer pursues (it earns the hysteresis bonus). Valid while
    /// [`Assessment::pursued_known`].
    pub(super) pursued: bool,
}

impl<G> Assessed<G> {
    /// The goal itself: the one the split made, or the offered one (reflexes first, then the
    /// score vector).
    pub(super) fn goal<'a>(
        &'a self,
        reflexes: &'a ScoreVector<G>,
        scores: &'a ScoreVector<G>,
    ) -> &'a GoalScore<G> {
        self.split.as_ref().unwrap_or_else(|| {
            match self.offered.checked_sub(reflexes.goals.len()) {
                None => &reflexes.goals[self.offered],
                Some(index) => &scores.goals[index],
            }
        })
    }
}

/// The activation function's answers for every goal a multiplexer offers, made by
/// [`Multiplexer::assess`] and ranked every cycle (the hysteresis bonus depends on the goal
/// pursued, which the ranking itself changes).
pub(super) struct Assessment<G> {
    pub(super) goals: Vec<Assessed<G>>,
    /// One per goal, in the same order.
    pub(super) reports: GoalReports,
    /// The world-state revision and the policy's reuse key the answers hold for; `None`: only
    /// for the cycle that made them (no revision given, no key, or a new score vector since).
    pub(super) key: Option<(u64, u64)>,
    /// Counts assessments, so that a selection is executed only on the assessment it was
    /// made from.
    pub(super) serial: u64,
    /// Whether the goals' `pursued` flags hold for the goal pursued now: comparing goals every
    /// cycle would compare their strings, though the goal pursued rarely changes.
    pub(super) pursued_known: bool,
}

impl<G: Goal, Cmd, W> Multiplexer<G, Cmd, W> {
    /// [`Multiplexer::evaluate`] on the world state numbered `revision` by the caller, if it
    /// numbers them: the answers of a policy with a reuse key are reused while the world
    /// state, the score vector and the key stay.
    pub(super) fn evaluate_on(
        &mut self,
        input: &ReactiveInput<'_, W>,
        revision: Option<u64>,
    ) -> Option<Selection> {
        let key = revision.zip(self.policy.reuse_key(input));
        if key.is_none() || key != self.assessment.key {
            self.assess(input);
            self.assessment.key = key;
        }
        self.report.goals = self.assessment.reports.clone();
        self.rank()
    }

    /// Both stages of the activation function for every offered goal, and the primitive that
    /// would pursue each.
    fn assess(&mut self, input: &ReactiveInput<'_, W>) {
        let mut goals = std::mem::take(&mut self.assessment.goals);
        goals.clear();
        let mut reports = std::mem::take(&mut self.scratch);
        let mut resolved = std::mem::take(&mut self.resolved);
        let mut notes = std::mem::take(&mut self.notes);
        // One for every offered goal, or the zip below would leave goals out.
        notes.resize_with(self.reflexes.goals.len() + self.scores.goals.len(), GoalNotes::default);
        let offered = self.reflexes.goals.iter().chain(self.scores.goals.iter());
        for ((offered_index, offered_goal), notes) in offered.enumerate().zip(&mut notes) {
            match self.policy.split_noted(offered_goal, notes, input) {
                None => {
                    let (report, final_score, primitive) = self.assess_goal(
                        offered_index,
                        offered_goal,
                        None,
                        notes,
                        input,
                        &mut resolved,
                    );
                    reports.push(report);
                    goals.push(Assessed {
                        offered: offered_index,
                        split: None,
                        final_score,
                        primitive,
                        pursued: false,
                    });
                }
                Some(made) => {
                    for goal in made {
                        let (report, final_score, primitive) = self.assess_goal(
                            offered_index,
                            offered_goal,
                            Some(&goal),
                            &mut GoalNotes::default(),
                            input,
                            &mut resolved,
                        );
                        reports.push(report);
                        goals.push(Assessed {
                            offered: offered_index,
                            split: Some(goal),
                            final_score,
                            primitive,
                            pursued: false,
                        });
                    }
                }
            }
        }
        self.resolved = resolved;
        self.notes = notes;
        self.assessment.goals = goals;
        self.assessment.reports.replace(&mut reports);
        self.scratch = reports;
        self.assessment.serial = self.assessment.serial.wrapping_add(1);
        self.assessment.pursued_known = false;
    }

    /// Stage 2 for one goal — `offered_goal` itself, or a goal `made` of it by the split —
    /// and the first primitive that may pursue it.
    fn assess_goal(
        &self,
        offered_index: usize,
        offered_goal: &GoalScore<G>,
        made: Option<&GoalScore<G>>,
        notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
        resolved: &mut Vec<(&'static [G::Primitive], Option<usize>)>,
    ) -> (GoalReport, f64, Option<usize>) {
        let goal = made.unwrap_or(offered_goal);
        let (reactive, primitives) = self.policy.assess_noted(goal, notes, input);
        let reactive = reactive.clamp(0.0, 1.0);
        let final_score = self.config.combination.combine(goal.deliberative, reactive);
        let primitive = self.resolve(primitives, resolved);
        let (label, objects) = match self.labels.get(offered_index) {
            Some((label, objects)) if made.is_none() || goal.goal == offered_goal.goal => {
                (label.clone(), objects.clone())
            }
            _ => (
                std::sync::Arc::from(goal.goal.label()),
                std::sync::Arc::from(goal.objects.as_slice()),
            ),
        };
        let report = GoalReport {
            goal: label,
            objects,
            deliberative: goal.deliberative,
            reactive,
            final_score,
            applicable: primitive.is_some(),
        };
        (report, final_score, primitive)
    }

    /// The first of `ids` that is registered and not deactivated, remembered in `resolved`
    /// (taken out of the multiplexer while its goals are assessed).
    fn resolve(
        &self,
        ids: &'static [G::Primitive],
        resolved: &mut Vec<(&'static [G::Primitive], Option<usize>)>,
    ) -> Option<usize> {
        // The same static list, at the same address and as long: the same ids.
        if let Some((_, primitive)) = resolved.iter().find(|(i, _)| std::ptr::eq(*i, ids)) {
            return *primitive;
        }
        let primitive = ids
            .iter()
            .copied()
            .filter(|id| !self.deactivated.contains(id.name()))
            .find_map(|id| self.primitives.iter().position(|p| p.id() == id));
        resolved.push((ids, primitive));
        primitive
    }

    /// The applicable goal with the highest final score, plus the hysteresis bonus for the
    /// goal pursued; on a tie the goal assessed first.
    fn rank(&mut self) -> Option<Selection> {
        if !self.assessment.pursued_known {
            for assessed in &mut self.assessment.goals {
                let goal = assessed.goal(&self.reflexes, &self.scores);
                assessed.pursued = self.active.as_ref().is_some_and(|a| a.goal == goal.goal);
            }
            self.assessment.pursued_known = true;
        }
        let mut best: Option<(usize, usize, f64)> = None;
        for (index, assessed) in self.assessment.goals.iter().enumerate() {
            let Some(primitive) = assessed.primitive else { continue };
            let bonus = if assessed.pursued { self.config.hysteresis } else { 0.0 };
            let ranked = assessed.final_score + bonus;
            if best.is_none_or(|(_, _, b)| ranked > b) {
                best = Some((index, primitive, ranked));
            }
        }
        let (goal, primitive, _) = best?;
        Some(Selection {
            goal,
            final_score: self.assessment.goals[goal].final_score,
            primitive,
            assessment: self.assessment.serial,
        })
    }
}
