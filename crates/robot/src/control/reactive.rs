//! The reactive layer (paper 3.5): primitive behaviors, resource multiplexers and their
//! activation function, inhibition between resources, and fall detection.
//!
//! Every reactive cycle (one per percept):
//! 1. The fall detector classifies the robot's stability from the newest inertial data.
//! 2. Each multiplexer — head+body first — runs its activation function on the score vector the
//!    deliberative layer last sent: stage 1 lets the application split goals that cannot be
//!    executed together now (two objects that do not fit in one gaze); stage 2 computes each
//!    goal's reactive score S_r from the newest percepts and combines it with the deliberative
//!    score S_d (the average, by default). S_d is never changed here: the reactive layer only
//!    rescales, it never changes the goals. A policy whose answers read the world state and
//!    little else ([`ActivationPolicy::reuse_key`]) is asked again only when a new world state
//!    or score vector has arrived or that little else changed; in between its answers could not
//!    change, and are reused.
//! 3. The goal with the highest final score among those some primitive behavior can pursue now
//!    (chosen from perceptual data, skipping primitives the deliberative layer deactivated) is
//!    selected, and that primitive is activated. The head+body multiplexer's selection inhibits
//!    the head and body multiplexers when its final score is at least theirs; otherwise it
//!    yields and they run independently (their resources are disjoint, so their primitives are
//!    orthogonal).
//! 4. The active primitives compute this cycle's commands: a [`MotionCommands`] value, which
//!    cannot hold two commands for one resource.

use std::collections::BTreeSet;
use std::fmt::Debug;

use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use crate::command::{
    ActuationMessage, BodyCommand, HeadCommand, MotionCommands, Resource, ResourceGroup,
    WholeBodyCommand,
};
use crate::control::scores::{Goal, GoalScore, ScoreCombination, ScoreVector};
use crate::percept::Percepts;
use crate::platform::FallDirection;

/// How stable the robot is, from its inertial sensors (the paper's standing status: stable,
/// unstable or fallen).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stability {
    #[default]
    Stable,
    /// Falling: the tilt will pass the point of no return; protect the robot now.
    Unstable(FallDirection),
    /// Lying on the ground.
    Fallen(FallDirection),
}

impl Stability {
    pub fn is_stable(&self) -> bool {
        matches!(self, Stability::Stable)
    }
}

/// Thresholds of the fall detector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FallDetectorConfig {
    /// Tilt (rad) predicted `lookahead` seconds ahead beyond which the robot is falling.
    pub unstable_tilt: f64,
    /// Tilt (rad) beyond which the robot is lying down.
    pub fallen_tilt: f64,
    /// How far ahead the tilt is extrapolated with the gyroscope, s.
    pub lookahead: f64,
    /// Consecutive samples that must agree before the status changes (debouncing noise).
    pub confirm_samples: u32,
}

impl Default for FallDetectorConfig {
    fn default() -> Self {
        FallDetectorConfig {
            unstable_tilt: 0.5,
            fallen_tilt: 1.0,
            lookahead: 0.1,
            confirm_samples: 1,
        }
    }
}

/// Classifies stability from body angles and gyroscope, every reactive cycle.
#[derive(Clone, Debug, Default)]
pub struct FallDetector {
    config: FallDetectorConfig,
    status: Stability,
    candidate: Option<(Stability, u32)>,
}

impl FallDetector {
    pub fn new(config: FallDetectorConfig) -> FallDetector {
        FallDetector { config, status: Stability::Stable, candidate: None }
    }

    pub fn status(&self) -> Stability {
        self.status
    }

    pub fn update(&mut self, percepts: &Percepts) -> Stability {
        let [roll, pitch] = percepts.inertial.body_angles;
        let [roll_rate, pitch_rate, _] = percepts.inertial.gyroscope;
        let predicted_roll = roll + roll_rate * self.config.lookahead;
        let predicted_pitch = pitch + pitch_rate * self.config.lookahead;
        let direction = |r: f64, p: f64| {
            if p.abs() >= r.abs() {
                if p > 0.0 { FallDirection::Front } else { FallDirection::Back }
            } else if r > 0.0 {
                FallDirection::Right
            } else {
                FallDirection::Left
            }
        };
        let observed = if roll.abs().max(pitch.abs()) > self.config.fallen_tilt {
            Stability::Fallen(direction(roll, pitch))
        } else if predicted_roll.abs().max(predicted_pitch.abs()) > self.config.unstable_tilt {
            Stability::Unstable(direction(predicted_roll, predicted_pitch))
        } else {
            Stability::Stable
        };
        if observed == self.status {
            self.candidate = None;
            return self.status;
        }
        let count = match self.candidate {
            Some((candidate, n)) if candidate == observed => n + 1,
            _ => 1,
        };
        if count >= self.config.confirm_samples.max(1) {
            self.status = observed;
            self.candidate = None;
        } else {
            self.candidate = Some((observed, count));
        }
        self.status
    }
}

/// What actuation has told the reactive layer about each resource.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ActuationStatus {
    /// Resources whose command is about to finish (actuation asks for the next action).
    pub finishing: BTreeSet<Resource>,
    /// Resources executing a cyclic command in its execution stage (changeable now).
    pub cyclic_part: BTreeSet<Resource>,
    /// Resources busy with a special (non-parametric) sequence.
    pub busy: BTreeSet<Resource>,
    /// The last rejection, for reports.
    pub last_rejection: Option<String>,
}

impl ActuationStatus {
    /// Folds actuation messages in, in arrival order.
    pub fn apply(&mut self, message: &ActuationMessage) {
        match message {
            ActuationMessage::CommandOdometry { .. } => {}
            ActuationMessage::CommandFinishing { resource, .. } => {
                self.finishing.insert(*resource);
                self.cyclic_part.remove(resource);
            }
            ActuationMessage::CommandCyclicPart { resource } => {
                self.cyclic_part.insert(*resource);
                self.finishing.remove(resource);
            }
            ActuationMessage::CommandRejected { resource, reason } => {
                self.last_rejection = Some(format!("{resource:?}: {reason}"));
            }
            ActuationMessage::ResourceBusy { resource } => {
                self.busy.insert(*resource);
            }
            ActuationMessage::ResourceReleased { resource } => {
                self.busy.remove(resource);
                self.finishing.remove(resource);
                self.cyclic_part.remove(resource);
            }
        }
    }

    pub fn is_busy(&self, group: ResourceGroup) -> bool {
        self.busy.iter().any(|r| group.uses(*r))
    }
}

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
pub trait PrimitiveBehavior<G, Cmd, W>: Send {
    fn name(&self) -> &'static str;

    /// The multiplexer activated this primitive (it was not active in the previous cycle, or
    /// its goal changed).
    fn activate(&mut self, _goal: &G, _input: &ReactiveInput<'_, W>) {}

    /// This cycle's command toward `goal`; `None` leaves actuation doing what it does.
    fn step(&mut self, goal: &G, input: &ReactiveInput<'_, W>) -> Option<Cmd>;

    /// Another primitive took over the resource, or the primitive was inhibited.
    fn deactivate(&mut self) {}
}

/// The application's part of a multiplexer's activation function.
pub trait ActivationPolicy<G, W>: Send {
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

    /// The primitive behaviors (by name) that can pursue `goal` given the percepts, preferred
    /// first. Empty: the goal cannot be pursued now (e.g. a fall goal while stable). A static
    /// list: the choice among a fixed catalogue, made every cycle without allocating.
    fn primitives_for(&self, goal: &G, input: &ReactiveInput<'_, W>) -> &'static [&'static str];

    /// Stage 2 and the choice of primitives at once: what the multiplexer asks of every goal
    /// each cycle. The default asks [`ActivationPolicy::reactive_score`] and
    /// [`ActivationPolicy::primitives_for`]; a policy whose two answers read the same percepts
    /// (the objects a goal is about) can read them once, with the same results.
    fn assess(
        &self,
        goal: &GoalScore<G>,
        input: &ReactiveInput<'_, W>,
    ) -> (f64, &'static [&'static str]) {
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

    /// [`ActivationPolicy::assess`] with the goal's notes ([`GoalNotes`]). The multiplexer
    /// asks this; the default ignores the notes.
    fn assess_noted(
        &self,
        goal: &GoalScore<G>,
        _notes: &mut GoalNotes,
        input: &ReactiveInput<'_, W>,
    ) -> (f64, &'static [&'static str]) {
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

/// One goal as the activation function scored it this cycle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalReport {
    /// Shared with the multiplexer's cache: reports are made every cycle and must not copy
    /// strings they already have.
    pub goal: std::sync::Arc<str>,
    pub objects: std::sync::Arc<[String]>,
    /// S_d
    pub deliberative: f64,
    /// S_r
    pub reactive: f64,
    /// combine(S_d, S_r), before the hysteresis bonus.
    pub final_score: f64,
    /// Whether a (non-deactivated) primitive could pursue it now.
    pub applicable: bool,
}

/// The goals a multiplexer scored in one cycle, in the order it scored them: a list shared
/// with the multiplexer, since consecutive cycles on one world state score the same goals the
/// same way and must not copy their reports. Reads as a slice.
///
/// Serialized as the goals' labels — what they are, which changes with the score vector or
/// the split of its goals, seldom at the reactive layer's rate: a [`Shared`] value a log stores
/// once — and each goal's scores of this cycle.
#[derive(Clone, Default)]
pub struct GoalReports {
    list: Option<std::sync::Arc<[GoalReport]>>,
    /// The labels of `list`'s goals; `None` when there are none.
    labels: Option<Shared<GoalLabels>>,
}

/// The labels of a multiplexer's scored goals, in order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GoalLabels(pub Vec<GoalLabel>);

impl std::ops::Deref for GoalLabels {
    type Target = [GoalLabel];

    fn deref(&self) -> &[GoalLabel] {
        &self.0
    }
}

/// What a scored goal is: its label, the objects it concerns and its deliberative score.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalLabel {
    pub goal: std::sync::Arc<str>,
    pub objects: std::sync::Arc<[String]>,
    /// S_d
    pub deliberative: f64,
}

impl GoalLabel {
    /// Whether `report` has this label: the same texts (usually the very same shared ones) and
    /// the same deliberative score, bit for bit.
    fn labels(&self, report: &GoalReport) -> bool {
        let same_goal =
            std::sync::Arc::ptr_eq(&self.goal, &report.goal) || self.goal == report.goal;
        let same_objects = std::sync::Arc::ptr_eq(&self.objects, &report.objects)
            || self.objects == report.objects;
        same_goal && same_objects && self.deliberative.to_bits() == report.deliberative.to_bits()
    }
}

impl std::ops::Deref for GoalReports {
    type Target = [GoalReport];

    fn deref(&self) -> &[GoalReport] {
        self.list.as_deref().unwrap_or_default()
    }
}

impl<'a> IntoIterator for &'a GoalReports {
    type Item = &'a GoalReport;
    type IntoIter = std::slice::Iter<'a, GoalReport>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl GoalReports {
    /// Replaces the list with `reports`' (leaving `reports` empty, its capacity kept): in
    /// place when nobody else holds the list any longer and it is as long, as it is when a
    /// multiplexer assesses the same goals on a new world state after the previous cycle's
    /// report was dropped. The labels are kept when the goals are the same.
    fn replace(&mut self, reports: &mut Vec<GoalReport>) {
        let same_labels = self.labels.as_ref().is_some_and(|labels| {
            labels.len() == reports.len()
                && labels.iter().zip(reports.iter()).all(|(l, r)| l.labels(r))
        });
        if !same_labels {
            self.labels = GoalReports::labels_of(reports);
        }
        if let Some(list) = self.list.as_mut().and_then(std::sync::Arc::get_mut)
            && list.len() == reports.len()
        {
            for (slot, report) in list.iter_mut().zip(reports.drain(..)) {
                *slot = report;
            }
            return;
        }
        self.list = (!reports.is_empty()).then(|| reports.drain(..).collect());
    }

    fn labels_of(reports: &[GoalReport]) -> Option<Shared<GoalLabels>> {
        (!reports.is_empty()).then(|| {
            Shared::new(GoalLabels(
                reports
                    .iter()
                    .map(|r| GoalLabel {
                        goal: r.goal.clone(),
                        objects: r.objects.clone(),
                        deliberative: r.deliberative,
                    })
                    .collect(),
            ))
        })
    }
}

impl From<Vec<GoalReport>> for GoalReports {
    fn from(reports: Vec<GoalReport>) -> GoalReports {
        let labels = GoalReports::labels_of(&reports);
        GoalReports { list: (!reports.is_empty()).then(|| reports.into()), labels }
    }
}

impl PartialEq for GoalReports {
    fn eq(&self, other: &GoalReports) -> bool {
        **self == **other
    }
}

impl Debug for GoalReports {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

/// One goal's scores of a cycle, as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "GoalScores")]
struct GoalScoresRecord {
    reactive: f64,
    final_score: f64,
    applicable: bool,
}

/// The scores of every goal, written one record each without collecting them first.
struct ScoreRecords<'a>(&'a [GoalReport]);

impl Serialize for ScoreRecords<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for r in self.0 {
            seq.serialize_element(&GoalScoresRecord {
                reactive: r.reactive,
                final_score: r.final_score,
                applicable: r.applicable,
            })?;
        }
        seq.end()
    }
}

#[derive(Serialize)]
#[serde(rename = "GoalReports")]
struct GoalReportsOut<'a> {
    labels: &'a Option<Shared<GoalLabels>>,
    scores: ScoreRecords<'a>,
}

#[derive(Deserialize)]
#[serde(rename = "GoalReports")]
struct GoalReportsIn {
    labels: Option<Shared<GoalLabels>>,
    scores: Vec<GoalScoresRecord>,
}

impl Serialize for GoalReports {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        GoalReportsOut { labels: &self.labels, scores: ScoreRecords(self) }.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for GoalReports {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let read = GoalReportsIn::deserialize(deserializer)?;
        let labels = read.labels.as_deref().map_or(&[][..], |labels| &labels.0[..]);
        if labels.len() != read.scores.len() {
            return Err(serde::de::Error::custom(format!(
                "{} goal scores for {} goal labels",
                read.scores.len(),
                labels.len()
            )));
        }
        let list: Vec<GoalReport> = labels
            .iter()
            .zip(read.scores)
            .map(|(label, scores)| GoalReport {
                goal: label.goal.clone(),
                objects: label.objects.clone(),
                deliberative: label.deliberative,
                reactive: scores.reactive,
                final_score: scores.final_score,
                applicable: scores.applicable,
            })
            .collect();
        Ok(GoalReports { list: (!list.is_empty()).then(|| list.into()), labels: read.labels })
    }
}

/// One multiplexer's decision in one cycle: the debugging view of the reactive layer.
///
/// Serialized with the selected goal as its place among `goals` (their labels are written once
/// per goal list, see [`GoalReports`]), or as its label when it is not one of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MuxReport {
    pub group: Option<ResourceGroup>,
    pub goals: GoalReports,
    pub selected_goal: Option<std::sync::Arc<str>>,
    pub primitive: Option<std::borrow::Cow<'static, str>>,
    /// The multiplexer whose selection inhibited this one.
    pub inhibited_by: Option<ResourceGroup>,
    /// When the score vector in use was received.
    pub scores_received: Option<Time>,
}

/// The selected goal, as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "SelectedGoal", rename_all = "snake_case")]
enum SelectedGoal<S> {
    /// Its place among the goals.
    Goal(u32),
    Label(S),
}

/// A multiplexer's report as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "MuxReport")]
struct MuxReportWire<G, S, P> {
    group: Option<ResourceGroup>,
    goals: G,
    selected_goal: Option<SelectedGoal<S>>,
    primitive: Option<P>,
    inhibited_by: Option<ResourceGroup>,
    scores_received: Option<Time>,
}

impl Serialize for MuxReport {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let selected_goal = self.selected_goal.as_deref().map(|selected| {
            let place = self.goals.iter().position(|g| &*g.goal == selected);
            match place.and_then(|i| u32::try_from(i).ok()) {
                Some(i) => SelectedGoal::Goal(i),
                None => SelectedGoal::Label(selected),
            }
        });
        MuxReportWire {
            group: self.group,
            goals: &self.goals,
            selected_goal,
            primitive: self.primitive.as_deref(),
            inhibited_by: self.inhibited_by,
            scores_received: self.scores_received,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for MuxReport {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let wire = MuxReportWire::<GoalReports, String, String>::deserialize(deserializer)?;
        let selected_goal = match wire.selected_goal {
            None => None,
            Some(SelectedGoal::Label(label)) => Some(std::sync::Arc::from(label)),
            Some(SelectedGoal::Goal(i)) => match wire.goals.get(i as usize) {
                Some(goal) => Some(goal.goal.clone()),
                None => {
                    return Err(serde::de::Error::custom(format!(
                        "selected goal {i} of {} goals",
                        wire.goals.len()
                    )));
                }
            },
        };
        Ok(MuxReport {
            group: wire.group,
            goals: wire.goals,
            selected_goal,
            primitive: wire.primitive.map(std::borrow::Cow::Owned),
            inhibited_by: wire.inhibited_by,
            scores_received: wire.scores_received,
        })
    }
}

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

struct Active<G> {
    goal: G,
    primitive: usize,
}

/// A selection made by the activation function, not yet executed. It names a goal of the
/// multiplexer's current assessment rather than holding a copy of it (goals own strings, and
/// a selection is made every cycle), so it is executed by the multiplexer that made it, before
/// that multiplexer evaluates again or receives another score vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Selection {
    /// The selected goal's place in [`Assessment::goals`].
    goal: usize,
    pub final_score: f64,
    primitive: usize,
    /// The assessment the selection was made from.
    assessment: u64,
}

/// One goal as the activation function assessed it: everything that holds until the score
/// vector or (for a world-only policy) the world state changes.
struct Assessed<G> {
    /// The offered goal (reflexes first, then the score vector) it comes from.
    offered: usize,
    /// The goal a split made, if the offered goal was split.
    split: Option<GoalScore<G>>,
    final_score: f64,
    /// The first primitive (by index) that may pursue it; `None`: not applicable.
    primitive: Option<usize>,
    /// It is the goal the multiplexer pursues (it earns the hysteresis bonus). Valid while
    /// [`Assessment::pursued_known`].
    pursued: bool,
}

impl<G> Assessed<G> {
    /// The goal itself: the one the split made, or the offered one (reflexes first, then the
    /// score vector).
    fn goal<'a>(
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
struct Assessment<G> {
    goals: Vec<Assessed<G>>,
    /// One per goal, in the same order.
    reports: GoalReports,
    /// The world-state revision and the policy's reuse key the answers hold for; `None`: only
    /// for the cycle that made them (no revision given, no key, or a new score vector since).
    key: Option<(u64, u64)>,
    /// Counts assessments, so that a selection is executed only on the assessment it was
    /// made from.
    serial: u64,
    /// Whether the goals' `pursued` flags hold for the goal pursued now: comparing goals every
    /// cycle would compare their strings, though the goal pursued rarely changes.
    pursued_known: bool,
}

/// Manages one resource group: holds the deliberative score vector, runs the activation
/// function, activates one primitive behavior.
pub struct Multiplexer<G, Cmd, W> {
    group: ResourceGroup,
    config: MultiplexerConfig,
    policy: Box<dyn ActivationPolicy<G, W>>,
    primitives: Vec<Box<dyn PrimitiveBehavior<G, Cmd, W>>>,
    scores: ScoreVector<G>,
    /// Goals the reactive layer always offers this multiplexer (reflexes such as the fall
    /// goal): they must not wait for a slow deliberative layer.
    reflexes: ScoreVector<G>,
    /// Labels of the reflexes and offered goals, made once per score vector rather than every
    /// cycle (a reactive cycle must not format strings it already has).
    labels: Vec<(std::sync::Arc<str>, std::sync::Arc<[String]>)>,
    /// The policy's notes on each offered goal (reflexes first), emptied with the labels.
    notes: Vec<GoalNotes>,
    deactivated: BTreeSet<String>,
    /// The primitive each list of names given by the policy resolves to, under the current
    /// deactivations: the policy answers with a few static lists, so each is resolved once
    /// per score vector rather than by comparing names for every goal.
    resolved: Vec<(&'static [&'static str], Option<usize>)>,
    assessment: Assessment<G>,
    /// Where the next assessment's reports are gathered (kept for its capacity).
    scratch: Vec<GoalReport>,
    active: Option<Active<G>>,
    report: MuxReport,
}

impl<G: Goal, Cmd, W> Debug for Multiplexer<G, Cmd, W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Multiplexer")
            .field("group", &self.group)
            .field("primitives", &self.primitives.iter().map(|p| p.name()).collect::<Vec<_>>())
            .field("scores", &self.scores)
            .finish()
    }
}

impl<G: Goal, Cmd, W> Multiplexer<G, Cmd, W> {
    pub fn new(
        group: ResourceGroup,
        config: MultiplexerConfig,
        policy: Box<dyn ActivationPolicy<G, W>>,
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

    /// Registers a primitive behavior. Names must be unique within the multiplexer.
    pub fn with_primitive(mut self, primitive: Box<dyn PrimitiveBehavior<G, Cmd, W>>) -> Self {
        self.primitives.retain(|p| p.name() != primitive.name());
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

    pub fn primitive_names(&self) -> Vec<&'static str> {
        self.primitives.iter().map(|p| p.name()).collect()
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

    /// [`Multiplexer::evaluate`] on the world state numbered `revision` by the caller, if it
    /// numbers them: the answers of a policy with a reuse key are reused while the world
    /// state, the score vector and the key stay.
    fn evaluate_on(
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
        resolved: &mut Vec<(&'static [&'static str], Option<usize>)>,
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

    /// The first of `names` that is registered and not deactivated, remembered in
    /// `resolved` (taken out of the multiplexer while its goals are assessed).
    fn resolve(
        &self,
        names: &'static [&'static str],
        resolved: &mut Vec<(&'static [&'static str], Option<usize>)>,
    ) -> Option<usize> {
        // The same static list, at the same address: the same names.
        if let Some((_, primitive)) = resolved.iter().find(|(n, _)| std::ptr::eq(*n, names)) {
            return *primitive;
        }
        let primitive = names
            .iter()
            .copied()
            .filter(|name| !self.deactivated.contains(*name))
            .find_map(|name| self.primitives.iter().position(|p| p.name() == name));
        resolved.push((names, primitive));
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
        self.report.primitive = Some(std::borrow::Cow::Borrowed(primitive.name()));
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
    fn take_report(&mut self) -> MuxReport {
        let fresh = MuxReport {
            group: Some(self.group),
            scores_received: self.report.scores_received,
            ..MuxReport::default()
        };
        std::mem::replace(&mut self.report, fresh)
    }
}

/// Everything the reactive layer decided in one cycle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReactiveReport {
    pub stamp: Time,
    pub stability: Stability,
    pub head: MuxReport,
    pub body: MuxReport,
    pub whole_body: MuxReport,
    pub commands: MotionCommands,
}

impl ReactiveReport {
    /// "head: observe ball > object tracking | body: go to position > go to position".
    pub fn active_path(&self) -> String {
        let part =
            |name: &str, r: &MuxReport| match (&r.selected_goal, &r.primitive, r.inhibited_by) {
                (Some(goal), Some(primitive), _) => format!("{name}: {goal} > {primitive}"),
                (_, _, Some(by)) => format!("{name}: inhibited by {}", by.name()),
                _ => format!("{name}: idle"),
            };
        format!(
            "{} | {} | {}",
            part("head+body", &self.whole_body),
            part("head", &self.head),
            part("body", &self.body)
        )
    }
}

/// The three multiplexers of a humanoid and the fall detector. `H`, `B`, `X`: the
/// application's head, body and head+body goal types; `W`: the world state type.
pub struct ReactiveLayer<H, B, X, W> {
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
    /// ([`ActivationPolicy::reuse_key`]) if their key is the same too: they are the answers
    /// the policies would give again. The fall detector, the ranking with its hysteresis and
    /// the primitives run every cycle.
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
