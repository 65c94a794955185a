"""The keeper's gaze as a Gymnasium environment (``strata/GoalKeeperGaze-v0``).

One episode is one ball path of the goal-covering scenario on the lockstep host; one step is
one deliberative decision (``1 / deliberative_hz`` simulated seconds, 1 s by default). The
action picks the gaze among active vision's candidates; the observation summarizes the keeper's
world model; the reward is goal coverage less penalties for an unknown ball and a poor pose.
See docs/python.md for the spaces and the reasons for them.
"""

from __future__ import annotations

import json
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from . import _native

__all__ = ["GazeEnv", "ACTION_NAMES"]

#: What each action looks at (``strata_soccer::gaze_override::GazeChoice``).
ACTION_NAMES: tuple[str, ...] = (
    ("ball",)
    + tuple(f"landmark {k}" for k in range(6))
    + tuple(f"ball + landmark {k}" for k in range(6))
)


class GazeEnv(gymnasium.Env[np.ndarray, np.int64]):
    """The goalkeeper's gaze. Keyword arguments are ``GazeEnvConfig``'s fields:
    ``scenario`` (TOML text; the built-in goal-covering scenario by default), ``method``,
    ``deliberative_hz``, ``path``, ``unknown_penalty``, ``pose_penalty``, ``pose_tolerance``.
    """

    metadata = {"render_modes": []}

    def __init__(self, render_mode: str | None = None, **config: Any) -> None:
        if render_mode is not None:
            raise ValueError("GazeEnv renders nothing (use `strata view` on a log)")
        self._env = _native.GazeEnv(json.dumps(config))
        limit = np.float32(_native.GazeEnv.observation_limit)
        self.observation_space = spaces.Box(
            -limit, limit, shape=(_native.GazeEnv.observation_size,), dtype=np.float32
        )
        self.action_space = spaces.Discrete(_native.GazeEnv.actions)
        self._seed: int | None = None

    @property
    def step_seconds(self) -> float:
        """Simulated seconds one step covers."""
        return self._env.step_seconds()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None:
            # Gymnasium's seeded generator chooses the next episode: reproducible after one
            # seeded reset, as the environment checker expects.
            seed = int(self.np_random.integers(0, 2**31 - 1))
        self._seed = seed
        observation = np.asarray(self._env.reset(seed), dtype=np.float32)
        return observation, {"seed": seed}

    def step(
        self, action: Any
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        obs, reward, terminated, truncated, info = self._env.step(int(action))
        time, path, coverage, unknown, pose_error = info
        return (
            np.asarray(obs, dtype=np.float32),
            float(reward),
            terminated,
            truncated,
            {
                "time": time,
                "path": path,
                "coverage": coverage,
                "ball_unknown": unknown,
                "pose_error": pose_error,
                "seed": self._seed,
            },
        )


gymnasium.register(id="strata/GoalKeeperGaze-v0", entry_point="strata.gym:GazeEnv")
