//! The simulator at the edge of a graph: it publishes each served robot's frames and motion
//! feedback every step and takes its orders back, and whatever its frames trigger runs after
//! the world moved — by the graph's edges, with every module at the same priority.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use strata_robot::geometry::{Pose, Velocity};
use strata_robot::platform::{ActuatorOrders, BodyMotionState, BodyOrder, SensorFrame};
use strata_runtime::{
    Context, GraphBuilder, HostConfig, Input, LockstepHost, Module, ModuleError, Policy, Time,
    Trigger,
};
use strata_worldsim::{Simulation, World, WorldHandle, WorldSim, WorldSimConfig, add_world_sim};

/// What a reader of the frames saw: (when it ran, the frame's stamp, the world's time then,
/// whether the frame had an image).
type Seen = Arc<Mutex<Vec<(Time, Time, Time, bool)>>>;

/// A stand-in for perception: triggered by every frame.
struct Reader {
    frames: Input<SensorFrame>,
    world: WorldHandle<()>,
    seen: Seen,
}

impl Module for Reader {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let world_time = self.world.lock().sim.time();
        let mut seen = self.seen.lock().unwrap_or_else(PoisonError::into_inner);
        for package in ctx.drain(self.frames) {
            let frame = package.value;
            seen.push((ctx.now(), frame.stamp, world_time, frame.camera.is_some()));
        }
        Ok(())
    }
}

fn world(robots: &[Pose]) -> WorldHandle<()> {
    let sim =
        WorldSim::new(WorldSimConfig::default(), World::default(), robots, 3).expect("valid world");
    WorldHandle::new(Simulation::new(sim, ()))
}

#[test]
fn served_robots_get_a_frame_every_step_after_the_world_moved_and_their_orders_act_next_step() {
    let handle = world(&[Pose::new(0.0, 0.0, 0.0), Pose::new(1.0, 0.0, 0.0)]);
    let mut graph = GraphBuilder::new();
    // The reader is added first: nothing but the edge puts it after the world's step.
    let seen: Seen = Arc::default();
    let frames = graph.add("reader", |p| {
        let frames = p.input::<SensorFrame>("frames", Policy::queue(64));
        p.trigger(Trigger::on_any([frames.into()]));
        (Reader { frames, world: handle.clone(), seen: Arc::clone(&seen) }, frames)
    });
    let served = add_world_sim(&mut graph, "world", handle.clone(), &[1]).expect("robot 1");
    assert!(served.platform(0).is_none(), "only the robots asked for are served");
    let platform = served.platform(1).expect("robot 1 is served");
    assert_eq!(platform.info.sensor_period, Duration::from_millis(20));
    graph.connect(platform.frames, frames);
    graph.external(platform.orders);
    let mut host = LockstepHost::new(graph.build().expect("graph"), HostConfig::with_seed(3));
    let walk = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Walk { velocity: Velocity::new(0.2, 0.0, 0.0) }),
    };
    let at = |ms: u64| Time::from_nanos(ms * 1_000_000);
    host.inject(platform.orders, walk, at(50), at(50)).expect("inject");
    let state = |robot| handle.lock().sim.body(robot).map(|b| b.motion_state());
    host.run_until(at(59)).expect("runs");
    assert_eq!(state(1), Some(BodyMotionState::Standing), "the order waits for the next step");
    host.run_until(at(61)).expect("runs");
    assert!(matches!(state(1), Some(BodyMotionState::Walking { .. })), "{:?}", state(1));
    host.run_until(at(200)).expect("runs");

    let seen = seen.lock().unwrap_or_else(PoisonError::into_inner).clone();
    assert_eq!(seen.len(), 10, "a frame every 20 ms: {seen:?}");
    for (k, (ran, stamp, world_time, image)) in seen.iter().enumerate() {
        let step = at(20 * (k as u64 + 1));
        assert_eq!((*ran, *stamp, *world_time), (step, step, step), "frame {k}");
        assert_eq!(*image, k % 2 == 1, "an image every second frame");
    }
    assert_eq!(state(0), Some(BodyMotionState::Standing), "an unserved robot gets no orders");
}

#[test]
fn a_robot_the_world_does_not_have_is_refused_when_the_graph_is_built() {
    let mut graph = GraphBuilder::new();
    let error = add_world_sim(&mut graph, "world", world(&[Pose::default()]), &[0, 2])
        .expect_err("no robot 2");
    assert_eq!(error.to_string(), "no robot 2 in the world");
}
