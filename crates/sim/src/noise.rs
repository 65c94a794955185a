//! Every noise and error level of the simulator, in one place (the `[noise]` config section).
//!
//! A preset (`none`, `default`, `high`) gives every value; any value written in the section
//! overrides its preset. `none` makes the simulator exact: no sensor noise, no detection misses,
//! no false positives, no odometry or actuation error, no random falls, stand-ups never fail.
//! Each value's three preset levels are written next to it below, so the table is the
//! documentation.

use serde::{Deserialize, Serialize};

/// A preset noise level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseLevel {
    /// Exact sensors and actuation: for tests.
    None,
    /// NAO-like levels.
    #[default]
    Default,
    /// Roughly two to three times the default: robustness experiments.
    High,
}

/// Declares a group of noise values: the resolved struct, the overrides struct (every field
/// optional, unknown fields rejected) and the preset table.
macro_rules! noise_group {
    (
        $(#[$meta:meta])*
        $name:ident, $overrides:ident {
            $( $(#[$fmeta:meta])* $field:ident : [$none:expr, $default:expr, $high:expr], )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: f64, )+
        }

        impl $name {
            pub fn preset(level: NoiseLevel) -> $name {
                match level {
                    NoiseLevel::None => $name { $( $field: $none, )+ },
                    NoiseLevel::Default => $name { $( $field: $default, )+ },
                    NoiseLevel::High => $name { $( $field: $high, )+ },
                }
            }

            /// Every value with its name, for validation and documentation.
            pub fn values(&self) -> Vec<(&'static str, f64)> {
                vec![$( (stringify!($field), self.$field), )+]
            }
        }

        #[doc = concat!("Overrides of [`", stringify!($name), "`]: each value replaces the preset's.")]
        #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct $overrides {
            $(
                #[serde(default, skip_serializing_if = "Option::is_none")]
                pub $field: Option<f64>,
            )+
        }

        impl $overrides {
            pub fn apply(&self, base: &mut $name) {
                $( if let Some(value) = self.$field { base.$field = value; } )+
            }
        }
    };
}

noise_group! {
    /// The simulated camera (perception simulation).
    CameraNoise, CameraNoiseOverrides {
        /// Range standard deviation at zero distance, m.
        range_sigma: [0.0, 0.03, 0.08],
        /// Range standard deviation added per metre of distance (a fraction of the range).
        range_sigma_per_metre: [0.0, 0.06, 0.15],
        /// Bearing standard deviation at zero distance, rad.
        bearing_sigma: [0.0, 0.02, 0.05],
        /// Bearing standard deviation added per metre of distance, rad/m.
        bearing_sigma_per_metre: [0.0, 0.005, 0.012],
        /// Orientation (line crossings, lines) standard deviation, rad.
        orientation_sigma: [0.0, 0.05, 0.15],
        /// Detection probability of an object at zero distance.
        detection_near: [1.0, 0.95, 0.85],
        /// Detection probability at the camera's range (linear in between).
        detection_far: [1.0, 0.6, 0.4],
        /// Detection probability lost per rad/s of head speed (motion blur).
        motion_blur_per_rad_s: [0.0, 0.12, 0.25],
        /// Detection probability factor of field features (posts, crossings, lines, marks,
        /// beacons) relative to the ball and robots.
        landmark_factor: [1.0, 0.85, 0.7],
        /// Probability that an image contains one false positive.
        false_positive_rate: [0.0, 0.02, 0.08],
    }
}

noise_group! {
    /// The inertial unit, joint encoders and foot pressure sensors.
    ImuNoise, ImuNoiseOverrides {
        /// Accelerometer standard deviation per axis, m/s^2.
        accel_sigma: [0.0, 0.05, 0.15],
        /// Gyroscope standard deviation per axis, rad/s.
        gyro_sigma: [0.0, 0.01, 0.03],
        /// Body angle (roll, pitch) standard deviation, rad.
        angle_sigma: [0.0, 0.005, 0.015],
        /// Head joint encoder standard deviation, rad.
        joint_sigma: [0.0, 0.002, 0.006],
        /// Foot pressure standard deviation per foot, kg.
        foot_sigma: [0.0, 0.05, 0.15],
    }
}

noise_group! {
    /// Odometry of the walking engine, against the motion the legs really made.
    OdometryNoise, OdometryNoiseOverrides {
        /// Systematic error: odometry reports forward motion times (1 + scale_x).
        scale_x: [0.0, 0.05, 0.12],
        /// Systematic error on sideways motion.
        scale_y: [0.0, 0.05, 0.15],
        /// Systematic error on rotation.
        scale_theta: [0.0, 0.03, 0.08],
        /// Random error: standard deviation sigma_xy * sqrt(d) per axis after d metres.
        sigma_xy: [0.0, 0.02, 0.06],
        /// Random error: standard deviation sigma_theta * sqrt(a) after turning a radians
        /// (or walking a metres).
        sigma_theta: [0.0, 0.03, 0.08],
    }
}

noise_group! {
    /// How the legs execute the walking engine's velocity, and kicks.
    ActuationNoise, ActuationNoiseOverrides {
        /// Per step, each velocity component is scaled by (1 + N(0, velocity_sigma)).
        velocity_sigma: [0.0, 0.05, 0.12],
        /// Kick speed standard deviation, as a fraction of the kick's speed.
        kick_speed_sigma: [0.0, 0.1, 0.2],
        /// Kick direction standard deviation, rad.
        kick_direction_sigma: [0.0, 0.08, 0.2],
    }
}

noise_group! {
    /// Random falls and failing stand-ups.
    FallNoise, FallNoiseOverrides {
        /// Falls per minute of walking (a hazard independent of anything else).
        hazard_per_minute: [0.0, 0.05, 0.3],
        /// When two robots come into contact, each falls with this probability per m/s of
        /// approach speed (capped at 1).
        collision_fall_per_mps: [0.0, 0.5, 1.0],
        /// While two robots keep pushing into each other, falls per second of contact.
        contact_fall_per_second: [0.0, 0.05, 0.2],
        /// Probability that a kick makes the kicker fall.
        kick_fall_probability: [0.0, 0.01, 0.05],
        /// Probability that a stand-up sequence fails (the robot ends lying again).
        stand_up_failure: [0.0, 0.1, 0.3],
    }
}

/// The `[noise]` section: a preset and overrides.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseConfig {
    /// `none`, `default` or `high` (also accepted under the key `noise`).
    #[serde(alias = "noise")]
    pub preset: NoiseLevel,
    pub camera: CameraNoiseOverrides,
    pub imu: ImuNoiseOverrides,
    pub odometry: OdometryNoiseOverrides,
    pub actuation: ActuationNoiseOverrides,
    pub falls: FallNoiseOverrides,
}

/// Every noise value, resolved from a preset and its overrides.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseParams {
    pub camera: CameraNoise,
    pub imu: ImuNoise,
    pub odometry: OdometryNoise,
    pub actuation: ActuationNoise,
    pub falls: FallNoise,
}

impl NoiseParams {
    pub fn preset(level: NoiseLevel) -> NoiseParams {
        NoiseParams {
            camera: CameraNoise::preset(level),
            imu: ImuNoise::preset(level),
            odometry: OdometryNoise::preset(level),
            actuation: ActuationNoise::preset(level),
            falls: FallNoise::preset(level),
        }
    }

    /// Every value as (`group.name`, value).
    pub fn values(&self) -> Vec<(String, f64)> {
        let groups: [(&str, Vec<(&str, f64)>); 5] = [
            ("camera", self.camera.values()),
            ("imu", self.imu.values()),
            ("odometry", self.odometry.values()),
            ("actuation", self.actuation.values()),
            ("falls", self.falls.values()),
        ];
        groups
            .into_iter()
            .flat_map(|(group, values)| {
                values.into_iter().map(move |(name, v)| (format!("{group}.{name}"), v))
            })
            .collect()
    }
}

impl NoiseConfig {
    /// A config with every value at `level`.
    pub fn level(level: NoiseLevel) -> NoiseConfig {
        NoiseConfig { preset: level, ..NoiseConfig::default() }
    }

    pub fn resolve(&self) -> NoiseParams {
        let mut params = NoiseParams::preset(self.preset);
        self.camera.apply(&mut params.camera);
        self.imu.apply(&mut params.imu);
        self.odometry.apply(&mut params.odometry);
        self.actuation.apply(&mut params.actuation);
        self.falls.apply(&mut params.falls);
        params
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn none_is_exact_and_overrides_replace_the_preset() {
        let none = NoiseParams::preset(NoiseLevel::None);
        for (name, value) in none.values() {
            let exact = if name.starts_with("camera.detection") || name == "camera.landmark_factor"
            {
                1.0
            } else {
                0.0
            };
            assert_eq!(value, exact, "{name}");
        }
        let config: NoiseConfig =
            toml::from_str("noise = \"high\"\n[camera]\nrange_sigma = 0.5\n").expect("parses");
        let params = config.resolve();
        assert_eq!(params.camera.range_sigma, 0.5);
        assert_eq!(params.imu, ImuNoise::preset(NoiseLevel::High));
    }

    #[test]
    fn unknown_override_is_rejected_by_name() {
        let error = toml::from_str::<NoiseConfig>("[camera]\nrange_sigmaa = 1.0\n")
            .expect_err("unknown field");
        assert!(error.to_string().contains("range_sigmaa"), "{error}");
    }
}
