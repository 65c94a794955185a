//! The patrol's objects of interest, as world modeling's configuration: fiducial markers and
//! wall corners (landmarks: known positions, they localize the robot), the points of interest
//! (estimated like mobile objects that do not move: their positions are what an inspection
//! finds out) and an intruder (a mobile object).

use strata_robot::geometry::Pose;
use strata_robot::perception::PerceptionConfig;
use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    CameraNoise, ObjectConfidence, ObjectKind, ObjectOfInterest, PoseConfig, PosePrior,
    WorldModelConfig,
};

use crate::building::FloorPlan;

/// Camera classes of the patrol's platforms.
pub const MARKER: ObjectClass = ObjectClass(1);
pub const CORNER: ObjectClass = ObjectClass(2);
pub const POINT_OF_INTEREST: ObjectClass = ObjectClass(3);
pub const PERSON: ObjectClass = ObjectClass(4);

pub const CORNER_GROUP: &str = "corner";
pub const INTRUDER: &str = "intruder";

/// World-model name of marker `k`.
pub fn marker_name(k: usize) -> String {
    format!("marker_{k}")
}

/// World-model name of point of interest `k`.
pub fn poi_name(k: usize) -> String {
    format!("poi_{k}")
}

/// The landmark groups a gaze can be pointed at.
pub fn landmark_groups(plan: &FloorPlan) -> Vec<String> {
    let mut groups: Vec<String> = (0..plan.markers.len()).map(marker_name).collect();
    groups.push(CORNER_GROUP.to_owned());
    groups
}

/// The patrol has no signals among its camera's detections.
pub fn perception_config() -> PerceptionConfig {
    PerceptionConfig::default()
}

/// The robot's camera model: the noise perception attaches to each observation and world
/// modeling predicts (a little above the platform's own: a filter told the truth about its
/// noise and nothing about its model errors is overconfident).
pub fn camera_noise() -> CameraNoise {
    CameraNoise {
        range_sigma: 0.04,
        range_sigma_per_metre: 0.05,
        bearing_sigma: 0.025,
        use_percept_sigmas: true,
    }
}

/// The world model of a patrol robot that starts at `start`.
pub fn world_config(plan: &FloorPlan, start: Pose) -> WorldModelConfig {
    let mut objects: Vec<ObjectOfInterest> = plan
        .markers
        .iter()
        .enumerate()
        .map(|(k, position)| ObjectOfInterest {
            name: marker_name(k),
            class: MARKER,
            variant: u16::try_from(k).ok(),
            kind: ObjectKind::Landmark { positions: vec![*position], position_noise: 1e-4 },
            confidence: None,
        })
        .collect();
    objects.push(ObjectOfInterest {
        name: CORNER_GROUP.into(),
        class: CORNER,
        variant: None,
        kind: ObjectKind::Landmark { positions: plan.corners.clone(), position_noise: 1e-4 },
        confidence: None,
    });
    for k in 0..plan.points_of_interest.len() {
        objects.push(ObjectOfInterest {
            name: poi_name(k),
            class: POINT_OF_INTEREST,
            variant: u16::try_from(k).ok(),
            // A point of interest does not move: a rolling object that stops at once, with
            // almost no process noise, so that every look sharpens the estimate.
            kind: ObjectKind::Mobile { friction: 5.0, acceleration_noise: 0.002, max_speed: 0.05 },
            // Remembered for minutes, not the seconds of a ball.
            confidence: Some(ObjectConfidence { half_life: 120.0, sigma_half: 0.5 }),
        });
    }
    objects.push(ObjectOfInterest {
        name: INTRUDER.into(),
        class: PERSON,
        variant: None,
        kind: ObjectKind::Mobile { friction: 1.0, acceleration_noise: 0.4, max_speed: 1.5 },
        confidence: Some(ObjectConfidence { half_life: 10.0, sigma_half: 0.5 }),
    });
    WorldModelConfig {
        objects,
        camera: camera_noise(),
        pose: PoseConfig {
            // Robots are switched on at their docks: the building has no symmetry to break.
            initial: Some(PosePrior { pose: start, sigma: [0.05, 0.05, 0.05] }),
            bounds: Some(plan.bounds),
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
    fn the_office_gives_a_valid_world_model() {
        let plan = FloorPlan::office();
        let model = WorldModel::new(world_config(&plan, Pose::new(-5.5, 1.6, 0.0)))
            .expect("valid world config");
        assert!(model.object_id(&poi_name(3)).is_some());
        assert!(model.object_id(INTRUDER).is_some());
    }
}
