"""Trains the keeper's learned gaze (PPO, stable-baselines3, CPU) and exports it for Rust.

    scripts/setup-python --train                  # once: torch and stable-baselines3
    .venv-python/bin/python python/train_gaze.py  # at most 30 minutes (--max-minutes)

The policy is the deliberative gaze of the goal-covering experiment's `learned` method: at each
deliberative decision it maps the gaze environment's observation (``strata.gym.GazeEnv``, the
same ``observation()`` the Rust experiment computes) to one of the 13 gaze choices.

Training paths: random ball paths drawn like those of
crates/experiments/scenarios/goal-covering-random.toml but from another seed (``--path-seed``),
so that neither evaluation (the three fixed trajectories, the 40 random paths of seed 29) has
been seen in training. The envs cycle through the experiment's three deliberative rates
(0.5, 1 and 2 Hz): one policy serves all three, since the observation carries the world
model's uncertainty, which is what a slower rate changes.

Outputs (``--out``, crates/experiments/data/ by default):
- ``gaze-policy.safetensors``: the deterministic action head, float32: ``obs_mean``,
  ``obs_std``, ``obs_clip`` (the observation normalization of VecNormalize), ``hidden.K.weight``
  and ``hidden.K.bias`` (tanh layers, PyTorch's (out, in) layout), ``logits.weight`` and
  ``logits.bias``; the action is the argmax of the logits;
- ``gaze-policy-fixture.json``: a few observations with the Python policy's logits and actions,
  which a Rust test checks the Rust forward pass against;
- ``gaze-policy-training.json``: the settings, steps, wall time and evaluation of the run.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import sys
import time
from pathlib import Path

# One core: the machines are shared, and a tiny MLP gains nothing from more threads.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from safetensors.numpy import save_file  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # noqa: E402

import strata.gym  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RANDOM_SCENARIO = ROOT / "crates/experiments/scenarios/goal-covering-random.toml"
RATES = (0.5, 1.0, 2.0)


def training_scenario(path_seed: int, paths: int) -> str:
    """The random scenario's text with its paths drawn from ``path_seed`` instead."""
    text = RANDOM_SCENARIO.read_text()
    text, seeds = re.subn(r"(?m)^seed = \d+", f"seed = {path_seed}", text)
    text, counts = re.subn(r"(?m)^paths = \d+", f"paths = {paths}", text)
    if seeds != 1 or counts != 1:
        raise SystemExit(f"{RANDOM_SCENARIO}: expected one `seed =` and one `paths =` line")
    return text


class WallClock(BaseCallback):
    """Stops training after ``minutes`` of wall time: the machines are shared, and a run that
    would overrun its budget under load ends with the steps it made (the report counts them)."""

    def __init__(self, minutes: float) -> None:
        super().__init__()
        self.deadline = time.monotonic() + 60.0 * minutes

    def _on_step(self) -> bool:
        return time.monotonic() < self.deadline


def make_env(scenario: str, hz: float, seed: int):
    def build():
        env = strata.gym.GazeEnv(scenario=scenario, deliberative_hz=hz)
        env.reset(seed=seed)
        return env

    return build


def export(model: PPO, normalize: VecNormalize, out: Path) -> dict[str, np.ndarray]:
    """The deterministic action head as plain float32 arrays (the safetensors layout)."""
    policy = model.policy
    tensors: dict[str, np.ndarray] = {
        "obs_mean": normalize.obs_rms.mean.astype(np.float32),
        "obs_std": np.sqrt(normalize.obs_rms.var + normalize.epsilon).astype(np.float32),
        "obs_clip": np.array([normalize.clip_obs], dtype=np.float32),
    }
    linear = [m for m in policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    activations = [m for m in policy.mlp_extractor.policy_net if not isinstance(m, torch.nn.Linear)]
    if not all(isinstance(a, torch.nn.Tanh) for a in activations):
        raise SystemExit(f"the Rust forward pass assumes tanh layers, not {activations}")
    for k, layer in enumerate(linear):
        tensors[f"hidden.{k}.weight"] = layer.weight.detach().numpy().astype(np.float32)
        tensors[f"hidden.{k}.bias"] = layer.bias.detach().numpy().astype(np.float32)
    tensors["logits.weight"] = policy.action_net.weight.detach().numpy().astype(np.float32)
    tensors["logits.bias"] = policy.action_net.bias.detach().numpy().astype(np.float32)
    tensors = {name: np.ascontiguousarray(t) for name, t in tensors.items()}
    save_file(tensors, str(out))
    return tensors


def python_logits(model: PPO, normalize: VecNormalize, obs: np.ndarray) -> np.ndarray:
    """The policy's logits as stable-baselines3 computes them (the reference for Rust)."""
    normalized = normalize.normalize_obs(obs.astype(np.float32))
    with torch.no_grad():
        tensor = torch.as_tensor(normalized, dtype=torch.float32)
        features = model.policy.extract_features(tensor, model.policy.pi_features_extractor)
        latent = model.policy.mlp_extractor.forward_actor(features)
        return model.policy.action_net(latent).numpy()


def fixture(model: PPO, normalize: VecNormalize, scenario: str, count: int) -> dict:
    """Observations from a few episodes (the policy acting), with logits and actions."""
    observations = []
    for i, hz in enumerate(RATES):
        env = strata.gym.GazeEnv(scenario=scenario, deliberative_hz=hz)
        obs, _ = env.reset(seed=10_000 + i)
        for _ in range(count // len(RATES)):
            observations.append(obs)
            action = int(python_logits(model, normalize, obs[None])[0].argmax())
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                obs, _ = env.reset(seed=20_000 + len(observations))
    obs = np.stack(observations).astype(np.float32)
    logits = python_logits(model, normalize, obs)
    deterministic, _ = model.predict(normalize.normalize_obs(obs), deterministic=True)
    if not np.array_equal(logits.argmax(axis=1), deterministic):
        raise SystemExit("the exported head's argmax differs from model.predict")
    return {
        "observations": obs.tolist(),
        "logits": logits.astype(np.float32).tolist(),
        "actions": [int(a) for a in deterministic],
    }


def evaluate(model: PPO, normalize: VecNormalize, scenario: str, episodes: int) -> dict:
    """Mean episode reward and measures of the deterministic policy on held-out seeds."""
    result = {}
    for hz in RATES:
        env = strata.gym.GazeEnv(scenario=scenario, deliberative_hz=hz)
        rewards, coverage, unknown = [], [], []
        for episode in range(episodes):
            obs, _ = env.reset(seed=50_000 + episode)
            total, done = 0.0, False
            while not done:
                action = int(python_logits(model, normalize, obs[None])[0].argmax())
                obs, reward, terminated, truncated, info = env.step(action)
                total += reward
                coverage.append(info["coverage"])
                unknown.append(info["ball_unknown"])
                done = terminated or truncated
            rewards.append(total)
        result[f"{hz} Hz"] = {
            "episode_reward": float(np.mean(rewards)),
            "coverage": float(np.mean(coverage)),
            "ball_unknown": float(np.mean(unknown)),
        }
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=1_000_000, help="PPO environment steps")
    parser.add_argument("--seed", type=int, default=1, help="PPO's and the episodes' seed")
    parser.add_argument("--path-seed", type=int, default=2026, help="the training paths' seed")
    parser.add_argument("--paths", type=int, default=200, help="training paths")
    parser.add_argument(
        "--max-minutes", type=float, default=30.0, help="stop training after this wall time"
    )
    parser.add_argument("--envs", type=int, default=6, help="environments (cycling the rates)")
    parser.add_argument("--out", type=Path, default=ROOT / "crates/experiments/data")
    parser.add_argument("--eval-episodes", type=int, default=20)
    args = parser.parse_args()

    torch.set_num_threads(1)
    scenario = training_scenario(args.path_seed, args.paths)
    envs = DummyVecEnv(
        [
            make_env(scenario, RATES[i % len(RATES)], args.seed * 1000 + i)
            for i in range(args.envs)
        ]
    )
    envs.seed(args.seed)
    # Covariances reach 25 m² while positions are metres: normalized inputs train far better.
    normalize = VecNormalize(envs, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.95)
    model = PPO(
        "MlpPolicy",
        normalize,
        n_steps=512,
        batch_size=256,
        n_epochs=5,
        learning_rate=3e-4,
        gamma=0.95,
        gae_lambda=0.95,
        ent_coef=0.01,
        policy_kwargs={"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "activation_fn": torch.nn.Tanh},
        seed=args.seed,
        device="cpu",
        verbose=1,
    )
    start = time.monotonic()
    model.learn(total_timesteps=args.steps, callback=WallClock(args.max_minutes), progress_bar=False)
    seconds = time.monotonic() - start
    normalize.training = False

    args.out.mkdir(parents=True, exist_ok=True)
    tensors = export(model, normalize, args.out / "gaze-policy.safetensors")
    (args.out / "gaze-policy-fixture.json").write_text(
        json.dumps(fixture(model, normalize, scenario, 12)) + "\n"
    )
    held_out = training_scenario(args.path_seed + 1, args.paths)
    report = {
        "command": " ".join([Path(sys.argv[0]).name] + sys.argv[1:]),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": f"{platform.machine()} {os.cpu_count()} cores, {platform.python_version()}",
        "torch": torch.__version__,
        "steps": int(model.num_timesteps),
        "stopped_by_wall_clock": bool(model.num_timesteps < args.steps),
        "training_seconds": round(seconds, 1),
        "steps_per_second": round(model.num_timesteps / seconds, 1),
        "settings": vars(args) | {"out": str(args.out)},
        "parameters": int(sum(t.size for t in tensors.values())),
        "evaluation_held_out_paths": evaluate(model, normalize, held_out, args.eval_episodes),
    }
    (args.out / "gaze-policy-training.json").write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
