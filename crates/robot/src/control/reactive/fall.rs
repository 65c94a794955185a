//! The fall detector: the robot's stability from its inertial sensors, every reactive cycle.

use serde::{Deserialize, Serialize};

use super::Stability;
use crate::percept::Percepts;
use crate::platform::FallDirection;

/// Thresholds of the fall detector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FallDetectorConfig {
    /// Tilt (rad) predicted `lookahead` seconds ahead beyond which the robot is falling.
    pub unstable_tilt: f64,
    /// Tilt (rad) beyond which the robot is lying down.
    pub fallen_tilt: f64,
    /// How far ahead the tilt is extrapolated with the gyroscope, s.
    pub lookahead: f64,
    /// Consecutive samples that must agree before the status changes (debouncing noise).
    pub confirm_samples: u32,
}

impl Default for FallDetectorConfig {
    fn default() -> Self {
        FallDetectorConfig {
            unstable_tilt: 0.5,
            fallen_tilt: 1.0,
            lookahead: 0.1,
            confirm_samples: 1,
        }
    }
}

/// Classifies stability from body angles and gyroscope, every reactive cycle.
#[derive(Clone, Debug, Default)]
pub struct FallDetector {
    config: FallDetectorConfig,
    status: Stability,
    candidate: Option<(Stability, u32)>,
}

impl FallDetector {
    pub fn new(config: FallDetectorConfig) -> FallDetector {
        FallDetector { config, status: Stability::Stable, candidate: None }
    }

    pub fn status(&self) -> Stability {
        self.status
    }

    pub fn update(&mut self, percepts: &Percepts) -> Stability {
        let [roll, pitch] = percepts.inertial.body_angles;
        let [roll_rate, pitch_rate, _] = percepts.inertial.gyroscope;
        let predicted_roll = roll + roll_rate * self.config.lookahead;
        let predicted_pitch = pitch + pitch_rate * self.config.lookahead;
        let direction = |r: f64, p: f64| {
            if p.abs() >= r.abs() {
                if p > 0.0 { FallDirection::Front } else { FallDirection::Back }
            } else if r > 0.0 {
                FallDirection::Right
            } else {
                FallDirection::Left
            }
        };
        let observed = if roll.abs().max(pitch.abs()) > self.config.fallen_tilt {
            Stability::Fallen(direction(roll, pitch))
        } else if predicted_roll.abs().max(predicted_pitch.abs()) > self.config.unstable_tilt {
            Stability::Unstable(direction(predicted_roll, predicted_pitch))
        } else {
            Stability::Stable
        };
        if observed == self.status {
            self.candidate = None;
            return self.status;
        }
        let count = match self.candidate {
            Some((candidate, n)) if candidate == observed => n + 1,
            _ => 1,
        };
        if count >= self.config.confirm_samples.max(1) {
            self.status = observed;
            self.candidate = None;
        } else {
            self.candidate = Some((observed, count));
        }
        self.status
    }
}
