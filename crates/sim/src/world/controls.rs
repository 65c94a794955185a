//! Ground truth for experiments, logs and viewers, and the controls experiments use to set up
//! and disturb the world. Robots see neither.

use strata_robot::platform::{BodyMotionState, FallDirection};
use strata_robot::{Global as FieldFrame, Point, Pose, Vector};
use strata_spl::gamecontroller::{GameState, Penalty, SetPlay};

use super::{Outbox, RobotSlot, SimError, Simulation};
use crate::body::{Body, FallCause, push_direction};
use crate::physics::BallScript;
use crate::truth::{BallTruth, Event, EventKind, GameTruth, GroundTruth, RobotId, RobotTruth};

impl Simulation {
    // ---------------------------------------------------------------------------------------
    // Ground truth.

    pub(super) fn robot_truth(&self, robot: &RobotSlot) -> RobotTruth {
        let body = &robot.body;
        RobotTruth {
            id: robot.id,
            team_number: self.team_number(robot.id.team),
            present: robot.present,
            pose: body.pose,
            team_pose: self.field_to_team(robot.id.team, body.pose),
            velocity: body.velocity,
            head: body.head,
            body: if robot.present { body.motion_state() } else { BodyMotionState::Limp },
            falling: body.is_falling(),
            fallen: body.is_fallen(),
            fall_onset: robot.last_fall.map(|f| f.onset),
            fall_direction: robot.last_fall.map(|f| f.direction),
            fall_cause: robot.last_fall.map(|f| f.cause),
            penalty: robot.penalty,
            penalty_remaining: robot.penalty_remaining,
        }
    }

    /// The true state of one robot.
    pub fn robot(&self, robot: RobotId) -> Result<RobotTruth, SimError> {
        let slot = self.slot(robot)?;
        Ok(self.robot_truth(&self.robots[slot]))
    }

    pub fn ball(&self) -> BallTruth {
        BallTruth {
            position: self.ball.position,
            velocity: self.ball.velocity,
            scripted: self.ball.script.is_some(),
            last_touch: self.referee.last_touch,
        }
    }

    pub fn game(&self) -> GameTruth {
        let r = &self.referee;
        GameTruth {
            state: r.state,
            set_play: r.set_play,
            first_half: r.first_half,
            kicking_team: r.kicking_team,
            secs_remaining: r.clock,
            score: r.score,
            team_numbers: [self.team_number(0), self.team_number(1)],
            attack_sign: r.attack_sign,
            message_budget: r.budget,
            game_over: r.game_over,
        }
    }

    /// Everything true about the world now, with every event so far.
    pub fn ground_truth(&self) -> GroundTruth {
        let mut truth = self.snapshot();
        truth.events = self.events.clone();
        truth
    }

    /// The ground truth without the event list (cheap enough for every step).
    pub fn snapshot(&self) -> GroundTruth {
        GroundTruth {
            time: self.time,
            robots: self.robots.iter().map(|r| self.robot_truth(r)).collect(),
            ball: self.ball(),
            game: self.game(),
            comms: self.comms.clone(),
            events: Vec::new(),
        }
    }

    /// The event log.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Events from index `start` of the log on.
    pub fn events_since(&self, start: usize) -> &[Event] {
        self.events.get(start..).unwrap_or(&[])
    }

    // ---------------------------------------------------------------------------------------
    // Experiment controls.

    /// Moves a robot instantly (a kidnapping): odometry does not see it.
    pub fn teleport(&mut self, robot: RobotId, pose: Pose) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if !pose.is_finite() {
            return Err(SimError::Invalid(format!("non-finite pose {pose:?}")));
        }
        self.robots[slot].body.place(pose);
        self.event(EventKind::Teleported { robot, pose });
        Ok(())
    }

    /// Pushes a robot: it moves with `velocity` (field frame, m/s), decaying, and falls when
    /// the push is faster than `robot.fall.push_fall_speed`.
    pub fn push(&mut self, robot: RobotId, velocity: Vector<FieldFrame>) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if !velocity.is_finite() {
            return Err(SimError::Invalid(format!("non-finite push {velocity:?}")));
        }
        self.event(EventKind::Pushed { robot, velocity });
        let threshold = self.config.robot.fall.push_fall_speed;
        let body = &mut self.robots[slot].body;
        body.push = body.push + velocity;
        if velocity.norm() >= threshold {
            let direction = push_direction(&body.pose, velocity);
            if body.start_fall(direction) {
                self.record_fall(slot, direction, FallCause::Push);
            }
        }
        Ok(())
    }

    /// Makes a robot fall now, in `direction`.
    pub fn force_fall(&mut self, robot: RobotId, direction: FallDirection) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if self.robots[slot].body.start_fall(direction) {
            self.record_fall(slot, direction, FallCause::Forced);
        }
        Ok(())
    }

    /// Places the ball, with a velocity (m/s, field frame); ends any script.
    pub fn place_ball(
        &mut self,
        position: Point<FieldFrame>,
        velocity: Vector<FieldFrame>,
    ) -> Result<(), SimError> {
        if !position.is_finite() || !velocity.is_finite() {
            return Err(SimError::Invalid("non-finite ball position or velocity".to_owned()));
        }
        self.put_ball(position);
        self.ball.velocity = velocity;
        self.event(EventKind::BallPlaced { position });
        Ok(())
    }

    /// Moves the ball along `script` at its speed, ignoring physics, until its end.
    pub fn script_ball(&mut self, script: BallScript) -> Result<(), SimError> {
        if script.waypoints.is_empty()
            || script.waypoints.iter().any(|p| !p.is_finite())
            || !(script.speed.is_finite() && script.speed >= 0.0)
        {
            return Err(SimError::Invalid(
                "a ball script needs waypoints and a non-negative speed".to_owned(),
            ));
        }
        self.ball.position = script.waypoints[0];
        self.ball.velocity = Vector::new(0.0, 0.0);
        self.event(EventKind::BallScripted {
            waypoints: script.waypoints.clone(),
            speed: script.speed,
        });
        self.ball.script = Some(script);
        Ok(())
    }

    /// Sets the game state (a manual referee, or a test jumping straight to Playing).
    pub fn set_game_state(&mut self, state: GameState) {
        let mut decisions = Vec::new();
        self.referee.set_state(state, &mut decisions);
        for decision in &decisions {
            self.carry_out(decision);
        }
    }

    /// Sets the team (index) taking the next kick-off or set play.
    pub fn set_kicking_team(&mut self, team: Option<usize>) {
        self.referee.kicking_team = team.map(|t| t.min(1));
    }

    /// Awards a set play to `team` (index) with the ball where it is.
    pub fn start_set_play(&mut self, set_play: SetPlay, team: usize) {
        self.referee.start_set_play(set_play, team.min(1), self.ball.position);
    }

    /// Changes the team broadcast's packet loss at run time.
    pub fn set_packet_loss(&mut self, loss: f64) -> Result<(), SimError> {
        if !(0.0..=1.0).contains(&loss) {
            return Err(SimError::Invalid(format!("packet loss {loss} is not in [0, 1]")));
        }
        self.broadcast_loss = loss;
        self.event(EventKind::PacketLoss { loss });
        Ok(())
    }

    pub fn packet_loss(&self) -> f64 {
        self.broadcast_loss
    }

    /// Takes a robot out of the world (a client that disconnected).
    pub fn remove_robot(&mut self, robot: RobotId) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if !self.robots[slot].present {
            return Ok(());
        }
        let r = &mut self.robots[slot];
        r.present = false;
        r.outbox = Outbox::default();
        r.penalty = Penalty::None;
        r.penalty_remaining = None;
        self.broadcast.forget(slot);
        self.event(EventKind::RobotRemoved { robot });
        Ok(())
    }

    /// Puts a robot (back) into the world: at its half-start place before the game starts,
    /// otherwise where penalized robots come back.
    pub fn add_robot(&mut self, robot: RobotId) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if self.robots[slot].present {
            return Ok(());
        }
        let pose = if self.referee.state == GameState::Initial {
            self.start_pose(robot)
        } else {
            self.reentry_pose(robot)
        };
        let r = &mut self.robots[slot];
        r.present = true;
        r.body = Body::new(pose);
        r.outbox = Outbox::default();
        self.event(EventKind::RobotAdded { robot });
        Ok(())
    }

    /// Penalizes a robot: it leaves the field until `duration` (s) has run in Ready and
    /// Playing, or until [`Simulation::unpenalize`] when `None`.
    pub fn penalize(
        &mut self,
        robot: RobotId,
        penalty: Penalty,
        duration: Option<f64>,
    ) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if penalty == Penalty::None {
            return self.unpenalize(robot);
        }
        self.penalize_slot(slot, penalty, duration);
        Ok(())
    }

    pub(super) fn penalize_slot(&mut self, slot: usize, penalty: Penalty, duration: Option<f64>) {
        let id = self.robots[slot].id;
        let pose = self.holding_pose(id);
        let r = &mut self.robots[slot];
        r.penalty = penalty;
        r.penalty_remaining = duration.map(|d| d.max(0.0));
        r.body.place(pose);
        self.event(EventKind::Penalty { robot: id, penalty, duration });
    }

    /// Ends a robot's penalty: it comes back at the side line.
    pub fn unpenalize(&mut self, robot: RobotId) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        if self.robots[slot].penalty != Penalty::None {
            self.unpenalize_slot(slot);
        }
        Ok(())
    }

    pub(super) fn unpenalize_slot(&mut self, slot: usize) {
        let id = self.robots[slot].id;
        let pose = self.reentry_pose(id);
        let r = &mut self.robots[slot];
        r.penalty = Penalty::None;
        r.penalty_remaining = None;
        r.body.place(pose);
        self.event(EventKind::Unpenalized { robot: id });
    }
}
