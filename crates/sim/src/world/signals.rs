//! The head referee's signals robots must perceive themselves (`referee.signals`): the Ready
//! gesture, which cameras see, and the whistle at the kick-off and at a goal, which
//! microphones hear, with misses and false detections.
//!
//! Every draw comes from each robot's own `gesture` and `whistle` streams, and with the signals
//! off nothing is drawn at all: turning them on or off leaves every other draw as it was.

use std::time::Duration;

use strata_robot::{Global as FieldFrame, Point};
use strata_runtime::Time;
use strata_spl::Gesture;
use strata_spl::gamecontroller::GameState;

use super::Simulation;
use crate::camera::GestureSight;
use crate::config::SignalConfig;
use crate::truth::{Event, EventKind};

/// Confidence of a heard whistle: uniform in this interval.
const WHISTLE_CONFIDENCE: (f64, f64) = (0.6, 1.0);
/// Confidence of a false detection: uniform in this interval, lower than most true ones as a
/// detector's matches of noise are weaker.
const FALSE_WHISTLE_CONFIDENCE: (f64, f64) = (0.5, 0.8);

/// What the world keeps of the signals.
#[derive(Clone, Debug)]
pub(super) struct Signals {
    config: SignalConfig,
    /// Where the referee stands, field frame.
    referee: Point<FieldFrame>,
    /// The Ready gesture is shown from then on, for `gesture_duration`.
    gesture_since: Option<Time>,
    /// The true state before the latest state decision: a transition, not a state, signals.
    state: GameState,
    /// Probability of a false whistle detection per sensor frame.
    false_whistle: f64,
}

impl Signals {
    pub fn new(
        config: &SignalConfig,
        half_width: f64,
        sensor_period: Duration,
        state: GameState,
    ) -> Signals {
        Signals {
            config: config.clone(),
            referee: Point::new(0.0, -(half_width + config.behind_line)),
            gesture_since: None,
            state,
            false_whistle: config.whistle_false_rate / 60.0 * sensor_period.as_secs_f64(),
        }
    }

    /// The referee as cameras see it at `now`, while the gesture is shown.
    pub fn gesture(&self, now: Time) -> Option<GestureSight> {
        let since = self.gesture_since?;
        // In seconds: a duration of any size, as configured, converts without overflow.
        let shown = now.saturating_since(since).as_secs_f64() < self.config.gesture_duration;
        (self.config.enabled && shown).then_some(GestureSight {
            position: self.referee,
            gesture: Gesture::Ready.code(),
            range: self.config.gesture_range,
            detection: self.config.gesture_detection,
        })
    }
}

impl Simulation {
    /// Follows the true game into `state`: Standby -> Ready starts the gesture and any other
    /// change ends it (the referee gestures only to start Ready); Set -> Playing is the
    /// kick-off whistle.
    pub(super) fn signal_state(&mut self, state: GameState) {
        let previous = std::mem::replace(&mut self.signals.state, state);
        if !self.signals.config.enabled {
            return;
        }
        self.signals.gesture_since =
            ((previous, state) == (GameState::Standby, GameState::Ready)).then_some(self.time);
        if (previous, state) == (GameState::Set, GameState::Playing) {
            self.whistle();
        }
    }

    /// The referee whistles: every present robot within range hears it (unless it misses it)
    /// in its next sensor frame. Penalized robots hear it too, from where they wait: the
    /// referee does not silence the bench.
    pub(super) fn whistle(&mut self) {
        let config = &self.signals.config;
        if !config.enabled {
            return;
        }
        let (range, miss) = (config.whistle_range, config.whistle_miss);
        let referee = self.signals.referee;
        let mut heard = Vec::new();
        for robot in &mut self.robots {
            if !robot.present || robot.body.pose.position().distance(referee) > range {
                continue;
            }
            if robot.whistle_rng.chance(miss) {
                continue;
            }
            let (low, high) = WHISTLE_CONFIDENCE;
            let confidence = robot.whistle_rng.uniform(low, high);
            robot.outbox.whistle = strongest(robot.outbox.whistle, Some(confidence));
            heard.push(robot.id);
        }
        self.event(EventKind::Whistle { robots: heard });
    }
}

/// What a robot's whistle detector reports in the sensor frame taken now: the strongest of the
/// whistles it heard since the frame before, the report of the unread frame this one replaces
/// (a platform that skips frames still learns of the whistle), and a false detection drawn
/// now.
pub(super) fn whistle_report(
    signals: &Signals,
    robot: &mut super::RobotSlot,
    now: Time,
    events: &mut Vec<Event>,
) -> Option<f64> {
    if !signals.config.enabled {
        return None;
    }
    let unread = robot.outbox.sensors.as_ref().and_then(|frame| frame.whistle);
    let mut report = strongest(robot.outbox.whistle.take(), unread);
    if robot.whistle_rng.chance(signals.false_whistle) {
        let (low, high) = FALSE_WHISTLE_CONFIDENCE;
        report = strongest(report, Some(robot.whistle_rng.uniform(low, high)));
        events.push(Event { time: now, kind: EventKind::FalseWhistle { robot: robot.id } });
    }
    report
}

fn strongest(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.max(b)),
        (a, b) => a.or(b),
    }
}
