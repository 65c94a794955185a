//! The expected update for active vision (paper 3.6, step (c)): the deliberative layer simulates
//! the correction stage of world modeling (steps (d) and (e)) for each candidate sensing action,
//! to pick the one that minimizes the expected variance of its value function. Only covariances
//! are needed, and they do not depend on the measured values: the simulation is exact for the
//! covariances a real update would produce, and never changes the filters.

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::expected_lines::ExpectedLineObservation;
use super::math::{MIN_RANGE, RangeBearing, polar, posterior_covariance, symmetrize2};
use super::pose::landmark_measurement;
use super::state::{ObjectId, WorldState};
use crate::geometry::{Global, Point, Pose, Robot, normalize_angle};
use crate::percept::ViewCone;

/// One observation a sensing action would produce.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExpectedObservation {
    pub object: ObjectId,
    /// Predicted measurement noise.
    pub range_sigma: f64,
    pub bearing_sigma: f64,
    /// Probability that the object is actually detected.
    pub detection_probability: f64,
}

/// A candidate sensing action, described by what it would observe.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SensingCandidate {
    pub observations: Vec<ExpectedObservation>,
    /// The painted lines the action would show ([`WorldState::expected_lines_into`]).
    #[serde(default)]
    pub lines: Vec<ExpectedLineObservation>,
}

/// The expected posterior covariance of one object filter (position, robot frame).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExpectedObject {
    pub id: ObjectId,
    pub covariance: Matrix2<f64>,
}

/// The belief after a simulated sensing action: posterior covariances of the observed objects
/// and of the pose, averaged over detection and miss.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ExpectedBelief {
    pub objects: Vec<ExpectedObject>,
    pub pose: Matrix3<f64>,
}

impl ExpectedBelief {
    pub fn object(&self, id: ObjectId) -> Option<&Matrix2<f64>> {
        self.objects.iter().find(|o| o.id == id).map(|o| &o.covariance)
    }
}

/// Where an object should appear for a given view, and how likely it is to be in it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PredictedObservation {
    pub object: ObjectId,
    pub range: f64,
    /// Body-relative, rad.
    pub bearing: f64,
    /// The camera noise expected at that range.
    pub range_sigma: f64,
    pub bearing_sigma: f64,
    /// Probability that the object lies inside the view cone, given its uncertainty.
    pub visibility: f64,
    /// The predicted position lies inside the cone, its margins excluded.
    pub in_view: bool,
}

/// What predicting one object's observation needs that does not depend on the view: its
/// range and bearing, the camera's noise there and the estimate's spread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObservationPrior {
    pub object: ObjectId,
    pub range: f64,
    /// Body-relative, rad.
    pub bearing: f64,
    pub range_sigma: f64,
    pub bearing_sigma: f64,
    /// Standard deviations of the estimate's range and bearing.
    pub range_spread: f64,
    pub bearing_spread: f64,
    /// Distance of the estimated position (for the view cone's test).
    pub distance: f64,
    /// An observation would correct the pose (a map position, and a pose that is not lost).
    corrects_pose: bool,
    /// Sine and cosine of the bearing, as [`polar`] computed them.
    bearing_sin_cos: (f64, f64),
    /// The probability that the object is within a camera's range, for the range it was made
    /// for: it does not depend on the view's direction.
    within: Option<WithinRange>,
    /// What simulating an observation of the object needs that does not depend on the view,
    /// kept the first time a view observes it (see [`WorldState::expected_view_update_into`]).
    correction: Option<Correction>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct WithinRange {
    range: f64,
    probability: f64,
}

/// The view-independent parts of the simulated correction of one observation.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Correction {
    /// The object's position covariance before the observation.
    covariance: Matrix2<f64>,
    /// The measurement's noise in the robot frame: what the pose filter is handed.
    gained: Matrix2<f64>,
    /// The object's position covariance after a detection; `None` when the update is singular
    /// (the observation is then left out).
    posterior: Option<Matrix2<f64>>,
    /// The Jacobian of a landmark's measurement with respect to the pose, when the observation
    /// corrects the pose (a map position and a pose that is not lost).
    landmark: Option<SMatrix<f64, 2, 3>>,
    /// The pose covariance after a detection of the landmark by a view that has corrected the
    /// pose with no other landmark yet (the pose's prior covariance is then corrected, whatever
    /// the view): made the first time a view needs it. The inner `None` is a singular update.
    first_pose_posterior: Option<Option<Matrix3<f64>>>,
}

impl Correction {
    /// The correction of observing `object`, at the range and the bearing's sine and cosine
    /// of its position (as [`polar`] computes them, kept in [`ObservationPrior`]), with the
    /// given noise.
    fn of(
        object: &ObjectPrior,
        (range, (s, c)): (f64, (f64, f64)),
        pose: Option<&Pose>,
        range_sigma: f64,
        bearing_sigma: f64,
    ) -> Correction {
        let r = Matrix2::new(range_sigma.powi(2), 0.0, 0.0, bearing_sigma.powi(2));
        // `cartesian_noise_at(position, r)` and `posterior_position_covariance(covariance,
        // position, r)` (object.rs), without computing the polar coordinates again: this is
        // `polar_to_cartesian_jacobian(range.max(MIN_RANGE), bearing)` with the bearing's
        // sine and cosine known.
        let range = range.max(MIN_RANGE);
        let j = Matrix2::new(c, -range * s, s, range * c);
        let gained = symmetrize2(j * r * j.transpose());
        let posterior = if object.tracked {
            posterior_covariance(&object.covariance, &Matrix2::identity(), &gained)
        } else {
            Some(gained)
        };
        let landmark = match (pose, object.map_position) {
            (Some(pose), Some(map)) => {
                Some(landmark_measurement(&Vector3::new(pose.x, pose.y, pose.theta), map).1)
            }
            _ => None,
        };
        Correction {
            covariance: object.covariance,
            gained,
            posterior,
            landmark,
            first_pose_posterior: None,
        }
    }

    /// Folds the observation into `out`: the object's and the pose's covariances, each the
    /// average of the detection's posterior and the miss's prior. `previous` is the object's
    /// entry in `out` when an earlier observation of the same candidate simulated it already.
    fn fold(&self, obs: &ExpectedObservation, previous: Option<usize>, out: &mut ExpectedBelief) {
        let Some(posterior) = self.posterior else { return };
        let pd = obs.detection_probability.clamp(0.0, 1.0);
        let expected = symmetrize2(posterior * pd + self.covariance * (1.0 - pd));
        match previous {
            Some(k) => out.objects[k].covariance = expected,
            None => out.objects.push(ExpectedObject { id: obs.object, covariance: expected }),
        }
        if let Some(jacobian) = &self.landmark
            && let Some(post) = posterior_covariance(&out.pose, jacobian, &self.gained)
        {
            Self::fold_pose(&post, pd, out);
        }
    }

    /// As [`Correction::fold`], for a first observation (`previous` is `None`); `pose_at_prior`
    /// says that `out.pose` is still the belief's prior pose covariance, whose correction by
    /// this landmark is then made once and reused; the object's covariance is kept when
    /// `keep_object`. Returns whether the pose was corrected.
    fn fold_first(
        &mut self,
        obs: &ExpectedObservation,
        pose_at_prior: bool,
        keep_object: bool,
        out: &mut ExpectedBelief,
    ) -> bool {
        let Some(posterior) = self.posterior else { return false };
        let pd = obs.detection_probability.clamp(0.0, 1.0);
        if keep_object {
            let expected = symmetrize2(posterior * pd + self.covariance * (1.0 - pd));
            out.objects.push(ExpectedObject { id: obs.object, covariance: expected });
        }
        let Some(jacobian) = &self.landmark else { return false };
        let post = if pose_at_prior {
            *self
                .first_pose_posterior
                .get_or_insert_with(|| posterior_covariance(&out.pose, jacobian, &self.gained))
        } else {
            posterior_covariance(&out.pose, jacobian, &self.gained)
        };
        let Some(post) = post else { return false };
        Self::fold_pose(&post, pd, out);
        true
    }

    /// The pose's covariance averaged over the detection's posterior `post` and the miss.
    fn fold_pose(post: &Matrix3<f64>, pd: f64, out: &mut ExpectedBelief) {
        out.pose = post * pd + out.pose * (1.0 - pd);
        out.pose = (out.pose + out.pose.transpose()) * 0.5;
    }
}

/// What the expected update needs to know about one object before the observation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ObjectPrior {
    /// A filter exists (otherwise the observation would start one).
    pub tracked: bool,
    pub position: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    pub map_position: Option<Point<Global>>,
}

/// The read-only belief an expected update runs on: the world model itself or a published
/// world state.
pub(crate) trait BeliefView {
    fn object_prior(&self, id: ObjectId) -> Option<ObjectPrior>;
    /// The pose and its covariance; `None` when lost (landmarks then do not correct the pose).
    fn pose_prior(&self) -> Option<(Pose, Matrix3<f64>)>;
    fn pose_covariance(&self) -> Matrix3<f64>;
}

pub(crate) fn expected_update_into(
    view: &impl BeliefView,
    candidate: &SensingCandidate,
    out: &mut ExpectedBelief,
) {
    out.objects.clear();
    out.pose = view.pose_covariance();
    let pose = view.pose_prior().map(|(pose, _)| pose);
    for obs in &candidate.observations {
        let Some(mut prior) = view.object_prior(obs.object) else { continue };
        let previous = out.objects.iter().position(|o| o.id == obs.object);
        if let Some(k) = previous {
            // A second observation of the same object builds on the first one's outcome.
            prior.tracked = true;
            prior.covariance = out.objects[k].covariance;
        }
        let (z, h) = polar(prior.position);
        let at = (z.x, bearing_sin_cos(&h));
        Correction::of(&prior, at, pose.as_ref(), obs.range_sigma, obs.bearing_sigma)
            .fold(obs, previous, out);
    }
    if pose.is_some() {
        for line in &candidate.lines {
            line.fold(out);
        }
    }
}

/// Standard normal cumulative distribution (Abramowitz & Stegun 7.1.26, error < 1.5e-7).
///
/// Beyond [`CDF_SATURATION`] standard deviations the approximation rounds to exactly 1 or 0:
/// its tail `poly(t) exp(-z^2)` (`poly(t) <= 1`, `z = |x| / sqrt(2)`) is then below
/// `exp(-40.5) < 2.6e-18`, under half an ulp of 1 (`2^-54`, 5.6e-17), so `erf` rounds to 1.
/// Those values are returned without the exponential (active vision asks for many: objects
/// well inside or outside a view's cone).
pub(crate) fn normal_cdf(x: f64) -> f64 {
    if x >= CDF_SATURATION {
        1.0
    } else if x <= -CDF_SATURATION {
        0.0
    } else {
        normal_cdf_approximation(x)
    }
}

/// See [`normal_cdf`].
const CDF_SATURATION: f64 = 9.0;

/// The approximation [`normal_cdf`] evaluates (NaN gives NaN).
fn normal_cdf_approximation(x: f64) -> f64 {
    let z = x.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-z * z).exp();
    if x >= 0.0 { 0.5 * (1.0 + erf) } else { 0.5 * (1.0 - erf) }
}

impl BeliefView for WorldState {
    fn object_prior(&self, id: ObjectId) -> Option<ObjectPrior> {
        let o = self.get(id)?;
        if !o.tracked && (o.map_position.is_none() || self.pose.lost) {
            return None;
        }
        Some(ObjectPrior {
            tracked: o.tracked,
            position: Vector2::new(o.position.x, o.position.y),
            covariance: o.covariance,
            map_position: o.map_position,
        })
    }

    fn pose_prior(&self) -> Option<(Pose, Matrix3<f64>)> {
        (!self.pose.lost).then_some((self.pose.pose, self.pose.covariance))
    }

    fn pose_covariance(&self) -> Matrix3<f64> {
        self.pose.covariance
    }
}

impl WorldState {
    /// The posterior covariances if `candidate` were executed (paper 3.6 (c)); changes nothing.
    pub fn expected_update(&self, candidate: &SensingCandidate) -> ExpectedBelief {
        let mut out = ExpectedBelief::default();
        expected_update_into(self, candidate, &mut out);
        out
    }

    /// As [`WorldState::expected_update`], reusing `out`'s storage (no allocation once warm).
    pub fn expected_update_into(&self, candidate: &SensingCandidate, out: &mut ExpectedBelief) {
        expected_update_into(self, candidate, out);
    }

    /// Where `object` would appear in a camera looking along `view`, if its position is known
    /// well enough to say (tracked, or an untracked landmark with a pose that is not lost).
    pub fn predicted_observation(
        &self,
        object: ObjectId,
        view: &ViewCone,
    ) -> Option<PredictedObservation> {
        let prior = self.observation_prior(object)?;
        Some(PredictedObservation {
            object,
            range: prior.range,
            bearing: prior.bearing,
            range_sigma: prior.range_sigma,
            bearing_sigma: prior.bearing_sigma,
            visibility: self.visibility(&prior, view),
            in_view: view.contains_polar(prior.distance, prior.bearing, self.view_margin),
        })
    }

    /// The part of `object`'s predicted observation that does not depend on the view.
    pub fn observation_prior(&self, object: ObjectId) -> Option<ObservationPrior> {
        let prior = self.object_prior(object)?;
        Some(self.observation_prior_of(object, &prior))
    }

    fn observation_prior_of(&self, object: ObjectId, prior: &ObjectPrior) -> ObservationPrior {
        let (z, h) = polar(prior.position);
        let s = h * prior.covariance * h.transpose();
        let (range_sigma, bearing_sigma) = self.camera.sigmas(z.x);
        ObservationPrior {
            object,
            range: z.x,
            bearing: z.y,
            range_sigma,
            bearing_sigma,
            range_spread: (s[(0, 0)] + 1e-12).sqrt(),
            bearing_spread: (s[(1, 1)] + 1e-12).sqrt(),
            distance: Point::<Robot>::new(prior.position.x, prior.position.y).range(),
            corrects_pose: prior.map_position.is_some() && !self.pose.lost,
            bearing_sin_cos: bearing_sin_cos(&h),
            within: None,
            correction: None,
        }
    }

    /// Probability that the object lies inside `view`, given its uncertainty.
    fn visibility(&self, prior: &ObservationPrior, view: &ViewCone) -> f64 {
        let half = self.half_angle(view);
        let angle = normalize_angle(prior.bearing - view.direction);
        let p_angle = angle_probability(half, angle, prior.bearing_spread);
        let p_range = range_probability(prior, view.range);
        (p_angle * p_range).clamp(0.0, 1.0)
    }

    /// [`WorldState::visibility`] when it reaches `min_visibility` (and is positive), `None`
    /// otherwise. Objects that surely fall short are left out before their angular
    /// probability is computed: those too far for the view's range, and those whose bearing
    /// lies more than `bearing_cut` standard deviations (see [`bearing_cut`]) outside the cone.
    ///
    /// `half` is the view's half angle less the margin, `(view.fov / 2 - view_margin).max(0)`
    /// (see [`WorldState::half_angle`]), the same for every object of a view. The tests that
    /// leave most objects out are inlined into the caller's loop, the probabilities are not.
    #[inline(always)]
    fn visibility_reaching(
        prior: &ObservationPrior,
        view: &ViewCone,
        half: f64,
        min_visibility: f64,
        bearing_cut: f64,
    ) -> Option<f64> {
        // The angular probability is at most 1, so the visibility at most the range's.
        let p_range = range_probability(prior, view.range);
        if p_range < min_visibility {
            return None;
        }
        let angle = normalize_angle(prior.bearing - view.direction);
        let sb = prior.bearing_spread;
        let outside = angle.abs() - half;
        if outside > 0.0 && outside * outside > bearing_cut * sb * sb {
            return None;
        }
        angular_visibility(half, angle, sb, p_range, min_visibility)
    }

    /// What [`WorldState::visibility`] uses as the half angle of `view`'s cone.
    fn half_angle(&self, view: &ViewCone) -> f64 {
        (view.fov / 2.0 - self.view_margin).max(0.0)
    }

    /// Every object's [`ObservationPrior`], in id order, into `out`: made once when several
    /// views are compared (active vision), instead of once per view.
    pub fn observation_priors_into(&self, out: &mut Vec<ObservationPrior>) {
        out.clear();
        out.extend(
            (0..self.objects.len())
                .filter_map(|i| u16::try_from(i).ok())
                .filter_map(|i| self.observation_prior(ObjectId(i))),
        );
    }

    /// As [`WorldState::observation_priors_into`], for views of detection range `range`: each
    /// prior also holds the probability that its object is within that range, which views of
    /// that range (whatever their direction) then do not compute again.
    pub fn observation_priors_within_into(&self, range: f64, out: &mut Vec<ObservationPrior>) {
        self.observation_priors_into(out);
        for prior in out.iter_mut() {
            let probability = normal_cdf((range - prior.range) / prior.range_spread);
            prior.within = Some(WithinRange { range, probability });
        }
    }

    /// As [`WorldState::observation_priors_within_into`], without the objects that no view of
    /// detection range `range` observes with a visibility of at least `min_visibility`: those
    /// whose probability of being within that range is below it (the first test of
    /// [`WorldState::expected_view_update_into`]). Objects surely that far are left out before
    /// their prior is made (see [`surely_out_of_range`]). Active vision compares views of one
    /// range and one threshold.
    pub fn observation_priors_reaching_into(
        &self,
        range: f64,
        min_visibility: f64,
        out: &mut Vec<ObservationPrior>,
    ) {
        out.clear();
        let cut = bearing_cut(min_visibility);
        for i in (0..self.objects.len()).filter_map(|i| u16::try_from(i).ok()) {
            let Some(object) = self.object_prior(ObjectId(i)) else { continue };
            if surely_out_of_range(&object, range, cut) {
                continue;
            }
            let mut prior = self.observation_prior_of(ObjectId(i), &object);
            let probability = normal_cdf((range - prior.range) / prior.range_spread);
            if probability < min_visibility {
                continue;
            }
            prior.within = Some(WithinRange { range, probability });
            out.push(prior);
        }
    }

    /// The sensing candidate of looking along `view`: every object likely enough to be seen
    /// (visibility at least `min_visibility`), with the camera's predicted noise.
    pub fn sensing_candidate(&self, view: &ViewCone, min_visibility: f64) -> SensingCandidate {
        let mut priors = Vec::new();
        self.observation_priors_into(&mut priors);
        let mut candidate = SensingCandidate::default();
        self.sensing_candidate_into(&priors, view, min_visibility, &mut candidate);
        candidate
    }

    /// As [`WorldState::sensing_candidate`], from priors made by
    /// [`WorldState::observation_priors_into`], reusing `out`'s storage.
    pub fn sensing_candidate_into(
        &self,
        priors: &[ObservationPrior],
        view: &ViewCone,
        min_visibility: f64,
        out: &mut SensingCandidate,
    ) {
        out.observations.clear();
        let cut = bearing_cut(min_visibility);
        let half = self.half_angle(view);
        for prior in priors {
            if let Some(visibility) =
                Self::visibility_reaching(prior, view, half, min_visibility, cut)
            {
                out.observations.push(self.expected_observation(prior, visibility));
            }
        }
        self.expected_lines_into(view, &mut out.lines);
    }

    fn expected_observation(
        &self,
        prior: &ObservationPrior,
        visibility: f64,
    ) -> ExpectedObservation {
        ExpectedObservation {
            object: prior.object,
            range_sigma: prior.range_sigma,
            bearing_sigma: prior.bearing_sigma,
            detection_probability: visibility * self.detection_probability,
        }
    }

    /// [`WorldState::sensing_candidate_into`] followed by [`WorldState::expected_update_into`],
    /// in one pass and with the same results, for active vision's many views of one belief
    /// (paper 3.6 (c)): what an observation's simulated correction needs that does not depend
    /// on the view (the measurement noise in the robot frame, the object's posterior, the
    /// landmark's Jacobian; the pose's posterior when the landmark is the first to correct a
    /// view's prior pose) is kept in the object's prior the first time a view needs it, and
    /// reused by the next views. `priors` must come from this world state.
    pub fn expected_view_update_into(
        &self,
        priors: &mut [ObservationPrior],
        view: &ViewCone,
        min_visibility: f64,
        sensing: &mut SensingCandidate,
        out: &mut ExpectedBelief,
    ) {
        self.expected_view_update_only_into(priors, view, min_visibility, None, sensing, out);
    }

    /// As [`WorldState::expected_view_update_into`], for a reader of the pose and of the
    /// `objects`' covariances only (active vision's value function): `out.objects` holds just
    /// theirs, and an observation that would correct neither is not simulated. When `priors`
    /// do not come in increasing id order (an object listed twice), every object is kept, as
    /// a second observation builds on the first one's outcome.
    pub fn expected_view_update_of_into(
        &self,
        priors: &mut [ObservationPrior],
        view: &ViewCone,
        min_visibility: f64,
        objects: &[ObjectId],
        sensing: &mut SensingCandidate,
        out: &mut ExpectedBelief,
    ) {
        let only = Some(objects).filter(|_| priors.is_sorted_by(|a, b| a.object < b.object));
        self.expected_view_update_only_into(priors, view, min_visibility, only, sensing, out);
    }

    /// The view update keeping the covariances of `only` (of every object when `None`).
    fn expected_view_update_only_into(
        &self,
        priors: &mut [ObservationPrior],
        view: &ViewCone,
        min_visibility: f64,
        only: Option<&[ObjectId]>,
        sensing: &mut SensingCandidate,
        out: &mut ExpectedBelief,
    ) {
        sensing.observations.clear();
        out.objects.clear();
        out.pose = self.pose_covariance();
        let pose = self.pose_prior().map(|(pose, _)| pose);
        let cut = bearing_cut(min_visibility);
        let half = self.half_angle(view);
        // Until a landmark corrects it, `out.pose` is the prior pose covariance, the same for
        // every view of this belief.
        let mut pose_at_prior = true;
        // The greatest object observed so far: one beyond it is surely a first observation
        // (priors come in id order), without looking for it among the kept ones.
        let mut greatest: Option<ObjectId> = None;
        for prior in priors.iter_mut() {
            let Some(visibility) =
                Self::visibility_reaching(prior, view, half, min_visibility, cut)
            else {
                continue;
            };
            let obs = self.expected_observation(prior, visibility);
            sensing.observations.push(obs);
            let at = (prior.range, prior.bearing_sin_cos);
            let previous = if greatest.is_none_or(|g| obs.object > g) {
                greatest = Some(obs.object);
                None
            } else {
                out.objects.iter().position(|o| o.id == obs.object)
            };
            match previous {
                None => {
                    let keep_object = only.is_none_or(|ids| ids.contains(&obs.object));
                    if !keep_object && !prior.corrects_pose {
                        continue;
                    }
                    if prior.correction.is_none() {
                        let Some(object) = self.object_prior(obs.object) else { continue };
                        let sigmas = (obs.range_sigma, obs.bearing_sigma);
                        prior.correction =
                            Some(Correction::of(&object, at, pose.as_ref(), sigmas.0, sigmas.1));
                    }
                    if let Some(correction) = &mut prior.correction
                        && correction.fold_first(&obs, pose_at_prior, keep_object, out)
                    {
                        pose_at_prior = false;
                    }
                }
                Some(k) => {
                    // As in the expected update: a second observation (priors listing an object
                    // twice) builds on the first one's outcome, and is not kept.
                    let Some(mut object) = self.object_prior(obs.object) else { continue };
                    object.tracked = true;
                    object.covariance = out.objects[k].covariance;
                    let before = out.pose;
                    Correction::of(&object, at, pose.as_ref(), obs.range_sigma, obs.bearing_sigma)
                        .fold(&obs, Some(k), out);
                    if before.map(f64::to_bits) != out.pose.map(f64::to_bits) {
                        pose_at_prior = false;
                    }
                }
            }
        }
        // The lines after the objects, as the generic update folds them.
        self.expected_lines_into(view, &mut sensing.lines);
        for line in &sensing.lines {
            line.fold(out);
        }
    }
}

/// Sine and cosine of the bearing, from [`polar`]'s Jacobian `[c, s; -s/r, c/r]`.
fn bearing_sin_cos(h: &Matrix2<f64>) -> (f64, f64) {
    (h[(0, 1)], h[(0, 0)])
}

/// The end of [`WorldState::visibility_reaching`], for the objects its tests keep.
#[inline(never)]
fn angular_visibility(
    half: f64,
    angle: f64,
    sb: f64,
    p_range: f64,
    min_visibility: f64,
) -> Option<f64> {
    let visibility = (angle_probability(half, angle, sb) * p_range).clamp(0.0, 1.0);
    (visibility >= min_visibility && visibility > 0.0).then_some(visibility)
}

/// Probability that an object at `angle` from a view's direction, with bearing spread `sb`,
/// lies within `half` of it.
fn angle_probability(half: f64, angle: f64, sb: f64) -> f64 {
    normal_cdf((half - angle) / sb) - normal_cdf((-half - angle) / sb)
}

/// Probability that an object is within a view's `range`: kept in its prior when made for that
/// range (compared bit for bit, so a kept value is the one computing it would give).
fn range_probability(prior: &ObservationPrior, range: f64) -> f64 {
    match prior.within {
        Some(w) if w.range.to_bits() == range.to_bits() => w.probability,
        _ => normal_cdf((range - prior.range) / prior.range_spread),
    }
}

/// Whether `object` is so far beyond `range` that its probability of being within it is below
/// the threshold whose [`bearing_cut`] is `cut`, whatever its range spread: the probability is
/// the normal tail at u = (distance - range) / spread, below the threshold when u^2 >= `cut`
/// (as for the bearing). The spread's square, `h P h^T + 1e-12` with `h` a unit row, is at most
/// the sum of the covariance's absolute entries plus 1e-12; the margins of 1 % cover rounding.
/// (A covariance negative along the range gives a NaN probability: never observed either.)
fn surely_out_of_range(object: &ObjectPrior, range: f64, cut: f64) -> bool {
    let beyond = object.position.norm() - range;
    let p = &object.covariance;
    let spread_bound =
        1.01 * (p[(0, 0)].abs() + p[(0, 1)].abs() + p[(1, 0)].abs() + p[(1, 1)].abs()) + 1e-12;
    cut.is_finite()
        && spread_bound.is_finite()
        && beyond.is_finite()
        && beyond > 0.0
        && beyond * beyond >= 1.01 * cut * spread_bound
}

/// The square of the number u of bearing standard deviations outside a view's cone beyond
/// which an object's visibility is surely below `min_visibility`.
///
/// Beyond the cone's edge by u, the angular probability is at most the tail `normal_cdf(-u)`
/// (the other term is subtracted, or its complement is), and the visibility at most that. The
/// approximation's tail is `0.5 poly(t) exp(-u^2 / 2)` with `poly(t) <= 1` on its domain, and
/// its rounding adds a few 1e-16: below `min_visibility` when `0.5 exp(-u^2 / 2) <=
/// min_visibility / 1.02`, i.e. `u^2 >= 2 ln(0.51 / min_visibility)`. Thresholds too small for
/// the rounding to be negligible against them cut nothing.
fn bearing_cut(min_visibility: f64) -> f64 {
    if min_visibility >= 1e-12 {
        (2.0 * (0.51 / min_visibility).ln()).max(0.0)
    } else {
        f64::INFINITY
    }
}

/// A range/bearing measurement with the camera's noise at the predicted point (for tests and
/// simulations of what the camera would report).
pub fn predicted_measurement(
    position: Vector2<f64>,
    range_sigma: f64,
    bearing_sigma: f64,
) -> RangeBearing {
    let (z, _) = polar(position);
    RangeBearing { range: z.x, bearing: z.y, range_sigma, bearing_sigma }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn normal_cdf_matches_known_values() {
        assert_relative_eq!(normal_cdf(0.0), 0.5, epsilon = 1e-7);
        assert_relative_eq!(normal_cdf(1.96), 0.975, epsilon = 1e-4);
        assert_relative_eq!(normal_cdf(-1.0), 0.158_655_25, epsilon = 1e-6);
    }

    #[test]
    fn a_correction_is_made_as_the_object_filter_makes_its_noise_and_posterior() {
        use crate::world::object::{cartesian_noise_at, posterior_position_covariance};
        let covariance = Matrix2::new(0.04, 0.01, 0.01, 0.02);
        for (x, y) in [(2.0, 0.4), (-1.3, 2.2), (0.01, -0.02), (0.0, 0.0), (5.5, -3.1)] {
            let position = Vector2::new(x, y);
            for tracked in [true, false] {
                let object = ObjectPrior { tracked, position, covariance, map_position: None };
                let (z, h) = polar(position);
                assert_eq!(bearing_sin_cos(&h), z.y.sin_cos());
                let at = (z.x, bearing_sin_cos(&h));
                let c = Correction::of(&object, at, None, 0.1 + 0.05 * x.abs(), 0.035);
                let r = Matrix2::new((0.1 + 0.05 * x.abs()).powi(2), 0.0, 0.0, 0.035f64.powi(2));
                let bits = |m: &Matrix2<f64>| m.map(f64::to_bits);
                assert_eq!(bits(&c.gained), bits(&cartesian_noise_at(position, &r)));
                let posterior = if tracked {
                    posterior_position_covariance(&covariance, position, &r)
                } else {
                    Some(cartesian_noise_at(position, &r))
                };
                assert_eq!(c.posterior.map(|p| bits(&p)), posterior.map(|p| bits(&p)));
            }
        }
    }

    #[test]
    fn the_normal_cdf_saturates_as_its_approximation_rounds() {
        let mut x = CDF_SATURATION;
        while x < 60.0 {
            for v in [x, -x, f64::from_bits(x.to_bits() + 1), -f64::from_bits(x.to_bits() + 1)] {
                assert_eq!(normal_cdf(v).to_bits(), normal_cdf_approximation(v).to_bits(), "{v}");
            }
            x += 0.001;
        }
        for v in [f64::INFINITY, f64::NEG_INFINITY, f64::MAX, f64::MIN, 1e300, -1e300] {
            assert_eq!(normal_cdf(v).to_bits(), normal_cdf_approximation(v).to_bits(), "{v}");
        }
        // Just inside the cut the approximation is not yet saturated: the cut is not too low
        // for a test of it to mean something.
        assert!(normal_cdf(-8.0) > 0.0 && normal_cdf(-8.0) < 1e-14);
        assert!(normal_cdf(f64::NAN).is_nan());
    }

    #[test]
    fn an_object_surely_out_of_range_is_below_the_threshold() {
        // A fixed-seed walk over distances, directions and covariances (some not positive).
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut cut_some = 0;
        for _ in 0..20_000 {
            let range = 1.0 + 7.0 * next();
            let distance = range + 3.0 * next() * next();
            let angle = 7.0 * next() - 3.5;
            let position = Vector2::new(distance * angle.cos(), distance * angle.sin());
            let scale = 10f64.powf(-6.0 + 6.0 * next());
            let (a, b, c) = (next() * scale, (next() - 0.5) * scale, next() * scale);
            let covariance = Matrix2::new(a, b, b, if next() < 0.1 { -c } else { c });
            let object = ObjectPrior { tracked: true, position, covariance, map_position: None };
            let (z, h) = polar(position);
            let spread = ((h * covariance * h.transpose())[(0, 0)] + 1e-12).sqrt();
            let probability = normal_cdf((range - z.x) / spread);
            for min_visibility in [0.01, 0.05, 0.2, 0.6, 1e-13] {
                if surely_out_of_range(&object, range, bearing_cut(min_visibility)) {
                    cut_some += 1;
                    // NaN (a covariance negative along the range) is never observed either.
                    assert!(
                        probability < min_visibility || probability.is_nan(),
                        "{object:?} {range} {min_visibility}"
                    );
                }
            }
        }
        assert!(cut_some > 1000, "{cut_some}");
    }

    #[test]
    fn beyond_the_bearing_cut_the_tail_is_below_the_threshold() {
        for min_visibility in [1e-12, 1e-6, 0.01, 0.05, 0.2, 0.5, 0.51, 0.9, 1.0] {
            let cut = bearing_cut(min_visibility).sqrt();
            let mut previous = f64::INFINITY;
            for k in 0..2000 {
                let u = cut + f64::from(k) * 0.005;
                let tail = normal_cdf(-u);
                // Decreasing, and below the threshold with the margin the rounding needs.
                assert!(tail <= previous, "{u}");
                assert!(tail < min_visibility / 1.01, "{min_visibility} {u} {tail}");
                previous = tail;
            }
        }
        assert_eq!(bearing_cut(0.0), f64::INFINITY);
        assert_eq!(bearing_cut(f64::NAN), f64::INFINITY);
    }
}
