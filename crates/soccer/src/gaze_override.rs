//! A gaze chosen from outside the deliberative layer: a learning environment (the Gymnasium
//! environment of `strata_experiments::goal_covering::gym`) picks which of active vision's
//! sensing candidates the head gets, in place of the value function's choice.
//!
//! The candidates are the ones [`crate::behaviors`] evaluates, in its order: the ball, then
//! the landmarks nearest first, each alone and together with the ball. A choice names a
//! candidate by its kind and rank, so the same action means the same kind of look whatever
//! landmarks happen to be in the world model.

use std::sync::{Arc, Mutex, PoisonError};

use strata_robot::control::scores::{GoalScore, ScoreVector};

use crate::goals::HeadGoal;
use crate::world_config::BALL;

/// Landmarks a choice can name by rank (nearest first): the candidates active vision makes.
pub const RANKED_LANDMARKS: usize = 6;

/// One of active vision's sensing candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GazeChoice {
    Ball,
    /// The k-th nearest landmark (0: the nearest).
    Landmark(usize),
    /// The ball and the k-th nearest landmark in one gaze.
    Together(usize),
}

impl GazeChoice {
    /// Every choice: the discrete action space, `index` order.
    pub const COUNT: usize = 1 + 2 * RANKED_LANDMARKS;

    /// The choice numbered `index` (0: ball; 1..=6: landmarks; 7..=12: ball with a landmark).
    pub fn from_index(index: usize) -> Option<GazeChoice> {
        match index {
            0 => Some(GazeChoice::Ball),
            i if i <= RANKED_LANDMARKS => Some(GazeChoice::Landmark(i - 1)),
            i if i < Self::COUNT => Some(GazeChoice::Together(i - 1 - RANKED_LANDMARKS)),
            _ => None,
        }
    }
}

/// The slot the environment writes and the deliberative layer reads: shared, since the
/// behavior lives inside a module the host owns. `None`: the behavior's own gaze.
#[derive(Debug, Default)]
pub struct GazeOverride {
    choice: Mutex<Option<GazeChoice>>,
}

impl GazeOverride {
    pub fn new() -> Arc<GazeOverride> {
        Arc::new(GazeOverride::default())
    }

    pub fn set(&self, choice: Option<GazeChoice>) {
        *self.choice.lock().unwrap_or_else(PoisonError::into_inner) = choice;
    }

    pub fn get(&self) -> Option<GazeChoice> {
        *self.choice.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// What each candidate of a score vector looks at, for [`apply`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Ball,
    Landmark,
    Together,
    /// A goal, a line, a rival: not among a policy's choices.
    Other,
}

/// Keeps only the chosen candidate of `vector` (scored 1, so the multiplexer's average with
/// the reactive score still decides between it and nothing else); the ball alone when the
/// candidate does not exist now (the ball unknown, fewer landmarks in the model).
pub(crate) fn apply(choice: GazeChoice, kinds: &[Kind], vector: &mut ScoreVector<HeadGoal>) {
    let (want, rank) = match choice {
        GazeChoice::Ball => (Kind::Ball, 0),
        GazeChoice::Landmark(k) => (Kind::Landmark, k),
        GazeChoice::Together(k) => (Kind::Together, k),
    };
    let chosen = kinds
        .iter()
        .enumerate()
        .filter(|(_, kind)| **kind == want)
        .nth(rank)
        .and_then(|(i, _)| vector.goals.get(i).cloned());
    let goal = match chosen {
        Some(mut goal) => {
            goal.deliberative = 1.0;
            goal
        }
        None => GoalScore::new(HeadGoal::ObserveBall, 1.0).about(BALL),
    };
    vector.goals.clear();
    vector.goals.push(goal);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_index_names_one_choice_and_back() {
        let choices: Vec<_> = (0..GazeChoice::COUNT).filter_map(GazeChoice::from_index).collect();
        assert_eq!(choices.len(), GazeChoice::COUNT);
        assert_eq!(choices[0], GazeChoice::Ball);
        assert_eq!(choices[1], GazeChoice::Landmark(0));
        assert_eq!(choices[GazeChoice::COUNT - 1], GazeChoice::Together(RANKED_LANDMARKS - 1));
        assert_eq!(GazeChoice::from_index(GazeChoice::COUNT), None);
    }

    #[test]
    fn a_missing_candidate_falls_back_to_the_ball() {
        let landmark =
            GoalScore::new(HeadGoal::ObserveLandmark { name: "post".into() }, 0.3).about("post");
        let ball = GoalScore::new(HeadGoal::ObserveBall, 0.9).about(BALL);
        let kinds = [Kind::Ball, Kind::Landmark];
        let mut vector = ScoreVector { goals: vec![ball.clone(), landmark.clone()] };
        apply(GazeChoice::Landmark(0), &kinds, &mut vector);
        assert_eq!(vector.goals.len(), 1);
        assert_eq!(vector.goals[0].goal, landmark.goal);
        assert_eq!(vector.goals[0].deliberative, 1.0);
        let mut vector = ScoreVector { goals: vec![ball, landmark] };
        apply(GazeChoice::Together(0), &kinds, &mut vector);
        assert_eq!(vector.goals[0].goal, HeadGoal::ObserveBall);
    }
}
