//! What one run measures: the samples of a run and the measures computed from them.

use super::*;

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    pub t: f64,
    /// The head multiplexer's selected goal is the ball alone (Table 5's "observe ball").
    pub observe_ball: bool,
    /// The selected goal is the ball together with other objects (a landmark).
    pub joint_gaze: bool,
    pub ball_known: bool,
    pub ball_confidence: f64,
    /// Distance of the pose estimate from the true pose, m (NaN before the first estimate).
    pub pose_error: f64,
    /// Distance of the ball estimate from the true ball when known, m.
    pub ball_error: f64,
    pub coverage: f64,
    pub ideal_coverage: f64,
    /// Head multiplexer scores per single object: (object, S_d, S_r, final).
    pub scores: Vec<ObjectScores>,
    pub keeper: (f64, f64),
    pub ball: (f64, f64),
    /// True head (yaw, pitch), rad: shows where the camera looked when the ball was lost.
    pub head: (f64, f64),
    /// True heading of the keeper, rad (team frame).
    pub keeper_heading: f64,
    /// The deliberative layer was in the cover behavior.
    pub covering: bool,
    /// The deliberative layer's active behavior path and the reactive layer's (run 0 only).
    pub behavior: String,
    pub reactive_path: String,
}

/// The metrics of one run (the columns of `runs.csv`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMetrics {
    pub samples: usize,
    pub observe_ball: f64,
    /// Fraction of the time the head looked at the ball together with other objects.
    pub joint_gaze: f64,
    pub ball_unknown: f64,
    pub pose_error_mean: f64,
    pub pose_error_p95: f64,
    pub ball_error_mean: f64,
    pub coverage: f64,
    pub ideal_coverage: f64,
    /// Gaze changes between the ball and anything else, per minute.
    pub gaze_switches_per_min: f64,
    /// Fraction of the time the deliberative layer was in the cover behavior (not searching
    /// for the ball, not localizing).
    pub covering_behavior: f64,
    /// Changes of the ball's direction ([`recover_times`]).
    pub direction_changes: usize,
    /// Mean time to re-cover after those the keeper re-covered from, s (NaN: none).
    pub recover_time_mean: f64,
    /// Fraction of the changes the keeper did not re-cover from before the next or the end.
    pub not_recovered: f64,
}

/// Where the head multiplexer's selected goal looks, in Table 5's terms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Gaze {
    /// At the ball alone: the paper's "observe ball".
    Ball,
    /// At the ball together with other objects in one gaze.
    BallWithOthers,
    /// At something else, or at nothing.
    #[default]
    Other,
}

/// The gaze of the head multiplexer's decision. The baselines send the plain observe-ball goal
/// without objects; the value functions name the objects of every goal.
pub fn gaze(head: &MuxReport) -> Gaze {
    let Some(label) = &head.selected_goal else { return Gaze::Other };
    let observe_ball = HeadGoal::ObserveBall.label();
    match head.goals.iter().find(|g| &g.goal == label) {
        Some(goal) => {
            let ball = goal.objects.iter().any(|o| o == BALL);
            match (ball, goal.objects.len()) {
                (true, 1) => Gaze::Ball,
                (true, _) => Gaze::BallWithOthers,
                (false, 0) if **label == *observe_ball => Gaze::Ball,
                _ => Gaze::Other,
            }
        }
        None if **label == *observe_ball => Gaze::Ball,
        None => Gaze::Other,
    }
}

/// The time to re-cover after each change of the ball's direction, in order; `None` where the
/// keeper did not re-cover before the next change or the end of the trace.
///
/// A change: the direction of the true ball's displacement between consecutive samples has
/// turned by more than `recover.turn` degrees from the direction at the previous change (or
/// where the ball started moving), so a gradual curve counts once per `turn` degrees. Samples
/// where the ball moved less than 0.1 mm have no direction. Re-covered: from some sample on,
/// `coverage >= ideal_coverage - recover.tolerance` for `recover.hold` s; the time is from the
/// change to that sample.
pub fn recover_times(trace: &[Sample], recover: &Recover) -> Vec<Option<f64>> {
    let turn = recover.turn.to_radians();
    let mut changes = Vec::new();
    let mut reference: Option<f64> = None;
    for (i, w) in trace.windows(2).enumerate() {
        let (dx, dy) = (w[1].ball.0 - w[0].ball.0, w[1].ball.1 - w[0].ball.1);
        if dx.hypot(dy) < 1e-4 {
            continue;
        }
        let heading = dy.atan2(dx);
        match reference {
            None => reference = Some(heading),
            Some(r) => {
                let turned = (heading - r + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                if turned.abs() > turn {
                    changes.push(i + 1);
                    reference = Some(heading);
                }
            }
        }
    }
    let covered: Vec<bool> =
        trace.iter().map(|s| s.coverage >= s.ideal_coverage - recover.tolerance).collect();
    changes
        .iter()
        .enumerate()
        .map(|(k, &start)| {
            let until = changes.get(k + 1).copied().unwrap_or(trace.len());
            (start..until)
                .find(|&j| {
                    let held = trace[j].t + recover.hold;
                    trace.last().is_some_and(|last| last.t >= held - 1e-9)
                        && trace[j..]
                            .iter()
                            .zip(&covered[j..])
                            .take_while(|(s, _)| s.t <= held + 1e-9)
                            .all(|(_, c)| *c)
                })
                .map(|j| trace[j].t - trace[start].t)
        })
        .collect()
}

/// The metrics of a trace sampled at a constant period.
pub fn metrics(trace: &[Sample], recover: &Recover) -> RunMetrics {
    let pose: Vec<f64> = trace.iter().map(|s| s.pose_error).filter(|e| e.is_finite()).collect();
    let ball: Vec<f64> = trace.iter().filter(|s| s.ball_known).map(|s| s.ball_error).collect();
    // A switch is between a gaze that includes the ball and one that does not.
    let with_ball = |s: &Sample| s.observe_ball || s.joint_gaze;
    let switches = trace.windows(2).filter(|w| with_ball(&w[0]) != with_ball(&w[1])).count();
    let recovered = recover_times(trace, recover);
    let times: Vec<f64> = recovered.iter().flatten().copied().collect();
    let minutes = match (trace.first(), trace.last()) {
        (Some(a), Some(b)) if b.t > a.t => (b.t - a.t) / 60.0,
        _ => f64::NAN,
    };
    RunMetrics {
        samples: trace.len(),
        observe_ball: fraction_true(trace.iter().map(|s| s.observe_ball)),
        joint_gaze: fraction_true(trace.iter().map(|s| s.joint_gaze)),
        ball_unknown: fraction_true(trace.iter().map(|s| !s.ball_known)),
        pose_error_mean: mean(&pose),
        pose_error_p95: percentile(&pose, 0.95),
        ball_error_mean: mean(&ball),
        coverage: mean(&trace.iter().map(|s| s.coverage).collect::<Vec<_>>()),
        ideal_coverage: mean(&trace.iter().map(|s| s.ideal_coverage).collect::<Vec<_>>()),
        gaze_switches_per_min: switches as f64 / minutes,
        covering_behavior: fraction_true(trace.iter().map(|s| s.covering)),
        direction_changes: recovered.len(),
        recover_time_mean: mean(&times),
        not_recovered: fraction_true(recovered.iter().map(Option::is_none)),
    }
}

// ---------------------------------------------------------------------------------------------
// Watching the keeper.
