"""The speed-up of a sweep on Ray: the same goal-covering jobs in one process (threads=1), then
as Ray tasks on a local instance of two workers; prints both wall times and their ratio.

    .venv-python/bin/python python/bench_sweep.py [--runs 4] [--workers 2]

The jobs are the built-in scenario's, `--runs` runs per condition. The Ray time includes
starting the local instance and the merge, as a user would wait for them. Nothing is asserted:
the figure depends on the machine and on what else it runs.
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

        started = time.monotonic()
        swept = sweep(
            args.experiment,
            runs=args.runs,
            seed=args.seed,
            num_workers=args.workers,
            out=os.path.join(tmp, "swept"),
        )
        swept_s = time.monotonic() - started

    same = swept["summary"] == single["summary"]
    jobs = swept["sweep"]["jobs"]
    print(f"{args.experiment}, {jobs} jobs ({args.runs} runs per condition), {os.cpu_count()} cores")
    print(f"single process (threads=1): {single_s:8.1f} s")
    print(f"Ray, {args.workers} workers:         {swept_s:8.1f} s")
    print(f"speed-up:                   {single_s / swept_s:8.2f}x")
    print(f"same summary:               {same}")


if __name__ == "__main__":
    main()
