//! The world state's fast paths give the answers of the plain ones: the name index against a
//! scan of the objects, sensing candidates from shared per-object priors against one
//! prediction per object, the covering gaze's direction against the candidate, and published
//! confidences (kept from the end of a frame) against ones worked out afresh.

mod world_support;

use std::sync::Arc;

use strata_robot::control::active_vision::GazeCandidate;
use strata_robot::geometry::{Odometry, Point, Pose, normalize_angle};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::world::{
    ObjectEstimate, ObjectId, PosePrior, SensingCandidate, WorldModel, WorldState,
};
use strata_runtime::Time;
use world_support::{BALL, DT, Sim, config, patrol_step, plain_sensing_candidate};

/// A world state with a tracked ball, a localized pose and untracked landmarks.
fn state() -> WorldState {
    let prior = PosePrior { pose: Pose::new(0.5, -0.3, 0.2), sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let ball = Point::<strata_robot::geometry::Robot>::new(2.0, 0.4);
    let mut t = 0.0;
    for _ in 0..10 {
        t += DT;
        let stamp = Time::from_secs_f64(t);
        let observations = vec![Observation {
            class: BALL,
            variant: None,
            range: ball.range(),
            bearing: ball.bearing(),
            orientation: None,
            range_sigma: 0.1,
            bearing_sigma: 0.03,
        }];
        let view = ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 };
        let camera = Some(CameraPercepts { stamp, view, observations });
        world.process(Odometry::ZERO, &Percepts { stamp, camera, ..Percepts::default() });
    }
    world.state()
}

fn scan<'a>(world: &'a WorldState, name: &str) -> Option<&'a ObjectEstimate> {
    world.objects.iter().find(|o| o.name == name)
}

fn same(a: Option<&ObjectEstimate>, b: Option<&ObjectEstimate>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => std::ptr::eq(a, b),
        (None, None) => true,
        _ => false,
    }
}

#[test]
fn the_name_index_finds_what_a_scan_finds() {
    let world = state();
    assert!(world.objects.len() > 5);
    let mut names: Vec<String> = world.objects.iter().map(|o| o.name.to_string()).collect();
    names.extend(
        ["goal_post", "corner", "", "ball#0", "nothing", "a much longer name than any"]
            .map(String::from),
    );
    for name in &names {
        assert!(same(world.object(name), scan(&world, name)), "{name}");
    }
    assert!(world.object("ball").is_some_and(|b| b.tracked));
}

#[test]
fn replaced_objects_are_scanned_not_indexed() {
    let world = state();
    // The same objects in another order, and a list with one object twice: the index (built
    // for the model's layout) must not answer for them.
    let mut reversed = world.clone();
    reversed.objects = world.objects.iter().rev().cloned().collect::<Vec<_>>().into();
    let mut doubled = world.clone();
    let mut list: Vec<ObjectEstimate> = world.objects.to_vec();
    list.swap(0, 3);
    list[1] = list[3].clone();
    doubled.objects = Arc::from(list);
    // And a state read back without its index.
    let mut bare = world.clone();
    bare.index = Default::default();
    for state in [&reversed, &doubled, &bare] {
        for o in world.objects.iter() {
            assert!(same(state.object(&o.name), scan(state, &o.name)), "{}", o.name);
        }
    }
}

#[test]
fn sensing_candidates_from_shared_priors_match_per_object_predictions() {
    let world = state();
    let mut priors = Vec::new();
    world.observation_priors_into(&mut priors);
    let mut reused = SensingCandidate::default();
    for direction in [-2.0, -0.7, 0.0, 0.3, 1.1, 2.0] {
        for (fov, range, min_visibility) in [(1.06, 6.0, 0.05), (0.5, 3.0, 0.0), (2.0, 9.0, 0.5)] {
            let view = ViewCone { direction, fov, range, near: 0.0 };
            let expected = plain_sensing_candidate(&world, &view, min_visibility).observations;
            assert_eq!(world.sensing_candidate(&view, min_visibility).observations, expected);
            world.sensing_candidate_into(&priors, &view, min_visibility, &mut reused);
            assert_eq!(reused.observations, expected);
        }
    }
}

/// The covering gaze as it was first written: bearings and offsets collected, then folded.
fn covering_reference(world: &WorldState, ids: &[ObjectId], usable_fov: f64) -> Option<f64> {
    let bearings: Vec<f64> =
        ids.iter().filter_map(|id| world.get(*id)).map(|o| o.position.bearing()).collect();
    if bearings.len() != ids.len() || bearings.is_empty() {
        return None;
    }
    let reference = bearings[0];
    let offsets: Vec<f64> = bearings.iter().map(|b| normalize_angle(b - reference)).collect();
    let (lo, hi) = offsets.iter().fold((0.0f64, 0.0f64), |(lo, hi), o| (lo.min(*o), hi.max(*o)));
    (hi - lo <= usable_fov).then(|| normalize_angle(reference + (lo + hi) / 2.0))
}

#[test]
fn the_covering_direction_is_the_covering_candidates() {
    let world = state();
    let ids: Vec<ObjectId> = world.objects.iter().map(|o| o.id).collect();
    let sets: Vec<Vec<ObjectId>> = vec![
        vec![],
        vec![ids[0]],
        vec![ids[0], ids[1]],
        vec![ids[2], ids[0], ids[5]],
        ids.clone(),
        vec![ids[0], ObjectId(999)],
    ];
    for set in &sets {
        for fov in [0.3, 1.0, 3.0, 7.0] {
            let expected = covering_reference(&world, set, fov).map(f64::to_bits);
            let candidate = GazeCandidate::covering(&world, set, fov, "c").map(|c| c.direction);
            let direction = GazeCandidate::covering_direction(&world, set.iter().copied(), fov);
            assert_eq!(candidate.map(f64::to_bits), expected, "{set:?} {fov}");
            assert_eq!(direction.map(f64::to_bits), expected, "{set:?} {fov}");
        }
    }
}

/// Every published confidence is the model's confidence at the time of publication, bit for
/// bit, whatever happened since the last frame.
fn assert_published_confidences_are_current(world: &WorldModel, when: &str) {
    let state = world.state();
    for o in state.objects.iter() {
        let fresh = world.object_confidence(o.id);
        assert_eq!(o.confidence.to_bits(), fresh.to_bits(), "{} {when}", o.name);
    }
}

#[test]
fn published_confidences_are_worked_out_afresh_after_any_change() {
    let prior = PosePrior { pose: Pose::new(-1.0, 0.5, 0.3), sigma: [0.05, 0.05, 0.02] };
    let mut world = WorldModel::new(config(Some(prior))).expect("valid config");
    let mut sim = Sim::new(7, Pose::new(-1.0, 0.5, 0.3));
    sim.ball_velocity = nalgebra::Vector2::new(0.4, -0.2);
    assert_published_confidences_are_current(&world, "before any frame");
    for frame in 0..120 {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        assert_published_confidences_are_current(&world, "after a frame");
        // Between a frame and the publication: each way the model can change.
        match frame % 6 {
            0 => world.predict(Odometry { dx: 0.02, dy: 0.0, dtheta: 0.05 }),
            1 => world.advance_to(Time::from_secs_f64(sim.time + 0.5 * DT)),
            2 => world.note_frame_without_image(&Percepts::default()),
            3 => world.update(&CameraPercepts {
                stamp: Time::from_secs_f64(sim.time + 0.7 * DT),
                view: ViewCone { direction: sim.head_yaw(), fov: sim.fov, range: 6.0, near: 0.0 },
                observations: Vec::new(),
            }),
            4 if frame == 100 => {
                world.command(strata_robot::world::WorldCommand::Kidnapped).expect("accepted")
            }
            _ => {}
        }
        assert_published_confidences_are_current(&world, &format!("after change {frame}"));
    }
    world.command(strata_robot::world::WorldCommand::Reset).expect("accepted");
    assert_published_confidences_are_current(&world, "after a reset");
}
