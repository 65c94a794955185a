"""strata.sweep on a local Ray instance with two workers: the sharded experiment's summary is the
single-process one, a second sweep resumes without running anything, a lost worker is replaced."""

import json
import os

import pytest

import strata
from conftest import SHORT_SCENARIO
from strata import sweep as sweep_module
from strata.sweep import FAIL_ONCE_ENV, record_path, sweep

ray = pytest.importorskip("ray")

# Two runs of the two short paths: four jobs.
RUNS = 2
JOBS = 4


@pytest.fixture(scope="module")
def two_workers():
    """One local Ray instance of two CPUs for the module (starting one takes seconds)."""
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "goal-covering.toml"
    path.write_text(SHORT_SCENARIO)
    return path


@pytest.fixture(scope="module")
def single_process(tmp_path_factory, scenario_file):
    out = tmp_path_factory.mktemp("single")
    return strata.run_experiment(
        "goal-covering", scenario_file, runs=RUNS, seed=5, threads=1, out=out
    )


def test_a_sharded_sweep_gives_the_single_process_summary_then_resumes(
    two_workers, tmp_path, scenario_file, single_process
):
    out = tmp_path / "swept"
    outcome = sweep("goal-covering", scenario_file, runs=RUNS, seed=5, out=out)
    assert outcome["sweep"]["jobs"] == JOBS
    assert outcome["sweep"]["ran"] == JOBS and outcome["sweep"]["skipped"] == 0
    assert outcome["summary"] == single_process["summary"]
    with open(os.path.join(single_process["out_dir"], "summary.json")) as file:
        assert json.loads((out / "summary.json").read_text()) == json.load(file)
    assert (out / "report.md").exists()

    records = out / "records"
    stamps = {job: os.stat(record_path(records, job)).st_mtime_ns for job in range(JOBS)}
    again = sweep("goal-covering", scenario_file, runs=RUNS, seed=5, out=out)
    assert again["sweep"]["ran"] == 0 and again["sweep"]["skipped"] == JOBS
    assert again["sweep"]["tasks"] == 0
    assert again["summary"] == single_process["summary"]
    assert stamps == {job: os.stat(record_path(records, job)).st_mtime_ns for job in range(JOBS)}


def test_a_lost_worker_is_replaced_and_the_summary_is_the_same(
    two_workers, tmp_path, scenario_file, single_process, monkeypatch
):
    marker = tmp_path / "worker-killed"
    monkeypatch.setenv(FAIL_ONCE_ENV, str(marker))
    outcome = sweep("goal-covering", scenario_file, runs=RUNS, seed=5, out=tmp_path / "out")
    # The fault happened: one task's worker process exited before running its job.
    assert marker.exists()
    assert outcome["sweep"]["ran"] == JOBS
    assert outcome["summary"] == single_process["summary"]


def test_a_partial_sweep_resumes_with_the_missing_jobs_only(
    two_workers, tmp_path, scenario_file, single_process
):
    out = tmp_path / "out"
    records = out / "records"
    # As if a sweep had stopped after two jobs: their records are there.
    strata.run_experiment(
        "goal-covering",
        scenario_file,
        runs=RUNS,
        seed=5,
        out=out,
        records=str(records),
        record_mode="run",
        only=[0, 3],
    )
    outcome = sweep("goal-covering", scenario_file, runs=RUNS, seed=5, out=out)
    assert outcome["sweep"]["ran"] == 2 and outcome["sweep"]["skipped"] == 2
    assert outcome["summary"] == single_process["summary"]


def test_records_of_another_sweep_and_real_time_experiments_are_refused(
    tmp_path, scenario_file
):
    out = tmp_path / "out"
    strata.run_experiment(
        "goal-covering",
        scenario_file,
        runs=RUNS,
        seed=5,
        out=out,
        records=str(out / "records"),
        record_mode="plan",
    )
    with pytest.raises(RuntimeError, match="another sweep"):
        sweep("goal-covering", scenario_file, runs=RUNS, seed=6, out=out)
    with pytest.raises(ValueError, match="real time"):
        sweep("rates", out=tmp_path / "rates")
    assert sweep_module.main(["rates", "--out", str(tmp_path / "rates")]) == 1
