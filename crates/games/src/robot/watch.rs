//! Taps on the robot's packages: the planning layer's decisions (game events, the latest
//! mission and role) and the world model's pose against the platform's ground truth.

use std::sync::{Mutex, PoisonError};

use strata_rcssmj::platform::TruthSource;
use strata_robot::geometry::normalize_angle;
use strata_runtime::{Tap, TapRecord};
use strata_soccer::behaviors::Decision;
use strata_soccer::world_config::BALL;

use super::report::{BallStatus, ConvergedAccuracy, GameEvent, LocalizationAccuracy};

/// Sees every package of the robot and keeps what the reports need from the planning layer.
/// Runs on the planning thread: it only copies under a short lock.
pub(crate) struct Watch {
    pub(crate) planning: String,
    pub(crate) state: Mutex<WatchState>,
}

#[derive(Default)]
pub(crate) struct WatchState {
    pub(crate) latest: Option<Decision>,
    pub(crate) events: Vec<GameEvent>,
    pub(crate) last_event: Option<GameEvent>,
    /// Every distinct game state seen, in order.
    pub(crate) history: Vec<String>,
}

impl Watch {
    pub(crate) fn new(planning: &str) -> Watch {
        Watch { planning: planning.to_owned(), state: Mutex::default() }
    }

    pub(crate) fn lock(&self) -> std::sync::MutexGuard<'_, WatchState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub(crate) fn take_events(&self) -> Vec<GameEvent> {
        std::mem::take(&mut self.lock().events)
    }

    pub(crate) fn latest(&self) -> Option<Decision> {
        self.lock().latest.clone()
    }
}

impl Tap for Watch {
    fn package(&self, record: &TapRecord<'_>) {
        let Some(decision) = record.value_from(&self.planning, crate::outputs::DECISION) else {
            return;
        };
        let mut state = self.lock();
        // Before the first control packet the directive is a default, not the game's.
        if decision.directive.connected {
            let event = GameEvent::of(&decision.directive);
            if state.last_event.as_ref() != Some(&event) {
                if state.history.last() != Some(&event.state) {
                    state.history.push(event.state.clone());
                }
                state.last_event = Some(event.clone());
                state.events.push(event);
            }
        }
        state.latest = Some(decision.clone());
    }
}

/// Compares each of the world module's states with the platform's ground truth.
pub(crate) struct Accuracy {
    pub(crate) world: String,
    pub(crate) truth: TruthSource,
    pub(crate) attack_sign: f64,
    pub(crate) state: Mutex<(LocalizationAccuracy, f64)>,
}

impl Accuracy {
    pub(crate) fn snapshot(&self) -> Option<LocalizationAccuracy> {
        let (accuracy, _) = *self.state.lock().unwrap_or_else(PoisonError::into_inner);
        (accuracy.samples > 0).then_some(accuracy)
    }
}

impl Tap for Accuracy {
    fn package(&self, record: &TapRecord<'_>) {
        let Some(world) = record.value_from(&self.world, crate::outputs::WORLD_STATE) else {
            return;
        };
        let Some(truth) = self.truth.get() else { return };
        let estimate = &world.pose;
        let pose = estimate.pose;
        // The team frame is the server's world frame turned half a circle for a team that
        // attacks towards -x.
        let s = self.attack_sign;
        let (tx, ty) = (s * truth.position[0], s * truth.position[1]);
        let heading = if s < 0.0 { truth.heading + std::f64::consts::PI } else { truth.heading };
        let error = (pose.x - tx).hypot(pose.y - ty);
        let heading_error = normalize_angle(pose.theta - heading).abs().to_degrees();
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let (accuracy, heading_sum) = &mut *state;
        accuracy.samples += 1;
        let n = accuracy.samples as f64;
        accuracy.mean_error_m += (error - accuracy.mean_error_m) / n;
        *heading_sum += heading_error;
        accuracy.mean_heading_error_deg = *heading_sum / n;
        accuracy.max_error_m = accuracy.max_error_m.max(error);
        accuracy.last_error_m = error;
        if accuracy.converged.is_none() && !estimate.lost && estimate.last_correction.is_some() {
            accuracy.converged =
                Some(ConvergedAccuracy { after_samples: n as u64 - 1, ..Default::default() });
        }
        if let Some(converged) = &mut accuracy.converged {
            converged.samples += 1;
            converged.lost_samples += u64::from(estimate.lost);
            let m = converged.samples as f64;
            converged.mean_error_m += (error - converged.mean_error_m) / m;
            converged.max_error_m = converged.max_error_m.max(error);
        }
        accuracy.truth = [tx, ty];
        accuracy.estimate = [pose.x, pose.y];
        accuracy.last_lost = estimate.lost;
        accuracy.last_ball = world.object(BALL).map(|b| BallStatus {
            known: b.known,
            confidence: b.confidence,
            estimate: b.known.then_some([b.global_position.x, b.global_position.y]),
        });
        accuracy.last_headings_deg =
            [pose.theta.to_degrees(), normalize_angle(heading).to_degrees()];
    }
}
