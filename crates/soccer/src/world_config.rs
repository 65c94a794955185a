//! The objects of interest of robot soccer, as world modeling's configuration: the ball, the
//! field's landmarks and painted lines (in the team frame) and the other robots as obstacles.

use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    FieldLinesConfig, ObjectKind as WorldObjectKind, ObjectOfInterest, PoseConfig, Region,
    SymmetryHint, WorldModelConfig,
};
use strata_spl::field::{Colour, Landmark, Side};
use strata_spl::{LandmarkKind, ObjectKind};

use crate::field::TeamField;

pub const BALL: &str = "ball";
pub const OBSTACLE: &str = "robot";
pub const GOAL_POST: &str = "goal_post";
pub const OWN_GOAL_POST: &str = "own_goal_post";
pub const OPPONENT_GOAL_POST: &str = "opponent_goal_post";

fn class(kind: ObjectKind) -> ObjectClass {
    ObjectClass(kind.code())
}

/// Ball rolling friction the world model assumes, m/s^2 (carpet).
pub const BALL_FRICTION: f64 = 0.5;

/// World-model object names of the landmark groups the field has (for gaze candidates).
pub fn landmark_groups(field: &TeamField) -> Vec<String> {
    let mut groups = Vec::new();
    let colours = field.field.dimensions().goal_colours;
    if colours.own == Colour::White && colours.opponent == Colour::White {
        groups.push(GOAL_POST.to_owned());
    } else {
        groups.push(OWN_GOAL_POST.to_owned());
        groups.push(OPPONENT_GOAL_POST.to_owned());
    }
    for beacon in &field.field.dimensions().beacons {
        groups.push(format!("beacon_{}", beacon.name));
    }
    for (name, kind) in [
        ("l_crossing", LandmarkKind::LCrossing),
        ("t_crossing", LandmarkKind::TCrossing),
        ("x_crossing", LandmarkKind::XCrossing),
        ("centre_circle", LandmarkKind::CenterCircle),
        ("penalty_mark", LandmarkKind::PenaltyMark),
    ] {
        if field.field.landmarks_of(kind).next().is_some() {
            groups.push(name.to_owned());
        }
    }
    groups
}

/// The world-model configuration of one robot of the team that plays on `field`.
pub fn world_config(field: &TeamField) -> WorldModelConfig {
    let mut objects = vec![ObjectOfInterest {
        name: BALL.into(),
        class: class(ObjectKind::Ball),
        variant: None,
        kind: WorldObjectKind::Mobile {
            friction: BALL_FRICTION,
            acceleration_noise: 0.6,
            max_speed: 6.0,
        },
        confidence: None,
    }];
    let landmark = |name: &str, class: ObjectClass, variant: Option<u16>, positions: Vec<_>| {
        ObjectOfInterest {
            name: name.into(),
            class,
            variant,
            kind: WorldObjectKind::Landmark { positions, position_noise: 1e-4 },
            confidence: None,
        }
    };
    let colours = field.field.dimensions().goal_colours;
    let posts = |side: Side| -> Vec<_> {
        field
            .landmarks()
            .filter_map(|(l, p)| match l {
                Landmark::GoalPost { goal, .. } if field.team_side(*goal) == side => Some(p),
                _ => None,
            })
            .collect()
    };
    if colours.own == Colour::White && colours.opponent == Colour::White {
        let mut all = posts(Side::Own);
        all.extend(posts(Side::Opponent));
        objects.push(landmark(GOAL_POST, class(ObjectKind::GoalPost), None, all));
    } else {
        // Coloured goals: the camera tells them apart; which colour is ours depends on the end
        // of the field the team defends.
        let colour_of = |side: Side| {
            let field_side = field.team_side(side);
            match field_side {
                Side::Own => colours.own,
                Side::Opponent => colours.opponent,
            }
        };
        objects.push(landmark(
            OWN_GOAL_POST,
            class(ObjectKind::GoalPost),
            Some(colour_of(Side::Own).code()),
            posts(Side::Own),
        ));
        objects.push(landmark(
            OPPONENT_GOAL_POST,
            class(ObjectKind::GoalPost),
            Some(colour_of(Side::Opponent).code()),
            posts(Side::Opponent),
        ));
    }
    for (landmark_entry, position) in field.landmarks() {
        if let Landmark::Beacon { index, .. } = landmark_entry
            && let Some(beacon) = field.field.dimensions().beacons.get(*index)
        {
            objects.push(landmark(
                &format!("beacon_{}", beacon.name),
                class(ObjectKind::Beacon),
                Some(u16::try_from(*index).unwrap_or(u16::MAX)),
                vec![position],
            ));
        }
    }
    for (name, kind) in [
        ("l_crossing", LandmarkKind::LCrossing),
        ("t_crossing", LandmarkKind::TCrossing),
        ("x_crossing", LandmarkKind::XCrossing),
        ("centre_circle", LandmarkKind::CenterCircle),
        ("penalty_mark", LandmarkKind::PenaltyMark),
    ] {
        let positions: Vec<_> =
            field.landmarks().filter(|(l, _)| l.kind() == kind).map(|(_, p)| p).collect();
        if !positions.is_empty() {
            objects.push(landmark(name, class(kind.into()), None, positions));
        }
    }
    objects.push(ObjectOfInterest {
        name: OBSTACLE.into(),
        class: class(ObjectKind::Robot),
        variant: None,
        kind: WorldObjectKind::Obstacle {
            max_tracks: 8,
            acceleration_noise: 0.5,
            velocity_decay: 1.0,
            max_speed: 0.6,
        },
        confidence: None,
    });
    let margin = field.field.dimensions().border_strip_width;
    let own_half = Region {
        min_x: -field.half_length - margin,
        max_x: 0.0,
        min_y: -field.half_width - margin,
        max_y: field.half_width + margin,
    };
    let segments = field
        .field
        .lines()
        .iter()
        .map(|l| [field.to_team(l.start.x, l.start.y), field.to_team(l.end.x, l.end.y)])
        .collect();
    WorldModelConfig {
        objects,
        lines: FieldLinesConfig {
            class: Some(class(ObjectKind::FieldLine)),
            segments,
            // The simulator's default camera noise (strata_sim::noise).
            direction_sigma: 0.05,
            // Half a line's width, and room for the pose's error along the line.
            end_margin: 0.1,
            // Beyond it a line is seen too flat for its direction to tell much.
            max_range: 5.0,
            // The simulator's camera (strata_sim's `min_line_length`).
            min_length: 0.15,
        },
        pose: PoseConfig {
            bounds: Some(Region {
                min_x: -field.half_length - margin,
                max_x: field.half_length + margin,
                min_y: -field.half_width - margin,
                max_y: field.half_width + margin,
            }),
            // Robots enter the field in their own half: the hint that breaks the field's
            // symmetry until the game says otherwise.
            hints: vec![SymmetryHint::Region { region: own_half }],
            ..PoseConfig::default()
        },
        ..WorldModelConfig::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::world::WorldModel;

    #[test]
    fn both_presets_give_valid_world_models_in_both_team_frames() {
        for preset in ["spl", "paper2010"] {
            for sign in [1.0, -1.0] {
                let field =
                    TeamField::new(strata_spl::Field::preset(preset).expect("preset"), sign);
                let config = world_config(&field);
                let model = WorldModel::new(config).expect("valid world config");
                assert!(model.object_id(BALL).is_some(), "{preset}");
            }
        }
    }

    #[test]
    fn coloured_goals_swap_with_the_attack_direction() {
        let field = strata_spl::Field::preset("paper2010").expect("preset");
        let colours = field.dimensions().goal_colours;
        let a = world_config(&TeamField::new(field.clone(), 1.0));
        let b = world_config(&TeamField::new(field, -1.0));
        let own = |c: &WorldModelConfig| {
            c.objects.iter().find(|o| o.name == OWN_GOAL_POST).and_then(|o| o.variant)
        };
        assert_eq!(own(&a), Some(colours.own.code()));
        assert_eq!(own(&b), Some(colours.opponent.code()));
    }
}
