//! The trainer of a rates run, through the server's monitor port: it kicks off once the robots
//! have had their Ready, then moves the ball to a new random place now and then so the robots
//! keep walking, and restarts play when the server's referee stops it (ball out, a goal).
//! Everything follows the simulation's clock; the placements are drawn from the run's seed.

use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use strata_rcssmj::protocol::monitor::MonitorCommand;
use strata_rcssmj::protocol::{FieldSide, PlayMode};

/// Simulation seconds between two attempts to restart play (the server applies a command after
/// its next monitor message; asking every poll would pile them up).
const RESTART_EVERY: f64 = 1.0;

/// Where the ball rests on the ground: its centre is its radius above it.
const BALL_Z: f64 = 0.11;

/// What the trainer needs from the scenario.
#[derive(Clone, Copy, Debug)]
pub struct TrainerPlan {
    /// Simulation seconds from the robots' arrival to the kick-off.
    pub ready: f64,
    /// Simulation seconds between ball placements.
    pub ball_period: f64,
    /// x_min, x_max, y_min, y_max of the placements, m, world frame.
    pub ball_area: [f64; 4],
}

/// The trainer of one run.
#[derive(Debug)]
pub struct Trainer {
    plan: TrainerPlan,
    rng: ChaCha8Rng,
    /// When the robots were all in the simulation.
    arrived: Option<f64>,
    kicked_off: Option<f64>,
    next_ball: f64,
    last_restart: f64,
    /// Restarts after the referee stopped play.
    pub restarts: usize,
    pub placements: usize,
}

impl Trainer {
    pub fn new(plan: TrainerPlan, seed: u64) -> Trainer {
        Trainer {
            plan,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7261_7465_3364),
            arrived: None,
            kicked_off: None,
            next_ball: f64::INFINITY,
            last_restart: f64::NEG_INFINITY,
            restarts: 0,
            placements: 0,
        }
    }

    /// The simulation time of the kick-off, once it was ordered.
    pub fn kicked_off(&self) -> Option<f64> {
        self.kicked_off
    }

    /// The commands for the monitor state at simulation time `t` (play mode `mode`), given
    /// whether every robot is in the simulation.
    pub fn step(
        &mut self,
        t: f64,
        mode: Option<PlayMode>,
        all_arrived: bool,
    ) -> Vec<MonitorCommand> {
        let mut commands = Vec::new();
        let Some(arrived) = self.arrived.or_else(|| all_arrived.then_some(t)) else {
            return commands;
        };
        self.arrived = Some(arrived);
        if self.kicked_off.is_none() {
            if t - arrived >= self.plan.ready {
                self.kicked_off = Some(t);
                self.last_restart = t;
                self.next_ball = t + self.plan.ball_period;
                commands.push(self.place_ball());
                commands.push(MonitorCommand::KickOff(Some(FieldSide::Left)));
            }
            return commands;
        }
        let stopped = !matches!(
            mode,
            None | Some(PlayMode::PlayOn | PlayMode::KickOffLeft | PlayMode::KickOffRight)
        );
        if stopped && t - self.last_restart >= RESTART_EVERY {
            // The referee stopped play (a goal, the ball out) or the game went back to its
            // kick-off: the ball to a new place, and play on from there.
            self.last_restart = t;
            self.restarts += 1;
            self.next_ball = t + self.plan.ball_period;
            commands.push(self.place_ball());
            commands.push(if mode == Some(PlayMode::BeforeKickOff) {
                MonitorCommand::KickOff(Some(FieldSide::Left))
            } else {
                MonitorCommand::DropBall
            });
        } else if t >= self.next_ball {
            self.next_ball = t + self.plan.ball_period;
            commands.push(self.place_ball());
        }
        commands
    }

    fn place_ball(&mut self) -> MonitorCommand {
        self.placements += 1;
        let [x0, x1, y0, y1] = self.plan.ball_area;
        let x = if x1 > x0 { self.rng.random_range(x0..x1) } else { x0 };
        let y = if y1 > y0 { self.rng.random_range(y0..y1) } else { y0 };
        MonitorCommand::PlaceBall { position: [x, y, BALL_Z], velocity: Some([0.0; 3]) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> TrainerPlan {
        TrainerPlan { ready: 5.0, ball_period: 10.0, ball_area: [-20.0, -4.0, -8.0, 8.0] }
    }

    fn ball_at(command: &MonitorCommand) -> Option<[f64; 3]> {
        match command {
            MonitorCommand::PlaceBall { position, .. } => Some(*position),
            _ => None,
        }
    }

    #[test]
    fn kicks_off_after_the_ready_time_then_moves_the_ball_each_period() {
        let mut trainer = Trainer::new(plan(), 1);
        assert!(trainer.step(0.0, Some(PlayMode::BeforeKickOff), false).is_empty());
        assert!(trainer.step(1.0, Some(PlayMode::BeforeKickOff), true).is_empty());
        assert!(trainer.step(5.9, Some(PlayMode::BeforeKickOff), true).is_empty());
        let kick_off = trainer.step(6.0, Some(PlayMode::BeforeKickOff), true);
        assert!(ball_at(&kick_off[0]).is_some());
        assert_eq!(kick_off[1], MonitorCommand::KickOff(Some(FieldSide::Left)));
        assert_eq!(trainer.kicked_off(), Some(6.0));
        assert!(trainer.step(10.0, Some(PlayMode::PlayOn), true).is_empty());
        let moved = trainer.step(16.0, Some(PlayMode::PlayOn), true);
        let [x, y, z] = ball_at(&moved[0]).expect("a placement");
        assert!((-20.0..-4.0).contains(&x) && (-8.0..8.0).contains(&y) && z == BALL_Z);
        assert!(trainer.step(16.5, Some(PlayMode::PlayOn), true).is_empty());
    }

    #[test]
    fn restarts_play_when_the_referee_stops_it_at_most_once_a_second() {
        let mut trainer = Trainer::new(plan(), 2);
        trainer.step(0.0, Some(PlayMode::BeforeKickOff), true);
        trainer.step(5.0, Some(PlayMode::BeforeKickOff), true);
        let restart = trainer.step(7.0, Some(PlayMode::KickInRight), true);
        assert_eq!(restart.len(), 2);
        assert_eq!(restart[1], MonitorCommand::DropBall);
        assert!(trainer.step(7.5, Some(PlayMode::KickInRight), true).is_empty());
        let again = trainer.step(8.1, Some(PlayMode::BeforeKickOff), true);
        assert_eq!(again[1], MonitorCommand::KickOff(Some(FieldSide::Left)));
        assert_eq!(trainer.restarts, 2);
    }

    #[test]
    fn the_same_seed_places_the_ball_in_the_same_places() {
        let run = |seed| {
            let mut trainer = Trainer::new(plan(), seed);
            (0..100)
                .flat_map(|i| trainer.step(i as f64, Some(PlayMode::PlayOn), true))
                .filter_map(|c| ball_at(&c))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
        assert!(run(3).len() >= 9);
    }
}
