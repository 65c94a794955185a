use super::*;

/// A short episode: one straight path, a second of warm-up.
const SCENARIO: &str = r#"
field = "spl"
noise = "default"
runs = 1
ball_speed = 0.4
deliberative_hz = [1.0]
reactive_hz = 57.0
warmup = 1.0
settle = 0.5
sample_period = 0.05
keeper_start = [-2.55, 0.0, 0.0]
reference = "value-function"
target_pose_error = 0.10

[[methods]]
name = "value-function"
team = "full"

[[methods]]
name = "always-ball"
team = "always-ball"

[[trajectories]]
name = "across"
waypoints = [[-1.0, -1.0], [-1.0, 1.0]]

[[trajectories]]
name = "toward"
waypoints = [[0.0, 0.5], [-1.5, 0.0]]
"#;

fn env(deliberative_hz: f64) -> GazeEnv {
    GazeEnv::new(GazeEnvConfig {
        scenario: SCENARIO.to_owned(),
        deliberative_hz,
        ..GazeEnvConfig::default()
    })
    .expect("the test scenario")
}

/// Observations and rewards of `steps` steps of `actions` (cycled) from `reset(seed)`.
fn rollout(env: &mut GazeEnv, seed: u64, actions: &[usize], steps: usize) -> Vec<(Vec<f32>, f64)> {
    let first = env.reset(seed).expect("reset");
    let mut out = vec![(first, 0.0)];
    for i in 0..steps {
        let step = env.step(actions[i % actions.len()]).expect("step");
        out.push((step.observation, step.reward));
        if step.terminated {
            break;
        }
    }
    out
}

#[test]
fn the_same_seed_gives_the_same_episode() {
    let actions = [0, 1, 7, 3];
    let mut a = env(2.0);
    let mut b = env(2.0);
    let first = rollout(&mut a, 7, &actions, 4);
    assert_eq!(first, rollout(&mut b, 7, &actions, 4));
    // Resetting the same environment replays it too: nothing leaks from the last episode.
    assert_eq!(first, rollout(&mut a, 7, &actions, 4));
    assert!(first.iter().all(|(obs, r)| obs.len() == OBS_LEN && r.is_finite()));
    assert_ne!(first, rollout(&mut b, 8, &actions, 4), "another seed, another episode");
}

#[test]
fn an_episode_follows_its_path_to_the_end() {
    let mut env = env(2.0);
    env.reset(1).expect("reset");
    let mut steps = 0;
    let last = loop {
        let step = env.step(0).expect("step");
        steps += 1;
        if step.terminated || steps > 100 {
            break step;
        }
    };
    // Path 1 ("toward"): about 1.58 m at 0.4 m/s, then 0.5 s of settling, in half-second steps.
    assert!(last.terminated);
    assert_eq!(last.info.path, 1);
    assert!((9..=11).contains(&steps), "{steps} steps");
    assert!(last.info.time > 1.0 + 1.58 / 0.4 + 0.5);
    assert!(env.step(0).is_err(), "the episode is over until the next reset");
}

#[test]
fn bad_settings_name_their_field() {
    let error = |config: GazeEnvConfig| format!("{:#}", GazeEnv::new(config).expect_err("refused"));
    let base = || GazeEnvConfig { scenario: SCENARIO.to_owned(), ..GazeEnvConfig::default() };
    assert!(error(GazeEnvConfig { method: "nope".into(), ..base() }).contains("`method`"));
    assert!(error(GazeEnvConfig { method: "always-ball".into(), ..base() }).contains("no gaze"));
    assert!(error(GazeEnvConfig { deliberative_hz: 0.0, ..base() }).contains("deliberative_hz"));
    assert!(error(GazeEnvConfig { path: Some(2), ..base() }).contains("`path`"));
    let typo = GazeEnvConfig { scenario: SCENARIO.replace("warmup", "warmpu"), ..base() };
    assert!(error(typo).contains("warmpu"));
    let mut env = env(1.0);
    assert!(env.step(0).is_err(), "no step before reset");
    env.reset(3).expect("reset");
    assert!(format!("{:#}", env.step(GazeChoice::COUNT).expect_err("refused")).contains("action"));
}
