//! The world-modeling module publishes with [`WorldModel::publish`], which writes into an object
//! list published before when no reader holds it any more and shares per-publication work
//! between objects (the heading's trigonometry, the estimate of objects nothing locates). It
//! must give [`WorldModel::state`]'s world state bit for bit, never change a list a reader
//! still holds, and place velocities on the field as [`Pose::vector_to_global`] does.

mod world_support;

use std::collections::VecDeque;
use std::sync::Arc;

use strata_robot::geometry::Pose;
use strata_robot::world::{PosePrior, WorldState};
use world_support::{kidnapped_patrol, state_text};

fn check_velocities_on_the_field(state: &WorldState) {
    for o in state.objects.iter() {
        let expected = o.velocity.map(|v| state.pose.pose.vector_to_global(v));
        let bits = |v: Option<strata_robot::geometry::Vector<strata_robot::geometry::Global>>| {
            v.map(|v| (v.x.to_bits(), v.y.to_bits()))
        };
        assert_eq!(bits(o.global_velocity), bits(expected), "{}", o.name);
    }
}

/// Runs a patrol, publishing after every frame while `holding` readers keep the newest
/// states; returns how many publications reused a list.
fn run(initial: Option<PosePrior>, seed: u64, frames: usize) -> usize {
    let mut held: VecDeque<(WorldState, String)> = VecDeque::new();
    let mut reused = 0;
    let mut free_lists: Vec<usize> = Vec::new();
    kidnapped_patrol(initial, seed, frames, |frame, world| {
        let plain = world.state();
        let published = world.publish();
        assert_eq!(state_text(&published), state_text(&plain), "frame {frame}");
        check_velocities_on_the_field(&published);
        let list = Arc::as_ptr(&published.objects).cast::<u8>() as usize;
        if free_lists.contains(&list) {
            reused += 1;
        }
        // Readers hold between none and three of the newest states.
        let holding = frame % 4;
        held.push_back((published.clone(), state_text(&published)));
        while held.len() > holding {
            let (state, _) = held.pop_front().expect("not empty");
            let ptr = Arc::as_ptr(&state.objects).cast::<u8>() as usize;
            drop(state);
            free_lists.push(ptr);
        }
        // A list readers hold is never written over.
        for (state, was) in &held {
            assert_eq!(&state_text(state), was, "frame {frame}: a held state changed");
        }
    });
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
