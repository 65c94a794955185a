"""strata's functions: matches, experiments and logs from dicts and TOML, errors as exceptions."""

import tomllib

import pytest

import strata


def test_a_match_from_a_dict_reports_as_plain_records():
    report = strata.run_match({"players": 2, "duration": 20.0, "seed": 3})
    assert report["seed"] == 3
    assert report["players_per_team"] == 2
    assert report["simulated_s"] == pytest.approx(20.0, abs=0.1)
    assert len(report["robots"]) == 4
    assert isinstance(report["score"], list)
    # Lockstep: the same seed plays the same game.
    again = strata.run_match(players=2, duration=20.0, seed=3)
    assert again["score"] == report["score"]
    assert again["events"] == report["events"]


def test_a_match_from_a_toml_file(tmp_path):
    config = tmp_path / "match.toml"
    config.write_text('players = 1\nduration = 5.0\nseed = 9\naway = "no-coordination"\n')
    report = strata.run_match(config)
    assert report["seed"] == 9
    assert report["players_per_team"] == 1


def test_bad_match_settings_raise_value_error_naming_the_field():
    with pytest.raises(ValueError, match="colour"):
        strata.run_match({"colour": "red"})
    with pytest.raises(ValueError, match="players"):
        strata.run_match({"players": "seven"})
    with pytest.raises(ValueError, match="home"):
        strata.run_match({"home": "no-such-team"})
    with pytest.raises(ValueError, match="packet_loss"):
        strata.run_match({"packet_loss": 2.0})


def test_a_logged_match_reads_back_as_records(tmp_path):
    log = tmp_path / "match.mcap"
    strata.run_match(players=1, duration=3.0, seed=2, log=str(log))
    info = strata.log_info(log)
    assert info, "the log describes itself"
    records = strata.read_log(log, limit=200)
    assert len(records) == 200
    assert {"topic", "time", "stamp", "seq", "value"} <= records[0].keys()
    topic = records[-1]["topic"]
    only = strata.read_log(log, topics=[topic], limit=10)
    assert only and all(r["topic"] == topic for r in only)
    with pytest.raises(RuntimeError, match="no topic"):
        strata.read_log(log, topics=["no/such/topic"])
    with pytest.raises(RuntimeError):
        strata.read_log(tmp_path / "missing.mcap")


def test_an_experiment_from_a_scenario_dict(tmp_path, short_scenario):
    scenario = tomllib.loads(short_scenario)
    outcome = strata.run_experiment(
        "goal-covering", scenario, runs=1, seed=4, out=tmp_path / "gc", threads=1
    )
    assert outcome["experiment"] == "goal-covering"
    summary = outcome["summary"]
    assert summary["seed"] == 4
    [condition] = summary["conditions"]
    assert condition["method"] == "value-function"
    assert condition["runs"] == 2
    assert 0.0 <= condition["coverage"]["mean"] <= 1.0
    assert (tmp_path / "gc" / "scenario.toml").exists()


def test_a_bad_scenario_raises_value_error_naming_the_field(tmp_path, short_scenario):
    scenario = tomllib.loads(short_scenario)
    scenario["warmup"] = -1.0
    with pytest.raises(ValueError, match="warmup"):
        strata.run_experiment("goal-covering", scenario, out=tmp_path)
    with pytest.raises(ValueError, match="no experiment"):
        strata.run_experiment("no-such-experiment")
    with pytest.raises(ValueError, match="runs"):
        strata.run_experiment("goal-covering", scenario, out=tmp_path, runs=0)
