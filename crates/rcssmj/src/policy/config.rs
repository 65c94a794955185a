use std::path::Path;

use serde::{Deserialize, Serialize};

#[cfg(test)]
use super::LEG_JOINTS;
use super::{JOINT_NAMES, JointTarget, PolicyError, T1_JOINT_COUNT};

const SHIPPED_TOML: &str = include_str!("../../assets/t1/t1.toml");
const SHIPPED_ORIGIN: &str = "the shipped assets/t1/t1.toml";

/// The T1 deployment constants the walking policy and its caller use, as in booster_gym's
/// `deploy/configs/T1.yaml` (units: rad, rad/s, s, Hz, N m/rad, N m s/rad, N m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct T1Config {
    pub control: ControlConfig,
    pub gait: GaitConfig,
    pub observation_scales: ObservationScales,
    pub action: ActionConfig,
    /// All 23 joints, in the order of [`JOINT_NAMES`].
    pub joints: Vec<JointConfig>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// The deployment's low-level step, s.
    pub dt: f64,
    /// Low-level steps per policy step; `dt * decimation` is the policy period.
    pub decimation: u32,
    /// The most each smoothed command component moves toward the desired one per policy step
    /// (m/s, or rad/s for yaw).
    pub command_smoothing_step: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaitConfig {
    /// Gait frequency while walking, Hz.
    pub frequency: f64,
    /// Below this Euclidean norm of the smoothed (vx, vy, yaw rate) command the robot stands:
    /// gait frequency zero, command and phase features zero.
    pub standing_command_norm: f64,
}

/// Factors applied to each observation part before the network sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationScales {
    pub gravity: f64,
    pub lin_vel: f64,
    pub ang_vel: f64,
    pub dof_pos: f64,
    pub dof_vel: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionConfig {
    /// Leg joint target = default position + `scale` * clipped action.
    pub scale: f64,
    /// The action is clipped to [-clip, clip].
    pub clip: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    pub name: String,
    /// rad
    pub default_position: f64,
    /// N m/rad
    pub stiffness: f64,
    /// N m s/rad
    pub damping: f64,
    /// N m
    pub torque_limit: f64,
}

impl T1Config {
    /// The configuration shipped with the crate (converted from booster_gym's T1.yaml).
    pub fn shipped() -> Result<Self, PolicyError> {
        Self::from_toml_str(SHIPPED_TOML, SHIPPED_ORIGIN)
    }

    /// Reads a configuration file in the shipped `t1.toml` format.
    pub fn load(path: &Path) -> Result<Self, PolicyError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| PolicyError::Read { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and checks a configuration; `origin` names it in errors (a file name).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, PolicyError> {
        let config: Self = toml::from_str(text).map_err(|source| PolicyError::ConfigSyntax {
            origin: origin.to_owned(),
            source: Box::new(source),
        })?;
        config.validate(origin)?;
        Ok(config)
    }

    /// Checks what the types cannot: 23 joints in the T1's order, finite numbers, positive
    /// periods and gains that cannot destabilise the PD loop by sign.
    pub fn validate(&self, origin: &str) -> Result<(), PolicyError> {
        let fail = |field: String, reason: &str| {
            Err(PolicyError::ConfigValue {
                origin: origin.to_owned(),
                field,
                reason: reason.to_owned(),
            })
        };
        let positive = [
            ("control.dt", self.control.dt),
            ("control.command_smoothing_step", self.control.command_smoothing_step),
            ("action.clip", self.action.clip),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return fail(field.to_owned(), "must be a finite number above zero");
            }
        }
        if self.control.decimation == 0 {
            return fail("control.decimation".to_owned(), "must be at least 1");
        }
        let non_negative = [
            ("gait.frequency", self.gait.frequency),
            ("gait.standing_command_norm", self.gait.standing_command_norm),
        ];
        for (field, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return fail(field.to_owned(), "must be a finite number, zero or above");
            }
        }
        let scales = &self.observation_scales;
        let finite = [
            ("observation_scales.gravity", scales.gravity),
            ("observation_scales.lin_vel", scales.lin_vel),
            ("observation_scales.ang_vel", scales.ang_vel),
            ("observation_scales.dof_pos", scales.dof_pos),
            ("observation_scales.dof_vel", scales.dof_vel),
            ("action.scale", self.action.scale),
        ];
        for (field, value) in finite {
            if !value.is_finite() {
                return fail(field.to_owned(), "must be a finite number");
            }
        }
        if self.joints.len() != T1_JOINT_COUNT {
            return fail(
                "joints".to_owned(),
                &format!("has {} entries, the T1 has {T1_JOINT_COUNT} joints", self.joints.len()),
            );
        }
        for (index, (joint, expected)) in self.joints.iter().zip(JOINT_NAMES).enumerate() {
            if joint.name != expected {
                return fail(
                    format!("joints[{index}].name"),
                    &format!("is {:?}, expected {expected:?} (the T1's joint order)", joint.name),
                );
            }
            if !joint.default_position.is_finite() {
                return fail(
                    format!("joints[{index}].default_position"),
                    "must be a finite number",
                );
            }
            let gains = [
                ("stiffness", joint.stiffness),
                ("damping", joint.damping),
                ("torque_limit", joint.torque_limit),
            ];
            for (name, value) in gains {
                if !(value.is_finite() && value >= 0.0) {
                    return fail(
                        format!("joints[{index}].{name}"),
                        "must be a finite number, zero or above",
                    );
                }
            }
        }
        Ok(())
    }

    /// The policy step, s (`dt * decimation`; 20 ms for the T1).
    pub fn policy_period(&self) -> f64 {
        self.control.dt * f64::from(self.control.decimation)
    }

    /// Joint `index` (into [`JOINT_NAMES`]) held at its default position with its gains.
    /// `None` past the T1's 23 joints.
    pub fn default_target(&self, index: usize) -> Option<JointTarget> {
        self.joints.get(index).map(|joint| JointTarget {
            q: joint.default_position,
            kp: joint.stiffness,
            kd: joint.damping,
        })
    }

    /// Every joint at its default position with its gains, in [`JOINT_NAMES`] order.
    pub fn default_targets(&self) -> [JointTarget; T1_JOINT_COUNT] {
        std::array::from_fn(|index| self.default_target(index).unwrap_or_default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_matches_the_deployment_yaml() -> Result<(), PolicyError> {
        let config = T1Config::shipped()?;
        assert_eq!(config.policy_period(), 0.02);
        assert_eq!(config.control.command_smoothing_step, 0.02);
        assert_eq!(config.gait.frequency, 1.0);
        assert_eq!(config.observation_scales.dof_vel, 0.1);
        let legs: Vec<f64> =
            LEG_JOINTS.iter().map(|&i| config.joints[i].default_position).collect();
        assert_eq!(legs, [-0.2, 0.0, 0.0, 0.4, -0.25, 0.0, -0.2, 0.0, 0.0, 0.4, -0.25, 0.0]);
        assert_eq!(config.joints[15].stiffness, 50.0);
        assert_eq!(config.joints[16].damping, 3.0);
        assert_eq!(config.joints[10].torque_limit, 30.0);
        Ok(())
    }

    #[test]
    fn unknown_field_is_named_with_the_file() {
        let text = SHIPPED_TOML.replace("[gait]\n", "[gait]\nstride = 3\n");
        let err = T1Config::from_toml_str(&text, "my-t1.toml").err();
        let message = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(message.contains("my-t1.toml"), "{message}");
        assert!(message.contains("stride"), "{message}");
    }

    #[test]
    fn out_of_order_joint_is_named() {
        let text = SHIPPED_TOML.replacen("name = \"head_pitch\"", "name = \"neck\"", 1);
        let message = T1Config::from_toml_str(&text, "my-t1.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains("joints[1].name"), "{message}");
        assert!(message.contains("my-t1.toml"), "{message}");
    }

    #[test]
    fn negative_gain_is_refused() {
        let text = SHIPPED_TOML.replacen("stiffness = 20.0", "stiffness = -20.0", 1);
        let message = T1Config::from_toml_str(&text, "my-t1.toml")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains("joints[0].stiffness"), "{message}");
    }
}
