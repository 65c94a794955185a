//! How a published object estimate follows from what the world model holds: the filter's
//! estimate in the robot frame (or, for an untracked landmark, the map and the pose), placed on
//! the field with the pose and its uncertainty.
//!
//! One function, [`derive`], used twice: by the world model when it publishes, and when a world
//! state is read back from a log, whose packages hold only what the model decided (the filters'
//! estimates and confidences) — the rest is worked out again, bit for bit the same, because it
//! is the same code on the same numbers.

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};
use strata_runtime::Time;

use super::math::symmetrize2;
use super::pose::landmark_measurement_with;
use super::state::{ObjectEstimate, ObjectId, ObjectInfo};
use crate::geometry::{Global, Point, Pose, Robot, Vector};

/// Large but finite: published covariances must survive a JSON log.
pub(crate) const UNKNOWN_VARIANCE: f64 = 1e4;
/// Uncertainty added to a landmark predicted from the map and the pose (map and camera-height
/// errors the pose covariance does not hold), m.
pub(crate) const MAP_SIGMA: f64 = 0.05;

/// What every object estimate of one publication shares.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PoseFrame {
    pub pose: Pose,
    pub pose_cov: Matrix3<f64>,
    /// `(sin, cos)` of `pose.theta`.
    pub heading: (f64, f64),
    /// Where the pose is usable: the pose filter's state (its heading as filtered, not
    /// normalized again) and `(sin, cos)` of that heading, which untracked landmarks are
    /// predicted from.
    pub map_frame: Option<(Vector3<f64>, (f64, f64))>,
    /// Confidence from which a tracked object is known.
    pub threshold: f64,
}

/// A filter's estimate of an object, robot frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Track {
    pub position: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    /// Mobile objects and obstacles: velocity and its covariance.
    pub velocity: Option<(Vector<Robot>, Matrix2<f64>)>,
    pub last_seen: Time,
}

/// The fields of a published object estimate that change from one publication to the next.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Estimate {
    pub tracked: bool,
    pub known: bool,
    pub position: Point<Robot>,
    pub covariance: Matrix2<f64>,
    pub global_position: Point<Global>,
    pub global_covariance: Matrix2<f64>,
    pub velocity: Option<Vector<Robot>>,
    pub velocity_covariance: Option<Matrix2<f64>>,
    pub global_velocity: Option<Vector<Global>>,
    pub confidence: f64,
    pub last_seen: Option<Time>,
}

impl Estimate {
    /// The published object `id`: `info`'s identity with this estimate.
    pub(crate) fn object(self, id: usize, info: &ObjectInfo) -> ObjectEstimate {
        ObjectEstimate {
            id: ObjectId(u16::try_from(id).unwrap_or(u16::MAX)),
            name: info.name.clone(),
            group: info.group.clone(),
            class: info.class,
            variant: info.variant,
            category: info.category,
            tracked: self.tracked,
            known: self.known,
            position: self.position,
            covariance: self.covariance,
            global_position: self.global_position,
            global_covariance: self.global_covariance,
            velocity: self.velocity,
            velocity_covariance: self.velocity_covariance,
            global_velocity: self.global_velocity,
            confidence: self.confidence,
            last_seen: self.last_seen,
            map_position: info.map_position,
        }
    }

    /// Writes this estimate into `object`, whose identity stays ([`Estimate::object`] for a
    /// new one: the two list the same fields).
    pub(crate) fn write_into(self, object: &mut ObjectEstimate) {
        object.tracked = self.tracked;
        object.known = self.known;
        object.position = self.position;
        object.covariance = self.covariance;
        object.global_position = self.global_position;
        object.global_covariance = self.global_covariance;
        object.velocity = self.velocity;
        object.velocity_covariance = self.velocity_covariance;
        object.global_velocity = self.global_velocity;
        object.confidence = self.confidence;
        object.last_seen = self.last_seen;
    }
}

/// The published estimate of an object with `confidence` and, if a filter follows it, `track`;
/// `map_position`: a landmark's known position. `unknown`: the field estimate of an object
/// nothing locates, the same for every such object of a publication (it depends on the pose
/// alone): worked out by the first that needs it.
// Inlined into the publication loops: the estimate goes straight into the published object's
// fields instead of through a returned copy.
#[inline(always)]
pub(crate) fn derive(
    frame: &PoseFrame,
    map_position: Option<Point<Global>>,
    confidence: f64,
    track: Option<Track>,
    unknown: &mut Option<(Point<Global>, Matrix2<f64>)>,
) -> Estimate {
    let field = |position: Vector2<f64>, covariance: &Matrix2<f64>| {
        let (f, c) =
            global_estimate_with(&frame.pose, frame.heading, &frame.pose_cov, position, covariance);
        (Point::new(f.x, f.y), c)
    };
    let (tracked, position, covariance, velocity, last_seen, on_field) = match track {
        Some(t) => {
            let on_field = field(t.position, &t.covariance);
            (true, t.position, t.covariance, t.velocity, Some(t.last_seen), on_field)
        }
        None => {
            let (position, covariance) = match frame.map_frame.zip(map_position) {
                Some(((state, heading), map)) => {
                    map_prediction_from(&state, &frame.pose_cov, heading, map)
                }
                None => (Vector2::zeros(), Matrix2::identity() * UNKNOWN_VARIANCE),
            };
            // With a usable pose an untracked object is reported where the map puts it;
            // without, the unknown estimate is placed with the pose.
            let on_field = if frame.map_frame.is_some() {
                (map_position.unwrap_or_default(), Matrix2::identity() * MAP_SIGMA.powi(2))
            } else {
                *unknown.get_or_insert_with(|| field(position, &covariance))
            };
            (false, position, covariance, None, None, on_field)
        }
    };
    let (global_position, global_covariance) = on_field;
    // `Pose::vector_to_global` with the publication's heading trigonometry.
    let (s, c) = frame.heading;
    let global_velocity = velocity.map(|(v, _)| Vector::new(c * v.x - s * v.y, s * v.x + c * v.y));
    Estimate {
        tracked,
        known: tracked && confidence >= frame.threshold,
        position: Point::new(position.x, position.y),
        covariance,
        global_position,
        global_covariance,
        velocity: velocity.map(|(v, _)| v),
        velocity_covariance: velocity.map(|(_, c)| c),
        global_velocity,
        confidence,
        last_seen,
    }
}

/// A robot-frame estimate placed on the field with the pose (`(s, c)`: sine and cosine of its
/// heading), the pose's uncertainty added.
pub(crate) fn global_estimate_with(
    pose: &Pose,
    (s, c): (f64, f64),
    pose_cov: &Matrix3<f64>,
    l: Vector2<f64>,
    cov: &Matrix2<f64>,
) -> (Vector2<f64>, Matrix2<f64>) {
    let r = Matrix2::new(c, -s, s, c);
    let f = Vector2::new(pose.x, pose.y) + r * l;
    let j = SMatrix::<f64, 2, 3>::new(1.0, 0.0, -s * l.x - c * l.y, 0.0, 1.0, c * l.x - s * l.y);
    (f, symmetrize2(r * cov * r.transpose() + j * pose_cov * j.transpose()))
}

/// Where a pose filter in `state` with covariance `pose_cov` puts the landmark at `map` (robot
/// frame), with covariance; `heading`: `(sin, cos)` of the state's heading.
pub(crate) fn map_prediction_from(
    state: &Vector3<f64>,
    pose_cov: &Matrix3<f64>,
    heading: (f64, f64),
    map: Point<Global>,
) -> (Vector2<f64>, Matrix2<f64>) {
    let (l, jac) = landmark_measurement_with(state, heading, map);
    let cov = jac * pose_cov * jac.transpose() + Matrix2::identity() * MAP_SIGMA * MAP_SIGMA;
    (l, symmetrize2(cov))
}
