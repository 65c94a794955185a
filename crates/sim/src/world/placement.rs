//! Where the referee puts robots: side lines at the start of a half, formation places at a
//! kick-off, the penalty bench and the re-entry point.

use strata_robot::Pose;

use super::Simulation;
use crate::truth::RobotId;

impl Simulation {
    // ---------------------------------------------------------------------------------------
    // Placements.

    /// A pose in a team's frame (own goal at -x) to the field frame.
    pub(super) fn team_to_field(&self, team: usize, pose: Pose) -> Pose {
        if self.referee.attack_sign[team] > 0.0 {
            pose
        } else {
            Pose::new(-pose.x, -pose.y, pose.theta + std::f64::consts::PI)
        }
    }

    pub(super) fn field_to_team(&self, team: usize, pose: Pose) -> Pose {
        // The mapping is its own inverse.
        self.team_to_field(team, pose)
    }

    /// Where a robot stands at the start of a half: on a side line of its own half, facing
    /// into the field.
    pub(super) fn start_pose(&self, robot: RobotId) -> Pose {
        let hl = self.field.half_length();
        let hw = self.field.half_width();
        let n = f64::from(self.config.referee.players_per_team.max(2) - 1);
        let k = f64::from(robot.player - 1);
        let x = -hl * (0.85 - 0.7 * k / n);
        let side = if robot.player % 2 == 1 { 1.0 } else { -1.0 };
        let pose = Pose::new(x, side * hw, -side * std::f64::consts::FRAC_PI_2);
        self.team_to_field(robot.team, pose)
    }

    /// Where a penalized robot comes back: the side line at the penalty mark of its own half,
    /// on the side away from the ball.
    pub(super) fn reentry_pose(&self, robot: RobotId) -> Pose {
        let hl = self.field.half_length();
        let hw = self.field.half_width();
        let x = -(hl - self.field.dimensions().penalty_mark_distance);
        let ball = self
            .field_to_team(robot.team, Pose::new(self.ball.position.x, self.ball.position.y, 0.0));
        let side = if ball.y > 0.0 { -1.0 } else { 1.0 };
        let pose = Pose::new(x, side * hw, -side * std::f64::consts::FRAC_PI_2);
        self.team_to_field(robot.team, pose)
    }

    /// Where a penalized robot waits: off the field beside its re-entry point.
    pub(super) fn holding_pose(&self, robot: RobotId) -> Pose {
        let entry = self.reentry_pose(robot);
        let border = self.field.dimensions().border_strip_width;
        let out = entry.y.signum() * (self.field.half_width() + border * 0.6);
        Pose::new(entry.x, out, entry.theta)
    }

    pub(super) fn formation_pose(&self, robot: RobotId) -> Pose {
        let hl = self.field.half_length();
        let hw = self.field.half_width();
        let formation = &self.config.referee.formation;
        let index = usize::from(robot.player - 1);
        let [fx, fy] = formation.get(index).copied().unwrap_or_else(|| {
            let extra = (index - formation.len()) as f64;
            [-0.5, (0.8 - 0.3 * extra).clamp(-0.9, 0.9)]
        });
        self.team_to_field(robot.team, Pose::new(fx * hl, fy * hw, 0.0))
    }

    /// The referee's placement at Set: robots outside their own half, and defenders inside the
    /// centre circle, go to their formation place.
    pub(super) fn place_for_kick_off(&mut self) {
        let radius = self.config.robot.radius;
        let circle = self.field.centre_circle().radius;
        let kicking = self.referee.kicking_team;
        for slot in 0..self.robots.len() {
            let robot = &self.robots[slot];
            if !robot.active() {
                continue;
            }
            let id = robot.id;
            let local = self.field_to_team(id.team, robot.body.pose);
            let in_own_half = local.x <= -radius;
            let clear_of_circle =
                kicking == Some(id.team) || local.x.hypot(local.y) >= circle + radius;
            if !(in_own_half && clear_of_circle) || robot.body.is_down() {
                let pose = self.formation_pose(id);
                self.robots[slot].body.place(pose);
            }
        }
    }
}
