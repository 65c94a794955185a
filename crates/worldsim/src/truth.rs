//! What really happened to the bodies, for tests and summaries (never for robots).

use serde::{Deserialize, Serialize};
use strata_robot::geometry::Pose;

/// The bodies' true history. Times are seconds of simulated time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Per robot: (time, true pose) every `truth_period`.
    pub trajectories: Vec<Vec<(f64, Pose)>>,
    /// (robot, time) of each landing on the floor.
    pub falls: Vec<(usize, f64)>,
    /// (robot, time) of each completed stand-up.
    pub stand_ups: Vec<(usize, f64)>,
    /// Steps in which a robot walked into a wall.
    pub bumps: u64,
}

impl Truth {
    /// A robot's true pose at time `t` (the nearest sample).
    pub fn pose_at(&self, robot: usize, t: f64) -> Option<Pose> {
        pose_at(self.trajectories.get(robot)?, t)
    }
}

/// The sample of `samples` (sorted by time) nearest to `t`.
pub fn pose_at(samples: &[(f64, Pose)], t: f64) -> Option<Pose> {
    let i = samples.partition_point(|(s, _)| *s < t);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|i| samples.get(i))
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
        .map(|(_, p)| *p)
}
