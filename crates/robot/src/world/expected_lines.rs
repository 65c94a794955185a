//! The painted lines in an expected update (paper 3.6 (c) with 3.1's lines as observations):
//! which map lines a view would show, and the pose correction each would make, so that active
//! vision can weigh a look at a line against a look at a landmark or the ball.
//!
//! A line is predicted as the camera reports one: the nearest point of the piece of it inside
//! the view's cone, with the line's direction; the world model then corrects the pose's
//! distance to the line and its heading (`model/lines.rs`). The prediction is made from the
//! pose estimate alone (a line is long: whether it is in view depends little on the pose's
//! uncertainty), and only for a world model that has corrected its pose with a line at least
//! once: one whose perception reports no lines (the T1's in rcssservermj) must not count on
//! them.

use nalgebra::{Matrix2, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::expected::ExpectedBelief;
use super::math::posterior_covariance;
use super::object::cartesian_noise_at;
use super::pose::{LineObservation, MapLine, line_jacobian};
use super::state::WorldState;
use crate::geometry::{Point, Robot};
use crate::percept::ViewCone;

/// One painted line a sensing action would observe.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExpectedLineObservation {
    /// The map line, by index in the world layout's `lines.segments`.
    pub line: u16,
    /// Where the camera would report it (robot frame): the nearest point of its visible piece,
    /// and its direction, rad.
    pub point: Point<Robot>,
    pub direction: f64,
    /// The Jacobian of the line measurement (distance to the line, its direction) with respect
    /// to the pose.
    pub jacobian: SMatrix<f64, 2, 3>,
    /// The measurement's noise.
    pub noise: Matrix2<f64>,
    /// Probability that the line is actually detected.
    pub detection_probability: f64,
}

impl ExpectedLineObservation {
    /// Folds the observation into `out.pose`: the average of the detection's posterior and
    /// the miss's prior, as for a landmark.
    pub(crate) fn fold(&self, out: &mut ExpectedBelief) {
        let Some(post) = posterior_covariance(&out.pose, &self.jacobian, &self.noise) else {
            return;
        };
        let pd = self.detection_probability.clamp(0.0, 1.0);
        out.pose = post * pd + out.pose * (1.0 - pd);
        out.pose = (out.pose + out.pose.transpose()) * 0.5;
    }
}

impl WorldState {
    /// Whether expected updates count on line observations: the world model fuses lines and
    /// has corrected its pose with one, and the pose is not lost.
    pub fn expects_lines(&self) -> bool {
        let lines = &self.layout.lines;
        lines.class.is_some()
            && !lines.segments.is_empty()
            && self.diagnostics.line_corrections > 0
            && !self.pose.lost
    }

    /// The lines a camera looking along `view` would observe, into `out` (cleared first);
    /// nothing unless [`WorldState::expects_lines`].
    pub fn expected_lines_into(&self, view: &ViewCone, out: &mut Vec<ExpectedLineObservation>) {
        out.clear();
        if !self.expects_lines() {
            return;
        }
        let lines = &self.layout.lines;
        let pose = self.pose.pose;
        let half = (view.fov / 2.0 - self.view_margin).max(0.0);
        if half <= 0.0 || half >= std::f64::consts::FRAC_PI_2 {
            return;
        }
        let reach = view.range.min(lines.max_range);
        let axis = pose.theta + view.direction;
        let state = Vector3::new(pose.x, pose.y, pose.theta);
        let tan_half = half.tan();
        // The camera's frame: x along the optical axis.
        let (sa, ca) = axis.sin_cos();
        let local = |p: &Point<crate::geometry::Global>| {
            let (dx, dy) = (p.x - pose.x, p.y - pose.y);
            Vector2::new(ca * dx + sa * dy, -sa * dx + ca * dy)
        };
        let (sv, cv) = view.direction.sin_cos();
        for (k, segment) in lines.segments.iter().enumerate() {
            let Ok(line) = u16::try_from(k) else { break };
            let (a, b) = (local(&segment[0]), local(&segment[1]));
            let Some(closest) = visible_piece_closest(a, b, tan_half, lines.min_length) else {
                continue;
            };
            if closest.norm() > reach {
                continue;
            }
            // Back into the robot frame, as the camera's observation would be.
            let point =
                Vector2::new(cv * closest.x - sv * closest.y, sv * closest.x + cv * closest.y);
            let map_direction = (segment[1].y - segment[0].y).atan2(segment[1].x - segment[0].x);
            let (range_sigma, bearing_sigma) = self.camera.sigmas(point.norm());
            let r =
                Matrix2::new(range_sigma * range_sigma, 0.0, 0.0, bearing_sigma * bearing_sigma);
            let observation = LineObservation {
                point,
                point_covariance: cartesian_noise_at(point, &r),
                direction: crate::geometry::normalize_angle(map_direction - pose.theta),
                direction_sigma: lines.direction_sigma,
            };
            let measured = observation.measurement();
            out.push(ExpectedLineObservation {
                line,
                point: Point::new(point.x, point.y),
                direction: observation.direction,
                jacobian: line_jacobian(&state, &MapLine::new(*segment), &observation),
                noise: measured.r,
                detection_probability: self.detection_probability,
            });
        }
    }
}

/// The point nearest the camera of the piece of segment `a`-`b` (camera frame) inside the cone
/// `|y| <= x tan_half`, when that piece is at least `min_length` long.
fn visible_piece_closest(
    a: Vector2<f64>,
    b: Vector2<f64>,
    tan_half: f64,
    min_length: f64,
) -> Option<Vector2<f64>> {
    // Each edge of the cone is a half-plane, linear along the segment: f(t) >= 0.
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for sign in [1.0, -1.0] {
        let f = |p: Vector2<f64>| p.x * tan_half - sign * p.y;
        let (fa, fb) = (f(a), f(b));
        if fa < 0.0 && fb < 0.0 {
            return None;
        }
        if fa < 0.0 {
            lo = lo.max(fa / (fa - fb));
        } else if fb < 0.0 {
            hi = hi.min(fa / (fa - fb));
        }
    }
    let d = b - a;
    let length = d.norm();
    if hi <= lo || (hi - lo) * length < min_length.max(1e-9) {
        return None;
    }
    let t = if length > 0.0 { (-a.dot(&d) / (length * length)).clamp(lo, hi) } else { lo };
    Some(a + d * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_segment_across_the_cone_is_seen_at_its_foot() {
        // A line 2 m ahead, across the view: seen at its perpendicular foot.
        let p = visible_piece_closest(Vector2::new(2.0, -5.0), Vector2::new(2.0, 5.0), 0.5, 0.1)
            .expect("in view");
        assert!((p - Vector2::new(2.0, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn a_segment_beside_or_behind_the_cone_is_not_seen() {
        let beside =
            visible_piece_closest(Vector2::new(1.0, 2.0), Vector2::new(3.0, 2.0), 0.5, 0.1);
        assert!(beside.is_none());
        let behind =
            visible_piece_closest(Vector2::new(-1.0, -3.0), Vector2::new(-1.0, 3.0), 0.5, 0.1);
        assert!(behind.is_none());
    }

    #[test]
    fn a_segment_entering_the_cone_is_seen_where_it_enters_and_a_sliver_is_not() {
        // Along the cone's axis direction but offset: enters at x = 2 (y = 1 = 2 * 0.5).
        let p = visible_piece_closest(Vector2::new(0.5, 1.0), Vector2::new(6.0, 1.0), 0.5, 0.1)
            .expect("in view");
        assert!((p - Vector2::new(2.0, 1.0)).norm() < 1e-9);
        // Only its last 5 cm are inside.
        let sliver =
            visible_piece_closest(Vector2::new(0.5, 1.0), Vector2::new(2.05, 1.0), 0.5, 0.1);
        assert!(sliver.is_none());
    }
}
