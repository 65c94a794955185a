//! The world-modeling module publishes with [`WorldModel::publish`], which writes into an object
//! list published before when no reader holds it any more and shares per-publication work
//! between objects (the heading's trigonometry, the estimate of objects nothing locates). It
//! must give [`WorldModel::state`]'s world state bit for bit, never change a list a reader
//! still holds, and place velocities on the field as [`Pose::vector_to_field`] does.

mod world_support;

use std::collections::VecDeque;
use std::sync::Arc;

use strata_robot::geometry::{Odometry, Pose};
use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    ObjectKind, ObjectOfInterest, PosePrior, WorldCommand, WorldModel, WorldModelConfig, WorldState,
};
use world_support::{Sim, config, patrol_step};

/// The test layout with obstacle tracks too (never observed here: untracked objects that
/// have no map position).
fn layout(initial: Option<PosePrior>) -> WorldModelConfig {
    let mut config = config(initial);
    config.objects.push(ObjectOfInterest {
        name: "obstacle".to_owned(),
        class: ObjectClass(30),
        variant: None,
        kind: ObjectKind::Obstacle {
            max_tracks: 3,
            acceleration_noise: 0.5,
            velocity_decay: 1.0,
            max_speed: 0.6,
        },
        confidence: None,
    });
    config
}

/// Debug prints every float with its sign and shortest round-trip digits: equal texts are
/// equal states, bit for bit (NaNs aside).
fn text(state: &WorldState) -> String {
    format!("{state:?}")
}

fn check_velocities_on_the_field(state: &WorldState) {
    for o in state.objects.iter() {
        let expected = o.velocity.map(|v| state.pose.pose.vector_to_field(v));
        let bits = |v: Option<strata_robot::geometry::Vector<strata_robot::geometry::Field>>| {
            v.map(|v| (v.x.to_bits(), v.y.to_bits()))
        };
        assert_eq!(bits(o.field_velocity), bits(expected), "{}", o.name);
    }
}

/// Runs a patrol, publishing after every frame while `holding` readers keep the newest
/// states; returns how many publications reused a list.
fn run(initial: Option<PosePrior>, seed: u64, frames: usize) -> usize {
    let mut world = WorldModel::new(layout(initial)).expect("valid config");
    let mut sim = Sim::new(seed, Pose::new(-1.0, 0.5, 0.3));
    sim.ball_velocity = nalgebra::Vector2::new(0.4, -0.2);
    let mut held: VecDeque<(WorldState, String)> = VecDeque::new();
    let mut reused = 0;
    let mut free_lists: Vec<usize> = Vec::new();
    for frame in 0..frames {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        if frame == frames / 2 {
            world.command(WorldCommand::Kidnapped).expect("accepted");
        }
        if frame % 37 == 5 {
            world.predict(Odometry { dx: 0.01, dy: 0.0, dtheta: -0.03 });
        }
        let plain = world.state();
        let published = world.publish();
        assert_eq!(text(&published), text(&plain), "frame {frame}");
        check_velocities_on_the_field(&published);
        let list = Arc::as_ptr(&published.objects).cast::<u8>() as usize;
        if free_lists.contains(&list) {
            reused += 1;
        }
        // Readers hold between none and three of the newest states.
        let holding = frame % 4;
        held.push_back((published.clone(), text(&published)));
        while held.len() > holding {
            let (state, _) = held.pop_front().expect("not empty");
            let ptr = Arc::as_ptr(&state.objects).cast::<u8>() as usize;
            drop(state);
            free_lists.push(ptr);
        }
        // A list readers hold is never written over.
        for (state, was) in &held {
            assert_eq!(&text(state), was, "frame {frame}: a held state changed");
        }
        drop(published);
        drop(plain);
    }
    reused
}

#[test]
fn publications_are_the_plain_state_bit_for_bit_localized() {
    let prior = PosePrior { pose: Pose::new(-1.0, 0.5, 0.3), sigma: [0.05, 0.05, 0.02] };
    let reused = run(Some(prior), 7, 240);
    assert!(reused > 60, "lists reused {reused} times");
}

#[test]
fn publications_are_the_plain_state_bit_for_bit_lost() {
    // No prior: lost until recovery; every untracked object shares the unknown estimate.
    let reused = run(None, 11, 180);
    assert!(reused > 40, "lists reused {reused} times");
}
