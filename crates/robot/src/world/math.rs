//! The small pieces of Gaussian algebra every filter of the world model shares: the
//! range/bearing measurement model, the Joseph-form update and chi-square gates.

use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

/// Observations closer than this are treated as if they were this far: the bearing Jacobian
/// grows as 1/range and would otherwise make one noisy close observation overwhelm a filter.
pub(crate) const MIN_RANGE: f64 = 0.05;

/// A range/bearing measurement of a point in the robot frame, with its standard deviations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeBearing {
    pub range: f64,
    pub bearing: f64,
    pub range_sigma: f64,
    pub bearing_sigma: f64,
}

impl RangeBearing {
    pub fn noise(&self) -> Matrix2<f64> {
        Matrix2::new(self.range_sigma.powi(2), 0.0, 0.0, self.bearing_sigma.powi(2))
    }

    pub fn vector(&self) -> Vector2<f64> {
        Vector2::new(self.range, self.bearing)
    }

    /// The measured point in the robot frame.
    pub fn cartesian(&self) -> Vector2<f64> {
        Vector2::new(self.range * self.bearing.cos(), self.range * self.bearing.sin())
    }

    /// The measurement noise expressed in the robot frame (first order, at the measured point).
    pub fn cartesian_noise(&self) -> Matrix2<f64> {
        let j = polar_to_cartesian_jacobian(self.range.max(MIN_RANGE), self.bearing);
        symmetrize2(j * self.noise() * j.transpose())
    }

    pub fn is_valid(&self) -> bool {
        self.range.is_finite()
            && self.range >= 0.0
            && self.bearing.is_finite()
            && self.range_sigma.is_finite()
            && self.range_sigma > 0.0
            && self.bearing_sigma.is_finite()
            && self.bearing_sigma > 0.0
    }
}

/// Range and bearing of `p`, and their Jacobian with respect to `p`.
pub(crate) fn polar(p: Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
    let r = p.norm().max(MIN_RANGE);
    let b = p.y.atan2(p.x);
    let (s, c) = b.sin_cos();
    let h = Matrix2::new(c, s, -s / r, c / r);
    (Vector2::new(p.norm(), b), h)
}

/// d(x, y)/d(range, bearing): the inverse of the polar Jacobian.
pub(crate) fn polar_to_cartesian_jacobian(range: f64, bearing: f64) -> Matrix2<f64> {
    let (s, c) = bearing.sin_cos();
    Matrix2::new(c, -range * s, s, range * c)
}

pub(crate) fn symmetrize2(m: Matrix2<f64>) -> Matrix2<f64> {
    (m + m.transpose()) * 0.5
}

pub(crate) fn symmetrize<const N: usize>(m: SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
    (m + m.transpose()) * 0.5
}

/// Normalized innovation squared `nu^T S^-1 nu`; `None` when `S` is not invertible.
pub(crate) fn nis(nu: &Vector2<f64>, s: &Matrix2<f64>) -> Option<f64> {
    let inv = s.try_inverse()?;
    let d = (nu.transpose() * inv * nu)[(0, 0)];
    d.is_finite().then_some(d)
}

/// The chi-square quantile with two degrees of freedom, in closed form.
pub fn chi2_2dof_quantile(probability: f64) -> f64 {
    -2.0 * (1.0 - probability.clamp(0.0, 1.0 - 1e-12)).ln()
}

/// The result of one Kalman update, for gating and diagnostics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation {
    /// `z - h(x)` (bearing wrapped).
    pub nu: Vector2<f64>,
    /// Innovation covariance.
    pub s: Matrix2<f64>,
    /// Normalized innovation squared.
    pub nis: f64,
}

impl Innovation {
    /// Negative log-likelihood up to a constant: what association compares between candidates
    /// of different uncertainty (a vague candidate must not win just by being vague).
    pub fn cost(&self) -> f64 {
        self.nis + self.s.determinant().max(1e-300).ln()
    }
}

/// A Kalman update with a 2-D measurement, in Joseph form (keeps `P` symmetric and positive
/// even when the gain is computed from a badly conditioned `S`). Returns `None`, leaving the
/// state untouched, when `S` is not invertible.
pub(crate) fn joseph_update<const N: usize>(
    x: &mut SVector<f64, N>,
    p: &mut SMatrix<f64, N, N>,
    h: &SMatrix<f64, 2, N>,
    nu: Vector2<f64>,
    r: &Matrix2<f64>,
) -> Option<Innovation> {
    let pht = *p * h.transpose();
    let s = symmetrize2(h * pht + r);
    let s_inv = s.try_inverse()?;
    let k = pht * s_inv;
    let nis = (nu.transpose() * s_inv * nu)[(0, 0)];
    if !nis.is_finite() {
        return None;
    }
    *x += k * nu;
    let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
    *p = symmetrize(i_kh * *p * i_kh.transpose() + k * r * k.transpose());
    Some(Innovation { nu, s, nis })
}

/// The posterior covariance a [`joseph_update`] would produce, without a measurement value.
pub(crate) fn posterior_covariance<const N: usize>(
    p: &SMatrix<f64, N, N>,
    h: &SMatrix<f64, 2, N>,
    r: &Matrix2<f64>,
) -> Option<SMatrix<f64, N, N>> {
    let pht = *p * h.transpose();
    let s = symmetrize2(h * pht + r);
    let k = pht * s.try_inverse()?;
    let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
    Some(symmetrize(i_kh * *p * i_kh.transpose() + k * r * k.transpose()))
}

/// `sqrt(det(P))^(1/2)`: the radius of the circle with the area of the 1-sigma ellipse.
pub(crate) fn sigma_radius(p: &Matrix2<f64>) -> f64 {
    p.determinant().max(0.0).sqrt().sqrt()
}

/// The larger standard deviation of a 2-D covariance (its major semi-axis).
pub(crate) fn major_sigma(p: &Matrix2<f64>) -> f64 {
    let tr = p[(0, 0)] + p[(1, 1)];
    let det = p.determinant();
    let disc = (tr * tr / 4.0 - det).max(0.0).sqrt();
    (tr / 2.0 + disc).max(0.0).sqrt()
}

/// A cheap test that a point is outside a view cone's bearing limits whatever margin (at least
/// `min_margin`) the exact test ([`ViewCone::contains_polar`]) uses: negative information asks
/// every unobserved filter, most of them are well outside the image, and this spares them the
/// bearing's `atan2` and `sin_cos`. One `sin_cos` per image instead.
///
/// Conservative: a point it calls outside is more than [`BearingBound::SLACK`] beyond the
/// widest accepted bearing, far more than the rounding of either test, so the exact test would
/// reject it too; points near the limit are left to the exact test.
///
/// [`ViewCone::contains_polar`]: crate::percept::ViewCone::contains_polar
#[derive(Clone, Copy, Debug)]
pub(crate) struct BearingBound {
    /// The optical axis as a unit vector.
    axis: Vector2<f64>,
    /// Cosine of the widest bearing off the axis that can be accepted, plus the slack; `None`
    /// when that reaches all around (nothing is certainly outside).
    cos_limit: Option<f64>,
}

impl BearingBound {
    /// Angular slack, rad: rounding of `atan2`, the angle's normalization and the dot product
    /// below stays under 1e-7 rad even where the cosine is flat.
    pub const SLACK: f64 = 1e-6;

    pub fn new(view: &crate::percept::ViewCone, min_margin: f64) -> BearingBound {
        // The exact test accepts |bearing - direction| <= max(fov / 2 - margin, 0), which only
        // shrinks as the margin grows.
        let limit = (view.fov / 2.0 - min_margin).max(0.0) + Self::SLACK;
        let (s, c) = view.direction.sin_cos();
        let cos_limit = (limit < std::f64::consts::PI).then(|| limit.cos());
        BearingBound { axis: Vector2::new(c, s), cos_limit }
    }

    /// Whether `p`, at distance `range` (its norm, > 0), is certainly outside the cone's
    /// bearing limits. NaN anywhere answers `false`.
    pub fn certainly_outside(&self, p: Vector2<f64>, range: f64) -> bool {
        // The angle off the axis exceeds the limit exactly when its cosine is below the
        // limit's (both in [0, pi]).
        self.cos_limit.is_some_and(|cos_limit| p.dot(&self.axis) < range * cos_limit)
    }
}

/// The rotation matrix of angle `a`.
pub(crate) fn rotation(a: f64) -> Matrix2<f64> {
    let (s, c) = a.sin_cos();
    Matrix2::new(c, -s, s, c)
}

pub(crate) fn all_finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn polar_jacobian_inverts_the_cartesian_one() {
        let p = Vector2::new(1.5, -0.7);
        let (z, h) = polar(p);
        let j = polar_to_cartesian_jacobian(z.x, z.y);
        let product = h * j;
        assert_relative_eq!(product, Matrix2::identity(), epsilon = 1e-12);
    }

    #[test]
    fn chi2_two_dof_matches_tables() {
        assert_relative_eq!(chi2_2dof_quantile(0.95), 5.991, epsilon = 1e-3);
        assert_relative_eq!(chi2_2dof_quantile(0.99), 9.210, epsilon = 1e-3);
    }

    #[test]
    fn the_bearing_bound_never_rejects_what_the_view_cone_accepts() {
        use crate::percept::ViewCone;
        let view_margin = 0.1;
        let mut outside = 0;
        let mut total = 0;
        for (direction, fov) in
            [(0.0, 1.06), (0.7, 1.06), (-2.9, 1.06), (3.1, 2.0), (1.0, 0.2), (0.0, 6.5)]
        {
            let view = ViewCone { direction, fov, range: 8.0, near: 0.0 };
            let bound = BearingBound::new(&view, view_margin);
            let limit = (fov / 2.0 - view_margin).max(0.0);
            // Points all around, and bearings right at the widest accepted one.
            let mut bearings: Vec<f64> =
                (0..720).map(|i| f64::from(i) * 0.5f64.to_radians()).collect();
            for side in [-1.0, 1.0] {
                for eps in [0.0, 1e-15, 1e-12, 1e-9, 1e-7, 1e-6, 2e-6, 1e-3] {
                    bearings.push(direction + side * (limit + eps));
                    bearings.push(direction + side * (limit - eps));
                }
            }
            for b in bearings {
                for r in [0.2, 1.0, 3.7, 7.9] {
                    let p = Vector2::new(r * b.cos(), r * b.sin());
                    let point = crate::geometry::Point::<crate::geometry::Robot>::new(p.x, p.y);
                    total += 1;
                    if !bound.certainly_outside(p, p.norm()) {
                        continue;
                    }
                    outside += 1;
                    for margin in [view_margin, view_margin + 1e-12, 0.3, f64::INFINITY] {
                        assert!(!view.contains(point, margin), "{direction} {fov} {b} {r}");
                    }
                }
            }
        }
        // And it does spare most points of a narrow camera.
        assert!(outside * 2 > total, "{outside} of {total}");
        let nan =
            BearingBound::new(&ViewCone { direction: 0.0, fov: 1.0, range: 8.0, near: 0.0 }, 0.1);
        assert!(!nan.certainly_outside(Vector2::new(f64::NAN, 1.0), f64::NAN));
    }

    #[test]
    fn major_sigma_of_a_diagonal_covariance() {
        let p = Matrix2::new(4.0, 0.0, 0.0, 1.0);
        assert_relative_eq!(major_sigma(&p), 2.0, epsilon = 1e-12);
        assert_relative_eq!(sigma_radius(&p), 2f64.sqrt(), epsilon = 1e-12);
    }
}
