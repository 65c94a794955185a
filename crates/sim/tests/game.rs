//! A whole 20-minute game of 14 robots, each driven by the test controller through its
//! in-process platform and GameController link, on the lockstep host — twice, to check that the
//! same seed gives the same game bit for bit: every ground truth the simulator publishes (10 Hz:
//! poses, velocities, head angles, body states of all robots, the ball, the game) and the final
//! one, with every event.

use std::time::Duration;

use strata_runtime::{GraphBuilder, HostConfig, LockstepHost};
use strata_sim::{
    EventKind, GameState, GroundTruth, RobotId, SimConfig, SimHandle, Simulation, TestController,
    add_simulator, add_test_controller,
};

/// FNV-1a over the serialized ground truth the simulator module publishes, in order.
/// `serde_json` writes every `f64` so that it parses back to the same bits (`float_roundtrip`),
/// so equal digests mean equal trajectories bit for bit (up to a hash collision).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Trajectory {
    digest: u64,
    samples: usize,
}

impl Default for Trajectory {
    fn default() -> Self {
        Trajectory { digest: 0xcbf2_9ce4_8422_2325, samples: 0 }
    }
}

impl Trajectory {
    fn add(&mut self, truth: &GroundTruth) {
        let bytes = serde_json::to_vec(truth).expect("serializable");
        for byte in bytes {
            self.digest = (self.digest ^ u64::from(byte)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        self.samples += 1;
    }
}

struct Digest {
    input: strata_runtime::Input<GroundTruth>,
    trajectory: std::sync::Arc<std::sync::Mutex<Trajectory>>,
}

impl strata_runtime::Module for Digest {
    fn cycle(
        &mut self,
        ctx: &mut strata_runtime::Context<'_>,
    ) -> Result<(), strata_runtime::ModuleError> {
        let packages = ctx.drain(self.input);
        let mut trajectory = self.trajectory.lock().map_err(|_| "poisoned")?;
        for package in packages {
            trajectory.add(&package.value);
        }
        Ok(())
    }
}

fn play(seed: u64) -> (GroundTruth, u64, Trajectory) {
    let config = SimConfig { seed, ..SimConfig::default() };
    let sim = SimHandle::new(Simulation::new(config).expect("the default config is valid"));
    let mut graph = GraphBuilder::new();
    let ports = add_simulator(&mut graph, sim.clone(), &[]);
    let trajectory = std::sync::Arc::new(std::sync::Mutex::new(Trajectory::default()));
    let digest = graph.add("digest", |p| {
        let input = p.input("truth", strata_runtime::Policy::queue(1000));
        (Digest { input, trajectory: trajectory.clone() }, input)
    });
    graph.connect(ports.ground_truth, digest);
    let (ids, info): (Vec<RobotId>, _) = {
        let world = sim.lock();
        (world.robot_ids().collect(), world.platform_info())
    };
    for id in ids {
        let team_number = sim.lock().team_number(id.team);
        let controller = TestController::new(info.clone(), team_number, id.player);
        let platform = sim.shared_platform(id).expect("a robot of the game");
        let game_controller = sim.game_controller_link(id).expect("a robot of the game");
        add_test_controller(
            &mut graph,
            &format!("robot-{}-{}", id.team, id.player),
            controller,
            platform,
            Some(Box::new(game_controller)),
            Duration::from_millis(12),
        );
    }
    let mut host =
        LockstepHost::new(graph.build().expect("a valid graph"), HostConfig::with_seed(seed));
    // Two halves of 600 s, the Ready and Set phases, half time and the restarts after goals.
    for _ in 0..200 {
        host.run_for(Duration::from_secs(10)).expect("the modules run");
        if sim.lock().game().game_over {
            break;
        }
    }
    let cycles = host.stats().modules.iter().map(|m| m.cycles).sum();
    let truth = sim.lock().ground_truth();
    let trajectory = *trajectory.lock().expect("not poisoned");
    (truth, cycles, trajectory)
}

#[test]
fn a_twenty_minute_game_of_fourteen_robots_is_deterministic() {
    let (first, cycles, trajectory) = play(11);
    assert!(first.game.game_over, "the game ended (at {} s)", first.time.as_secs_f64());
    assert_eq!(first.game.state, GameState::Finished);
    let played = first.time.as_secs_f64();
    assert!(played >= 1200.0, "two halves of 600 s and more: {played} s");
    assert!(cycles > 14 * 83 * 1200, "every robot ran at the sensor rate: {cycles} cycles");
    let count = |f: fn(&EventKind) -> bool| first.events.iter().filter(|e| f(&e.kind)).count();
    let kicks = count(|e| matches!(e, EventKind::Kick { hit: true, .. }));
    let falls = count(|e| matches!(e, EventKind::Fall { .. }));
    let stand_ups = count(|e| matches!(e, EventKind::StandUp { .. }));
    let outs = count(|e| matches!(e, EventKind::BallOut { .. }));
    let goals = count(|e| matches!(e, EventKind::Goal { .. }));
    println!(
        "{played:.0} s played, score {:?}, {kicks} kicks, {goals} goals, {outs} outs, {falls} falls, {stand_ups} stand-ups, {} team messages",
        first.game.score, first.comms.sent
    );
    assert!(kicks > 10, "robots find and kick the ball: {kicks}");
    assert!(falls > 0 && stand_ups > 0, "robots fall and get up: {falls} {stand_ups}");

    let samples = trajectory.samples as f64;
    assert!(samples >= played * 10.0 - 1.0, "ground truth at 10 Hz: {samples}");

    let (second, _, second_trajectory) = play(11);
    assert_eq!(trajectory, second_trajectory, "the same seed gave two different trajectories");
    let a = serde_json::to_string(&first).expect("serializable");
    let b = serde_json::to_string(&second).expect("serializable");
    assert!(a == b, "the same seed gave two different games");
}

/// Keeps what the simulator module publishes.
struct Recorder {
    input: strata_runtime::Input<GroundTruth>,
    received: std::sync::Arc<std::sync::Mutex<Vec<GroundTruth>>>,
}

impl strata_runtime::Module for Recorder {
    fn cycle(
        &mut self,
        ctx: &mut strata_runtime::Context<'_>,
    ) -> Result<(), strata_runtime::ModuleError> {
        let packages = ctx.drain(self.input);
        let mut received = self.received.lock().map_err(|_| "poisoned")?;
        received.extend(packages.into_iter().map(|p| p.value));
        Ok(())
    }
}

#[test]
fn the_simulator_module_publishes_ground_truth_with_new_events() {
    let sim = SimHandle::new(Simulation::new(SimConfig::default()).expect("valid"));
    let mut graph = GraphBuilder::new();
    let ports = add_simulator(&mut graph, sim.clone(), &[]);
    let received = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let sink = graph.add("recorder", |p| {
        let input = p.input("truth", strata_runtime::Policy::queue(1000));
        (Recorder { input, received: received.clone() }, input)
    });
    graph.connect(ports.ground_truth, sink);
    let mut host =
        LockstepHost::new(graph.build().expect("a valid graph"), HostConfig::with_seed(1));
    host.run_for(Duration::from_secs(5)).expect("runs");
    let received = received.lock().expect("not poisoned");
    assert!((49..=51).contains(&received.len()), "10 Hz: {}", received.len());
    let events: Vec<_> = received.iter().flat_map(|t| t.events.iter()).collect();
    assert_eq!(events.len(), sim.lock().events().len(), "each event published once");
    assert!(
        events
            .iter()
            .any(|e| matches!(e.kind, EventKind::GameState { state: GameState::Ready, .. }))
    );
    assert!(received.windows(2).all(|w| w[0].time < w[1].time));
}
