//! Watching the robots from outside: a [`Tap`] on the host that reads the packages the layers
//! publish anyway — the planning layer's decisions, the deliberative layer's behavior paths,
//! the reactive layer's reports — and keeps what a summary or a test needs. Works on either
//! host; the robots do not know it is there.

use std::collections::BTreeMap;
use std::sync::Mutex;

use strata_robot::application::{DeliberativePortsOf, PlanningPortsOf, ReactivePortsOf};
use strata_runtime::{Tap, TapRecord};

use crate::goals::GazeKind;
use crate::planning::{Mission, Role};
use crate::robot::Patrol;

/// What one robot did, as its layers reported it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RobotLog {
    /// (time, mission, role, alone) whenever the planning layer's assignment changed.
    pub assignments: Vec<(f64, Mission, Role, bool)>,
    /// (time, behavior path) whenever the deliberative layer's path changed.
    pub paths: Vec<(f64, String)>,
    /// Reactive cycles in which the head multiplexer selected a goal of each kind, per
    /// deliberative state ("Patrol", "Inspect", "Responding", ...).
    pub gaze: BTreeMap<(String, GazeKind), u64>,
    /// Reactive cycles per primitive behavior of the head+body multiplexer (the reflexes).
    pub reflexes: BTreeMap<String, u64>,
}

impl RobotLog {
    /// Reactive cycles with a head goal of `kind` while the deliberative layer was in `state`.
    pub fn gaze_cycles(&self, state: &str, kind: GazeKind) -> u64 {
        self.gaze.get(&(state.to_owned(), kind)).copied().unwrap_or(0)
    }

    /// The role held at time `t`.
    pub fn role_at(&self, t: f64) -> Option<Role> {
        self.assignments.iter().take_while(|(s, ..)| *s <= t).last().map(|(_, _, r, _)| *r)
    }

    fn state(&self) -> String {
        self.paths.last().map(|(_, p)| state_of(p)).unwrap_or_default()
    }
}

/// The deliberative state a behavior path is in: the state below "Patrolling", or the
/// top-level state.
pub fn state_of(path: &str) -> String {
    let path = path.split(" [").next().unwrap_or("");
    let mut parts = path.split('/');
    match (parts.next(), parts.next()) {
        (Some("Patrolling"), Some(child)) => child.to_owned(),
        (Some(top), _) => top.to_owned(),
        _ => String::new(),
    }
}

/// Everything observed, per robot (by module-name prefix, e.g. `patrol/1`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observations {
    pub robots: BTreeMap<String, RobotLog>,
}

/// The tap.
#[derive(Debug, Default)]
pub struct PatrolObserver {
    observations: Mutex<Observations>,
}

impl PatrolObserver {
    pub fn snapshot(&self) -> Observations {
        self.observations.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone()
    }
}

impl Tap for PatrolObserver {
    fn package(&self, record: &TapRecord<'_>) {
        let Some((robot, module)) = record.sent_on.module_name.rsplit_once('/') else { return };
        let t = record.time.as_secs_f64();
        let mut observations =
            self.observations.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match module {
            "planning" => {
                let Some(decision) = record.value(PlanningPortsOf::<Patrol>::DECISION) else {
                    return;
                };
                let a = &decision.assignment;
                let log = observations.robots.entry(robot.to_owned()).or_default();
                let changed = log
                    .assignments
                    .last()
                    .is_none_or(|l| (l.1, l.2, l.3) != (a.mission, a.role, a.alone));
                if changed {
                    log.assignments.push((t, a.mission, a.role, a.alone));
                }
            }
            "deliberative" => {
                let Some(scores) = record.value(DeliberativePortsOf::<Patrol>::SCORES) else {
                    return;
                };
                let log = observations.robots.entry(robot.to_owned()).or_default();
                if log.paths.last().is_none_or(|(_, last)| *last != scores.behavior_path) {
                    log.paths.push((t, scores.behavior_path.clone()));
                }
            }
            "reactive" => {
                let Some(report) = record.value(ReactivePortsOf::<Patrol>::REPORT) else { return };
                let log = observations.robots.entry(robot.to_owned()).or_default();
                if let Some(goal) = &report.head.selected_goal {
                    let key = (log.state(), GazeKind::of_label(goal));
                    *log.gaze.entry(key).or_default() += 1;
                }
                if let Some(primitive) = &report.whole_body.primitive {
                    *log.reflexes.entry(primitive.to_string()).or_default() += 1;
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_are_read_from_behavior_paths() {
        assert_eq!(state_of("Patrolling/Inspect/inspect/observe [waypoint 1]"), "Inspect");
        assert_eq!(state_of("Responding/respond/go to alarm [waypoint 4]"), "Responding");
        assert_eq!(state_of(""), "");
    }
}
