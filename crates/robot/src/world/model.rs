//! The world model (paper 3.1): one filter per object of interest in the robot's frame, and a
//! robot-pose filter fed by the landmark filters. Plain data and methods, no threads: the
//! world-modeling module is a thin shell around it.

mod association;
mod confidence;
mod lines;
mod localization;
mod publication;
mod team_objects;

use std::ops::Range;

use association::{Assignment, Gaussian2, Measured, Pending};
use confidence::bayes_detect;
use localization::KidnapDetector;

use nalgebra::{Matrix2, Matrix3, Vector2};
use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use super::config::{
    ConfigError, ObjectConfidence, ObjectKind, PosePrior, SymmetryHint, WorldModelConfig,
    validate_hint, validate_pose_prior,
};
use super::expected::{BeliefView, ExpectedBelief, ObjectPrior, SensingCandidate};
use super::math::{chi2_2dof_quantile, major_sigma};
use super::object::{GainedInformation, MotionModel, ObjectFilter, innovation_at};
use super::odometry_error::{Lag, LandmarkShift, OdometryErrorEstimator};
use super::pose::{MapLine, PoseFilter};
use super::published::{UNKNOWN_VARIANCE, global_estimate_with, map_prediction_from};
use super::state::{
    LostReason, ObjectCategory, ObjectEstimate, ObjectId, ObjectInfo, ObjectName, WorldDiagnostics,
    WorldLayout,
};
use super::team::{FusionCandidate, TeamFusion, TeamObject};
use crate::geometry::{Global, Odometry, Point, Pose};
use crate::percept::{CameraPercepts, Observation, Percepts};
use crate::platform::ObjectClass;

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

#[derive(Clone, Debug)]
struct Slot {
    name: ObjectName,
    group: usize,
    map_position: Option<Point<Global>>,
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
    /// The image's line observations.
    lines: Vec<super::pose::MeasuredLine>,
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
    /// Lost after a kidnap: when it was declared, and the odometry since the landmarks began to
    /// disagree, which carries the `Relocations` hints to where the robot went after it may
    /// have been put there.
    relocated: Option<(Time, Odometry)>,
    time: Option<Time>,
    frame_gains: Vec<FrameGain>,
    /// The configuration's field lines, prepared for line observations.
    map_lines: Vec<MapLine>,
    kidnap: KidnapDetector,
    /// The current kidnap was declared because the landmarks disagreed with the pose (not a
    /// placement, a lift or a command): `pose.disagreement_prior` applies.
    disagreed: bool,
    lifted: bool,
    /// The torso tilted beyond `pose.fall_tilt` and not yet upright again.
    fallen: bool,
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
            layout: Shared::new(
                WorldLayout::new(
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
                )
                .with_lines(config.lines.clone()),
            ),
            groups,
            slots,
            pose,
            lost,
            last_pose_correction: None,
            last_recovery_attempt: None,
            relocated: None,
            time: None,
            frame_gains: Vec::new(),
            map_lines: config.lines.segments.iter().map(|s| MapLine::new(*s)).collect(),
            kidnap: KidnapDetector::default(),
            disagreed: false,
            lifted: false,
            fallen: false,
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
        self.kidnap.travel(odometry);
        if let Some((_, moved)) = &mut self.relocated {
            *moved = moved.then(odometry);
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
    /// A frame that says the robot was placed ([`Percepts::placed`]) declares a kidnap after
    /// that odometry (made where the robot was) and before its observations (made where it is).
    pub fn process(&mut self, odometry: Odometry, percepts: &Percepts) {
        self.check_lift(&percepts.foot_contact);
        self.predict(odometry);
        self.check_fall(&percepts.inertial);
        let stamp = percepts.camera.as_ref().map_or(percepts.stamp, |c| c.stamp);
        self.advance_to(stamp);
        if percepts.placed {
            self.declare_placed();
        }
        match &percepts.camera {
            Some(camera) => self.update(camera),
            None => self.finish_frame(false),
        }
    }

    /// A frame without an image that the caller does not run the filters for (its odometry is
    /// merged into the next one): only the lift detector needs every frame, and a placement
    /// must not be missed ([`WorldModule`](super::WorldModule) runs [`WorldModel::process`] for
    /// a placed frame, so that the odometry before it is applied first).
    pub fn note_frame_without_image(&mut self, percepts: &Percepts) {
        self.check_lift(&percepts.foot_contact);
        self.check_fall(&percepts.inertial);
        if percepts.placed {
            self.declare_placed();
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
        self.correct_with_lines(now);
        self.finish_frame(true);
    }

    /// Where the pose and the map put a landmark instance (robot frame), with covariance.
    fn map_prediction(&self, slot: usize) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let pose = self.pose_usable()?;
        Some(map_prediction_at(pose, pose.heading_sin_cos(), self.slots[slot].map_position?))
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

    fn estimate_odometry_error(&mut self) {
        let shifts = &mut self.scratch.shifts;
        shifts.clear();
        shifts.extend(self.frame_gains.iter().filter_map(|g| g.prior));
        self.odometry_error.observe(shifts);
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

    /// Applies a command from the application.
    pub fn command(&mut self, command: WorldCommand) -> Result<(), ConfigError> {
        self.confidence_changes();
        match command {
            WorldCommand::SetPose { prior } => {
                validate_pose_prior("command.prior", &prior)?;
                self.pose = Some(PoseFilter::new(prior.pose, prior.covariance()));
                self.lost = None;
                self.relocated = None;
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
                self.relocated = None;
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

    // ----- expected update (active vision) ----------------------------------------------

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
fn global_estimate(
    pose: &Pose,
    pose_cov: &Matrix3<f64>,
    l: Vector2<f64>,
    cov: &Matrix2<f64>,
) -> (Vector2<f64>, Matrix2<f64>) {
    global_estimate_with(pose, pose.theta.sin_cos(), pose_cov, l, cov)
}

/// Where the pose and the map put the landmark instance at `map` (robot frame), with
/// covariance; `heading` is `pose.heading_sin_cos()`.
fn map_prediction_at(
    pose: &PoseFilter,
    heading: (f64, f64),
    map: Point<Global>,
) -> (Vector2<f64>, Matrix2<f64>) {
    map_prediction_from(&pose.state(), &pose.covariance(), heading, map)
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
    /// them, field velocities as [`Pose::vector_to_global`] turns them.
    fn check_against_plain(world: &WorldModel, when: &str) {
        let state = world.state();
        let usable = world.pose_usable().is_some();
        for (i, o) in state.objects.iter().enumerate() {
            let position = Vector2::new(o.position.x, o.position.y);
            let bits2 = |m: &Matrix2<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            if o.tracked || !usable {
                let (f, c) = global_estimate(
                    &state.pose.pose,
                    &state.pose.covariance,
                    position,
                    &o.covariance,
                );
                assert_eq!(
                    (o.global_position.x.to_bits(), o.global_position.y.to_bits()),
                    (f.x.to_bits(), f.y.to_bits()),
                    "{} {when}",
                    o.name
                );
                assert_eq!(bits2(&o.global_covariance), bits2(&c), "{} {when}", o.name);
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
            let v = o.velocity.map(|v| state.pose.pose.vector_to_global(v));
            assert_eq!(
                o.global_velocity.map(|v| (v.x.to_bits(), v.y.to_bits())),
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
                view: ViewCone { direction: 0.0, fov: 1.2, range: 6.0, near: 0.0 },
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
