//! The field as one team sees it: the team frame has its own goal at negative x, whichever end
//! of the field the team defends, so every behavior is written once.

use strata_robot::geometry::{Global as FieldFrame, Point, Pose};
use strata_spl::Field;
use strata_spl::field::{Landmark, Side};

/// Team-frame geometry the behaviors need, precomputed.
#[derive(Clone, Debug, PartialEq)]
pub struct TeamField {
    pub field: Field,
    /// +1 when this team attacks the field's positive x, -1 otherwise.
    pub attack_sign: f64,
    pub half_length: f64,
    pub half_width: f64,
    pub goal_half_width: f64,
    pub penalty_area_length: f64,
    pub penalty_area_half_width: f64,
    pub center_circle_radius: f64,
}

impl TeamField {
    pub fn new(field: Field, attack_sign: f64) -> TeamField {
        let d = field.dimensions().clone();
        TeamField {
            attack_sign: if attack_sign < 0.0 { -1.0 } else { 1.0 },
            half_length: d.field_length / 2.0,
            half_width: d.field_width / 2.0,
            goal_half_width: d.goal_inner_width / 2.0,
            penalty_area_length: d.penalty_area.length,
            penalty_area_half_width: d.penalty_area.width / 2.0,
            center_circle_radius: d.center_circle_diameter / 2.0,
            field,
        }
    }

    /// A point of the field's own frame, in this team's frame.
    pub fn to_team(&self, x: f64, y: f64) -> Point<FieldFrame> {
        Point::new(self.attack_sign * x, self.attack_sign * y)
    }

    /// A team-frame pose in the field's own frame (what the simulator and logs use).
    pub fn pose_to_field(&self, pose: Pose) -> Pose {
        if self.attack_sign > 0.0 {
            pose
        } else {
            Pose::new(-pose.x, -pose.y, pose.theta + std::f64::consts::PI)
        }
    }

    /// Which goal a landmark belongs to, from this team's point of view.
    pub fn team_side(&self, side: Side) -> Side {
        match (side, self.attack_sign > 0.0) {
            (s, true) => s,
            (Side::Own, false) => Side::Opponent,
            (Side::Opponent, false) => Side::Own,
        }
    }

    pub fn own_goal(&self) -> Point<FieldFrame> {
        Point::new(-self.half_length, 0.0)
    }

    pub fn opponent_goal(&self) -> Point<FieldFrame> {
        Point::new(self.half_length, 0.0)
    }

    /// The posts of a goal (left, right as seen from the field centre).
    pub fn posts(&self, side: Side) -> [Point<FieldFrame>; 2] {
        let x = match side {
            Side::Own => -self.half_length,
            Side::Opponent => self.half_length,
        };
        [Point::new(x, self.goal_half_width), Point::new(x, -self.goal_half_width)]
    }

    pub fn is_inside(&self, p: Point<FieldFrame>, margin: f64) -> bool {
        p.x.abs() <= self.half_length + margin && p.y.abs() <= self.half_width + margin
    }

    pub fn in_own_penalty_area(&self, p: Point<FieldFrame>, margin: f64) -> bool {
        p.x <= -self.half_length + self.penalty_area_length + margin
            && p.y.abs() <= self.penalty_area_half_width + margin
    }

    /// Where the head referee stands, in the team frame: on the halfway line, `behind_line` m
    /// outside the side line at the field's negative y (the field's own frame, as the
    /// simulator places it).
    pub fn referee(&self, behind_line: f64) -> Point<FieldFrame> {
        self.to_team(0.0, -(self.half_width + behind_line))
    }

    /// Every landmark with its position in the team frame.
    pub fn landmarks(&self) -> impl Iterator<Item = (&Landmark, Point<FieldFrame>)> + '_ {
        self.field.landmarks().iter().map(|l| {
            let p = l.position();
            (l, self.to_team(p.x, p.y))
        })
    }
}
