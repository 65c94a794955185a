//! Perception simulation: the detections a robot's camera delivers, like HL-SIM's simulated
//! vision. Objects are reported only inside the horizontal field of view, within range and the
//! vertical coverage the head pitch gives, when no robot stands in the line of sight; range and
//! bearing carry noise that grows with distance; detection probability falls with distance and
//! with head speed (motion blur); an image may contain a false positive.
//!
//! Detections are relative to the camera: `range` is the ground distance from the robot,
//! `bearing` the angle from the optical axis (the head yaw), left positive.

use strata_robot::platform::{Detection, HeadAngles, ObjectClass};
use strata_robot::{Field as FieldFrame, Point, Pose};
use strata_spl::field::{Colour, Landmark, Side};
use strata_spl::{Field, ObjectKind};

use crate::config::CameraConfig;
use crate::noise::CameraNoise;
use crate::random::Stream;
use crate::util::{atan2, length, sin_cos, wrap_half_turn};

/// What the camera reports about a fixed point feature.
#[derive(Clone, Copy, Debug)]
struct PointFeature {
    class: ObjectClass,
    variant: Option<u16>,
    /// Orientation in the field frame (line crossings).
    orientation: Option<f64>,
    /// Sticks up from the ground: seen above the lower edge of the image.
    tall: bool,
}

/// The static part of what cameras can see: the field's landmarks and lines, stored as columns
/// so transforming them into a camera's frame is one vectorizable loop.
#[derive(Clone, Debug)]
pub(crate) struct Scene {
    /// Point features' positions, then the lines' start points, then their end points.
    xs: Vec<f64>,
    ys: Vec<f64>,
    points: Vec<PointFeature>,
    /// Direction of each line in the field frame.
    lines: Vec<f64>,
}

fn class(kind: ObjectKind) -> ObjectClass {
    ObjectClass(kind.code())
}

impl Scene {
    pub fn new(field: &Field) -> Scene {
        let colours = field.dimensions().goal_colours;
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        let mut points = Vec::new();
        for landmark in field.landmarks() {
            let p = landmark.position();
            xs.push(p.x);
            ys.push(p.y);
            let mut feature = PointFeature {
                class: class(landmark.object_kind()),
                variant: None,
                orientation: None,
                tall: false,
            };
            match landmark {
                Landmark::GoalPost { goal, .. } => {
                    let colour = match goal {
                        Side::Own => colours.own,
                        Side::Opponent => colours.opponent,
                    };
                    // White posts look alike; coloured ones tell their goal apart.
                    feature.variant = (colour != Colour::White).then(|| colour.code());
                    feature.tall = true;
                }
                Landmark::Crossing { orientation, .. } => {
                    feature.orientation = Some(*orientation);
                }
                Landmark::Beacon { index, .. } => {
                    feature.variant = Some(u16::try_from(*index).unwrap_or(u16::MAX));
                    feature.tall = true;
                }
                Landmark::CenterCircle { .. } | Landmark::PenaltyMark { .. } => {}
            }
            points.push(feature);
        }
        let lines: Vec<_> = field.lines().to_vec();
        xs.extend(lines.iter().map(|l| l.start.x));
        ys.extend(lines.iter().map(|l| l.start.y));
        xs.extend(lines.iter().map(|l| l.end.x));
        ys.extend(lines.iter().map(|l| l.end.y));
        let lines =
            lines.iter().map(|l| (l.end.y - l.start.y).atan2(l.end.x - l.start.x)).collect();
        Scene { xs, ys, points, lines }
    }
}

/// Another robot as a camera sees it: something to detect and something that hides.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RobotMark {
    pub position: Point<FieldFrame>,
    /// Jersey colour code.
    pub variant: u16,
}

/// The robot taking the image.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Viewer {
    pub pose: Pose,
    /// Sine and cosine of the camera's direction (heading plus head yaw).
    pub axis: (f64, f64),
    pub head: HeadAngles,
    /// Head angular speed, rad/s (motion blur).
    pub head_rate: f64,
    /// Its own index among the robot marks (it does not see or hide behind itself).
    pub index: Option<usize>,
    /// Lying, falling or getting up: the camera sees the sky or the carpet.
    pub blind: bool,
    /// The ground distances the camera covers at the head's pitch ([`ground_band`]).
    pub band: (f64, f64),
}

/// An object in the camera frame: x along the optical axis, y to the left.
#[derive(Clone, Copy, Debug)]
struct Local {
    x: f64,
    y: f64,
    distance: f64,
}

impl Local {
    fn new(x: f64, y: f64) -> Local {
        Local { x, y, distance: length(x, y) }
    }
}

/// Reusable buffers, so taking an image allocates nothing in the steady state.
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    occluders: Vec<Local>,
    seen: Vec<(Local, u16)>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    left: Vec<f64>,
    right: Vec<f64>,
    seen_points: Vec<u64>,
    seen_lines: Vec<u64>,
}

/// Sets `mask` to the bits `i < n` for which `keep(i)`, 64 per word, without branches.
#[inline]
fn bitmask(mask: &mut Vec<u64>, n: usize, keep: impl Fn(usize) -> bool) {
    mask.clear();
    mask.resize(n.div_ceil(64), 0);
    for i in 0..n {
        mask[i / 64] |= u64::from(keep(i)) << (i % 64);
    }
}

/// The indices of the set bits, ascending.
#[inline]
fn set_bits(mask: &[u64]) -> impl Iterator<Item = usize> + '_ {
    mask.iter().enumerate().flat_map(|(word, &bits)| {
        let mut bits = bits;
        std::iter::from_fn(move || {
            (bits != 0).then(|| {
                let bit = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                word * 64 + bit
            })
        })
    })
}

pub(crate) struct Camera<'a> {
    pub config: &'a CameraConfig,
    pub noise: &'a CameraNoise,
    pub robot_radius: f64,
    /// tan(fov / 2).
    pub tan_half: f64,
}

impl<'a> Camera<'a> {
    pub fn new(config: &'a CameraConfig, noise: &'a CameraNoise, robot_radius: f64) -> Camera<'a> {
        Camera { config, noise, robot_radius, tan_half: (config.fov / 2.0).tan() }
    }
}

impl Camera<'_> {
    /// Appends the detections of one image to `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn capture(
        &self,
        scene: &Scene,
        viewer: &Viewer,
        robots: &[Option<RobotMark>],
        ball: Option<Point<FieldFrame>>,
        rng: &mut Stream,
        scratch: &mut Scratch,
        out: &mut Vec<Detection>,
    ) {
        if viewer.blind {
            return;
        }
        let config = self.config;
        let axis = viewer.pose.theta + viewer.head.yaw;
        let (sin, cos) = viewer.axis;
        let (ox, oy) = (viewer.pose.x, viewer.pose.y);
        let to_local = |p: Point<FieldFrame>| {
            let dx = p.x - ox;
            let dy = p.y - oy;
            (cos * dx + sin * dy, -sin * dx + cos * dy)
        };
        let tan_half = self.tan_half;
        let range = config.range;
        let range2 = range * range;
        let in_view =
            |x: f64, y: f64| x > 0.0 && y.abs() <= x * tan_half && x * x + y * y <= range2;
        let (near, far) = viewer.band;

        // Robots in or beside the view can hide what is behind them; those in it are seen.
        let radius = self.robot_radius;
        let beside = radius * (1.0 + tan_half * tan_half).sqrt();
        scratch.occluders.clear();
        scratch.seen.clear();
        for (i, mark) in robots.iter().enumerate() {
            let Some(mark) = mark else { continue };
            if Some(i) == viewer.index {
                continue;
            }
            let (x, y) = to_local(mark.position);
            if x > -radius && y.abs() <= x * tan_half + beside && x * x + y * y < range2 {
                let local = Local::new(x, y);
                scratch.occluders.push(local);
                if in_view(x, y) && local.distance >= near {
                    scratch.seen.push((local, mark.variant));
                }
            }
        }
        let occluders = &scratch.occluders;
        let hidden = |target: &Local| {
            occluders.iter().any(|o| {
                o.distance < target.distance - radius
                    && o.x * target.x + o.y * target.y > 0.0
                    && (o.x * target.y - o.y * target.x).abs() < radius * target.distance
            })
        };

        let noise = self.noise;
        let blur = (1.0 - noise.motion_blur_per_rad_s * viewer.head_rate).max(0.0);
        let probability = |distance: f64, factor: f64| {
            let t = (distance / range).clamp(0.0, 1.0);
            (noise.detection_near + (noise.detection_far - noise.detection_near) * t)
                * factor
                * blur
        };
        let report = |rng: &mut Stream,
                      out: &mut Vec<Detection>,
                      class: ObjectClass,
                      variant: Option<u16>,
                      local: &Local,
                      orientation: Option<f64>,
                      factor: f64| {
            if !rng.chance(probability(local.distance, factor)) {
                return;
            }
            let range_sigma = noise.range_sigma + noise.range_sigma_per_metre * local.distance;
            let bearing_sigma =
                noise.bearing_sigma + noise.bearing_sigma_per_metre * local.distance;
            let range = (local.distance + rng.gauss(range_sigma)).max(0.0);
            let bearing = atan2(local.y, local.x) + rng.gauss(bearing_sigma);
            let orientation = orientation.map(|o| o + rng.gauss(noise.orientation_sigma));
            out.push(Detection { class, variant, range, bearing, orientation });
        };

        if let Some(ball) = ball {
            let (x, y) = to_local(ball);
            if in_view(x, y) {
                let local = Local::new(x, y);
                if local.distance >= near && local.distance <= far && !hidden(&local) {
                    report(rng, out, class(ObjectKind::Ball), None, &local, None, 1.0);
                }
            }
        }
        for (local, variant) in &scratch.seen {
            if !hidden(local) {
                report(rng, out, class(ObjectKind::Robot), Some(*variant), local, None, 1.0);
            }
        }

        // Every fixed point and line end into the camera frame at once, with its side of the
        // two edges of the view (inside both: `left >= 0` and `right >= 0`), in one
        // vectorizable loop.
        let n = scene.xs.len();
        scratch.xs.resize(n, 0.0);
        scratch.ys.resize(n, 0.0);
        scratch.left.resize(n, 0.0);
        scratch.right.resize(n, 0.0);
        // Slices of one length: no bounds checks, so the loop vectorizes.
        let (xs, ys) = (&mut scratch.xs[..n], &mut scratch.ys[..n]);
        let (left, right) = (&mut scratch.left[..n], &mut scratch.right[..n]);
        let (px, py) = (&scene.xs[..n], &scene.ys[..n]);
        for i in 0..n {
            let dx = px[i] - ox;
            let dy = py[i] - oy;
            let x = cos * dx + sin * dy;
            let y = -sin * dx + cos * dy;
            xs[i] = x;
            ys[i] = y;
            left[i] = x * tan_half - y;
            right[i] = x * tan_half + y;
        }
        let landmark = noise.landmark_factor;
        let points = scene.points.len();
        // Which points are in the view, as bits: deciding per point with a branch mispredicts
        // about every other point, a bitmask built without branches does not.
        bitmask(&mut scratch.seen_points, points, |i| {
            (left[i] >= 0.0) & (right[i] >= 0.0) & (xs[i] * xs[i] + ys[i] * ys[i] <= range2)
        });
        for i in set_bits(&scratch.seen_points) {
            let feature = &scene.points[i];
            let (x, y) = (xs[i], ys[i]);
            if x <= 0.0 {
                continue;
            }
            let local = Local::new(x, y);
            if local.distance < near || (!feature.tall && local.distance > far) || hidden(&local) {
                continue;
            }
            let orientation = feature.orientation.map(|o| wrap_relative(o - axis));
            report(rng, out, feature.class, feature.variant, &local, orientation, landmark);
        }
        let line_class = class(ObjectKind::FieldLine);
        let lines = scene.lines.len();
        let (starts, ends) = (points, points + lines);
        // A line with both ends beyond the same edge of the view has nothing in it.
        bitmask(&mut scratch.seen_lines, lines, |i| {
            let (a, b) = (starts + i, ends + i);
            !(((left[a] < 0.0) & (left[b] < 0.0)) | ((right[a] < 0.0) & (right[b] < 0.0)))
        });
        for i in set_bits(&scratch.seen_lines) {
            let (a, b) = (starts + i, ends + i);
            let Some(closest) =
                visible_piece((xs[a], ys[a]), (xs[b], ys[b]), tan_half, config.min_line_length)
            else {
                continue;
            };
            if closest.distance > range.min(far) || hidden(&closest) {
                continue;
            }
            let orientation = Some(wrap_half_turn(scene.lines[i] - axis));
            report(rng, out, line_class, None, &closest, orientation, landmark);
        }

        if rng.chance(noise.false_positive_rate) {
            const GHOSTS: [ObjectKind; 6] = [
                ObjectKind::Ball,
                ObjectKind::Ball,
                ObjectKind::Robot,
                ObjectKind::GoalPost,
                ObjectKind::LCrossing,
                ObjectKind::TCrossing,
            ];
            let pick = rng.uniform(0.0, GHOSTS.len() as f64) as usize;
            let kind = GHOSTS[pick.min(GHOSTS.len() - 1)];
            let range = rng.uniform(0.3, config.range);
            let bearing = rng.uniform(-config.fov / 2.0, config.fov / 2.0);
            let orientation = matches!(kind, ObjectKind::LCrossing | ObjectKind::TCrossing)
                .then(|| rng.uniform(-std::f64::consts::PI, std::f64::consts::PI));
            out.push(Detection { class: class(kind), variant: None, range, bearing, orientation });
        }
    }
}

fn wrap_relative(angle: f64) -> f64 {
    strata_robot::normalize_angle(angle)
}

/// The ground distances the camera covers at head pitch `pitch`: [near, far].
pub(crate) fn ground_band(config: &CameraConfig, pitch: f64) -> (f64, f64) {
    let tan = |a: f64| {
        let (s, c) = sin_cos(a);
        s / c
    };
    let lower = pitch + config.min_depression;
    let upper = pitch + config.max_depression;
    let far = if lower > 1e-6 { config.height / tan(lower) } else { f64::INFINITY };
    let near = if upper < std::f64::consts::FRAC_PI_2 - 1e-6 {
        (config.height / tan(upper)).max(0.0)
    } else {
        0.0
    };
    (near, far)
}

/// Clips a segment (camera frame) to the horizontal field of view; returns the point of the
/// visible piece nearest to the camera, if the piece is long enough.
fn visible_piece(a: (f64, f64), b: (f64, f64), tan_half: f64, min_length: f64) -> Option<Local> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    // Inside the wedge: x * tan_half - y >= 0 and x * tan_half + y >= 0.
    for sign in [-1.0, 1.0] {
        let ha = a.0 * tan_half + sign * a.1;
        let hb = b.0 * tan_half + sign * b.1;
        if ha < 0.0 && hb < 0.0 {
            return None;
        }
        if ha < 0.0 {
            t0 = t0.max(ha / (ha - hb));
        } else if hb < 0.0 {
            t1 = t1.min(ha / (ha - hb));
        }
    }
    if t1 <= t0 {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    if len2 * (t1 - t0) * (t1 - t0) < min_length * min_length {
        return None;
    }
    let t = if len2 > 0.0 { (-(a.0 * dx + a.1 * dy) / len2).clamp(t0, t1) } else { t0 };
    let x = a.0 + dx * t;
    let y = a.1 + dy * t;
    // Both wedge edges meet at the camera: a piece through it has no direction to report.
    (x > 1e-6).then(|| Local::new(x, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_across_the_view_is_seen_at_its_nearest_point() {
        let tan_half = 0.5f64;
        let piece =
            visible_piece((2.0, -5.0), (2.0, 5.0), tan_half, 0.1).expect("crosses the view");
        assert!((piece.x - 2.0).abs() < 1e-12 && piece.y.abs() < 1e-12);
        // Beside the wedge on both ends.
        assert!(visible_piece((1.0, 2.0), (3.0, 4.0), tan_half, 0.1).is_none());
        // Behind the camera.
        assert!(visible_piece((-1.0, -1.0), (-1.0, 1.0), tan_half, 0.1).is_none());
    }

    #[test]
    fn head_pitch_moves_the_visible_band() {
        let config = CameraConfig::default();
        let (near, far) = ground_band(&config, 0.0);
        assert!(far.is_infinite() && near > 0.1 && near < 0.5, "{near}");
        let (near, far) = ground_band(&config, 0.5);
        assert_eq!(near, 0.0);
        assert!(far > 2.0 && far < 10.0, "{far}");
    }
}
