"""Steps per second of strata.gym.GazeEnv on one core (docs/python.md, "Benchmark").

    .venv-python/bin/python python/bench_env.py [--steps N] [--hz HZ]

One step is one deliberative decision: 1 / HZ simulated seconds of the keeper's whole
architecture on the lockstep host (perception at 57 Hz, world model, both control layers,
the simulator). Resets (each with its warm-up) are timed apart from the steps. Prints the
figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from strata.gym import GazeEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--hz", type=float, default=1.0, help="deliberative decisions per s")
    args = parser.parse_args()
    # One core: the lockstep host runs every module on the calling thread already.
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    env = GazeEnv(deliberative_hz=args.hz)
    steps = resets = 0
    stepping = resetting = 0.0
    seed = 0
    while steps < args.steps:
        start = time.perf_counter()
        env.reset(seed=seed)
        resetting += time.perf_counter() - start
        resets += 1
        seed += 1
        terminated = False
        start = time.perf_counter()
        while not terminated and steps < args.steps:
            _, _, terminated, _, _ = env.step(steps % env.action_space.n)
            steps += 1
        stepping += time.perf_counter() - start
    simulated = steps * env.step_seconds
    print(f"machine: {platform.node()}, {platform.processor() or platform.machine()}, one core")
    print(f"{steps} steps of {env.step_seconds:g} simulated s in {stepping:.2f} s")
    print(f"steps/s: {steps / stepping:.1f}  (simulated s per wall s: {simulated / stepping:.1f})")
    print(f"resets: {resets}, {resetting / resets:.3f} s each (warm-up included)")


if __name__ == "__main__":
    main()
