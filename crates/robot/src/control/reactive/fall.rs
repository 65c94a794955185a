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
    /// Tilt (rad) beyond which the robot is falling whatever its rate of turn: a body that
    /// cannot catch itself once leaning this far (measured per body) need not wait for the
    /// lean to speed up. None: the predicted tilt alone decides.
    pub falling_tilt: Option<f64>,
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
            falling_tilt: None,
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
        } else if self.config.falling_tilt.is_some_and(|t| roll.abs().max(pitch.abs()) > t) {
            Stability::Unstable(direction(roll, pitch))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn leaning(body_angles: [f64; 2], gyroscope: [f64; 3]) -> Percepts {
        let mut percepts = Percepts::default();
        percepts.inertial.body_angles = body_angles;
        percepts.inertial.gyroscope = gyroscope;
        percepts
    }

    #[test]
    fn a_lean_that_speeds_up_is_a_fall_before_it_is_deep() {
        let mut detector = FallDetector::new(FallDetectorConfig::default());
        // 0.3 rad, tipping forward at 3 rad/s: 0.6 rad predicted 0.1 s ahead.
        assert_eq!(
            detector.update(&leaning([0.0, 0.3], [0.0, 3.0, 0.0])),
            Stability::Unstable(FallDirection::Front)
        );
    }

    #[test]
    fn a_still_lean_falls_only_past_the_bodys_falling_tilt() {
        let still_lean = leaning([-0.44, 0.05], [0.0, 0.0, 0.0]);
        let mut predicted_only = FallDetector::new(FallDetectorConfig::default());
        assert_eq!(predicted_only.update(&still_lean), Stability::Stable);
        let mut with_body = FallDetector::new(FallDetectorConfig {
            falling_tilt: Some(0.35),
            ..FallDetectorConfig::default()
        });
        assert_eq!(with_body.update(&still_lean), Stability::Unstable(FallDirection::Left));
        // Catching itself (turning back upright fast) does not make the lean safe.
        let mut catching = FallDetector::new(FallDetectorConfig {
            falling_tilt: Some(0.35),
            ..FallDetectorConfig::default()
        });
        assert_eq!(
            catching.update(&leaning([0.0, -0.4], [0.0, 2.0, 0.0])),
            Stability::Unstable(FallDirection::Back)
        );
        assert_eq!(catching.update(&leaning([0.0, 0.2], [0.0, 0.0, 0.0])), Stability::Stable);
    }
}
