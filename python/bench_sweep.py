"""The speed-up of a sweep on Ray: the same goal-covering jobs in one process (threads=1), then
as Ray tasks on a local instance of two workers; prints both wall times and their ratio.

    .venv-python/bin/python python/bench_sweep.py [--runs 4] [--workers 2]

The jobs are the built-in scenario's (45 per run of every condition), `--runs` runs per
condition. Both times include writing the report (the sweep's: planning, the tasks and the
merge); starting the local Ray instance (a few seconds, once per cluster) is timed apart and the
ratio is given without and with it. Nothing is asserted: the figure depends on the machine and
on what else it runs.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import strata
from strata.sweep import sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=4, help="runs per condition")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--experiment", default="goal-covering")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="strata-bench-sweep-") as tmp:
        started = time.monotonic()
        single = strata.run_experiment(
            args.experiment,
            runs=args.runs,
            seed=args.seed,
            threads=1,
            out=os.path.join(tmp, "single"),
        )
        single_s = time.monotonic() - started

        import ray  # noqa: PLC0415 - only after the single-process run

        started = time.monotonic()
        ray.init(num_cpus=args.workers, include_dashboard=False, logging_level="WARNING")
        ray_start_s = time.monotonic() - started

        started = time.monotonic()
        swept = sweep(
            args.experiment,
            runs=args.runs,
            seed=args.seed,
            num_workers=args.workers,
            out=os.path.join(tmp, "swept"),
        )
        swept_s = time.monotonic() - started
        ray.shutdown()

    same = swept["summary"] == single["summary"]
    jobs = swept["sweep"]["jobs"]
    tasks = swept["sweep"]["tasks"]
    load = os.getloadavg()[0]
    print(f"{args.experiment}: {jobs} jobs ({args.runs} runs per condition) in {tasks} tasks")
    print(f"{os.cpu_count()} cores, 1-minute load average {load:.1f} at the end")
    print(f"single process (threads=1):     {single_s:8.1f} s")
    print(f"Ray, {args.workers} workers:             {swept_s:8.1f} s")
    print(f"  of which the tasks:           {swept['sweep']['tasks_s']:8.1f} s")
    print(f"Ray start (apart):              {ray_start_s:8.1f} s")
    print(f"speed-up:                       {single_s / swept_s:8.2f}x")
    print(f"speed-up with the Ray start:    {single_s / (swept_s + ray_start_s):8.2f}x")
    print(f"same summary:                   {same}")


if __name__ == "__main__":
    main()
