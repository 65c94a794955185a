"""An experiment's runs as Ray tasks: ``strata.sweep`` and ``strata experiment NAME --ray``.

The driver plans the jobs (one per run of a condition), submits the ones whose record is
missing from the records directory as Ray tasks, writes each record it gets back, then merges
the records into the report and ``summary.json`` one process would have written (the lockstep
experiments are deterministic for a seed, so the merged summary equals the single-process one).

Workers need the ``strata`` package, not the records directory: a task returns its records to
the driver, which alone writes them. A record is written whole (temporary file, rename), so a
sweep stopped at any point resumes where it was: finished jobs are not run again. A task whose
worker dies is run again elsewhere by Ray (``max_retries``).

Ray is imported only here, when a sweep starts: the rest of the package does not need it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from typing import Any

from . import _native

__all__ = ["sweep", "record_path"]

#: A fault for the tests (the lost-worker case): set to a path that does not exist, the first
#: task to create that file kills its own worker process; Ray must then run it again.
FAIL_ONCE_ENV = "STRATA_SWEEP_FAIL_ONCE"


def record_path(records: str | os.PathLike[str], job: int) -> str:
    """Job ``job``'s record file in ``records`` (as crates/experiments/src/records.rs names it)."""
    return os.path.join(os.fspath(records), f"job-{job:05d}.msgpack")


def _native_run(name: str, settings: Mapping[str, Any]) -> dict[str, Any]:
    return json.loads(_native.run_experiment(name, json.dumps(dict(settings))))


def _write_atomic(path: str, data: bytes) -> None:
    # Renamed into place: a driver killed mid-write leaves no half record to be taken for a
    # finished job on resume.
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "wb") as file:
        file.write(data)
    os.replace(tmp, path)


def _fail_once(marker: str | None) -> None:
    """Kills this worker process the first time any task gets here (the lost-worker test)."""
    if not marker:
        return
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.close(fd)
    os._exit(17)


def _run_chunk(
    name: str,
    settings: dict[str, Any],
    scenario_text: str | None,
    scenario_path: str | None,
    jobs: list[int],
    fail_once: str | None,
) -> list[tuple[int, bytes]]:
    """A Ray task: runs `jobs` in this worker's own temporary directory, returns their records."""
    _fail_once(fail_once)
    with tempfile.TemporaryDirectory(prefix="strata-sweep-") as tmp:
        settings = dict(settings)
        if scenario_text is not None:
            # The driver's file when this machine has the same one (relative team files in it
            # resolve from its directory); a copy of its text otherwise.
            same = False
            if scenario_path and os.path.isfile(scenario_path):
                with open(scenario_path, encoding="utf-8") as file:
                    same = file.read() == scenario_text
            if not same:
                scenario_path = os.path.join(tmp, "scenario.toml")
                with open(scenario_path, "w", encoding="utf-8") as file:
                    file.write(scenario_text)
            settings["scenario_file"] = scenario_path
        records = os.path.join(tmp, "records")
        settings.update(
            records=records, record_mode="run", only=jobs, threads=1, out=os.path.join(tmp, "out")
        )
        _native_run(name, settings)
        out = []
        for job in jobs:
            with open(record_path(records, job), "rb") as file:
                out.append((job, file.read()))
        return out


def _import_ray() -> Any:
    try:
        import ray  # noqa: PLC0415 - only a sweep needs Ray
    except ImportError as e:
        raise ImportError(
            "strata.sweep needs Ray: install the Python package with ./scripts/setup-python "
            "(python/requirements.txt pins ray)"
        ) from e
    return ray


def sweep(
    name: str,
    scenario: Mapping[str, Any] | str | os.PathLike[str] | None = None,
    *,
    address: str | None = None,
    records: str | os.PathLike[str] | None = None,
    num_workers: int | None = None,
    chunk: int | None = None,
    max_retries: int = 3,
    progress: bool = False,
    **options: Any,
) -> dict[str, Any]:
    """Runs experiment ``name`` as Ray tasks and returns what :func:`strata.run_experiment`
    returns (``experiment``, ``out_dir``, ``files``, ``summary``), with ``sweep``: the job
    count, the jobs run and skipped (their records were there), the tasks.

    ``address``: a Ray cluster (``ray start --head`` prints it; ``"auto"`` finds a local one);
    without it, a Ray instance of this machine with ``num_workers`` CPUs (all by default), unless
    Ray is already initialized. ``records``: the records directory, ``OUT/records`` by
    default; it resumes a sweep. ``chunk``: jobs per task; by default about eight tasks per CPU
    of the cluster (a job of a short scenario takes milliseconds: a task per job would spend
    more on scheduling than on running). ``options``: ``runs``, ``seed``,
    ``out`` as for :func:`strata.run_experiment`.
    """
    if chunk is not None and chunk < 1:
        raise ValueError("chunk: must be at least 1")
    if options.get("log") is not None or options.get("threads") is not None:
        # A task runs its jobs with one thread on its worker; a log would stay on that worker.
        raise ValueError("log, threads: not options of a sweep (use strata.run_experiment)")
    settings: dict[str, Any] = {k: v for k, v in options.items() if v is not None}
    for key in ("out",):
        if key in settings:
            settings[key] = os.fspath(settings[key])
    out = settings.setdefault("out", os.path.join("results", name))
    records_dir = os.fspath(records) if records is not None else os.path.join(out, "records")
    scenario_text: str | None = None
    scenario_path: str | None = None
    if isinstance(scenario, Mapping):
        settings["scenario"] = dict(scenario)
    elif scenario is not None:
        scenario_path = os.path.abspath(os.fspath(scenario))
        with open(scenario_path, encoding="utf-8") as file:
            scenario_text = file.read()
        settings["scenario_file"] = os.fspath(scenario)

    plan = _native_run(name, settings | {"records": records_dir, "record_mode": "plan"})
    jobs = int(plan["summary"]["jobs"])
    if isinstance(scenario, Mapping):
        # The plan wrote the table as OUT/scenario.toml: the workers get that text, so that
        # their runs and the merge read the same scenario.
        scenario_path = os.path.abspath(os.path.join(out, "scenario.toml"))
        with open(scenario_path, encoding="utf-8") as file:
            scenario_text = file.read()
        settings.pop("scenario")
        settings["scenario_file"] = scenario_path
    todo = [job for job in range(jobs) if not os.path.exists(record_path(records_dir, job))]
    started = time.monotonic()
    tasks = 0
    if todo:
        tasks = _run_tasks(
            name,
            settings,
            scenario_text,
            scenario_path,
            todo,
            chunk,
            records_dir,
            address=address,
            num_workers=num_workers,
            max_retries=max_retries,
            progress=progress,
        )
    ran_s = time.monotonic() - started

    outcome = _native_run(name, settings | {"records": records_dir, "record_mode": "merge"})
    outcome["sweep"] = {
        "records": records_dir,
        "jobs": jobs,
        "ran": len(todo),
        "skipped": jobs - len(todo),
        "tasks": tasks,
        "tasks_s": ran_s,
    }
    return outcome


def _run_tasks(
    name: str,
    settings: dict[str, Any],
    scenario_text: str | None,
    scenario_path: str | None,
    todo: list[int],
    chunk: int | None,
    records_dir: str,
    *,
    address: str | None,
    num_workers: int | None,
    max_retries: int,
    progress: bool,
) -> int:
    """Runs the jobs `todo` as tasks, writing each record as its task returns; the task count."""
    ray = _import_ray()
    if not ray.is_initialized():
        if address:
            ray.init(address=address, logging_level="WARNING")
        else:
            ray.init(
                num_cpus=num_workers or os.cpu_count() or 1,
                include_dashboard=False,
                logging_level="WARNING",
            )
    if chunk is None:
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        chunk = max(1, -(-len(todo) // (8 * cpus)))
    chunks = [todo[i : i + chunk] for i in range(0, len(todo), chunk)]
    # Worker deaths (a lost node, a killed process) are retried; an error the experiment
    # raises is not: it would fail again.
    remote = ray.remote(num_cpus=1, max_retries=max_retries)(_run_chunk)
    fail_once = os.environ.get(FAIL_ONCE_ENV) or None
    pending = [
        remote.remote(name, settings, scenario_text, scenario_path, jobs, fail_once)
        for jobs in chunks
    ]
    done = 0
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        for ref in ready:
            for job, data in ray.get(ref):
                _write_atomic(record_path(records_dir, job), data)
            done += 1
            if progress:
                print(f"{name}: {done}/{len(chunks)} tasks done", file=sys.stderr, flush=True)
    return len(chunks)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m strata.sweep``: what ``strata experiment NAME --ray`` runs."""
    parser = argparse.ArgumentParser(prog="python -m strata.sweep", description=__doc__)
    parser.add_argument("name")
    parser.add_argument("--address", help="a Ray cluster; a local instance without it")
    parser.add_argument("--runs", type=int)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out")
    parser.add_argument("--scenario", help="a scenario TOML file")
    parser.add_argument("--records", help="the records directory [default: OUT/records]")
    parser.add_argument("--num-workers", type=int, help="CPUs of a local Ray instance")
    parser.add_argument("--chunk", type=int, help="jobs per task [default: 8 tasks per CPU]")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    args = parser.parse_args(argv)
    try:
        outcome = sweep(
            args.name,
            args.scenario,
            address=args.address,
            records=args.records,
            num_workers=args.num_workers,
            chunk=args.chunk,
            progress=not args.json,
            runs=args.runs,
            seed=args.seed,
            out=args.out,
        )
    except (ValueError, RuntimeError, ImportError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(outcome["summary"]))
    else:
        s = outcome["sweep"]
        print(
            f"{outcome['experiment']}: {os.path.join(outcome['out_dir'], 'report.md')} "
            f"({s['jobs']} jobs: {s['ran']} run, {s['skipped']} from earlier records)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
