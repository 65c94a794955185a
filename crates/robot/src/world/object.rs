//! The filter of one object of interest (paper 3.1): an EKF in the robot's own frame,
//! predicted with odometry (and its uncertainty) and corrected by range/bearing observations.
//!
//! State `(x, y, vx, vy)` in the robot frame. Static landmarks keep a zero velocity with zero
//! covariance, so the same filter serves every kind of object; the motion model decides how the
//! object moves between two frames.

use nalgebra::{Matrix2, Matrix3, Matrix4, SMatrix, Vector2, Vector4};
use serde::{Deserialize, Serialize};

use super::math::{
    Innovation, RangeBearing, all_finite, joseph_update, nis, polar, polar_to_cartesian_jacobian,
    posterior_covariance, symmetrize, symmetrize2,
};
use crate::geometry::{Odometry, Point, Robot, Vector};

/// How an object moves by itself between two frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum MotionModel {
    /// Does not move; `position_noise` (m^2/s) lets a long-tracked estimate still follow an
    /// odometry model that is slightly wrong.
    Static { position_noise: f64 },
    /// Rolls and decelerates at `friction` m/s^2 until it stops; `acceleration_noise` is the
    /// white acceleration noise density (m/s^(3/2)).
    Rolling { friction: f64, acceleration_noise: f64 },
    /// Moves at a velocity that decays with time constant `velocity_decay` (s) unless observed.
    Walking { velocity_decay: f64, acceleration_noise: f64 },
}

impl MotionModel {
    pub fn is_static(&self) -> bool {
        matches!(self, MotionModel::Static { .. })
    }
}

/// An EKF on one object's position (and velocity) in the robot frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectFilter {
    x: Vector4<f64>,
    p: Matrix4<f64>,
    model: MotionModel,
}

/// The robot-frame measurement carrying exactly the information one observation added to an
/// object filter (the filter's posterior information minus its prior information): what the
/// pose filter is fed, so that no observation counts twice however long the object has been
/// tracked. With the converted-measurement update it is the observation in the robot frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainedInformation {
    /// The measured position in the robot frame.
    pub position: Vector2<f64>,
    /// Its covariance.
    pub covariance: Matrix2<f64>,
}

impl ObjectFilter {
    /// A filter at a known position and velocity.
    pub fn new(
        position: Point<Robot>,
        position_covariance: Matrix2<f64>,
        velocity: Vector<Robot>,
        velocity_covariance: Matrix2<f64>,
        model: MotionModel,
    ) -> ObjectFilter {
        let mut p = Matrix4::zeros();
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&symmetrize2(position_covariance));
        let (velocity, velocity_covariance) = if model.is_static() {
            (Vector::new(0.0, 0.0), Matrix2::zeros())
        } else {
            (velocity, symmetrize2(velocity_covariance))
        };
        p.fixed_view_mut::<2, 2>(2, 2).copy_from(&velocity_covariance);
        ObjectFilter { x: Vector4::new(position.x, position.y, velocity.x, velocity.y), p, model }
    }

    /// A filter started from one observation: the observed point with the observation's
    /// noise, at rest with velocity standard deviation `velocity_sigma` (ignored when static).
    pub fn from_observation(
        z: &RangeBearing,
        velocity_sigma: f64,
        model: MotionModel,
    ) -> ObjectFilter {
        ObjectFilter::from_converted(z.cartesian(), z.cartesian_noise(), velocity_sigma, model)
    }

    /// [`ObjectFilter::from_observation`] with the observation already converted to the robot
    /// frame (`measured`, with covariance `noise`).
    pub(crate) fn from_converted(
        measured: Vector2<f64>,
        noise: Matrix2<f64>,
        velocity_sigma: f64,
        model: MotionModel,
    ) -> ObjectFilter {
        ObjectFilter::new(
            Point::new(measured.x, measured.y),
            noise,
            Vector::new(0.0, 0.0),
            Matrix2::identity() * velocity_sigma.powi(2),
            model,
        )
    }

    pub fn model(&self) -> MotionModel {
        self.model
    }

    pub fn position(&self) -> Point<Robot> {
        Point::new(self.x[0], self.x[1])
    }

    pub fn position_vector(&self) -> Vector2<f64> {
        Vector2::new(self.x[0], self.x[1])
    }

    pub fn velocity(&self) -> Vector<Robot> {
        Vector::new(self.x[2], self.x[3])
    }

    pub fn position_covariance(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    pub fn velocity_covariance(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(2, 2).into_owned()
    }

    /// The full state `(x, y, vx, vy)` and its covariance.
    pub fn state(&self) -> (Vector4<f64>, Matrix4<f64>) {
        (self.x, self.p)
    }

    pub fn is_finite(&self) -> bool {
        all_finite(&self.x) && all_finite(&self.p)
    }

    /// Moves the object into the robot frame reached after `odometry`, whose error covariance
    /// (in the starting frame) is `odometry_covariance`.
    pub fn predict_odometry(&mut self, odometry: &Odometry, odometry_covariance: &Matrix3<f64>) {
        self.predict_odometry_with(odometry, odometry.dtheta.sin_cos(), odometry_covariance);
    }

    /// [`ObjectFilter::predict_odometry`] with `(sin, cos)` of `odometry.dtheta` given: the
    /// world model moves every filter by the same increment.
    pub(crate) fn predict_odometry_with(
        &mut self,
        odometry: &Odometry,
        (s, c): (f64, f64),
        odometry_covariance: &Matrix3<f64>,
    ) {
        // Rotation by -dtheta: a fixed point turns the other way when the robot turns.
        let rt = Matrix2::new(c, s, -s, c);
        let pos = rt * (self.position_vector() - Vector2::new(odometry.dx, odometry.dy));
        let vel = rt * Vector2::new(self.x[2], self.x[3]);
        if self.model.is_static() {
            // A static object's velocity block and cross-covariances stay zero: the 4x4
            // propagation would only add zero terms to the position block.
            let mut g = SMatrix::<f64, 2, 3>::zeros();
            g.fixed_view_mut::<2, 2>(0, 0).copy_from(&(-rt));
            g[(0, 2)] = pos.y;
            g[(1, 2)] = -pos.x;
            let p = self.position_covariance();
            let p = symmetrize2(rt * p * rt.transpose() + g * odometry_covariance * g.transpose());
            self.x = Vector4::new(pos.x, pos.y, vel.x, vel.y);
            self.p.fixed_view_mut::<2, 2>(0, 0).copy_from(&p);
            return;
        }
        let mut f = Matrix4::zeros();
        f.fixed_view_mut::<2, 2>(0, 0).copy_from(&rt);
        f.fixed_view_mut::<2, 2>(2, 2).copy_from(&rt);
        let mut g = SMatrix::<f64, 4, 3>::zeros();
        g.fixed_view_mut::<2, 2>(0, 0).copy_from(&(-rt));
        g[(0, 2)] = pos.y;
        g[(1, 2)] = -pos.x;
        g[(2, 2)] = vel.y;
        g[(3, 2)] = -vel.x;
        self.x = Vector4::new(pos.x, pos.y, vel.x, vel.y);
        self.p = symmetrize(f * self.p * f.transpose() + g * odometry_covariance * g.transpose());
    }

    /// Lets `dt` seconds pass: the object moves by its own motion model.
    pub fn predict_motion(&mut self, dt: f64) {
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        match self.model {
            MotionModel::Static { position_noise } => {
                self.p[(0, 0)] += position_noise * dt;
                self.p[(1, 1)] += position_noise * dt;
            }
            MotionModel::Rolling { friction, acceleration_noise } => {
                self.roll(dt, friction, acceleration_noise.powi(2));
            }
            MotionModel::Walking { velocity_decay, acceleration_noise } => {
                let k = (-dt / velocity_decay).exp();
                let tau = velocity_decay * (1.0 - k);
                let v = Vector2::new(self.x[2], self.x[3]);
                let pos = self.position_vector() + v * tau;
                self.x = Vector4::new(pos.x, pos.y, v.x * k, v.y * k);
                let f = transition(Matrix2::identity() * tau, Matrix2::identity() * k);
                self.p = symmetrize(
                    f * self.p * f.transpose() + white_acceleration(dt, acceleration_noise.powi(2)),
                );
            }
        }
    }

    /// Rolling with constant deceleration `a`. The mean follows the exact model; the covariance
    /// is propagated with the Jacobian evaluated at the speed the velocity uncertainty allows
    /// when the mean is (nearly) at rest — at the mean itself the Jacobian of a stopped ball is
    /// zero and observations could never again tell the filter that the ball is rolling.
    fn roll(&mut self, dt: f64, a: f64, q: f64) {
        let v = Vector2::new(self.x[2], self.x[3]);
        let s = v.norm();
        let (dp, v_new) = if a <= 0.0 {
            (v * dt, v)
        } else if s > a * dt {
            (v * (dt - a * dt * dt / (2.0 * s)), v * (1.0 - a * dt / s))
        } else {
            (v * (s / (2.0 * a)), Vector2::zeros())
        };
        let pvv = self.velocity_covariance();
        let sigma_v = ((pvv[(0, 0)] + pvv[(1, 1)]) / 2.0).max(0.0).sqrt();
        let (f_pv, f_vv) = if a <= 0.0 {
            (Matrix2::identity() * dt, Matrix2::identity())
        } else {
            let s_eff = s.max(sigma_v);
            let (tau, k) = if s_eff > a * dt {
                (dt - a * dt * dt / (2.0 * s_eff), 1.0 - a * dt / s_eff)
            } else {
                (s_eff / (2.0 * a), 0.0)
            };
            let mut f_pv = Matrix2::identity() * tau;
            let mut f_vv = Matrix2::identity() * k;
            if s > a * dt {
                // Along the direction of motion the speed loses a constant amount: the
                // derivative of the travelled distance is dt and of the speed is 1.
                let u = v / s;
                let uu = u * u.transpose();
                f_pv += uu * (dt - tau);
                f_vv += uu * (1.0 - k);
            }
            (f_pv, f_vv)
        };
        let pos = self.position_vector() + dp;
        self.x = Vector4::new(pos.x, pos.y, v_new.x, v_new.y);
        let f = transition(f_pv, f_vv);
        self.p = symmetrize(f * self.p * f.transpose() + white_acceleration(dt, q));
    }

    /// Adds velocity uncertainty (the object may have been kicked or pushed).
    pub fn inflate_velocity(&mut self, sigma: f64) {
        if !self.model.is_static() {
            self.p[(2, 2)] += sigma * sigma;
            self.p[(3, 3)] += sigma * sigma;
        }
    }

    /// Scales the whole covariance (negative information: the object was not where expected).
    pub fn inflate(&mut self, factor: f64) {
        self.p *= factor;
    }

    /// What observing `z` would give, without changing the filter; `None` if degenerate.
    pub fn innovation(&self, z: &RangeBearing) -> Option<Innovation> {
        cartesian_innovation(self.position_vector(), &self.position_covariance(), z)
    }

    /// Corrects the filter with a range/bearing observation. The observation is converted to
    /// the robot frame (its noise evaluated at the measured point) and the update is linear:
    /// unlike linearizing the polar model at the prior, this stays consistent for objects close
    /// to the robot and for priors far from the measurement. Joseph form. Returns the
    /// innovation, or `None` (filter untouched) when the update is numerically degenerate.
    pub fn update(&mut self, z: &RangeBearing) -> Option<Innovation> {
        self.update_at(z.cartesian(), &z.cartesian_noise())
    }

    /// [`ObjectFilter::update`] with the observation already converted to the robot frame
    /// (`measured`, with covariance `noise`).
    pub(crate) fn update_at(
        &mut self,
        measured: Vector2<f64>,
        noise: &Matrix2<f64>,
    ) -> Option<Innovation> {
        let nu = measured - self.position_vector();
        if self.model.is_static() {
            // Only the position block of a static object's covariance is non-zero (see
            // `predict_odometry_with`): the 4-state update would only add zero terms.
            let mut x = self.position_vector();
            let mut p = self.position_covariance();
            let innovation = joseph_update(&mut x, &mut p, &Matrix2::identity(), nu, noise)?;
            if !(all_finite(&x) && all_finite(&p)) {
                return None;
            }
            self.x[0] = x.x;
            self.x[1] = x.y;
            self.p.fixed_view_mut::<2, 2>(0, 0).copy_from(&p);
            return Some(innovation);
        }
        let mut x = self.x;
        let mut p = self.p;
        let h = SMatrix::<f64, 2, 4>::identity();
        let innovation = joseph_update(&mut x, &mut p, &h, nu, noise)?;
        if !(all_finite(&x) && all_finite(&p)) {
            return None;
        }
        self.x = x;
        self.p = p;
        Some(innovation)
    }

    /// The position covariance after observing with range/bearing noise `r` at the predicted
    /// position, without changing the filter.
    pub fn posterior_position_covariance(&self, r: &Matrix2<f64>) -> Option<Matrix2<f64>> {
        posterior_position_covariance(&self.position_covariance(), self.position_vector(), r)
    }

    /// The information observing `z` adds to this filter, as a robot-frame measurement.
    pub fn gained_information(&self, z: &RangeBearing) -> GainedInformation {
        GainedInformation { position: z.cartesian(), covariance: z.cartesian_noise() }
    }
}

fn transition(f_pv: Matrix2<f64>, f_vv: Matrix2<f64>) -> Matrix4<f64> {
    let mut f = Matrix4::identity();
    f.fixed_view_mut::<2, 2>(0, 2).copy_from(&f_pv);
    f.fixed_view_mut::<2, 2>(2, 2).copy_from(&f_vv);
    f
}

/// Process noise of a white acceleration of density `q` over `dt`, per axis.
fn white_acceleration(dt: f64, q: f64) -> Matrix4<f64> {
    let a = q * dt.powi(3) / 3.0;
    let b = q * dt.powi(2) / 2.0;
    let c = q * dt;
    Matrix4::new(a, 0.0, b, 0.0, 0.0, a, 0.0, b, b, 0.0, c, 0.0, 0.0, b, 0.0, c)
}

/// The robot-frame innovation of `z` against a Gaussian estimate of a position.
pub(crate) fn cartesian_innovation(
    position: Vector2<f64>,
    covariance: &Matrix2<f64>,
    z: &RangeBearing,
) -> Option<Innovation> {
    innovation_at(position, covariance, z.cartesian(), &z.cartesian_noise())
}

/// [`cartesian_innovation`] of an observation already converted to the robot frame (`measured`
/// with covariance `noise`): association converts each observation once for all candidates.
pub(crate) fn innovation_at(
    position: Vector2<f64>,
    covariance: &Matrix2<f64>,
    measured: Vector2<f64>,
    noise: &Matrix2<f64>,
) -> Option<Innovation> {
    let nu = measured - position;
    let s = symmetrize2(covariance + noise);
    let d = nis(&nu, &s)?;
    Some(Innovation { nu, s, nis: d })
}

/// The robot-frame noise of a range/bearing observation with noise `r` at `position`.
pub fn cartesian_noise_at(position: Vector2<f64>, r: &Matrix2<f64>) -> Matrix2<f64> {
    let (z, _) = polar(position);
    let j = polar_to_cartesian_jacobian(z.x.max(super::math::MIN_RANGE), z.y);
    symmetrize2(j * r * j.transpose())
}

/// The position covariance after a range/bearing observation with noise `r` of an object at
/// `position` with covariance `p` (the measurement's noise taken at the predicted position).
/// Observations see only the position, so the position block of the posterior depends on the
/// position block of the prior alone: this is exact for mobile objects too.
pub fn posterior_position_covariance(
    p: &Matrix2<f64>,
    position: Vector2<f64>,
    r: &Matrix2<f64>,
) -> Option<Matrix2<f64>> {
    posterior_covariance(p, &Matrix2::identity(), &cartesian_noise_at(position, r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn landmark_at(x: f64, y: f64, var: f64) -> ObjectFilter {
        ObjectFilter::new(
            Point::new(x, y),
            Matrix2::identity() * var,
            Vector::new(0.0, 0.0),
            Matrix2::zeros(),
            MotionModel::Static { position_noise: 0.0 },
        )
    }

    #[test]
    fn pure_translation_shifts_the_object_and_adds_odometry_noise() {
        let mut f = landmark_at(2.0, 1.0, 0.01);
        let q = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.0004, 0.0004, 0.0));
        f.predict_odometry(&Odometry { dx: 0.5, dy: 0.0, dtheta: 0.0 }, &q);
        assert_relative_eq!(f.position().x, 1.5, epsilon = 1e-12);
        assert_relative_eq!(f.position().y, 1.0, epsilon = 1e-12);
        assert_relative_eq!(f.position_covariance(), Matrix2::identity() * 0.0104, epsilon = 1e-12);
    }

    #[test]
    fn heading_noise_spreads_a_far_object_sideways() {
        // A point 3 m ahead, heading variance 0.01: the lateral variance grows by 3^2 * 0.01.
        let mut f = landmark_at(3.0, 0.0, 0.0);
        let q = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.0, 0.0, 0.01));
        f.predict_odometry(&Odometry::ZERO, &q);
        let p = f.position_covariance();
        assert_relative_eq!(p[(0, 0)], 0.0, epsilon = 1e-12);
        assert_relative_eq!(p[(1, 1)], 0.09, epsilon = 1e-12);
    }

    #[test]
    fn update_matches_a_hand_computed_kalman_gain() {
        // Object straight ahead at 2 m with variance 0.04 on each axis. An observation at
        // range 2.1, bearing 0 with range sigma 0.1 and bearing sigma 0.05 is the point
        // (2.1, 0) with noise diag(0.1^2, (2.1 * 0.05)^2) = diag(0.01, 0.011025).
        // S = diag(0.05, 0.051025); K = diag(0.04 / 0.05, 0.04 / 0.051025).
        let mut f = landmark_at(2.0, 0.0, 0.04);
        let z = RangeBearing { range: 2.1, bearing: 0.0, range_sigma: 0.1, bearing_sigma: 0.05 };
        let innovation = f.update(&z).expect("a regular update");
        assert_relative_eq!(innovation.nu, Vector2::new(0.1, 0.0), epsilon = 1e-12);
        assert_relative_eq!(innovation.s, Matrix2::new(0.05, 0.0, 0.0, 0.051025), epsilon = 1e-12);
        assert_relative_eq!(innovation.nis, 0.01 / 0.05, epsilon = 1e-12);
        assert_relative_eq!(f.position().x, 2.0 + 0.8 * 0.1, epsilon = 1e-12);
        assert_relative_eq!(f.position().y, 0.0, epsilon = 1e-12);
        // (I - K) P = diag(0.2 * 0.04, (1 - 0.04 / 0.051025) * 0.04).
        let expected = Matrix2::new(0.008, 0.0, 0.0, 0.04 * 0.011025 / 0.051025);
        assert_relative_eq!(f.position_covariance(), expected, epsilon = 1e-12);
    }

    #[test]
    fn static_objects_take_the_position_block_shortcut_exactly() {
        // The same estimate as a static landmark and as a resting walker without velocity
        // uncertainty: odometry and observations move them identically, bit for bit.
        let covariance = Matrix2::new(0.04, 0.01, 0.01, 0.02);
        let at_rest = |model| {
            ObjectFilter::new(
                Point::new(2.0, -0.5),
                covariance,
                Vector::new(0.0, 0.0),
                Matrix2::zeros(),
                model,
            )
        };
        let mut fixed = at_rest(MotionModel::Static { position_noise: 0.0 });
        let mut general =
            at_rest(MotionModel::Walking { velocity_decay: 1.0, acceleration_noise: 0.0 });
        let q = Matrix3::new(4e-4, 1e-5, 0.0, 1e-5, 3e-4, 2e-5, 0.0, 2e-5, 1e-3);
        let z = RangeBearing { range: 2.2, bearing: -0.3, range_sigma: 0.1, bearing_sigma: 0.05 };
        for step in 0..5 {
            let odometry = Odometry { dx: 0.03 * f64::from(step), dy: -0.01, dtheta: 0.02 };
            fixed.predict_odometry(&odometry, &q);
            general.predict_odometry(&odometry, &q);
            assert_eq!(fixed.update(&z), general.update(&z));
            assert_eq!(fixed.position_vector(), general.position_vector());
            assert_eq!(fixed.position_covariance(), general.position_covariance());
        }
    }

    #[test]
    fn a_rolling_object_slows_down_and_stops() {
        let model = MotionModel::Rolling { friction: 0.5, acceleration_noise: 0.0 };
        let mut f = ObjectFilter::new(
            Point::new(0.0, 0.0),
            Matrix2::identity() * 1e-4,
            Vector::new(1.0, 0.0),
            Matrix2::identity() * 1e-4,
            model,
        );
        f.predict_motion(1.0);
        // x = v t - a t^2 / 2 = 1 - 0.25; v = 1 - 0.5.
        assert_relative_eq!(f.position().x, 0.75, epsilon = 1e-12);
        assert_relative_eq!(f.velocity().x, 0.5, epsilon = 1e-12);
        f.predict_motion(5.0);
        // Stops after 1 more second, 0.25 m further.
        assert_relative_eq!(f.position().x, 1.0, epsilon = 1e-12);
        assert_relative_eq!(f.velocity().x, 0.0, epsilon = 1e-12);
    }
}
