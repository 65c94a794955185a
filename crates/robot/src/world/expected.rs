//! The expected update for active vision (paper 3.6, step (c)): the deliberative layer simulates
//! the correction stage of world modeling (steps (d) and (e)) for each candidate sensing action,
//! to pick the one that minimizes the expected variance of its value function. Only covariances
//! are needed, and they do not depend on the measured values: the simulation is exact for the
//! covariances a real update would produce, and never changes the filters.

use nalgebra::{Matrix2, Matrix3, Vector2};
use serde::{Deserialize, Serialize};

use super::math::{RangeBearing, polar, symmetrize2};
use super::object::{cartesian_noise_at, posterior_position_covariance};
use super::pose::pose_posterior_covariance;
use super::state::{ObjectId, WorldState};
use crate::geometry::{Field, Point, Pose, Robot, normalize_angle};
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

/// What the expected update needs to know about one object before the observation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ObjectPrior {
    /// A filter exists (otherwise the observation would start one).
    pub tracked: bool,
    pub position: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    pub map_position: Option<Point<Field>>,
}

/// The read-only belief an expected update runs on: the world model itself or a published
/// world state.
pub(crate) trait BeliefView {
    fn object_prior(&self, id: ObjectId) -> Option<ObjectPrior>;
    /// The pose and its covariance; `None` when lost (landmarks then do not correct the pose).
    fn pose_prior(&self) -> Option<(Pose, Matrix3<f64>)>;
    fn pose_covariance(&self) -> Matrix3<f64>;
}

/// Covariance of the robot-frame measurement an observation with noise `r` of an object at
/// `position` hands to the pose filter (see `GainedInformation`).
pub(crate) fn gained_covariance(position: Vector2<f64>, r: &Matrix2<f64>) -> Matrix2<f64> {
    cartesian_noise_at(position, r)
}

pub(crate) fn expected_update_into(
    view: &impl BeliefView,
    candidate: &SensingCandidate,
    out: &mut ExpectedBelief,
) {
    out.objects.clear();
    out.pose = view.pose_covariance();
    let pose = view.pose_prior();
    for obs in &candidate.observations {
        let Some(mut prior) = view.object_prior(obs.object) else { continue };
        let previous = out.objects.iter().position(|o| o.id == obs.object);
        if let Some(k) = previous {
            // A second observation of the same object builds on the first one's outcome.
            prior.tracked = true;
            prior.covariance = out.objects[k].covariance;
        }
        let pd = obs.detection_probability.clamp(0.0, 1.0);
        let r = Matrix2::new(obs.range_sigma.powi(2), 0.0, 0.0, obs.bearing_sigma.powi(2));
        let gained = gained_covariance(prior.position, &r);
        let posterior = if prior.tracked {
            posterior_position_covariance(&prior.covariance, prior.position, &r)
        } else {
            Some(gained)
        };
        let Some(posterior) = posterior else { continue };
        let expected = symmetrize2(posterior * pd + prior.covariance * (1.0 - pd));
        match previous {
            Some(k) => out.objects[k].covariance = expected,
            None => out.objects.push(ExpectedObject { id: obs.object, covariance: expected }),
        }
        if let (Some((pose, _)), Some(map)) = (pose, prior.map_position)
            && let Some(post) = pose_posterior_covariance(&pose, &out.pose, map, &gained)
        {
            out.pose = post * pd + out.pose * (1.0 - pd);
            out.pose = (out.pose + out.pose.transpose()) * 0.5;
        }
    }
}

/// Standard normal cumulative distribution (Abramowitz & Stegun 7.1.26, error < 1.5e-7).
pub(crate) fn normal_cdf(x: f64) -> f64 {
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
        let prior = self.object_prior(object)?;
        let (z, h) = polar(prior.position);
        let s = h * prior.covariance * h.transpose();
        let (range_sigma, bearing_sigma) = self.camera.sigmas(z.x);
        let half = (view.fov / 2.0 - self.view_margin).max(0.0);
        let angle = normalize_angle(z.y - view.direction);
        let sb = (s[(1, 1)] + 1e-12).sqrt();
        let sr = (s[(0, 0)] + 1e-12).sqrt();
        let p_angle = normal_cdf((half - angle) / sb) - normal_cdf((-half - angle) / sb);
        let p_range = normal_cdf((view.range - z.x) / sr);
        let position = Point::<Robot>::new(prior.position.x, prior.position.y);
        Some(PredictedObservation {
            object,
            range: z.x,
            bearing: z.y,
            range_sigma,
            bearing_sigma,
            visibility: (p_angle * p_range).clamp(0.0, 1.0),
            in_view: view.contains_polar(position.range(), z.y, self.view_margin),
        })
    }

    /// The sensing candidate of looking along `view`: every object likely enough to be seen
    /// (visibility at least `min_visibility`), with the camera's predicted noise.
    pub fn sensing_candidate(&self, view: &ViewCone, min_visibility: f64) -> SensingCandidate {
        let observations = (0..self.objects.len())
            .filter_map(|i| u16::try_from(i).ok())
            .filter_map(|i| self.predicted_observation(ObjectId(i), view))
            .filter(|p| p.visibility >= min_visibility && p.visibility > 0.0)
            .map(|p| ExpectedObservation {
                object: p.object,
                range_sigma: p.range_sigma,
                bearing_sigma: p.bearing_sigma,
                detection_probability: p.visibility * self.detection_probability,
            })
            .collect();
        SensingCandidate { observations }
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
}
