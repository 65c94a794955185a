//! The robot-pose filter (paper 3.1): an EKF on (x, y, theta) in the field frame, predicted with
//! odometry and corrected with the estimated positions of the landmarks against the known map.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};

use super::math::{Innovation, all_finite, joseph_update, nis, posterior_covariance, symmetrize};
use super::object::GainedInformation;
use crate::geometry::{Global, Odometry, Point, Pose, normalize_angle};

/// An EKF on the robot's pose in the field frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFilter {
    x: Vector3<f64>,
    p: Matrix3<f64>,
}

impl PoseFilter {
    pub fn new(pose: Pose, covariance: Matrix3<f64>) -> PoseFilter {
        PoseFilter {
            x: Vector3::new(pose.x, pose.y, normalize_angle(pose.theta)),
            p: symmetrize(covariance),
        }
    }

    pub fn pose(&self) -> Pose {
        Pose::new(self.x[0], self.x[1], self.x[2])
    }

    pub fn covariance(&self) -> Matrix3<f64> {
        self.p
    }

    /// The state `(x, y, theta)` as filtered (the heading not normalized again).
    pub(crate) fn state(&self) -> Vector3<f64> {
        self.x
    }

    pub fn is_finite(&self) -> bool {
        all_finite(&self.x) && all_finite(&self.p)
    }

    /// Moves the pose by `odometry` (expressed in the robot frame it started from), whose
    /// error covariance is `odometry_covariance`.
    pub fn predict(&mut self, odometry: &Odometry, odometry_covariance: &Matrix3<f64>) {
        let (s, c) = self.x[2].sin_cos();
        let (dx, dy) = (odometry.dx, odometry.dy);
        self.x = Vector3::new(
            self.x[0] + c * dx - s * dy,
            self.x[1] + s * dx + c * dy,
            normalize_angle(self.x[2] + odometry.dtheta),
        );
        let f = Matrix3::new(1.0, 0.0, -s * dx - c * dy, 0.0, 1.0, c * dx - s * dy, 0.0, 0.0, 1.0);
        let g = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        self.p = symmetrize(f * self.p * f.transpose() + g * odometry_covariance * g.transpose());
    }

    /// Where the landmark at `map` should appear in the robot frame, and the Jacobian of that
    /// with respect to the pose.
    pub fn expected_landmark(&self, map: Point<Global>) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
        landmark_measurement(&self.x, map)
    }

    /// The heading as the filter holds it (not normalized again).
    pub(crate) fn heading(&self) -> f64 {
        self.x[2]
    }

    /// `(sin, cos)` of the heading, for [`PoseFilter::expected_landmark_with`].
    pub(crate) fn heading_sin_cos(&self) -> (f64, f64) {
        self.x[2].sin_cos()
    }

    /// The innovation of a landmark estimate `measured` of the landmark at `map`.
    pub fn landmark_innovation(
        &self,
        map: Point<Global>,
        measured: &GainedInformation,
    ) -> Option<Innovation> {
        let (h, jac) = self.expected_landmark(map);
        let nu = measured.position - h;
        let s = jac * self.p * jac.transpose() + measured.covariance;
        let s = (s + s.transpose()) * 0.5;
        Some(Innovation { nu, s, nis: nis(&nu, &s)? })
    }

    /// Corrects the pose with a landmark estimate (Joseph form). `None`: nothing changed.
    pub fn update_landmark(
        &mut self,
        map: Point<Global>,
        measured: &GainedInformation,
    ) -> Option<Innovation> {
        let (h, jac) = self.expected_landmark(map);
        let nu = measured.position - h;
        self.correct(&jac, nu, &measured.covariance)
    }

    /// The covariance after a landmark estimate with covariance `r`, without changing anything.
    pub fn posterior_covariance(
        &self,
        map: Point<Global>,
        r: &Matrix2<f64>,
    ) -> Option<Matrix3<f64>> {
        let (_, jac) = self.expected_landmark(map);
        posterior_covariance(&self.p, &jac, r)
    }
}

/// One observation of a painted line, in the robot frame: the nearest point of its visible
/// piece and its direction (modulo a half turn), with their noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineObservation {
    pub point: Vector2<f64>,
    pub point_covariance: Matrix2<f64>,
    pub direction: f64,
    pub direction_sigma: f64,
}

impl LineObservation {
    /// The measurement `(s, phi)` this observation makes of the line: the robot's signed
    /// distance from it (along the line's left normal) and the line's direction relative to
    /// the robot's heading, with their covariance. The point's position along the line carries
    /// no information about the pose, so it is projected out here.
    pub fn measurement(&self) -> MeasuredLine {
        let (s, c) = self.direction.sin_cos();
        let (x, y) = (self.point.x, self.point.y);
        let distance = x * s - y * c;
        // d distance / d (x, y, direction).
        let j = nalgebra::Vector3::new(s, -c, x * c + y * s);
        let mut noise = Matrix3::zeros();
        noise.fixed_view_mut::<2, 2>(0, 0).copy_from(&self.point_covariance);
        noise[(2, 2)] = self.direction_sigma * self.direction_sigma;
        let jac = SMatrix::<f64, 2, 3>::new(j.x, j.y, j.z, 0.0, 0.0, 1.0);
        let r = jac * noise * jac.transpose();
        MeasuredLine {
            observation: *self,
            z: Vector2::new(distance, self.direction),
            r: (r + r.transpose()) * 0.5,
        }
    }
}

/// A line observation with its measurement `(s, phi)` and covariance, worked out once for
/// comparing it with every map line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredLine {
    pub observation: LineObservation,
    pub z: Vector2<f64>,
    pub r: Matrix2<f64>,
}

/// A map line, with what comparing observations with it needs worked out once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapLine {
    pub start: Point<Global>,
    pub end: Point<Global>,
    /// Direction from `start` to `end`, rad, and its sine and cosine.
    direction: f64,
    sin_cos: (f64, f64),
    pub length: f64,
}

impl MapLine {
    pub fn new([start, end]: [Point<Global>; 2]) -> MapLine {
        let direction = (end.y - start.y).atan2(end.x - start.x);
        MapLine { start, end, direction, sin_cos: direction.sin_cos(), length: start.distance(end) }
    }
}

/// A map line's expected measurement `(s, phi)` for the pose (see
/// [`LineObservation::measurement`]), its Jacobian, and where along the segment (m from
/// `start`) the observed point falls. The line's direction is taken as whichever of its two
/// senses is nearer the observed one: a painted line has no arrow.
fn line_measurement(
    pose: &Vector3<f64>,
    line: &MapLine,
    observation: &LineObservation,
) -> (Vector2<f64>, SMatrix<f64, 2, 3>, f64) {
    let (mut alpha, (mut sa, mut ca)) = (line.direction, line.sin_cos);
    if normalize_angle(alpha - pose[2] - observation.direction).abs() > FRAC_PI_2 {
        alpha += PI;
        (sa, ca) = (-sa, -ca);
    }
    let (dx, dy) = (pose[0] - line.start.x, pose[1] - line.start.y);
    let distance = -sa * dx + ca * dy;
    let h = Vector2::new(distance, normalize_angle(alpha - pose[2]));
    let jac = SMatrix::<f64, 2, 3>::new(-sa, ca, 0.0, 0.0, 0.0, -1.0);
    // The observed point in the field frame, measured along the segment from `start` (whose
    // direction is the unflipped one).
    let (st, ct) = pose[2].sin_cos();
    let (px, py) = (observation.point.x, observation.point.y);
    let (fx, fy) = (dx + ct * px - st * py, dy + st * px + ct * py);
    let (us, uc) = line.sin_cos;
    let along = fx * uc + fy * us;
    (h, jac, along)
}

/// The Jacobian of a line observation's measurement `(s, phi)` with respect to the pose, for
/// the map line `line` (expected updates: it does not depend on the measured values).
pub(crate) fn line_jacobian(
    pose: &Vector3<f64>,
    line: &MapLine,
    observation: &LineObservation,
) -> SMatrix<f64, 2, 3> {
    line_measurement(pose, line, observation).1
}

impl PoseFilter {
    /// The innovation of a line observation against the map line `segment`, and where along
    /// the segment the observed point falls (m from its start; outside `[0, length]` it is off
    /// the painted segment).
    pub fn line_innovation(
        &self,
        segment: [Point<Global>; 2],
        observation: &LineObservation,
    ) -> Option<(Innovation, f64)> {
        self.line_innovation_within(
            &MapLine::new(segment),
            &observation.measurement(),
            f64::INFINITY,
        )
    }

    /// [`PoseFilter::line_innovation`] for a prepared line and measurement; `None` as soon as
    /// either component alone lies outside `gate` (a 2-D innovation's NIS is at least each
    /// component's own, so nothing inside the gate is lost): most map lines of a field run
    /// the other way or lie metres off, and are dismissed before any matrix is formed.
    pub fn line_innovation_within(
        &self,
        line: &MapLine,
        measured: &MeasuredLine,
        gate: f64,
    ) -> Option<(Innovation, f64)> {
        let (z, r) = (measured.z, measured.r);
        let p = &self.p;
        let (angle_variance, distance_noise) = (p[(2, 2)] + r[(1, 1)], r[(0, 0)]);
        let mut alpha = line.direction;
        let mut flip = 1.0;
        if normalize_angle(alpha - self.x[2] - z.y).abs() > FRAC_PI_2 {
            alpha += PI;
            flip = -1.0;
        }
        let angle = normalize_angle(z.y - normalize_angle(alpha - self.x[2]));
        if angle * angle > gate * angle_variance {
            return None;
        }
        let (sa, ca) = (flip * line.sin_cos.0, flip * line.sin_cos.1);
        let distance = -sa * (self.x[0] - line.start.x) + ca * (self.x[1] - line.start.y);
        let distance_variance =
            sa * sa * p[(0, 0)] - 2.0 * sa * ca * p[(0, 1)] + ca * ca * p[(1, 1)] + distance_noise;
        let off = z.x - distance;
        if off * off > gate * distance_variance {
            return None;
        }
        let (h, jac, along) = line_measurement(&self.x, line, &measured.observation);
        let nu = Vector2::new(z.x - h.x, normalize_angle(z.y - h.y));
        let s = jac * self.p * jac.transpose() + r;
        let s = (s + s.transpose()) * 0.5;
        Some((Innovation { nu, s, nis: nis(&nu, &s)? }, along))
    }

    /// Corrects the pose with a line observation of the map line `segment` (Joseph form).
    /// `None`: nothing changed.
    pub fn update_line(
        &mut self,
        segment: [Point<Global>; 2],
        observation: &LineObservation,
    ) -> Option<Innovation> {
        self.update_line_with(&MapLine::new(segment), &observation.measurement())
    }

    /// [`PoseFilter::update_line`] for a prepared line and measurement.
    pub fn update_line_with(
        &mut self,
        line: &MapLine,
        measured: &MeasuredLine,
    ) -> Option<Innovation> {
        let (h, jac, _) = line_measurement(&self.x, line, &measured.observation);
        let nu = Vector2::new(measured.z.x - h.x, normalize_angle(measured.z.y - h.y));
        self.correct(&jac, nu, &measured.r)
    }

    /// The correction with innovation `nu`, measurement Jacobian `jac` and noise `r` (Joseph
    /// form); the filter is left as it was if the result is not finite. `None`: nothing changed.
    fn correct(
        &mut self,
        jac: &SMatrix<f64, 2, 3>,
        nu: Vector2<f64>,
        r: &Matrix2<f64>,
    ) -> Option<Innovation> {
        let mut x = self.x;
        let mut p = self.p;
        let innovation = joseph_update(&mut x, &mut p, jac, nu, r)?;
        x[2] = normalize_angle(x[2]);
        if !(all_finite(&x) && all_finite(&p)) {
            return None;
        }
        self.x = x;
        self.p = p;
        Some(innovation)
    }
}

/// `h(pose) = R(-theta) (m - p)` and its Jacobian with respect to `(x, y, theta)`.
pub(crate) fn landmark_measurement(
    pose: &Vector3<f64>,
    map: Point<Global>,
) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
    landmark_measurement_with(pose, pose[2].sin_cos(), map)
}

/// [`landmark_measurement`] with `(sin, cos)` of the heading given.
pub(crate) fn landmark_measurement_with(
    pose: &Vector3<f64>,
    (s, c): (f64, f64),
    map: Point<Global>,
) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
    let dx = map.x - pose[0];
    let dy = map.y - pose[1];
    let h = Vector2::new(c * dx + s * dy, -s * dx + c * dy);
    let jac = SMatrix::<f64, 2, 3>::new(-c, -s, h.y, s, -c, -h.x);
    (h, jac)
}

/// The pose covariance after a landmark estimate with covariance `r` of the landmark at `map`,
/// for a pose `pose` with covariance `p` (active vision's simulated correction).
pub fn pose_posterior_covariance(
    pose: &Pose,
    p: &Matrix3<f64>,
    map: Point<Global>,
    r: &Matrix2<f64>,
) -> Option<Matrix3<f64>> {
    let (_, jac) = landmark_measurement(&Vector3::new(pose.x, pose.y, pose.theta), map);
    posterior_covariance(p, &jac, r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn prediction_moves_in_the_robot_frame_and_grows_the_covariance() {
        let mut f = PoseFilter::new(Pose::new(1.0, 2.0, FRAC_PI_2), Matrix3::zeros());
        let q = Matrix3::from_diagonal(&Vector3::new(0.01, 0.0, 0.0));
        f.predict(&Odometry { dx: 1.0, dy: 0.0, dtheta: 0.0 }, &q);
        let pose = f.pose();
        assert_relative_eq!(pose.x, 1.0, epsilon = 1e-12);
        assert_relative_eq!(pose.y, 3.0, epsilon = 1e-12);
        // Forward noise of a robot facing +y is noise along the field's y axis.
        assert_relative_eq!(f.covariance()[(1, 1)], 0.01, epsilon = 1e-12);
        assert_relative_eq!(f.covariance()[(0, 0)], 0.0, epsilon = 1e-12);
    }

    #[test]
    fn a_landmark_ahead_corrects_the_distance_to_it() {
        // Robot at the origin facing +x, variance 0.04 in x and y, exact heading. A landmark
        // at (3, 0) is measured 2.9 m ahead with variance 0.04: x moves half-way, to +0.05.
        let p0 = Matrix3::from_diagonal(&Vector3::new(0.04, 0.04, 0.0));
        let mut f = PoseFilter::new(Pose::new(0.0, 0.0, 0.0), p0);
        let measured = GainedInformation {
            position: Vector2::new(2.9, 0.0),
            covariance: Matrix2::identity() * 0.04,
        };
        let innovation = f.update_landmark(Point::new(3.0, 0.0), &measured).expect("regular");
        assert_relative_eq!(innovation.nu, Vector2::new(-0.1, 0.0), epsilon = 1e-12);
        assert_relative_eq!(f.pose().x, 0.05, epsilon = 1e-12);
        assert_relative_eq!(f.pose().y, 0.0, epsilon = 1e-12);
        assert_relative_eq!(f.covariance()[(0, 0)], 0.02, epsilon = 1e-12);
        assert_relative_eq!(f.covariance()[(1, 1)], 0.02, epsilon = 1e-12);
    }

    fn line_seen(pose: Pose, segment: [Point<Global>; 2]) -> LineObservation {
        // The foot of the perpendicular from the robot, and the line's direction, both in the
        // robot frame, without noise.
        let [a, b] = segment;
        let (ux, uy) = ((b.x - a.x) / a.distance(b), (b.y - a.y) / a.distance(b));
        let t = (pose.x - a.x) * ux + (pose.y - a.y) * uy;
        let foot = Point::<Global>::new(a.x + t * ux, a.y + t * uy);
        let (h, _) = landmark_measurement(&Vector3::new(pose.x, pose.y, pose.theta), foot);
        LineObservation {
            point: h,
            point_covariance: Matrix2::identity() * 0.01,
            direction: normalize_angle(uy.atan2(ux) - pose.theta),
            direction_sigma: 0.05,
        }
    }

    #[test]
    fn a_line_corrects_the_distance_to_it_and_the_heading_not_the_position_along_it() {
        // The halfway line x = 0; the robot believes it stands at x = -1.2, facing it, but it
        // stands at x = -1.0 and is turned by 0.1 rad.
        let segment = [Point::new(0.0, -3.0), Point::new(0.0, 3.0)];
        let truth = Pose::new(-1.0, 0.5, 0.1);
        let observation = line_seen(truth, segment);
        let p0 = Matrix3::from_diagonal(&Vector3::new(0.04, 0.04, 0.04));
        let mut f = PoseFilter::new(Pose::new(-1.2, 0.0, 0.0), p0);
        let (innovation, along) = f.line_innovation(segment, &observation).expect("regular");
        assert!((0.0..=6.0).contains(&along), "the observed point is on the segment: {along}");
        assert!(innovation.nis > 1.0);
        f.update_line(segment, &observation).expect("regular");
        let pose = f.pose();
        assert!((pose.x + 1.0).abs() < 0.05, "moved toward the true distance: {pose:?}");
        assert!((pose.theta - 0.1).abs() < 0.03, "heading corrected: {pose:?}");
        assert_relative_eq!(pose.y, 0.0, epsilon = 0.02);
        // Along the line, nothing was learnt.
        assert_relative_eq!(f.covariance()[(1, 1)], 0.04, epsilon = 1e-9);
        assert!(f.covariance()[(0, 0)] < 0.01);
    }

    #[test]
    fn a_line_has_no_arrow() {
        let segment = [Point::new(0.0, -3.0), Point::new(0.0, 3.0)];
        let reversed = [segment[1], segment[0]];
        let truth = Pose::new(-1.0, 0.5, 0.1);
        let mut observation = line_seen(truth, segment);
        let f = PoseFilter::new(truth, Matrix3::identity() * 0.01);
        for direction in [observation.direction, normalize_angle(observation.direction + PI)] {
            observation.direction = direction;
            for s in [segment, reversed] {
                let (innovation, _) = f.line_innovation(s, &observation).expect("regular");
                assert!(innovation.nu.norm() < 1e-9, "{:?}", innovation.nu);
            }
        }
    }

    #[test]
    fn line_jacobian_matches_finite_differences() {
        let pose = Vector3::new(0.3, -1.2, 0.8);
        let segment = [Point::new(-2.0, 1.0), Point::new(3.0, 2.5)];
        let observation = LineObservation {
            point: Vector2::new(1.0, 0.5),
            point_covariance: Matrix2::identity() * 0.01,
            direction: -0.5,
            direction_sigma: 0.05,
        };
        let line = MapLine::new(segment);
        let (h0, jac, _) = line_measurement(&pose, &line, &observation);
        for k in 0..3 {
            let mut d = pose;
            d[k] += 1e-7;
            let (h1, _, _) = line_measurement(&d, &line, &observation);
            let numeric = (h1 - h0) / 1e-7;
            assert_relative_eq!(numeric, jac.column(k).into_owned(), epsilon = 1e-5);
        }
    }

    #[test]
    fn measurement_jacobian_matches_finite_differences() {
        let pose = Vector3::new(0.3, -1.2, 0.8);
        let map = Point::new(2.0, 1.0);
        let (h0, jac) = landmark_measurement(&pose, map);
        for k in 0..3 {
            let mut d = pose;
            d[k] += 1e-7;
            let (h1, _) = landmark_measurement(&d, map);
            let numeric = (h1 - h0) / 1e-7;
            assert_relative_eq!(numeric, jac.column(k).into_owned(), epsilon = 1e-5);
        }
    }
}
