//! The world state this model publishes: every object's estimate in both frames, the pose, the
//! map accuracy.

use nalgebra::{Matrix2, Matrix3};
use strata_runtime::Time;

use super::WorldModel;
use crate::geometry::{Global, Point, Pose};
use crate::world::math::major_sigma;
use crate::world::pose::PoseFilter;
use crate::world::published::{
    Estimate, PoseFrame, Track as PublishedTrack, UNKNOWN_VARIANCE, derive,
};
use crate::world::state::{MapAccuracy, ObjectCategory, ObjectEstimate, PoseEstimate, WorldState};

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

impl WorldModel {
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
        unknown: &mut Option<(Point<Global>, Matrix2<f64>)>,
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
            errors.add(e.global_position.distance(map));
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
