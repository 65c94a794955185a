//! The world model (paper 3.1): one filter per object of interest in the robot's frame, and a
//! robot-pose filter fed by the landmark filters. Plain data and methods, no threads: the
//! world-modeling module is a thin shell around it.

use std::ops::Range;

use nalgebra::{Matrix2, Matrix3, Vector2};
use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use super::config::{
    ConfigError, ObjectConfidence, ObjectKind, PosePrior, SymmetryHint, WorldModelConfig,
    validate_hint, validate_pose_prior,
};
use super::expected::{BeliefView, ExpectedBelief, ObjectPrior, SensingCandidate};
use super::math::{
    BearingBound, RangeBearing, chi2_2dof_quantile, major_sigma, polar, sigma_radius,
};
use super::object::{GainedInformation, MotionModel, ObjectFilter, innovation_at};
use super::odometry_error::{Lag, LandmarkShift, OdometryErrorEstimator};
use super::pose::PoseFilter;
use super::published::{
    Estimate, PoseFrame, Track as PublishedTrack, UNKNOWN_VARIANCE, derive, field_estimate_with,
    map_prediction_from,
};
use super::recovery::{MapInstance, RecoveryInput, RecoveryOutcome, Sighting, TeamCue, recover};
use super::state::{
    LostReason, MapAccuracy, ObjectCategory, ObjectEstimate, ObjectId, ObjectInfo, ObjectName,
    PoseEstimate, WorldDiagnostics, WorldLayout, WorldState,
};
use super::team::{
    FusionCandidate, Source, TeamError, TeamFusion, TeamObject, TeammateEstimate, fuse,
};
use crate::geometry::{Field, Odometry, Point, Pose, Vector};
use crate::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use crate::platform::{FootContact, ObjectClass};

/// What the application can tell world modeling at run time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldCommand {
    /// The robot is here (placed by the referee, start of a half).
    SetPose { prior: PosePrior },
    /// The robot was carried: forget the pose and the stale landmark tracks.
    Kidnapped,
    /// Forget everything.
    Reset,
    /// Replace the standing symmetry hints.
    SetHints { hints: Vec<SymmetryHint> },
}

/// Innovations of a moving object above this (chi-square, 2 dof, 97.5%) suggest a maneuver.
const MANEUVER_GATE: f64 = 7.38;
/// Objects closer than this are not expected to be seen (below the camera), m.
const MIN_VISIBLE_RANGE: f64 = 0.2;

#[derive(Clone, Debug)]
struct Group {
    name: ObjectName,
    class: ObjectClass,
    variant: Option<u16>,
    category: ObjectCategory,
    model: MotionModel,
    /// Velocity uncertainty of a new track.
    velocity_sigma: f64,
    friction: f64,
    confidence: ObjectConfidence,
    slots: Range<usize>,
    pending: Vec<Pending>,
}

impl Group {
    fn accepts(&self, obs: &Observation) -> bool {
        obs.class == self.class && (self.variant.is_none() || obs.variant == self.variant)
    }
}

/// A rejected observation kept for a while: several consistent ones restart a track.
#[derive(Clone, Copy, Debug)]
struct Pending {
    position: Vector2<f64>,
    stamp: Time,
}

#[derive(Clone, Debug)]
struct Slot {
    name: ObjectName,
    group: usize,
    map_position: Option<Point<Field>>,
    track: Option<Track>,
}

#[derive(Clone, Debug)]
struct Track {
    filter: ObjectFilter,
    /// Static landmarks: the estimate's error due to odometry's relative error.
    lag: Lag,
    existence: f64,
    last_seen: Time,
    updated: bool,
}

/// A landmark corrected in this frame, for the pose filter and the odometry-error estimate.
#[derive(Clone, Copy, Debug)]
struct FrameGain {
    slot: usize,
    gained: GainedInformation,
    /// The filter's prediction, innovation (with covariance) and lag before the observation
    /// (`None`: the track started now).
    prior: Option<LandmarkShift>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Assignment {
    Open,
    Taken,
    /// Fits several instances of this group about equally well.
    Ambiguous(usize),
}

/// A position estimate (robot frame) and its covariance.
type Gaussian2 = (Vector2<f64>, Matrix2<f64>);

/// One observation of an image, ready for association: the group that accepts it, and the
/// measured point with its noise in the robot frame. Converted from range and bearing once per
/// image: gating, the update, a new track and the pose filter all use the same conversion
/// (each costs a sine and cosine of the bearing).
#[derive(Clone, Copy, Debug)]
struct Measured {
    group: usize,
    position: Vector2<f64>,
    noise: Matrix2<f64>,
}

impl Measured {
    fn gained(&self) -> GainedInformation {
        GainedInformation { position: self.position, covariance: self.noise }
    }
}

/// Buffers reused from frame to frame (no allocation in the steady state).
#[derive(Clone, Debug, Default)]
struct Scratch {
    measurements: Vec<Option<Measured>>,
    /// (cost, observation, slot) of every gated candidate.
    pairs: Vec<(f64, usize, usize)>,
    observation_done: Vec<Assignment>,
    slot_taken: Vec<bool>,
    shifts: Vec<LandmarkShift>,
    /// Per slot, once asked for: its [`WorldModel::association_prior`].
    priors: Vec<Option<Option<Gaussian2>>>,
    /// Team fusion's candidates.
    candidates: Vec<FusionCandidate>,
}

#[derive(Clone, Debug, Default)]
struct KidnapDetector {
    consecutive: usize,
    slots: Vec<usize>,
    /// When the current run of disagreements started.
    since: Option<Time>,
}

impl KidnapDetector {
    fn accept(&mut self) {
        self.consecutive = 0;
        self.slots.clear();
        self.since = None;
    }

    fn reject(&mut self, slot: usize, now: Time) {
        self.consecutive += 1;
        self.since.get_or_insert(now);
        if !self.slots.contains(&slot) {
            self.slots.push(slot);
        }
    }

    fn triggered(&self, needed: usize) -> bool {
        self.consecutive >= needed && self.slots.len() >= 2
    }
}

/// The world model: object filters, the robot-pose filter, confidence, map accuracy, the
/// odometry-error estimate and team fusion.
#[derive(Clone, Debug)]
pub struct WorldModel {
    config: WorldModelConfig,
    gate: f64,
    groups: Vec<Group>,
    slots: Vec<Slot>,
    /// The objects of interest and parameters every published state shares.
    layout: Shared<WorldLayout>,
    pose: Option<PoseFilter>,
    lost: Option<LostReason>,
    last_pose_correction: Option<Time>,
    last_recovery_attempt: Option<Time>,
    hints: Vec<SymmetryHint>,
    time: Option<Time>,
    frame_gains: Vec<FrameGain>,
    kidnap: KidnapDetector,
    lifted: bool,
    odometry_error: OdometryErrorEstimator,
    team: TeamFusion,
    team_objects: Vec<TeamObject>,
    diagnostics: WorldDiagnostics,
    scratch: Scratch,
    /// Each slot's confidence as worked out at the end of the last frame (0 when untracked),
    /// while `confidences_current`: the publication that follows a frame reuses them instead
    /// of working each out again. Anything that may change a filter, the time or the slots'
    /// tracks clears the flag (see [`WorldModel::confidence_changes`]).
    confidences: Vec<f64>,
    confidences_current: bool,
    /// Object lists this model published, newest last: one no reader holds any more is
    /// written over by the next publication instead of allocating another.
    published: Vec<std::sync::Arc<[ObjectEstimate]>>,
}

/// How many published object lists [`WorldModel::publish`] keeps for reuse: readers hold the
/// newest (Latest) and sometimes the one before for a while, and a log's writer those it has
/// not written yet (a match's lockstep log holds up to about half a simulated second).
const PUBLISHED_LISTS: usize = 32;

/// What every object of one publication shares.
#[derive(Clone, Copy, Debug)]
struct PublicationFrame {
    stamp: Time,
    pose: PoseFrame,
    max_age: f64,
}

fn bayes_detect(e: f64, pd: f64, pf: f64) -> f64 {
    e * pd / (e * pd + (1.0 - e) * pf)
}

fn bayes_miss(e: f64, pd: f64) -> f64 {
    e * (1.0 - pd) / (e * (1.0 - pd) + (1.0 - e))
}

impl WorldModel {
    /// Builds the filters the configuration describes; checks it first.
    pub fn new(config: WorldModelConfig) -> Result<WorldModel, ConfigError> {
        config.validate()?;
        let mut groups = Vec::new();
        let mut slots = Vec::new();
        for (g, o) in config.objects.iter().enumerate() {
            let start = slots.len();
            let (category, model, velocity_sigma, friction, default_confidence) = match &o.kind {
                ObjectKind::Landmark { positions, position_noise } => {
                    for (k, p) in positions.iter().enumerate() {
                        let name = if positions.len() == 1 {
                            o.name.clone()
                        } else {
                            format!("{}#{k}", o.name)
                        };
                        slots.push(Slot {
                            name: name.into(),
                            group: g,
                            map_position: Some(*p),
                            track: None,
                        });
                    }
                    (
                        ObjectCategory::Landmark,
                        MotionModel::Static { position_noise: *position_noise },
                        0.0,
                        0.0,
                        config.confidence.landmark,
                    )
                }
                ObjectKind::Mobile { friction, acceleration_noise, max_speed } => {
                    slots.push(Slot {
                        name: o.name.as_str().into(),
                        group: g,
                        map_position: None,
                        track: None,
                    });
                    (
                        ObjectCategory::Mobile,
                        MotionModel::Rolling {
                            friction: *friction,
                            acceleration_noise: *acceleration_noise,
                        },
                        max_speed / 2.0,
                        *friction,
                        config.confidence.mobile,
                    )
                }
                ObjectKind::Obstacle {
                    max_tracks,
                    acceleration_noise,
                    velocity_decay,
                    max_speed,
                } => {
                    for k in 0..*max_tracks {
                        slots.push(Slot {
                            name: format!("{}#{k}", o.name).into(),
                            group: g,
                            map_position: None,
                            track: None,
                        });
                    }
                    (
                        ObjectCategory::Obstacle,
                        MotionModel::Walking {
                            velocity_decay: *velocity_decay,
                            acceleration_noise: *acceleration_noise,
                        },
                        max_speed / 2.0,
                        0.0,
                        config.confidence.obstacle,
                    )
                }
            };
            groups.push(Group {
                name: o.name.as_str().into(),
                class: o.class,
                variant: o.variant,
                category,
                model,
                velocity_sigma,
                friction,
                confidence: o.confidence.unwrap_or(default_confidence),
                slots: start..slots.len(),
                pending: Vec::new(),
            });
        }
        let (pose, lost) = match &config.pose.initial {
            Some(prior) => (Some(PoseFilter::new(prior.pose, prior.covariance())), None),
            None => (None, Some(LostReason::Uninitialized)),
        };
        Ok(WorldModel {
            gate: chi2_2dof_quantile(config.association.gate_probability),
            hints: config.pose.hints.clone(),
            odometry_error: OdometryErrorEstimator::new(config.pose.correct_odometry),
            team: TeamFusion::new(config.team),
            layout: Shared::new(WorldLayout::new(
                slots
                    .iter()
                    .map(|slot| {
                        let group = &groups[slot.group];
                        ObjectInfo {
                            name: slot.name.clone(),
                            group: group.name.clone(),
                            class: group.class,
                            variant: group.variant,
                            category: group.category,
                            map_position: slot.map_position,
                        }
                    })
                    .collect(),
                config.camera,
                config.confidence.detection_probability,
                config.confidence.view_margin,
                config.confidence.unknown_threshold,
            )),
            groups,
            slots,
            pose,
            lost,
            last_pose_correction: None,
            last_recovery_attempt: None,
            time: None,
            frame_gains: Vec::new(),
            kidnap: KidnapDetector::default(),
            lifted: false,
            team_objects: Vec::new(),
            diagnostics: WorldDiagnostics::default(),
            scratch: Scratch::default(),
            confidences: Vec::new(),
            confidences_current: false,
            published: Vec::new(),
            config,
        })
    }

    pub fn config(&self) -> &WorldModelConfig {
        &self.config
    }

    /// The Mahalanobis gate (chi-square, 2 dof) used for association.
    pub fn gate(&self) -> f64 {
        self.gate
    }

    pub fn object_count(&self) -> usize {
        self.slots.len()
    }

    /// The id of the object (or instance, `name#k`) with this name.
    pub fn object_id(&self, name: &str) -> Option<ObjectId> {
        self.slots
            .iter()
            .position(|s| s.name == name)
            .and_then(|i| u16::try_from(i).ok())
            .map(ObjectId)
    }

    pub fn object_name(&self, id: ObjectId) -> Option<&str> {
        self.slots.get(id.index()).map(|s| s.name.as_str())
    }

    /// The ids of an object of interest's instances (one for mobile objects).
    pub fn instances(&self, name: &str) -> Vec<ObjectId> {
        self.groups
            .iter()
            .find(|g| g.name == name)
            .map(|g| g.slots.clone().filter_map(|i| u16::try_from(i).ok()).map(ObjectId).collect())
            .unwrap_or_default()
    }

    /// The filter following an object, if it is tracked.
    pub fn filter(&self, id: ObjectId) -> Option<&ObjectFilter> {
        self.slots.get(id.index())?.track.as_ref().map(|t| &t.filter)
    }

    pub fn pose_filter(&self) -> Option<&PoseFilter> {
        self.pose.as_ref()
    }

    pub fn lost(&self) -> Option<LostReason> {
        self.lost
    }

    pub fn time(&self) -> Option<Time> {
        self.time
    }

    pub fn diagnostics(&self) -> WorldDiagnostics {
        self.diagnostics
    }

    fn pose_usable(&self) -> Option<&PoseFilter> {
        if self.lost.is_none() { self.pose.as_ref() } else { None }
    }

    // ----- prediction -------------------------------------------------------------------

    /// Applies a motion of the robot (odometry) to every filter.
    pub fn predict(&mut self, odometry: Odometry) {
        self.confidence_changes();
        if !odometry.is_finite() {
            self.diagnostics.ignored += 1;
            return;
        }
        if odometry == Odometry::ZERO {
            return;
        }
        let reported = odometry;
        let used = self.odometry_error.applied();
        let odometry = self.odometry_error.correct(odometry);
        let q = self.config.odometry.covariance(&odometry);
        if let Some(pose) = &mut self.pose {
            pose.predict(&odometry, &q);
        }
        let turn = odometry.dtheta.sin_cos();
        // Uncorrected (the usual case) the turn is the reported one, bit for bit.
        let reported_turn = if reported.dtheta.to_bits() == odometry.dtheta.to_bits() {
            turn
        } else {
            reported.dtheta.sin_cos()
        };
        for slot in &mut self.slots {
            if let Some(track) = &mut slot.track {
                track.filter.predict_odometry_with(&odometry, turn, &q);
                if slot.map_position.is_some() {
                    let position = track.filter.position_vector();
                    track.lag.predict(position, &reported, reported_turn, &used);
                }
            }
        }
        for group in &mut self.groups {
            for p in &mut group.pending {
                let moved = odometry.transform_point(Point::new(p.position.x, p.position.y));
                p.position = Vector2::new(moved.x, moved.y);
            }
        }
    }

    /// Lets time pass until `time`: mobile objects move by their own motion models.
    pub fn advance_to(&mut self, time: Time) {
        self.confidence_changes();
        let dt = match self.time {
            Some(t) if time > t => (time - t).as_secs_f64(),
            Some(_) => return,
            None => 0.0,
        };
        self.time = Some(time);
        if dt > 0.0 {
            for slot in &mut self.slots {
                if let Some(track) = &mut slot.track {
                    track.filter.predict_motion(dt);
                }
            }
        }
    }

    /// One percept frame: odometry since the previous frame, then the frame's observations.
    pub fn process(&mut self, odometry: Odometry, percepts: &Percepts) {
        self.check_lift(&percepts.foot_contact);
        self.predict(odometry);
        let stamp = percepts.camera.as_ref().map_or(percepts.stamp, |c| c.stamp);
        self.advance_to(stamp);
        match &percepts.camera {
            Some(camera) => self.update(camera),
            None => self.finish_frame(false),
        }
    }

    /// A frame without an image that the caller does not run the filters for (its odometry is
    /// merged into the next one): only the lift detector needs every frame.
    pub fn note_frame_without_image(&mut self, percepts: &Percepts) {
        self.check_lift(&percepts.foot_contact);
    }

    fn check_lift(&mut self, contact: &FootContact) {
        let Some(threshold) = self.config.pose.kidnap_on_lift else { return };
        if !contact.on_ground(threshold) {
            self.lifted = true;
        } else if self.lifted {
            self.lifted = false;
            self.declare_kidnapped();
        }
    }

    // ----- correction -------------------------------------------------------------------

    /// Corrects the filters with one camera image's observations (paper 3.1): each object
    /// filter with its own observations, then the pose filter with what the landmark filters
    /// gained.
    pub fn update(&mut self, camera: &CameraPercepts) {
        self.confidence_changes();
        self.advance_to(camera.stamp);
        let now = self.time.unwrap_or(camera.stamp);
        self.diagnostics.frames += 1;
        for slot in &mut self.slots {
            if let Some(track) = &mut slot.track {
                track.updated = false;
            }
        }
        self.frame_gains.clear();
        let window = self.config.association.reinit_window;
        for group in &mut self.groups {
            group.pending.retain(|p| (now - p.stamp).as_secs_f64() <= window);
        }
        self.associate_frame(&camera.observations, now);
        self.negative_information(&camera.view);
        self.estimate_odometry_error();
        self.correct_pose(now);
        self.finish_frame(true);
    }

    fn measurement(&self, obs: &Observation) -> Option<RangeBearing> {
        let camera = &self.config.camera;
        let (range_sigma, bearing_sigma) = camera.sigmas(obs.range);
        let usable = |s: f64| s.is_finite() && s > 0.0;
        let z = if camera.use_percept_sigmas && usable(obs.range_sigma) && usable(obs.bearing_sigma)
        {
            RangeBearing {
                range: obs.range,
                bearing: obs.bearing,
                range_sigma: obs.range_sigma,
                bearing_sigma: obs.bearing_sigma,
            }
        } else {
            RangeBearing { range: obs.range, bearing: obs.bearing, range_sigma, bearing_sigma }
        };
        z.is_valid().then_some(z)
    }

    /// Where the pose and the map put a landmark instance (robot frame), with covariance.
    fn map_prediction(&self, slot: usize) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let pose = self.pose_usable()?;
        Some(map_prediction_at(pose, pose.heading_sin_cos(), self.slots[slot].map_position?))
    }

    /// What association compares an observation with: the filter's position estimate, or
    /// where the pose and the map put an untracked landmark instance.
    fn association_prior(
        &self,
        slot: usize,
        pose: Option<&(PoseFilter, (f64, f64))>,
    ) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let slot = &self.slots[slot];
        match &slot.track {
            Some(track) => {
                Some((track.filter.position_vector(), track.filter.position_covariance()))
            }
            None => {
                let (pose, heading) = pose?;
                Some(map_prediction_at(pose, *heading, slot.map_position?))
            }
        }
    }

    /// Associates one image's observations with the object filters (global nearest neighbour:
    /// each filter takes at most one observation per image, best fits first, so a false
    /// positive next to the real object does not also correct it), then corrects them.
    fn associate_frame(&mut self, observations: &[Observation], now: Time) {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.measurements.clear();
        scratch.pairs.clear();
        // Nothing changes until every candidate pair is scored: each filter's prior (or map
        // prediction) is worked out once per image, each observation converted once.
        scratch.priors.clear();
        scratch.priors.resize(self.slots.len(), None);
        let pose = self.pose_usable().map(|p| (p.clone(), p.heading_sin_cos()));
        for (i, obs) in observations.iter().enumerate() {
            self.diagnostics.observations += 1;
            let z = self.measurement(obs);
            let group = self.groups.iter().position(|g| g.accepts(obs));
            let (Some(z), Some(group)) = (z, group) else {
                self.diagnostics.ignored += 1;
                scratch.measurements.push(None);
                continue;
            };
            let (measured, noise) = (z.cartesian(), z.cartesian_noise());
            scratch.measurements.push(Some(Measured { group, position: measured, noise }));
            for g in self.groups.iter().filter(|g| g.accepts(obs)) {
                for slot in g.slots.clone() {
                    let prior = *scratch.priors[slot]
                        .get_or_insert_with(|| self.association_prior(slot, pose.as_ref()));
                    if let Some((position, covariance)) = prior
                        && let Some(innovation) =
                            innovation_at(position, &covariance, measured, &noise)
                        && innovation.nis <= self.gate
                    {
                        scratch.pairs.push((innovation.cost(), i, slot));
                    }
                }
            }
        }
        scratch.pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        scratch.observation_done.clear();
        scratch.observation_done.resize(observations.len(), Assignment::Open);
        scratch.slot_taken.clear();
        scratch.slot_taken.resize(self.slots.len(), false);
        let margin = self.config.association.ambiguity_margin;
        for k in 0..scratch.pairs.len() {
            let (cost, i, slot) = scratch.pairs[k];
            if scratch.observation_done[i] != Assignment::Open || scratch.slot_taken[slot] {
                continue;
            }
            let second = scratch
                .pairs
                .iter()
                .filter(|&&(_, j, s)| j == i && s != slot && !scratch.slot_taken[s])
                .map(|p| p.0)
                .fold(f64::INFINITY, f64::min);
            if second - cost < margin {
                scratch.observation_done[i] = Assignment::Ambiguous(self.slots[slot].group);
                continue;
            }
            scratch.observation_done[i] = Assignment::Taken;
            scratch.slot_taken[slot] = true;
            if let Some(m) = scratch.measurements[i] {
                self.associate(slot, &m, now);
            }
        }
        for (i, m) in scratch.measurements.iter().enumerate() {
            let Some(m) = m else { continue };
            match scratch.observation_done[i] {
                Assignment::Taken => {}
                Assignment::Ambiguous(g) => {
                    self.diagnostics.ambiguous += 1;
                    self.reject(g, m, now);
                }
                Assignment::Open => self.reject(m.group, m, now),
            }
        }
        self.scratch = scratch;
    }

    fn associate(&mut self, slot: usize, m: &Measured, now: Time) {
        let group = &self.groups[self.slots[slot].group];
        let (model, velocity_sigma, landmark) =
            (group.model, group.velocity_sigma, group.category == ObjectCategory::Landmark);
        let k = self.config.confidence;
        match &mut self.slots[slot].track {
            Some(track) => {
                let (measured, noise) = (m.position, m.noise);
                let gained = m.gained();
                let Some(innovation) = innovation_at(
                    track.filter.position_vector(),
                    &track.filter.position_covariance(),
                    measured,
                    &noise,
                ) else {
                    self.diagnostics.ignored += 1;
                    return;
                };
                // A moving object far from where it should be was probably pushed or kicked:
                // open up its velocity so that the next frames can follow.
                if !model.is_static() && innovation.nis > MANEUVER_GATE {
                    track.filter.inflate_velocity(velocity_sigma);
                }
                let prior = track.filter.position_vector();
                let prior_covariance = track.filter.position_covariance();
                if track.filter.update_at(measured, &noise).is_none() {
                    self.diagnostics.ignored += 1;
                    return;
                }
                track.existence = bayes_detect(
                    track.existence,
                    k.detection_probability,
                    k.false_alarm_probability,
                )
                .clamp(k.min_existence, k.max_existence);
                track.last_seen = now;
                track.updated = true;
                if landmark {
                    let shift = LandmarkShift {
                        prior,
                        innovation: innovation.nu,
                        covariance: innovation.s,
                        lag: track.lag,
                    };
                    if let Some(s_inv) = innovation.s.try_inverse() {
                        track.lag.correct(&(prior_covariance * s_inv));
                    }
                    self.frame_gains.push(FrameGain { slot, gained, prior: Some(shift) });
                }
            }
            None => {
                self.start_track(slot, m, now, model, velocity_sigma);
                if landmark {
                    self.frame_gains.push(FrameGain { slot, gained: m.gained(), prior: None });
                }
            }
        }
        self.diagnostics.associated += 1;
    }

    fn start_track(
        &mut self,
        slot: usize,
        m: &Measured,
        now: Time,
        model: MotionModel,
        velocity_sigma: f64,
    ) {
        self.slots[slot].track = Some(Track {
            filter: ObjectFilter::from_converted(m.position, m.noise, velocity_sigma, model),
            lag: Lag::default(),
            existence: self.config.confidence.initial_existence,
            last_seen: now,
            updated: true,
        });
    }

    fn is_stale(&self, slot: usize, now: Time) -> bool {
        self.slots[slot].track.as_ref().is_none_or(|t| {
            (now - t.last_seen).as_secs_f64() > self.config.association.reinit_window
        })
    }

    fn reject(&mut self, g: usize, m: &Measured, now: Time) {
        self.diagnostics.rejected += 1;
        let position = m.position;
        let group = &self.groups[g];
        let (model, velocity_sigma, category) = (group.model, group.velocity_sigma, group.category);
        // A mobile object or obstacle nobody follows starts at once (a false positive dies of
        // negative information); a free landmark instance waits for consistent observations,
        // which keeps false positives out of recovery.
        if category != ObjectCategory::Landmark
            && let Some(free) = group.slots.clone().find(|&s| self.slots[s].track.is_none())
        {
            self.start_track(free, m, now, model, velocity_sigma);
            self.diagnostics.reinitialized += 1;
            return;
        }
        let radius = self.config.association.reinit_radius;
        let group = &mut self.groups[g];
        group.pending.push(Pending { position, stamp: now });
        let (consistent, since) = group
            .pending
            .iter()
            .filter(|p| (p.position - position).norm() <= radius)
            .fold((0, now), |(n, t), p| (n + 1, t.min(p.stamp)));
        if consistent < self.config.association.reinit_observations {
            return;
        }
        group.pending.retain(|p| (p.position - position).norm() > radius);
        let Some(slot) = self.reinit_slot(g, m, now, since) else {
            if category == ObjectCategory::Landmark && self.pose_usable().is_some() {
                // Consistent observations of a landmark where the map and the pose put none:
                // a persistent false positive, or the robot is not where it believes.
                self.kidnap.reject(usize::MAX - g, now);
                if self.kidnap.triggered(self.config.pose.kidnap_rejections) {
                    self.declare_kidnapped();
                }
            }
            return;
        };
        self.slots[slot].track = None;
        self.diagnostics.reinitialized += 1;
        self.diagnostics.associated += 1;
        self.start_track(slot, m, now, model, velocity_sigma);
        if category == ObjectCategory::Landmark {
            self.frame_gains.push(FrameGain { slot, gained: m.gained(), prior: None });
        }
    }

    /// Which filter a cluster of consistent rejected observations, the oldest made at `since`,
    /// restarts. A mobile object or obstacle confirmed since then is really elsewhere: the
    /// cluster was clutter.
    fn reinit_slot(&self, g: usize, m: &Measured, now: Time, since: Time) -> Option<usize> {
        let group = &self.groups[g];
        let unconfirmed =
            |s: usize| self.slots[s].track.as_ref().is_none_or(|t| t.last_seen < since);
        match group.category {
            ObjectCategory::Mobile => Some(group.slots.start).filter(|&s| unconfirmed(s)),
            ObjectCategory::Obstacle => group
                .slots
                .clone()
                .filter(|&s| unconfirmed(s))
                .min_by(|&a, &b| self.confidence(a).total_cmp(&self.confidence(b))),
            ObjectCategory::Landmark => {
                let eligible = group.slots.clone().filter(|&s| self.is_stale(s, now));
                if self.pose_usable().is_some() {
                    // The instance the pose and the map make most likely, if any fits.
                    eligible
                        .filter_map(|s| {
                            let (l, cov) = self.map_prediction(s)?;
                            let i = innovation_at(l, &cov, m.position, &m.noise)?;
                            (i.nis <= self.gate).then_some((s, i.cost()))
                        })
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .map(|(s, _)| s)
                } else {
                    // Lost: any label will do, recovery relabels the instances.
                    eligible.min_by_key(|&s| {
                        self.slots[s]
                            .track
                            .as_ref()
                            .map_or(0, |t| t.last_seen.as_nanos().saturating_add(1))
                    })
                }
            }
        }
    }

    /// Objects predicted well inside the view that were not seen: less likely to be there,
    /// and a little less certain where they are.
    fn negative_information(&mut self, view: &ViewCone) {
        let k = self.config.confidence;
        let bearing_bound = BearingBound::new(view, k.view_margin);
        for slot in &mut self.slots {
            let Some(track) = &mut slot.track else { continue };
            if track.updated {
                continue;
            }
            // Too close, beyond the camera's range or outside its bearings whatever the
            // uncertainty (the tests below only get stricter): no need for the bearing's
            // trigonometry.
            let position = track.filter.position_vector();
            let range = position.norm();
            if range < MIN_VISIBLE_RANGE
                || range > view.range
                || bearing_bound.certainly_outside(position, range)
            {
                continue;
            }
            let (z, h) = polar(position);
            let s = h * track.filter.position_covariance() * h.transpose();
            let (sr, sb) = (s[(0, 0)].max(0.0).sqrt(), s[(1, 1)].max(0.0).sqrt());
            if z.x < MIN_VISIBLE_RANGE || z.x + 2.0 * sr > view.range {
                continue;
            }
            let margin = k.view_margin + 2.0 * sb;
            if !view.contains_polar(track.filter.position().range(), z.y, margin) {
                continue;
            }
            track.existence = bayes_miss(track.existence, k.detection_probability)
                .clamp(k.min_existence, k.max_existence);
            track.filter.inflate(k.miss_inflation);
        }
    }

    fn estimate_odometry_error(&mut self) {
        let shifts = &mut self.scratch.shifts;
        shifts.clear();
        shifts.extend(self.frame_gains.iter().filter_map(|g| g.prior));
        self.odometry_error.observe(shifts);
    }

    /// The pose filter's correction: the landmark filters' estimates as observations (only
    /// what each gained in this frame, so no observation counts twice).
    fn correct_pose(&mut self, now: Time) {
        if self.pose_usable().is_none() {
            return;
        }
        let gains = std::mem::take(&mut self.frame_gains);
        for gain in &gains {
            let Some(map) = self.slots[gain.slot].map_position else { continue };
            let Some(pose) = self.pose.as_ref() else { break };
            let fits =
                pose.landmark_innovation(map, &gain.gained).is_some_and(|i| i.nis <= self.gate);
            if fits {
                if let Some(pose) = self.pose.as_mut()
                    && pose.update_landmark(map, &gain.gained).is_some()
                {
                    self.last_pose_correction = Some(now);
                }
                self.kidnap.accept();
                continue;
            }
            // The track may carry the wrong label (started while lost, or ambiguous): another
            // free instance of the same landmark that fits takes it over.
            if let Some(other) = self.relabel_candidate(gain, now) {
                swap_tracks(&mut self.slots, gain.slot, other);
                self.diagnostics.relabels += 1;
                if let (Some(map), Some(pose)) =
                    (self.slots[other].map_position, self.pose.as_mut())
                    && pose.update_landmark(map, &gain.gained).is_some()
                {
                    self.last_pose_correction = Some(now);
                }
                self.kidnap.accept();
                continue;
            }
            self.diagnostics.pose_rejections += 1;
            self.kidnap.reject(gain.slot, now);
        }
        self.frame_gains = gains;
        if self.kidnap.triggered(self.config.pose.kidnap_rejections) {
            self.declare_kidnapped();
        }
    }

    fn relabel_candidate(&self, gain: &FrameGain, now: Time) -> Option<usize> {
        let pose = self.pose.as_ref()?;
        let group = &self.groups[self.slots[gain.slot].group];
        group
            .slots
            .clone()
            .filter(|&s| s != gain.slot && self.is_stale(s, now))
            .filter_map(|s| {
                let i = pose.landmark_innovation(self.slots[s].map_position?, &gain.gained)?;
                (i.nis <= self.gate).then_some((s, i.cost()))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| s)
    }

    fn declare_kidnapped(&mut self) {
        self.confidence_changes();
        let now = self.time.unwrap_or(Time::ZERO);
        // The robot was carried: landmark tracks not confirmed since the landmarks started
        // to disagree (or within the last moment, when told) are wrong.
        let window = std::time::Duration::from_secs_f64(self.config.association.reinit_window);
        let since = self.kidnap.since.unwrap_or(Time::from_nanos(
            now.as_nanos().saturating_sub(u64::try_from(window.as_nanos()).unwrap_or(u64::MAX)),
        ));
        self.lost = Some(LostReason::Kidnapped);
        self.diagnostics.kidnaps += 1;
        self.kidnap.accept();
        for slot in &mut self.slots {
            if slot.map_position.is_some()
                && slot.track.as_ref().is_some_and(|t| t.last_seen < since)
            {
                slot.track = None;
            }
        }
    }

    /// End of a frame: forget what is no longer believed, check the pose, try to recover it,
    /// fuse the team's estimates.
    fn finish_frame(&mut self, camera: bool) {
        let forget = self.config.confidence.forget_threshold;
        let mut confidences = std::mem::take(&mut self.confidences);
        confidences.resize(self.slots.len(), 0.0);
        for (i, confidence) in confidences.iter_mut().enumerate() {
            let tracked = self.slots[i].track.is_some();
            let mut c = if tracked { self.confidence(i) } else { 0.0 };
            if tracked && c < forget {
                self.slots[i].track = None;
                c = 0.0;
            }
            *confidence = c;
        }
        self.confidences = confidences;
        self.confidences_current = true;
        if self.lost.is_none() {
            match &self.pose {
                None => self.lost = Some(LostReason::Uninitialized),
                Some(pose) => {
                    let p = pose.covariance();
                    let xy = p.fixed_view::<2, 2>(0, 0).into_owned();
                    if major_sigma(&xy) > self.config.pose.lost_position_sigma
                        || p[(2, 2)].max(0.0).sqrt() > self.config.pose.lost_heading_sigma
                        || !pose.is_finite()
                    {
                        self.lost = Some(LostReason::Uncertain);
                    }
                }
            }
        }
        let now = self.time.unwrap_or(Time::ZERO);
        self.team.prune(now);
        let due = self
            .last_recovery_attempt
            .is_none_or(|t| (now - t).as_secs_f64() >= self.config.pose.recovery_period);
        if camera && self.lost.is_some() && due {
            self.last_recovery_attempt = Some(now);
            self.try_recover(now);
        }
        self.fuse_team(now);
    }

    fn try_recover(&mut self, now: Time) {
        let max_age = self.config.pose.recovery_max_age;
        let mut sightings = Vec::new();
        let mut map = Vec::new();
        for (i, slot) in self.slots.iter().enumerate() {
            let Some(position) = slot.map_position else { continue };
            map.push(MapInstance { group: slot.group, slot: i, position });
            if let Some(t) = &slot.track
                && (now - t.last_seen).as_secs_f64() <= max_age
            {
                sightings.push(Sighting {
                    group: slot.group,
                    slot: i,
                    position: t.filter.position_vector(),
                    covariance: t.filter.position_covariance(),
                });
            }
        }
        if sightings.len() < self.config.pose.recovery_min_landmarks {
            return;
        }
        let prior = match (self.lost, &self.pose) {
            (Some(LostReason::Uncertain), Some(p)) => Some((p.pose(), p.covariance())),
            _ => None,
        };
        let team = self.team_cues(now);
        let input = RecoveryInput {
            sightings: &sightings,
            map: &map,
            bounds: self.config.pose.field_bounds,
            hints: &self.hints,
            prior,
            team: &team,
            gate: self.gate,
            min_landmarks: self.config.pose.recovery_min_landmarks,
            margin: self.config.pose.recovery_margin,
            max_hypotheses: self.config.pose.recovery_max_hypotheses,
        };
        let h = match recover(&input) {
            RecoveryOutcome::Found(h) => h,
            RecoveryOutcome::Ambiguous { best, competitor } => {
                tracing::debug!(
                    best = ?best.pose,
                    competitor = ?competitor.pose,
                    "pose recovery ambiguous: waiting for more landmarks or a hint"
                );
                return;
            }
            RecoveryOutcome::Insufficient => return,
        };
        // Relabel: each sighting's track moves to the map instance it was matched with.
        self.confidence_changes();
        let mut moved: Vec<(usize, Option<Track>)> = Vec::new();
        for &(i, to) in &h.assignment {
            let from = sightings[i].slot;
            moved.push((to, self.slots[from].track.take()));
            if from != to {
                self.diagnostics.relabels += 1;
            }
        }
        for (to, track) in moved {
            self.slots[to].track = track;
        }
        self.pose = Some(PoseFilter::new(h.pose, h.covariance));
        self.lost = None;
        self.kidnap.accept();
        self.last_pose_correction = Some(now);
        self.diagnostics.recoveries += 1;
    }

    /// Mobile objects this robot tracks that the teammates also report, for recovery.
    fn team_cues(&self, now: Time) -> Vec<TeamCue> {
        let mut cues = Vec::new();
        for group in self.groups.iter().filter(|g| g.category == ObjectCategory::Mobile) {
            let slot = group.slots.start;
            let Some(track) = &self.slots[slot].track else { continue };
            if self.frame_confidence(slot) < self.config.confidence.unknown_threshold {
                continue;
            }
            let candidates = self.team.candidates(now, group.class, group.variant, group.friction);
            if let Some(f) = fuse(&candidates, self.team.gate()) {
                cues.push(TeamCue {
                    own_position: track.filter.position_vector(),
                    own_covariance: track.filter.position_covariance(),
                    team_position: f.position,
                    team_covariance: f.covariance,
                });
            }
        }
        cues
    }

    fn fuse_team(&mut self, now: Time) {
        self.team_objects.clear();
        if self.team.teammates().next().is_none() {
            return;
        }
        let pose = self.pose_usable().map(|p| (p.pose(), p.covariance()));
        let mut candidates = std::mem::take(&mut self.scratch.candidates);
        for group in &self.groups {
            if group.category != ObjectCategory::Mobile {
                continue;
            }
            let slot = group.slots.start;
            self.team.candidates_into(
                now,
                group.class,
                group.variant,
                group.friction,
                &mut candidates,
            );
            if let (Some((pose, pose_cov)), Some(track)) = (pose, &self.slots[slot].track)
                && self.frame_confidence(slot) >= self.config.confidence.unknown_threshold
            {
                let (position, covariance) = field_estimate(
                    &pose,
                    &pose_cov,
                    track.filter.position_vector(),
                    &track.filter.position_covariance(),
                );
                let v = track.filter.velocity();
                let fv = pose.vector_to_field(v);
                candidates.push(FusionCandidate {
                    source: Source::Own,
                    position,
                    covariance,
                    velocity: Some(Vector2::new(fv.x, fv.y)),
                });
            }
            let Some(f) = fuse(&candidates, self.team.gate()) else { continue };
            let teammates = |sources: &[Source]| {
                sources
                    .iter()
                    .filter_map(|s| match s {
                        Source::Teammate(p) => Some(*p),
                        Source::Own => None,
                    })
                    .collect::<Vec<u8>>()
            };
            self.team_objects.push(TeamObject {
                id: ObjectId(u16::try_from(slot).unwrap_or(u16::MAX)),
                name: group.name.clone(),
                class: group.class,
                position: Point::new(f.position.x, f.position.y),
                velocity: f.velocity.map(|v| Vector::new(v.x, v.y)),
                covariance: f.covariance,
                includes_own: f.members.contains(&Source::Own),
                teammates: teammates(&f.members),
                rejected: teammates(&f.rejected),
            });
        }
        self.scratch.candidates = candidates;
    }

    /// Stores a teammate's estimate for team fusion (MAWM); malformed ones are refused.
    pub fn add_teammate_estimate(&mut self, estimate: TeammateEstimate) -> Result<(), TeamError> {
        let result = self.team.insert(estimate);
        if result.is_err() {
            self.diagnostics.team_rejected += 1;
        }
        result
    }

    /// Applies a command from the application.
    pub fn command(&mut self, command: WorldCommand) -> Result<(), ConfigError> {
        self.confidence_changes();
        match command {
            WorldCommand::SetPose { prior } => {
                validate_pose_prior("command.prior", &prior)?;
                self.pose = Some(PoseFilter::new(prior.pose, prior.covariance()));
                self.lost = None;
                self.kidnap.accept();
            }
            WorldCommand::Kidnapped => self.declare_kidnapped(),
            WorldCommand::Reset => {
                for slot in &mut self.slots {
                    slot.track = None;
                }
                for group in &mut self.groups {
                    group.pending.clear();
                }
                self.pose = None;
                self.lost = Some(LostReason::Reset);
                self.kidnap.accept();
            }
            WorldCommand::SetHints { hints } => {
                for (i, hint) in hints.iter().enumerate() {
                    validate_hint(&format!("command.hints[{i}]"), hint)?;
                }
                self.hints = hints;
            }
        }
        Ok(())
    }

    // ----- confidence and state ---------------------------------------------------------

    /// Confidence of an object filter, in [0, 1]:
    /// `existence * 2^(-age / half_life) / (1 + (sigma / sigma_half)^2)`.
    fn confidence(&self, slot: usize) -> f64 {
        let Some(track) = &self.slots[slot].track else { return 0.0 };
        let c = self.groups[self.slots[slot].group].confidence;
        let now = self.time.unwrap_or(track.last_seen);
        let age = (now - track.last_seen).as_secs_f64();
        let sigma = sigma_radius(&track.filter.position_covariance());
        // An object seen in this very frame has not aged: exp(-0) is exactly 1, without the
        // call (most of the filters a frame updates are asked right after).
        let decay =
            if age == 0.0 { 1.0 } else { (-age / c.half_life * std::f64::consts::LN_2).exp() };
        let value = track.existence * decay / (1.0 + (sigma / c.sigma_half).powi(2));
        if value.is_finite() { value.clamp(0.0, 1.0) } else { 0.0 }
    }

    /// [`WorldModel::confidence`], from the end of the frame when nothing changed since.
    fn frame_confidence(&self, slot: usize) -> f64 {
        if !self.confidences_current {
            return self.confidence(slot);
        }
        let c = self.confidences[slot];
        debug_assert_eq!(c.to_bits(), self.confidence(slot).to_bits(), "slot {slot}");
        c
    }

    /// Something that a confidence depends on may change: the end-of-frame confidences are
    /// no longer those of the model.
    fn confidence_changes(&mut self) {
        self.confidences_current = false;
    }

    /// The confidence of an object, in [0, 1] (0 when not tracked).
    pub fn object_confidence(&self, id: ObjectId) -> f64 {
        if id.index() < self.slots.len() { self.confidence(id.index()) } else { 0.0 }
    }

    fn pose_confidence(&self) -> f64 {
        let Some(pose) = self.pose_usable() else { return 0.0 };
        let p = pose.covariance();
        let k = &self.config.confidence;
        let xy = major_sigma(&p.fixed_view::<2, 2>(0, 0).into_owned());
        let th = p[(2, 2)].max(0.0).sqrt();
        let c = 1.0
            / (1.0 + (xy / k.pose_sigma_half).powi(2))
            / (1.0 + (th / k.pose_heading_sigma_half).powi(2));
        if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 }
    }

    /// The world state to publish.
    pub fn state(&self) -> WorldState {
        let frame = self.publication_frame();
        let mut errors = MapErrors::default();
        let mut unknown = None;
        // Collected straight into the shared list (exact size): no intermediate `Vec` to copy.
        let objects: std::sync::Arc<[ObjectEstimate]> = self
            .layout
            .objects
            .iter()
            .enumerate()
            .map(|(i, info)| self.estimate(i, &frame, &mut unknown, &mut errors).object(i, info))
            .collect();
        self.world_state(&frame, objects, &errors)
    }

    /// [`WorldModel::state`], writing the objects into a list published before when no reader
    /// holds it any more (no allocation, and the fields fixed by the layout — id, names, class,
    /// category, map position — are already there). The same state, bit for bit.
    pub fn publish(&mut self) -> WorldState {
        let reusable = self.published.iter_mut().position(|list| {
            std::sync::Arc::get_mut(list).is_some_and(|objects| objects.len() == self.slots.len())
        });
        let Some(k) = reusable else {
            let state = self.state();
            if self.published.len() >= PUBLISHED_LISTS {
                self.published.remove(0);
            }
            self.published.push(state.objects.clone());
            return state;
        };
        let mut list = self.published.remove(k);
        let frame = self.publication_frame();
        let mut errors = MapErrors::default();
        let mut unknown = None;
        if let Some(objects) = std::sync::Arc::get_mut(&mut list) {
            for (i, o) in objects.iter_mut().enumerate() {
                self.estimate(i, &frame, &mut unknown, &mut errors).write_into(o);
            }
        }
        let state = self.world_state(&frame, list.clone(), &errors);
        self.published.push(list);
        state
    }

    /// What every object's estimate of a publication shares.
    fn publication_frame(&self) -> PublicationFrame {
        let unknown_pose = Matrix3::from_diagonal(&nalgebra::Vector3::new(
            UNKNOWN_VARIANCE,
            UNKNOWN_VARIANCE,
            std::f64::consts::PI.powi(2),
        ));
        let (pose, pose_cov) = self
            .pose
            .as_ref()
            .map_or((Pose::default(), unknown_pose), |p| (p.pose(), p.covariance()));
        // The heading's trigonometry once per publication rather than once per object, and
        // once for both frames when the published heading is the filter's (normalized already).
        let heading = pose.theta.sin_cos();
        let filter_heading = |p: &PoseFilter| {
            if p.heading().to_bits() == pose.theta.to_bits() {
                heading
            } else {
                p.heading_sin_cos()
            }
        };
        PublicationFrame {
            stamp: self.time.unwrap_or(Time::ZERO),
            pose: PoseFrame {
                pose,
                pose_cov,
                map_frame: self.pose_usable().map(|p| (p.state(), filter_heading(p))),
                heading,
                threshold: self.config.confidence.unknown_threshold,
            },
            max_age: self.config.pose.map_accuracy_max_age,
        }
    }

    /// The parts of slot `i`'s published estimate that change from one publication to the
    /// next (see [`derive`]); adds what the map accuracy needs to `errors`.
    // Inlined into the publication loops: the estimate goes straight into the published
    // object's fields instead of through a returned copy.
    #[inline(always)]
    fn estimate(
        &self,
        i: usize,
        frame: &PublicationFrame,
        unknown: &mut Option<(Point<Field>, Matrix2<f64>)>,
        errors: &mut MapErrors,
    ) -> Estimate {
        let slot = &self.slots[i];
        let moving = self.groups[slot.group].category != ObjectCategory::Landmark;
        let track = slot.track.as_ref().map(|t| PublishedTrack {
            position: t.filter.position_vector(),
            covariance: t.filter.position_covariance(),
            velocity: moving.then(|| (t.filter.velocity(), t.filter.velocity_covariance())),
            last_seen: t.last_seen,
        });
        let e = derive(&frame.pose, slot.map_position, self.frame_confidence(i), track, unknown);
        // The age of the last sighting only for the landmarks that may take part.
        let recent =
            || e.last_seen.is_some_and(|t| (frame.stamp - t).as_secs_f64() <= frame.max_age);
        if e.known
            && frame.pose.map_frame.is_some()
            && let Some(map) = slot.map_position
            && recent()
        {
            errors.add(e.field_position.distance(map));
        }
        e
    }

    fn world_state(
        &self,
        frame: &PublicationFrame,
        objects: std::sync::Arc<[ObjectEstimate]>,
        errors: &MapErrors,
    ) -> WorldState {
        WorldState {
            stamp: frame.stamp,
            pose: PoseEstimate {
                pose: frame.pose.pose,
                covariance: frame.pose.pose_cov,
                confidence: self.pose_confidence(),
                lost: self.lost.is_some(),
                lost_reason: self.lost,
                last_correction: self.last_pose_correction,
            },
            objects,
            map_accuracy: errors.accuracy(),
            odometry_error: self.odometry_error.estimate(),
            team: self.team_objects.clone(),
            camera: self.config.camera,
            detection_probability: self.config.confidence.detection_probability,
            view_margin: self.config.confidence.view_margin,
            unknown_threshold: frame.pose.threshold,
            diagnostics: self.diagnostics,
            layout: self.layout.clone(),
            filter_heading: frame.pose.map_frame.map(|(state, _)| state[2]),
            index: self.layout.index().clone(),
        }
    }

    /// The posterior covariances if `candidate` were executed (paper 3.6 (c)); changes nothing.
    pub fn expected_update(&self, candidate: &SensingCandidate) -> ExpectedBelief {
        let mut out = ExpectedBelief::default();
        super::expected::expected_update_into(self, candidate, &mut out);
        out
    }

    /// As [`WorldModel::expected_update`], reusing `out`'s storage.
    pub fn expected_update_into(&self, candidate: &SensingCandidate, out: &mut ExpectedBelief) {
        super::expected::expected_update_into(self, candidate, out);
    }
}

impl BeliefView for WorldModel {
    fn object_prior(&self, id: ObjectId) -> Option<ObjectPrior> {
        let slot = self.slots.get(id.index())?;
        match &slot.track {
            Some(t) => Some(ObjectPrior {
                tracked: true,
                position: t.filter.position_vector(),
                covariance: t.filter.position_covariance(),
                map_position: slot.map_position,
            }),
            None => {
                let (position, covariance) = self.map_prediction(id.index())?;
                Some(ObjectPrior {
                    tracked: false,
                    position,
                    covariance,
                    map_position: slot.map_position,
                })
            }
        }
    }

    fn pose_prior(&self) -> Option<(Pose, Matrix3<f64>)> {
        self.pose_usable().map(|p| (p.pose(), p.covariance()))
    }

    fn pose_covariance(&self) -> Matrix3<f64> {
        self.pose.as_ref().map_or_else(
            || {
                Matrix3::from_diagonal(&nalgebra::Vector3::new(
                    UNKNOWN_VARIANCE,
                    UNKNOWN_VARIANCE,
                    std::f64::consts::PI.powi(2),
                ))
            },
            |p| p.covariance(),
        )
    }
}

/// A robot-frame estimate placed on the field, with the pose's uncertainty added.
fn field_estimate(
    pose: &Pose,
    pose_cov: &Matrix3<f64>,
    l: Vector2<f64>,
    cov: &Matrix2<f64>,
) -> (Vector2<f64>, Matrix2<f64>) {
    field_estimate_with(pose, pose.theta.sin_cos(), pose_cov, l, cov)
}

/// Where the pose and the map put the landmark instance at `map` (robot frame), with
/// covariance; `heading` is `pose.heading_sin_cos()`.
fn map_prediction_at(
    pose: &PoseFilter,
    heading: (f64, f64),
    map: Point<Field>,
) -> (Vector2<f64>, Matrix2<f64>) {
    map_prediction_from(&pose.state(), &pose.covariance(), heading, map)
}

/// The map accuracy's statistics, accumulated without storing the errors (same order and
/// starting values as summing a list of them).
#[derive(Clone, Copy, Debug)]
struct MapErrors {
    sum: f64,
    sum_squares: f64,
    max: f64,
    count: usize,
}

impl Default for MapErrors {
    fn default() -> Self {
        // `Sum for f64` starts from -0.0.
        MapErrors { sum: -0.0, sum_squares: -0.0, max: 0.0, count: 0 }
    }
}

impl MapErrors {
    fn add(&mut self, error: f64) {
        self.sum += error;
        self.sum_squares += error * error;
        self.max = self.max.max(error);
        self.count += 1;
    }

    fn accuracy(&self) -> Option<MapAccuracy> {
        (self.count > 0).then(|| {
            let n = self.count as f64;
            MapAccuracy {
                mean_error: self.sum / n,
                rms_error: (self.sum_squares / n).sqrt(),
                max_error: self.max,
                landmarks: self.count,
            }
        })
    }
}

fn swap_tracks(slots: &mut [Slot], a: usize, b: usize) {
    let ta = slots[a].track.take();
    slots[a].track = slots[b].track.take();
    slots[b].track = ta;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::percept::ViewCone;
    use crate::world::config::ObjectOfInterest;

    fn layout(initial: Option<PosePrior>) -> WorldModelConfig {
        let object = |name: &str, class: u16, kind: ObjectKind| ObjectOfInterest {
            name: name.to_owned(),
            class: ObjectClass(class),
            variant: None,
            kind,
            confidence: None,
        };
        let mut config = WorldModelConfig {
            objects: vec![
                object(
                    "ball",
                    1,
                    ObjectKind::Mobile { friction: 0.4, acceleration_noise: 0.15, max_speed: 3.0 },
                ),
                object(
                    "post",
                    10,
                    ObjectKind::Landmark {
                        positions: vec![Point::new(4.5, 0.8), Point::new(4.5, -0.8)],
                        position_noise: 0.0,
                    },
                ),
                object(
                    "obstacle",
                    30,
                    ObjectKind::Obstacle {
                        max_tracks: 3,
                        acceleration_noise: 0.5,
                        velocity_decay: 1.0,
                        max_speed: 0.6,
                    },
                ),
            ],
            ..WorldModelConfig::default()
        };
        config.pose.initial = initial;
        config
    }

    /// Every published estimate against the plain computations: field estimates with their
    /// own trigonometry (the publication shares the heading's, and one estimate among the
    /// objects nothing locates), untracked landmarks where [`WorldModel::map_prediction`] puts
    /// them, field velocities as [`Pose::vector_to_field`] turns them.
    fn check_against_plain(world: &WorldModel, when: &str) {
        let state = world.state();
        let usable = world.pose_usable().is_some();
        for (i, o) in state.objects.iter().enumerate() {
            let position = Vector2::new(o.position.x, o.position.y);
            let bits2 = |m: &Matrix2<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            if o.tracked || !usable {
                let (f, c) = field_estimate(
                    &state.pose.pose,
                    &state.pose.covariance,
                    position,
                    &o.covariance,
                );
                assert_eq!(
                    (o.field_position.x.to_bits(), o.field_position.y.to_bits()),
                    (f.x.to_bits(), f.y.to_bits()),
                    "{} {when}",
                    o.name
                );
                assert_eq!(bits2(&o.field_covariance), bits2(&c), "{} {when}", o.name);
            }
            if !o.tracked
                && let Some((l, cov)) = world.map_prediction(i)
            {
                assert_eq!(
                    (position.x.to_bits(), position.y.to_bits()),
                    (l.x.to_bits(), l.y.to_bits())
                );
                assert_eq!(bits2(&o.covariance), bits2(&cov), "{} {when}", o.name);
            }
            let v = o.velocity.map(|v| state.pose.pose.vector_to_field(v));
            assert_eq!(
                o.field_velocity.map(|v| (v.x.to_bits(), v.y.to_bits())),
                v.map(|v| (v.x.to_bits(), v.y.to_bits())),
                "{} {when}",
                o.name
            );
        }
    }

    fn run(initial: Option<PosePrior>) {
        let mut world = WorldModel::new(layout(initial)).expect("valid config");
        check_against_plain(&world, "at the start");
        for k in 0..60u32 {
            let t = f64::from(k + 1) / 30.0;
            let stamp = Time::from_secs_f64(t);
            let observation = |class: u16, range: f64, bearing: f64| Observation {
                class: ObjectClass(class),
                variant: None,
                range,
                bearing,
                orientation: None,
                range_sigma: 0.1,
                bearing_sigma: 0.03,
            };
            let mut observations = vec![observation(1, 2.0 + 0.01 * f64::from(k), 0.3)];
            if k % 2 == 0 {
                observations.push(observation(10, 3.6, 0.25));
                observations.push(observation(10, 3.6, -0.2));
            }
            let camera = Some(CameraPercepts {
                stamp,
                view: ViewCone { direction: 0.0, fov: 1.2, range: 6.0 },
                observations,
            });
            let odometry = Odometry { dx: 0.01, dy: 0.002, dtheta: 0.004 };
            world.process(odometry, &Percepts { stamp, camera, ..Percepts::default() });
            check_against_plain(&world, &format!("after frame {k}"));
        }
    }

    #[test]
    fn published_estimates_are_the_plain_ones_localized() {
        run(Some(PosePrior { pose: Pose::new(0.5, 0.1, 0.05), sigma: [0.05, 0.05, 0.02] }));
    }

    #[test]
    fn published_estimates_are_the_plain_ones_lost() {
        run(None);
    }
}
