//! Estimating the odometry's error from the landmark filters (paper 3.1: the robot corrects its
//! odometry even when it is totally lost). Static landmarks do not move: when the landmark
//! filters keep finding their landmarks displaced the same way after odometry moved them, the
//! robot moved differently than odometry said. That needs only the robot-frame landmark
//! estimates, never the pose.
//!
//! Model: the true increment is `(1 + e) * reported` component-wise, e = (ex, ey, etheta). Each
//! landmark filter carries its lag `L` (2x3): the mean error its estimate has because of e,
//! `true - estimate = L e`. L grows with every increment (`L <- R(-dtheta) L + G diag(o)`, G the
//! filter's odometry Jacobian) and shrinks with every correction (`L <- (I - K) L`). Its
//! innovations are then linear observations of e, `nu = L e + noise(S)`, white for a consistent
//! filter: a Kalman filter on e needs nothing else. (Using innovations without the lag would
//! misjudge e by the filter's gain.)

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};

use super::math::{all_finite, symmetrize};
use super::state::OdometryErrorEstimate;
use crate::geometry::Odometry;

/// The part of a landmark filter's error explained by odometry's relative error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Lag {
    /// `true - estimate = matrix * e`.
    pub matrix: SMatrix<f64, 2, 3>,
    /// The part of it already compensated by the correction applied to odometry.
    pub applied: Vector2<f64>,
}

impl Default for Lag {
    fn default() -> Self {
        Lag { matrix: SMatrix::zeros(), applied: Vector2::zeros() }
    }
}

impl Lag {
    /// After the reported increment `reported` (corrected with `used` before being applied),
    /// for a landmark now at `position`; `(s, c)` is `reported.dtheta.sin_cos()`, computed once
    /// for every landmark of the frame.
    pub fn predict(
        &mut self,
        position: Vector2<f64>,
        reported: &Odometry,
        (s, c): (f64, f64),
        used: &Vector3<f64>,
    ) {
        let rt = Matrix2::new(c, s, -s, c);
        let mut g = SMatrix::<f64, 2, 3>::zeros();
        g.fixed_view_mut::<2, 2>(0, 0).copy_from(&(-rt));
        g[(0, 2)] = position.y;
        g[(1, 2)] = -position.x;
        let go =
            g * Matrix3::from_diagonal(&Vector3::new(reported.dx, reported.dy, reported.dtheta));
        self.matrix = rt * self.matrix + go;
        self.applied = rt * self.applied + go * used;
    }

    /// After a correction with gain `k` (position block).
    pub fn correct(&mut self, k: &Matrix2<f64>) {
        let i_k = Matrix2::identity() - k;
        self.matrix = i_k * self.matrix;
        self.applied = i_k * self.applied;
    }
}

/// One static landmark corrected in this frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LandmarkShift {
    /// Where the filter predicted the landmark (robot frame).
    pub prior: Vector2<f64>,
    /// Observation minus prediction, and its covariance.
    pub innovation: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    /// The filter's lag before the correction.
    pub lag: Lag,
}

/// Relative-error states drift this much per frame (lets the estimate follow a changing floor).
const RANDOM_WALK: f64 = 0.0005 * 0.0005;
const INITIAL_SIGMA: f64 = 0.2;
/// Frames needed before the estimate is used to correct odometry.
const MIN_SAMPLES: u64 = 90;
/// Lags smaller than this (m per unit relative error) say nothing about a relative error.
const MIN_LAG: f64 = 1e-3;

#[derive(Clone, Debug)]
pub(crate) struct OdometryErrorEstimator {
    e: Vector3<f64>,
    p: Matrix3<f64>,
    estimate: OdometryErrorEstimate,
}

impl OdometryErrorEstimator {
    pub fn new(apply: bool) -> OdometryErrorEstimator {
        OdometryErrorEstimator {
            e: Vector3::zeros(),
            p: Matrix3::identity() * INITIAL_SIGMA * INITIAL_SIGMA,
            estimate: OdometryErrorEstimate { applied: apply, ..OdometryErrorEstimate::default() },
        }
    }

    pub fn estimate(&self) -> OdometryErrorEstimate {
        self.estimate
    }

    /// The relative error currently applied to incoming odometry.
    pub fn applied(&self) -> Vector3<f64> {
        if self.estimate.applied && self.estimate.samples >= MIN_SAMPLES {
            self.e
        } else {
            Vector3::zeros()
        }
    }

    /// The reported increment corrected with the estimated relative error (when enabled).
    pub fn correct(&self, odometry: Odometry) -> Odometry {
        let e = self.applied();
        Odometry {
            dx: odometry.dx * (1.0 + e[0]),
            dy: odometry.dy * (1.0 + e[1]),
            dtheta: odometry.dtheta * (1.0 + e[2]),
        }
    }

    /// Updates the estimate with the landmark innovations of one frame.
    pub fn observe(&mut self, shifts: &[LandmarkShift]) {
        if shifts.is_empty() {
            return;
        }
        let informative = shifts.iter().any(|s| s.lag.matrix.iter().any(|v| v.abs() >= MIN_LAG));
        if informative {
            self.p += Matrix3::identity() * RANDOM_WALK;
        }
        let mut info = Matrix3::zeros();
        let mut b = Vector3::zeros();
        for s in shifts {
            let Some(w) = s.covariance.try_inverse() else { continue };
            // The rigid motion that best explains the innovations (a diagnostic).
            let l = s.prior;
            let j = SMatrix::<f64, 2, 3>::new(-1.0, 0.0, l.y, 0.0, -1.0, -l.x);
            info += j.transpose() * w * j;
            b += j.transpose() * w * s.innovation;
            if !informative {
                continue;
            }
            let h = s.lag.matrix;
            let y = s.innovation - (h * self.e - s.lag.applied);
            let sm = h * self.p * h.transpose() + s.covariance;
            let Some(s_inv) = sm.try_inverse() else { continue };
            let k = self.p * h.transpose() * s_inv;
            let e = self.e + k * y;
            let i_kh = Matrix3::identity() - k * h;
            let p = symmetrize(i_kh * self.p * i_kh.transpose() + k * s.covariance * k.transpose());
            if all_finite(&e) && all_finite(&p) {
                self.e = e;
                self.p = p;
            }
        }
        if informative {
            self.estimate.samples += 1;
        }
        // Innovations all at one place (one landmark) leave the rigid motion undetermined:
        // the information matrix is then singular up to rounding, and its "inverse" holds
        // variances of 1e15 of either sign. Such frames keep the previous fit.
        if determined(&info)
            && let Some(covariance) = info.try_inverse()
            && all_finite(&covariance)
        {
            let delta = covariance * b;
            self.estimate.last_correction =
                Odometry { dx: delta[0], dy: delta[1], dtheta: delta[2] };
            self.estimate.last_correction_covariance = covariance;
        }
        self.estimate.relative_error = [self.e[0], self.e[1], self.e[2]];
        self.estimate.relative_error_sigma = [
            self.p[(0, 0)].max(0.0).sqrt(),
            self.p[(1, 1)].max(0.0).sqrt(),
            self.p[(2, 2)].max(0.0).sqrt(),
        ];
    }
}

/// The smallest eigenvalue an information matrix needs, relative to its largest, for the
/// motion it describes to count as determined (rank-deficient ones come out near 1e-17).
const MIN_CONDITION: f64 = 1e-9;

/// Whether the information matrix of a rigid-motion fit determines all three components.
fn determined(info: &Matrix3<f64>) -> bool {
    let eigenvalues = info.symmetric_eigenvalues();
    let largest = eigenvalues.max();
    let smallest = eigenvalues.min();
    largest.is_finite() && largest > 0.0 && smallest > largest * MIN_CONDITION
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shift of the landmark at `prior` as the robot-frame motion `delta` (dx, dy, dtheta)
    /// missed by odometry would make it, with 1 cm of measurement noise and no lag.
    fn shift(prior: Vector2<f64>, delta: Vector3<f64>) -> LandmarkShift {
        let j = SMatrix::<f64, 2, 3>::new(-1.0, 0.0, prior.y, 0.0, -1.0, -prior.x);
        LandmarkShift {
            prior,
            innovation: j * delta,
            covariance: Matrix2::identity() * 1e-4,
            lag: Lag::default(),
        }
    }

    #[test]
    fn one_landmark_leaves_the_missed_motion_unknown() {
        let mut estimator = OdometryErrorEstimator::new(false);
        estimator.observe(&[shift(Vector2::new(2.0, 0.5), Vector3::new(0.01, -0.02, 0.005))]);
        let estimate = estimator.estimate();
        assert_eq!(estimate.last_correction, Odometry::default());
        assert_eq!(estimate.last_correction_covariance, Matrix3::zeros());
    }

    #[test]
    fn one_landmark_seen_twice_leaves_it_unknown_too() {
        let mut estimator = OdometryErrorEstimator::new(false);
        let delta = Vector3::new(0.01, -0.02, 0.005);
        let prior = Vector2::new(2.0, 1.0);
        estimator.observe(&[shift(prior, delta), shift(prior, delta)]);
        assert_eq!(estimator.estimate().last_correction_covariance, Matrix3::zeros());
    }

    #[test]
    fn two_landmarks_give_the_missed_motion_with_a_proper_covariance() {
        let mut estimator = OdometryErrorEstimator::new(false);
        let delta = Vector3::new(0.01, -0.02, 0.005);
        estimator.observe(&[
            shift(Vector2::new(2.0, 0.5), delta),
            shift(Vector2::new(3.0, -1.5), delta),
        ]);
        let estimate = estimator.estimate();
        let found = estimate.last_correction;
        assert!((found.dx - delta.x).abs() < 1e-9, "{found:?}");
        assert!((found.dy - delta.y).abs() < 1e-9, "{found:?}");
        assert!((found.dtheta - delta.z).abs() < 1e-9, "{found:?}");
        let covariance = estimate.last_correction_covariance;
        let eigenvalues = covariance.symmetric_eigenvalues();
        assert!(eigenvalues.min() > 0.0, "{covariance}");
        // Centimetre observations a few metres away pin the motion to centimetres.
        assert!(eigenvalues.max().sqrt() < 0.1, "{covariance}");
    }
}
