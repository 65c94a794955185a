"""strata.gym.GazeEnv: Gymnasium's checks, determinism per seed, registration."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from strata.gym import ACTION_NAMES, GazeEnv


@pytest.fixture
def env(short_scenario):
    return GazeEnv(scenario=short_scenario, deliberative_hz=2.0)


def test_passes_gymnasiums_environment_checker(env):
    check_env(env, skip_render_check=True)


def test_the_same_seed_gives_the_same_episode(env, short_scenario):
    def rollout(e, seed):
        obs, _ = e.reset(seed=seed)
        out = [obs]
        for action in [0, 1, 7, 3, 0]:
            obs, reward, terminated, truncated, info = e.step(action)
            out.append(obs)
            out.append(np.float32(reward))
            assert not truncated
            if terminated:
                break
        return out

    first = rollout(env, 11)
    other = GazeEnv(scenario=short_scenario, deliberative_hz=2.0)
    for a, b in zip(first, rollout(other, 11), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(first, rollout(env, 11), strict=True):
        np.testing.assert_array_equal(a, b)
    assert not all(
        np.array_equal(a, b) for a, b in zip(first, rollout(env, 12), strict=True)
    )


def test_an_episode_ends_with_its_path(env):
    env.reset(seed=1)
    steps, terminated = 0, False
    while not terminated and steps < 100:
        obs, reward, terminated, _, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert -3.0 < reward <= 1.0
        steps += 1
    assert terminated
    assert info["path"] == 1
    assert 9 <= steps <= 11  # ~1.58 m at 0.4 m/s, 0.5 s to settle, half-second steps


def test_registered_and_refuses_bad_settings(short_scenario):
    env = gymnasium.make("strata/GoalKeeperGaze-v0", scenario=short_scenario)
    obs, info = env.reset(seed=2)
    assert obs.shape == env.observation_space.shape
    assert len(ACTION_NAMES) == env.action_space.n
    with pytest.raises(ValueError, match="deliberative_hz"):
        GazeEnv(deliberative_hz=-1.0)
    with pytest.raises(ValueError, match="method"):
        GazeEnv(method="fixed-scan")
    with pytest.raises(ValueError, match="unknown field"):
        GazeEnv(deliberative_hzz=1.0)
