//! The world-modeling module in a module graph: percepts queued, odometry merged, the world
//! state published with the percepts' stamps.

mod world_support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use strata_robot::geometry::{Odometry, Pose};
use strata_robot::percept::Percepts;
use strata_robot::world::{
    PosePrior, WorldCommand, WorldModelConfig, WorldState, add_world_module,
};
use strata_runtime::{
    Context, GraphBuilder, HostConfig, Input, LockstepHost, Module, ModuleError, Policy, Time,
};
use world_support::{DT, Sim, config};

type States = Arc<Mutex<Vec<(Time, WorldState)>>>;

struct Keep {
    input: Input<WorldState>,
    states: States,
}

impl Module for Keep {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let mut states = self.states.lock().unwrap_or_else(|e| e.into_inner());
        for p in ctx.drain(self.input) {
            states.push((p.stamp, p.value));
        }
        Ok(())
    }
}

#[test]
fn the_module_filters_what_it_receives_and_publishes_stamped_world_states() {
    let start = Pose::new(-2.0, 0.5, 0.0);
    let mut graph = GraphBuilder::new();
    let ports = add_world_module(
        &mut graph,
        "world",
        config(Some(PosePrior { pose: start, sigma: [0.05, 0.05, 0.02] })),
    )
    .expect("valid config");
    let states: States = Arc::default();
    let keep = graph.add("keep", |p| {
        let input = p.input("world", Policy::queue(1000));
        (Keep { input, states: Arc::clone(&states) }, input)
    });
    graph.connect(ports.world_state, keep);
    graph.external(ports.percepts);
    graph.external(ports.odometry);
    graph.external(ports.commands);
    let mut host =
        LockstepHost::new(graph.build().expect("a valid graph"), HostConfig::with_seed(1));

    // Odometry at three times the camera rate; the reported increments are merged by the
    // connection into one per camera frame.
    let mut sim = Sim::new(11, start);
    let step = Odometry { dx: 0.2 * DT / 3.0, dy: 0.0, dtheta: 0.1 * DT / 3.0 };
    for frame in 0..90 {
        let t0 = sim.time;
        for k in 0..3 {
            let at = Time::from_secs_f64(t0 + DT * (f64::from(k) + 0.5) / 3.0);
            let odometry = sim.walk(step);
            host.inject(ports.odometry, odometry, at, at).expect("external");
        }
        sim.time += DT;
        sim.roll_ball(DT);
        let percepts: Percepts = sim.camera_frame();
        let stamp = percepts.stamp;
        host.inject(ports.percepts, percepts, stamp, stamp).expect("external");
        if frame == 60 {
            let prior = PosePrior { pose: sim.truth, sigma: [0.01, 0.01, 0.01] };
            host.inject(ports.commands, WorldCommand::SetPose { prior }, stamp, stamp)
                .expect("external");
        }
    }
    host.run_for(Duration::from_secs_f64(90.0 * DT + 0.1)).expect("runs");
    let states = states.lock().unwrap_or_else(|e| e.into_inner());
    assert_eq!(states.len(), 90, "one world state per camera frame");
    for (k, (stamp, state)) in states.iter().enumerate() {
        assert_eq!(*stamp, state.stamp);
        assert_eq!(*stamp, Time::from_secs_f64(DT * (k + 1) as f64));
    }
    let (_, last) = states.last().expect("published");
    assert!(!last.pose.lost);
    // The pose followed the merged odometry (the landmarks keep it near the truth).
    let e = last.pose.pose.position().distance(sim.truth.position());
    assert!(e < 0.15, "pose error {e}");
    assert!(last.objects.iter().any(|o| o.known));
}

#[test]
fn an_invalid_configuration_is_refused_when_the_module_is_added() {
    let mut graph = GraphBuilder::new();
    let mut cfg: WorldModelConfig = config(None);
    cfg.confidence.unknown_threshold = 1.5;
    let error = add_world_module(&mut graph, "world", cfg).expect_err("threshold above 1");
    assert_eq!(error.field, "confidence.unknown_threshold");
}

#[test]
fn a_placed_frame_without_an_image_is_filtered_and_published_at_once() {
    let start = Pose::new(-2.0, 0.5, 0.0);
    let mut graph = GraphBuilder::new();
    let ports = add_world_module(
        &mut graph,
        "world",
        config(Some(PosePrior { pose: start, sigma: [0.05, 0.05, 0.02] })),
    )
    .expect("valid config");
    let states: States = Arc::default();
    let keep = graph.add("keep", |p| {
        let input = p.input("world", Policy::queue(1000));
        (Keep { input, states: Arc::clone(&states) }, input)
    });
    graph.connect(ports.world_state, keep);
    graph.external(ports.percepts);
    graph.external(ports.odometry);
    let mut host =
        LockstepHost::new(graph.build().expect("a valid graph"), HostConfig::with_seed(2));
    let mut sim = Sim::new(12, start);
    for _ in 0..30 {
        sim.time += DT;
        let percepts = sim.camera_frame();
        let stamp = percepts.stamp;
        host.inject(ports.percepts, percepts, stamp, stamp).expect("external");
    }
    // 12 ms after the last image (no publication due): the platform saw the robot placed.
    let at = Time::from_secs_f64(sim.time + 0.012);
    let placed = Percepts { stamp: at, placed: true, ..Percepts::default() };
    host.inject(ports.percepts, placed, at, at).expect("external");
    host.run_for(Duration::from_secs_f64(30.0 * DT + 0.1)).expect("runs");
    let states = states.lock().unwrap_or_else(|e| e.into_inner());
    let (before, _) = states.split_at(states.len() - 1);
    assert!(before.iter().all(|(_, s)| !s.pose.lost), "localized before the placement");
    let (stamp, last) = states.last().expect("published");
    assert_eq!(*stamp, at, "the placed frame was published");
    assert!(last.pose.lost, "lost at once: {:?}", last.pose);
}
