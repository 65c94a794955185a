//! Plane geometry with frames in the type: a point in the global frame cannot be mistaken for
//! one relative to the robot. SI units throughout: metres, radians, seconds.
//!
//! - `Global`: the frame of the map the robot localizes in; the application places it (soccer:
//!   the centre of the field, x towards the opponent goal, y to the left).
//! - `Robot`: origin between the robot's feet, x forward, y to the left.

use std::f64::consts::PI;
use std::fmt;
use std::marker::PhantomData;
use std::ops::{Add, Mul, Neg, Sub};

use serde::{Deserialize, Serialize};

/// The global frame: the map's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Global;

/// The robot's own frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Robot;

/// Wraps an angle into (-pi, pi].
pub fn normalize_angle(angle: f64) -> f64 {
    // Most angles are in range already; `%` (a call to fmod) would return them unchanged.
    if angle > -PI && angle <= PI {
        return angle;
    }
    let mut a = angle % (2.0 * PI);
    if a <= -PI {
        a += 2.0 * PI;
    } else if a > PI {
        a -= 2.0 * PI;
    }
    a
}

/// A position in frame `F`.
#[derive(Serialize, Deserialize)]
#[serde(bound = "")]
pub struct Point<F> {
    pub x: f64,
    pub y: f64,
    #[serde(skip)]
    frame: PhantomData<F>,
}

/// A displacement in frame `F`.
#[derive(Serialize, Deserialize)]
#[serde(bound = "")]
pub struct Vector<F> {
    pub x: f64,
    pub y: f64,
    #[serde(skip)]
    frame: PhantomData<F>,
}

macro_rules! xy_common {
    ($name:ident) => {
        impl<F> $name<F> {
            pub const fn new(x: f64, y: f64) -> Self {
                $name { x, y, frame: PhantomData }
            }
            pub fn from_polar(range: f64, angle: f64) -> Self {
                Self::new(range * angle.cos(), range * angle.sin())
            }
            pub fn is_finite(&self) -> bool {
                self.x.is_finite() && self.y.is_finite()
            }
            pub fn as_array(&self) -> [f64; 2] {
                [self.x, self.y]
            }
        }
        impl<F> Clone for $name<F> {
            fn clone(&self) -> Self {
                *self
            }
        }
        impl<F> Copy for $name<F> {}
        impl<F> PartialEq for $name<F> {
            fn eq(&self, other: &Self) -> bool {
                self.x == other.x && self.y == other.y
            }
        }
        impl<F> Default for $name<F> {
            fn default() -> Self {
                Self::new(0.0, 0.0)
            }
        }
        impl<F> fmt::Debug for $name<F> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}({:.3}, {:.3})", stringify!($name), self.x, self.y)
            }
        }
    };
}
xy_common!(Point);
xy_common!(Vector);

impl<F> Point<F> {
    pub const ORIGIN: Point<F> = Point::new(0.0, 0.0);

    pub fn coords(&self) -> Vector<F> {
        Vector::new(self.x, self.y)
    }

    pub fn distance(&self, other: Point<F>) -> f64 {
        (*self - other).norm()
    }

    /// Distance from the frame's origin.
    pub fn range(&self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Direction from the frame's origin (in the robot frame: the bearing).
    pub fn bearing(&self) -> f64 {
        self.y.atan2(self.x)
    }

    pub fn lerp(&self, other: Point<F>, t: f64) -> Point<F> {
        Point::new(self.x + (other.x - self.x) * t, self.y + (other.y - self.y) * t)
    }
}

impl<F> Vector<F> {
    pub fn norm(&self) -> f64 {
        self.x.hypot(self.y)
    }

    pub fn angle(&self) -> f64 {
        self.y.atan2(self.x)
    }

    pub fn dot(&self, other: Vector<F>) -> f64 {
        self.x * other.x + self.y * other.y
    }

    pub fn cross(&self, other: Vector<F>) -> f64 {
        self.x * other.y - self.y * other.x
    }

    pub fn normalized(&self) -> Vector<F> {
        let n = self.norm();
        if n > 0.0 { Vector::new(self.x / n, self.y / n) } else { *self }
    }

    pub fn rotated(&self, angle: f64) -> Vector<F> {
        let (s, c) = angle.sin_cos();
        Vector::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }
}

impl<F> Sub for Point<F> {
    type Output = Vector<F>;
    fn sub(self, rhs: Point<F>) -> Vector<F> {
        Vector::new(self.x - rhs.x, self.y - rhs.y)
    }
}

impl<F> Add<Vector<F>> for Point<F> {
    type Output = Point<F>;
    fn add(self, rhs: Vector<F>) -> Point<F> {
        Point::new(self.x + rhs.x, self.y + rhs.y)
    }
}

impl<F> Sub<Vector<F>> for Point<F> {
    type Output = Point<F>;
    fn sub(self, rhs: Vector<F>) -> Point<F> {
        Point::new(self.x - rhs.x, self.y - rhs.y)
    }
}

impl<F> Add for Vector<F> {
    type Output = Vector<F>;
    fn add(self, rhs: Vector<F>) -> Vector<F> {
        Vector::new(self.x + rhs.x, self.y + rhs.y)
    }
}

impl<F> Sub for Vector<F> {
    type Output = Vector<F>;
    fn sub(self, rhs: Vector<F>) -> Vector<F> {
        Vector::new(self.x - rhs.x, self.y - rhs.y)
    }
}

impl<F> Mul<f64> for Vector<F> {
    type Output = Vector<F>;
    fn mul(self, rhs: f64) -> Vector<F> {
        Vector::new(self.x * rhs, self.y * rhs)
    }
}

impl<F> Neg for Vector<F> {
    type Output = Vector<F>;
    fn neg(self) -> Vector<F> {
        Vector::new(-self.x, -self.y)
    }
}

/// A robot's pose in the field frame: where it stands and where it faces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    /// Heading, in (-pi, pi].
    pub theta: f64,
}

impl Pose {
    pub fn new(x: f64, y: f64, theta: f64) -> Pose {
        Pose { x, y, theta: normalize_angle(theta) }
    }

    pub fn position(&self) -> Point<Global> {
        Point::new(self.x, self.y)
    }

    /// Where a field point appears relative to this robot.
    pub fn to_robot(&self, point: Point<Global>) -> Point<Robot> {
        let (s, c) = self.theta.sin_cos();
        let dx = point.x - self.x;
        let dy = point.y - self.y;
        Point::new(c * dx + s * dy, -s * dx + c * dy)
    }

    /// Where a point seen by this robot lies on the field.
    pub fn to_global(&self, point: Point<Robot>) -> Point<Global> {
        let (s, c) = self.theta.sin_cos();
        Point::new(self.x + c * point.x - s * point.y, self.y + s * point.x + c * point.y)
    }

    pub fn vector_to_global(&self, v: Vector<Robot>) -> Vector<Global> {
        let r = v.rotated(self.theta);
        Vector::new(r.x, r.y)
    }

    pub fn vector_to_robot(&self, v: Vector<Global>) -> Vector<Robot> {
        let r = v.rotated(-self.theta);
        Vector::new(r.x, r.y)
    }

    /// The pose after moving by `step`, expressed in this pose's own frame (odometry).
    pub fn moved(&self, step: Odometry) -> Pose {
        let p = self.to_global(Point::new(step.dx, step.dy));
        Pose::new(p.x, p.y, self.theta + step.dtheta)
    }

    /// The motion that takes `self` to `other`, in `self`'s frame.
    pub fn odometry_to(&self, other: &Pose) -> Odometry {
        let p = self.to_robot(other.position());
        Odometry { dx: p.x, dy: p.y, dtheta: normalize_angle(other.theta - self.theta) }
    }

    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

/// A motion of the robot, expressed in the frame where it started: what odometry reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub dx: f64,
    pub dy: f64,
    pub dtheta: f64,
}

impl Odometry {
    pub const ZERO: Odometry = Odometry { dx: 0.0, dy: 0.0, dtheta: 0.0 };

    /// `self` followed by `next` (what the `Merge` connection of odometry computes): the
    /// increments compose as rigid motions, they do not simply add component-wise.
    pub fn then(self, next: Odometry) -> Odometry {
        let (s, c) = self.dtheta.sin_cos();
        Odometry {
            dx: self.dx + c * next.dx - s * next.dy,
            dy: self.dy + s * next.dx + c * next.dy,
            dtheta: normalize_angle(self.dtheta + next.dtheta),
        }
    }

    /// Where a point fixed in the world, seen at `point` before the motion, is seen after it.
    pub fn transform_point(&self, point: Point<Robot>) -> Point<Robot> {
        let (s, c) = self.dtheta.sin_cos();
        let dx = point.x - self.dx;
        let dy = point.y - self.dy;
        Point::new(c * dx + s * dy, -s * dx + c * dy)
    }

    pub fn is_finite(&self) -> bool {
        self.dx.is_finite() && self.dy.is_finite() && self.dtheta.is_finite()
    }
}

/// A commanded or measured walking velocity, in the robot frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Velocity {
    /// Forward, m/s.
    pub vx: f64,
    /// Left, m/s.
    pub vy: f64,
    /// Counter-clockwise, rad/s.
    pub omega: f64,
}

impl Velocity {
    pub const ZERO: Velocity = Velocity { vx: 0.0, vy: 0.0, omega: 0.0 };

    pub fn new(vx: f64, vy: f64, omega: f64) -> Velocity {
        Velocity { vx, vy, omega }
    }

    pub fn is_zero(&self) -> bool {
        self.vx == 0.0 && self.vy == 0.0 && self.omega == 0.0
    }

    pub fn is_finite(&self) -> bool {
        self.vx.is_finite() && self.vy.is_finite() && self.omega.is_finite()
    }
}

/// A circle on the field (the centre circle, a robot's footprint).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Circle<F> {
    #[serde(bound = "")]
    pub center: Point<F>,
    pub radius: f64,
}

/// A segment (a field line).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment<F> {
    #[serde(bound = "")]
    pub start: Point<F>,
    #[serde(bound = "")]
    pub end: Point<F>,
}

impl<F> Segment<F> {
    pub fn new(start: Point<F>, end: Point<F>) -> Segment<F> {
        Segment { start, end }
    }

    pub fn length(&self) -> f64 {
        self.start.distance(self.end)
    }

    pub fn closest_point(&self, p: Point<F>) -> Point<F> {
        let d = self.end - self.start;
        let len2 = d.dot(d);
        if len2 <= 0.0 {
            return self.start;
        }
        let t = ((p - self.start).dot(d) / len2).clamp(0.0, 1.0);
        self.start + d * t
    }

    pub fn distance_to(&self, p: Point<F>) -> f64 {
        self.closest_point(p).distance(p)
    }

    /// The parameter along `self` at which it crosses `other`, if they intersect.
    pub fn intersection(&self, other: &Segment<F>) -> Option<Point<F>> {
        let r = self.end - self.start;
        let s = other.end - other.start;
        let denom = r.cross(s);
        if denom.abs() < 1e-12 {
            return None;
        }
        let q = other.start - self.start;
        let t = q.cross(s) / denom;
        let u = q.cross(r) / denom;
        ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then(|| self.start + r * t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn normalize_wraps_into_half_open_interval() {
        assert_relative_eq!(normalize_angle(3.0 * PI), PI);
        assert_relative_eq!(normalize_angle(-PI), PI);
        assert_relative_eq!(normalize_angle(0.5), 0.5);
        assert_relative_eq!(normalize_angle(-2.0 * PI - 0.1), -0.1, epsilon = 1e-12);
        // The in-range shortcut returns exactly what the remainder would.
        for k in -1000..=1000 {
            let a = f64::from(k) * PI / 1000.0 + 1e-9;
            if a > -PI && a <= PI {
                assert_eq!(normalize_angle(a).to_bits(), (a % (2.0 * PI)).to_bits());
            }
        }
        assert_eq!(normalize_angle(-0.0).to_bits(), (-0.0f64).to_bits());
    }

    #[test]
    fn field_and_robot_frames_are_inverse() {
        let pose = Pose::new(1.0, -2.0, 0.7);
        let p = Point::<Global>::new(3.0, 0.5);
        let back = pose.to_global(pose.to_robot(p));
        assert_relative_eq!(back.x, p.x, epsilon = 1e-12);
        assert_relative_eq!(back.y, p.y, epsilon = 1e-12);
        // A robot at the origin facing +y sees a point at (0, 1) straight ahead.
        let facing_left = Pose::new(0.0, 0.0, PI / 2.0);
        let ahead = facing_left.to_robot(Point::new(0.0, 1.0));
        assert_relative_eq!(ahead.x, 1.0, epsilon = 1e-12);
        assert_relative_eq!(ahead.y, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn odometry_composes_like_poses() {
        let start = Pose::new(0.5, 0.5, 0.3);
        let a = Odometry { dx: 0.2, dy: 0.1, dtheta: 0.4 };
        let b = Odometry { dx: -0.1, dy: 0.3, dtheta: -1.0 };
        let stepwise = start.moved(a).moved(b);
        let merged = start.moved(a.then(b));
        assert_relative_eq!(stepwise.x, merged.x, epsilon = 1e-12);
        assert_relative_eq!(stepwise.y, merged.y, epsilon = 1e-12);
        assert_relative_eq!(stepwise.theta, merged.theta, epsilon = 1e-12);
        let o = start.odometry_to(&stepwise);
        let again = start.moved(o);
        assert_relative_eq!(again.x, stepwise.x, epsilon = 1e-12);
    }

    #[test]
    fn a_fixed_point_moves_opposite_to_the_robot() {
        let step = Odometry { dx: 1.0, dy: 0.0, dtheta: 0.0 };
        let seen = step.transform_point(Point::new(2.0, 0.0));
        assert_relative_eq!(seen.x, 1.0);
        let turn = Odometry { dx: 0.0, dy: 0.0, dtheta: PI / 2.0 };
        let seen = turn.transform_point(Point::new(1.0, 0.0));
        assert_relative_eq!(seen.x, 0.0, epsilon = 1e-12);
        assert_relative_eq!(seen.y, -1.0, epsilon = 1e-12);
    }

    #[test]
    fn segments_intersect_and_project() {
        let a = Segment::<Global>::new(Point::new(0.0, 0.0), Point::new(2.0, 0.0));
        let b = Segment::<Global>::new(Point::new(1.0, -1.0), Point::new(1.0, 1.0));
        let x = a.intersection(&b).map(|p| (p.x, p.y));
        assert_eq!(x, Some((1.0, 0.0)));
        assert_relative_eq!(a.distance_to(Point::new(3.0, 1.0)), 2f64.sqrt());
    }
}
