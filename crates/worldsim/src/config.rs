//! The simulator's parameters: its period, the head camera and the walking body. Every field has
//! a default (a small humanoid in an office), so a configuration file names only what differs.

use serde::{Deserialize, Serialize};
use strata_robot::geometry::Velocity;

/// Why a configuration could not be used: the field, what it must be and what it was.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("worldsim configuration: `{field}` must be {requirement}, got {value}")]
pub struct ConfigError {
    pub field: String,
    pub requirement: String,
    pub value: String,
}

/// Everything the simulator needs besides the world and the robots' starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldSimConfig {
    /// The name the robots' platform reports (`PlatformInfo::name`).
    pub name: String,
    /// Sensor (and simulation step) period, s.
    pub sensor_period: f64,
    /// Ground truth records each robot's pose this often, s.
    pub truth_period: f64,
    pub camera: CameraConfig,
    pub body: BodyConfig,
}

impl Default for WorldSimConfig {
    fn default() -> Self {
        WorldSimConfig {
            name: "worldsim".into(),
            sensor_period: 0.02,
            truth_period: 0.1,
            camera: CameraConfig::default(),
            body: BodyConfig::default(),
        }
    }
}

/// The head camera: what it can see and how badly it measures it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// An image every this many sensor frames.
    pub every: u32,
    /// Horizontal field of view, rad.
    pub fov: f64,
    /// Nearer than this an object is too close to be recognised, m.
    pub min_range: f64,
    pub range: f64,
    /// Chance that a visible object is reported (a miss otherwise).
    pub detection_probability: f64,
    /// Range noise, m: `range_sigma + range_sigma_per_metre * range`.
    pub range_sigma: f64,
    pub range_sigma_per_metre: f64,
    /// Bearing noise, rad.
    pub bearing_sigma: f64,
    /// A body tilted more than this (rad) takes no usable images.
    pub max_tilt: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            every: 2,
            fov: 1.06,
            min_range: 0.3,
            range: 6.0,
            detection_probability: 0.9,
            range_sigma: 0.03,
            range_sigma_per_metre: 0.04,
            bearing_sigma: 0.02,
            max_tilt: 0.2,
        }
    }
}

/// The walking body: gait limits, head, odometry errors, and how long its sequences take.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BodyConfig {
    pub max_velocity: Velocity,
    /// m/s^2.
    pub acceleration: f64,
    /// rad/s^2.
    pub angular_acceleration: f64,
    /// rad/s.
    pub max_head_speed: f64,
    pub head_yaw_limits: (f64, f64),
    pub head_pitch_limits: (f64, f64),
    /// Standard deviation of each robot's systematic odometry scale error (per axis).
    pub odometry_scale_sigma: f64,
    /// Random odometry error: sigma per square root of metre (and of radian).
    pub odometry_noise: f64,
    /// Bodies keep this far from walls (they bump otherwise), m.
    pub radius: f64,
    /// The gait's initialization and end stages, s.
    pub walk_start: f64,
    pub walk_stop: f64,
    /// An unprotected fall, from the slip to the floor, s.
    pub fall_time: f64,
    /// The protective fall sequence, s.
    pub protective_fall_time: f64,
    /// Each stand-up sequence, s.
    pub stand_up_time: f64,
    /// How far landing shoves the body, unseen by odometry: sigmas of x, y (m) and heading (rad).
    pub landing_shove: [f64; 3],
}

impl Default for BodyConfig {
    fn default() -> Self {
        BodyConfig {
            max_velocity: Velocity::new(0.35, 0.2, 1.2),
            acceleration: 0.8,
            angular_acceleration: 3.0,
            max_head_speed: 4.0,
            head_yaw_limits: (-2.0, 2.0),
            head_pitch_limits: (-0.6, 0.5),
            odometry_scale_sigma: 0.04,
            odometry_noise: 0.02,
            radius: 0.15,
            walk_start: 0.1,
            walk_stop: 0.15,
            fall_time: 0.7,
            protective_fall_time: 0.8,
            stand_up_time: 3.0,
            landing_shove: [0.08, 0.08, 0.1],
        }
    }
}

impl WorldSimConfig {
    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("sensor_period", self.sensor_period)?;
        positive("truth_period", self.truth_period)?;
        let c = &self.camera;
        if c.every == 0 {
            return Err(invalid("camera.every", "at least 1", &c.every.to_string()));
        }
        range("camera.fov", c.fov, f64::MIN_POSITIVE, std::f64::consts::TAU)?;
        non_negative("camera.min_range", c.min_range)?;
        positive("camera.range", c.range)?;
        range("camera.detection_probability", c.detection_probability, 0.0, 1.0)?;
        non_negative("camera.range_sigma", c.range_sigma)?;
        non_negative("camera.range_sigma_per_metre", c.range_sigma_per_metre)?;
        non_negative("camera.bearing_sigma", c.bearing_sigma)?;
        non_negative("camera.max_tilt", c.max_tilt)?;
        let b = &self.body;
        non_negative("body.max_velocity.vx", b.max_velocity.vx)?;
        non_negative("body.max_velocity.vy", b.max_velocity.vy)?;
        non_negative("body.max_velocity.omega", b.max_velocity.omega)?;
        positive("body.acceleration", b.acceleration)?;
        positive("body.angular_acceleration", b.angular_acceleration)?;
        positive("body.max_head_speed", b.max_head_speed)?;
        limits("body.head_yaw_limits", b.head_yaw_limits)?;
        limits("body.head_pitch_limits", b.head_pitch_limits)?;
        non_negative("body.odometry_scale_sigma", b.odometry_scale_sigma)?;
        non_negative("body.odometry_noise", b.odometry_noise)?;
        non_negative("body.radius", b.radius)?;
        non_negative("body.walk_start", b.walk_start)?;
        non_negative("body.walk_stop", b.walk_stop)?;
        positive("body.fall_time", b.fall_time)?;
        positive("body.protective_fall_time", b.protective_fall_time)?;
        positive("body.stand_up_time", b.stand_up_time)?;
        for (axis, sigma) in ["x", "y", "heading"].into_iter().zip(b.landing_shove) {
            non_negative(&format!("body.landing_shove.{axis}"), sigma)?;
        }
        Ok(())
    }
}

fn invalid(field: &str, requirement: &str, value: &str) -> ConfigError {
    ConfigError {
        field: field.to_owned(),
        requirement: requirement.to_owned(),
        value: value.to_owned(),
    }
}

fn positive(field: &str, value: f64) -> Result<(), ConfigError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, "a positive number", &value.to_string()))
    }
}

fn non_negative(field: &str, value: f64) -> Result<(), ConfigError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(field, "zero or positive", &value.to_string()))
    }
}

fn range(field: &str, value: f64, min: f64, max: f64) -> Result<(), ConfigError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(invalid(field, &format!("in [{min}, {max}]"), &value.to_string()))
    }
}

fn limits(field: &str, (low, high): (f64, f64)) -> Result<(), ConfigError> {
    if low.is_finite() && high.is_finite() && low <= high {
        Ok(())
    } else {
        Err(invalid(
            field,
            "a finite (low, high) pair with low <= high",
            &format!("({low}, {high})"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_a_bad_value_is_named() {
        assert_eq!(WorldSimConfig::default().validate(), Ok(()));
        let mut config = WorldSimConfig::default();
        config.camera.detection_probability = 1.5;
        let error = config.validate().expect_err("probability above 1");
        assert_eq!(error.field, "camera.detection_probability");
        config = WorldSimConfig::default();
        config.body.head_yaw_limits = (1.0, -1.0);
        assert_eq!(config.validate().map_err(|e| e.field), Err("body.head_yaw_limits".into()));
    }

    #[test]
    fn a_configuration_file_names_only_what_differs_and_no_unknown_field() {
        let config: WorldSimConfig =
            serde_json::from_str(r#"{"camera": {"range": 4.0}}"#).expect("parses");
        assert_eq!(config.camera.range, 4.0);
        assert_eq!(config.camera.fov, CameraConfig::default().fov);
        assert!(serde_json::from_str::<WorldSimConfig>(r#"{"camera": {"rnage": 4.0}}"#).is_err());
    }
}
