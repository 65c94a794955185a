//! The camera model the platform puts between the server's ideal vision and the robot.
//!
//! rcssservermj sees every marker within +-60 degrees both ways, exactly (to 0.01 m and 0.01
//! degrees), at any distance and through other robots. A real head camera sees less, and worse:
//! a narrower field of view, detectors that miss small things far away, range estimates that
//! come from projecting a pixel on the ground and so grow worse with distance, and robots in
//! the way. [`CameraModel`] applies all of that, seeded, before perception sees a detection.
//! The defaults describe a wide-angle head camera (87 x 58 degrees, like the stereo camera in
//! the T1's head) with a detector of RoboCup quality; `CameraConfig::ideal` switches it off.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use strata_robot::platform::{Detection, Footprint, ObjectClass};

use crate::kinematics::{CameraPose, polar_to_camera};

/// What one kind of object looks like to the detector.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectorRange {
    /// Beyond this ground distance the object is never detected, m.
    pub max_range: f64,
    /// Detection probability up close; it falls linearly to `far_probability` at `max_range`.
    pub near_probability: f64,
    pub far_probability: f64,
}

/// How far inside the image's upper and lower edges an object must be to count as surely in
/// view, degrees: objects at the border are often missed without being absent.
const EDGE_MARGIN_DEG: f64 = 3.0;

/// The camera and detector the platform simulates on top of the server's ideal vision.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Horizontal field of view, degrees (the server's is 120).
    pub horizontal_fov_deg: f64,
    /// Vertical field of view, degrees (the server's is 120).
    pub vertical_fov_deg: f64,
    /// Range noise: standard deviation `range_sigma_fraction * d + range_sigma_quadratic * d^2`,
    /// m (the error of a ground projection grows with the square of the distance).
    pub range_sigma_fraction: f64,
    pub range_sigma_quadratic: f64,
    /// Bearing noise, degrees.
    pub bearing_sigma_deg: f64,
    pub ball: DetectorRange,
    /// Goal posts.
    pub goal_post: DetectorRange,
    /// Line crossings and penalty marks.
    pub field_feature: DetectorRange,
    pub robot: DetectorRange,
    /// Whether robots hide what is behind them.
    pub occlusion: bool,
    /// Half the width a robot covers in the image, m.
    pub robot_radius: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            horizontal_fov_deg: 87.0,
            vertical_fov_deg: 58.0,
            range_sigma_fraction: 0.03,
            range_sigma_quadratic: 0.004,
            bearing_sigma_deg: 1.0,
            ball: DetectorRange { max_range: 10.0, near_probability: 0.95, far_probability: 0.5 },
            goal_post: DetectorRange {
                max_range: 25.0,
                near_probability: 0.9,
                far_probability: 0.5,
            },
            field_feature: DetectorRange {
                max_range: 10.0,
                near_probability: 0.85,
                far_probability: 0.3,
            },
            robot: DetectorRange { max_range: 15.0, near_probability: 0.9, far_probability: 0.5 },
            occlusion: true,
            robot_radius: 0.2,
        }
    }
}

impl CameraConfig {
    /// The server's camera as it is: 120 x 120 degrees, no noise, no misses, no occlusion.
    pub fn ideal() -> CameraConfig {
        let all =
            DetectorRange { max_range: f64::INFINITY, near_probability: 1.0, far_probability: 1.0 };
        CameraConfig {
            horizontal_fov_deg: 120.0,
            vertical_fov_deg: 120.0,
            range_sigma_fraction: 0.0,
            range_sigma_quadratic: 0.0,
            bearing_sigma_deg: 0.0,
            ball: all,
            goal_post: all,
            field_feature: all,
            robot: all,
            occlusion: false,
            robot_radius: 0.0,
        }
    }

    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        let nonnegative = [
            ("range_sigma_fraction", self.range_sigma_fraction),
            ("range_sigma_quadratic", self.range_sigma_quadratic),
            ("bearing_sigma_deg", self.bearing_sigma_deg),
            ("robot_radius", self.robot_radius),
        ];
        for (name, value) in nonnegative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("camera.{name} must be a number >= 0, got {value}"));
            }
        }
        for (name, value) in [
            ("horizontal_fov_deg", self.horizontal_fov_deg),
            ("vertical_fov_deg", self.vertical_fov_deg),
        ] {
            if !(value.is_finite() && value > 0.0 && value <= 360.0) {
                return Err(format!("camera.{name} must be in (0, 360], got {value}"));
            }
        }
        for (name, range) in [
            ("ball", self.ball),
            ("goal_post", self.goal_post),
            ("field_feature", self.field_feature),
            ("robot", self.robot),
        ] {
            if range.max_range.is_nan() || range.max_range < 0.0 {
                return Err(format!(
                    "camera.{name}.max_range must be >= 0, got {}",
                    range.max_range
                ));
            }
            for (which, p) in [
                ("near_probability", range.near_probability),
                ("far_probability", range.far_probability),
            ] {
                if !(0.0..=1.0).contains(&p) {
                    return Err(format!("camera.{name}.{which} must be in [0, 1], got {p}"));
                }
            }
        }
        Ok(())
    }
}

/// Which detector range applies to an object.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DetectorKind {
    Ball,
    GoalPost,
    FieldFeature,
    Robot,
}

/// One object the server reported, already classified.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sighting {
    pub class: ObjectClass,
    pub variant: Option<u16>,
    pub detector: DetectorKind,
    /// The server's polar coordinates in the camera frame: m, rad, rad.
    pub distance: f64,
    pub azimuth: f64,
    pub elevation: f64,
}

/// The camera model with its random numbers.
#[derive(Debug)]
pub struct CameraModel {
    config: CameraConfig,
    rng: ChaCha8Rng,
}

/// A marker carried to the ground frame.
#[derive(Clone, Copy, Debug)]
struct Grounded {
    marker: Sighting,
    x: f64,
    y: f64,
    range: f64,
}

impl CameraModel {
    pub fn new(config: CameraConfig, seed: u64) -> CameraModel {
        CameraModel { config, rng: ChaCha8Rng::seed_from_u64(seed) }
    }

    pub fn config(&self) -> &CameraConfig {
        &self.config
    }

    /// The camera's horizontal field of view, rad.
    pub fn horizontal_fov(&self) -> f64 {
        self.config.horizontal_fov_deg.to_radians()
    }

    /// The largest range any detector reaches, m.
    pub fn max_range(&self) -> f64 {
        let c = &self.config;
        [c.ball, c.goal_post, c.field_feature, c.robot]
            .iter()
            .map(|r| r.max_range)
            .fold(0.0, f64::max)
    }

    /// The stretch of ground the image covers along its optical axis, from the torso: a T1
    /// looking at its feet sees about 2 m ahead, one looking ahead nothing nearer than about
    /// 1 m. World modeling expects to see only what lies inside it.
    pub fn footprint(&self, pose: &CameraPose) -> Footprint {
        let half_v = (self.config.vertical_fov_deg / 2.0 - EDGE_MARGIN_DEG).max(0.0).to_radians();
        let reach = self.max_range();
        let origin = pose.camera_to_ground([0.0; 3]);
        // Where a ray of the image's centre column at `elevation` meets the ground, if it does.
        let ground = |elevation: f64| -> Option<f64> {
            let p = pose.camera_to_ground(polar_to_camera(1.0, 0.0, elevation));
            let down = origin[2] - p[2];
            if origin[2] <= 0.0 || down <= 0.0 {
                return None;
            }
            let t = origin[2] / down;
            let x = origin[0] + t * (p[0] - origin[0]);
            let y = origin[1] + t * (p[1] - origin[1]);
            Some(x.hypot(y))
        };
        let far = ground(half_v).map_or(reach, |d| d.min(reach));
        // A lower edge that never meets the ground (the camera looks up): no ground in view.
        let near = ground(-half_v).map_or(far, |d| d.min(far));
        Footprint { near, far }
    }

    fn range_of(&self, kind: DetectorKind) -> DetectorRange {
        match kind {
            DetectorKind::Ball => self.config.ball,
            DetectorKind::GoalPost => self.config.goal_post,
            DetectorKind::FieldFeature => self.config.field_feature,
            DetectorKind::Robot => self.config.robot,
        }
    }

    /// The detections one image yields: each marker inside the field of view and the
    /// detector's range, not hidden behind a robot, detected with its probability, with noise
    /// on range and bearing. Bearings are relative to `head_yaw` (perception adds the head yaw
    /// at capture back), ranges on the ground from the torso. Markers with non-finite numbers
    /// are dropped.
    pub fn detect(
        &mut self,
        pose: &CameraPose,
        head_yaw: f64,
        markers: &[Sighting],
    ) -> Vec<Detection> {
        let half_h = self.config.horizontal_fov_deg.to_radians() / 2.0;
        let half_v = self.config.vertical_fov_deg.to_radians() / 2.0;
        let grounded: Vec<Grounded> = markers
            .iter()
            .filter(|m| {
                m.distance.is_finite()
                    && m.distance >= 0.0
                    && m.azimuth.is_finite()
                    && m.elevation.is_finite()
                    && m.azimuth.abs() <= half_h
                    && m.elevation.abs() <= half_v
            })
            .map(|&marker| {
                let p = pose.camera_to_ground(polar_to_camera(
                    marker.distance,
                    marker.azimuth,
                    marker.elevation,
                ));
                Grounded { marker, x: p[0], y: p[1], range: p[0].hypot(p[1]) }
            })
            .collect();
        let mut detections = Vec::with_capacity(grounded.len());
        for g in &grounded {
            let range = self.range_of(g.marker.detector);
            if g.range > range.max_range || self.occluded(g, &grounded) {
                continue;
            }
            let share = if range.max_range.is_finite() && range.max_range > 0.0 {
                g.range / range.max_range
            } else {
                0.0
            };
            let probability =
                range.near_probability + (range.far_probability - range.near_probability) * share;
            if probability < 1.0 && self.rng.random::<f64>() >= probability {
                continue;
            }
            let range_sigma = self.config.range_sigma_fraction * g.range
                + self.config.range_sigma_quadratic * g.range * g.range;
            let bearing_sigma = self.config.bearing_sigma_deg.to_radians();
            let range_noise: f64 = self.rng.sample(StandardNormal);
            let bearing_noise: f64 = self.rng.sample(StandardNormal);
            detections.push(Detection {
                class: g.marker.class,
                variant: g.marker.variant,
                range: (g.range + range_sigma * range_noise).max(0.0),
                bearing: strata_robot::geometry::normalize_angle(
                    g.y.atan2(g.x) + bearing_sigma * bearing_noise - head_yaw,
                ),
                orientation: None,
            });
        }
        detections
    }

    /// Whether a robot nearer than `target` covers its direction (robots do not hide
    /// themselves, and a robot's own markers are merged before this).
    fn occluded(&self, target: &Grounded, all: &[Grounded]) -> bool {
        if !self.config.occlusion {
            return false;
        }
        let direction = target.y.atan2(target.x);
        all.iter().any(|other| {
            other.marker.detector == DetectorKind::Robot
                && other.range + self.config.robot_radius < target.range
                && other.range > self.config.robot_radius
                && {
                    let half_width = (self.config.robot_radius / other.range).asin();
                    let apart =
                        strata_robot::geometry::normalize_angle(other.y.atan2(other.x) - direction);
                    apart.abs() < half_width
                }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{NeckGeometry, Quaternion};

    fn marker(detector: DetectorKind, distance: f64, azimuth_deg: f64) -> Sighting {
        Sighting {
            class: ObjectClass(match detector {
                DetectorKind::Ball => 1,
                DetectorKind::Robot => 2,
                _ => 10,
            }),
            variant: None,
            detector,
            distance,
            azimuth: azimuth_deg.to_radians(),
            elevation: 0.0,
        }
    }

    fn level() -> CameraPose {
        CameraPose::new(NeckGeometry::T1, 0.0, 0.0, Quaternion::IDENTITY, 0.67)
    }

    #[test]
    fn the_ideal_camera_passes_everything_through_exactly() {
        let mut camera = CameraModel::new(CameraConfig::ideal(), 1);
        let seen = camera.detect(
            &level(),
            0.0,
            &[marker(DetectorKind::Ball, 40.0, 55.0), marker(DetectorKind::Robot, 2.0, 0.0)],
        );
        assert_eq!(seen.len(), 2);
        // 40 m at 55 degrees from a camera 0.11 m ahead of the torso.
        let expected =
            (40.0 * 55f64.to_radians().sin()).hypot(0.1125 + 40.0 * 55f64.to_radians().cos());
        assert!((seen[0].range - expected).abs() < 1e-9);
    }

    #[test]
    fn the_default_camera_sees_less_and_noisier() {
        let mut camera = CameraModel::new(CameraConfig::default(), 7);
        // Outside the 87 degree field of view, beyond the ball detector's range: never.
        for _ in 0..100 {
            let seen = camera.detect(
                &level(),
                0.0,
                &[marker(DetectorKind::Ball, 3.0, 50.0), marker(DetectorKind::Ball, 12.0, 0.0)],
            );
            assert!(seen.is_empty());
        }
        // Up close and ahead: mostly, with noise of the configured size.
        let mut errors = Vec::new();
        for _ in 0..2000 {
            for d in camera.detect(&level(), 0.0, &[marker(DetectorKind::Ball, 5.0, 0.0)]) {
                errors.push(d.range - 5.1125);
            }
        }
        let rate = errors.len() as f64 / 2000.0;
        assert!(rate > 0.65 && rate < 0.85, "detection rate {rate}");
        let sigma = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        let expected = 0.03 * 5.1125 + 0.004 * 5.1125 * 5.1125;
        assert!((sigma / expected - 1.0).abs() < 0.1, "range sigma {sigma} vs {expected}");
    }

    #[test]
    fn a_robot_hides_the_ball_behind_it() {
        let mut camera = CameraModel::new(CameraConfig { ..CameraConfig::ideal() }, 3);
        let mut config = CameraConfig::ideal();
        config.occlusion = true;
        config.robot_radius = 0.2;
        let mut occluding = CameraModel::new(config, 3);
        let scene = [marker(DetectorKind::Robot, 2.0, 0.0), marker(DetectorKind::Ball, 5.0, 1.0)];
        assert_eq!(camera.detect(&level(), 0.0, &scene).len(), 2);
        let seen = occluding.detect(&level(), 0.0, &scene);
        assert_eq!(seen.len(), 1);
        assert_eq!(seen[0].class, ObjectClass(2));
        // Beside the robot, the ball is seen.
        let beside = [marker(DetectorKind::Robot, 2.0, 0.0), marker(DetectorKind::Ball, 5.0, 15.0)];
        assert_eq!(occluding.detect(&level(), 0.0, &beside).len(), 2);
    }

    #[test]
    fn the_footprint_follows_the_head_pitch() {
        let camera = CameraModel::new(CameraConfig::default(), 1);
        let pitched = |pitch: f64| {
            let pose = CameraPose::new(NeckGeometry::T1, 0.0, pitch, Quaternion::IDENTITY, 0.67);
            camera.footprint(&pose)
        };
        // Looking ahead: the horizon is in the image, the feet are not.
        let ahead = pitched(0.0);
        assert_eq!(ahead.far, camera.max_range());
        assert!(ahead.near > 1.0 && ahead.near < 3.0, "{ahead:?}");
        // Looking down as far as the neck goes: a ball within kicking reach is in view, the far
        // field is not.
        let down = pitched(1.2);
        assert!(down.near < 0.2, "{down:?}");
        assert!(down.far > 1.0 && down.far < 3.0, "{down:?}");
        // Halfway: both edges in between.
        let half = pitched(0.5);
        assert!(half.near > down.near && half.near < ahead.near, "{half:?}");
        assert!(half.far > down.far, "{half:?}");
        // Looking up with the torso on its back: no ground at all.
        let up = pitched(-1.5);
        assert_eq!(up.near, up.far, "{up:?}");
    }

    #[test]
    fn bearings_are_relative_to_the_head_yaw() {
        let mut camera = CameraModel::new(CameraConfig::ideal(), 1);
        let pose = CameraPose::new(NeckGeometry::T1, 0.5, 0.0, Quaternion::IDENTITY, 0.67);
        let seen = camera.detect(&pose, 0.5, &[marker(DetectorKind::Ball, 10.0, 0.0)]);
        assert!(seen[0].bearing.abs() < 0.01, "{}", seen[0].bearing);
    }

    #[test]
    fn bad_values_are_named() {
        let mut config = CameraConfig::default();
        config.ball.near_probability = 1.5;
        assert!(config.validate().expect_err("rejected").contains("camera.ball.near_probability"));
        assert!(CameraConfig::default().validate().is_ok());
        assert!(CameraConfig::ideal().validate().is_ok());
    }
}
