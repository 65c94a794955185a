"""Strata from Python: run a match or an experiment, read a log, train a gaze.

Configurations are plain dicts (or TOML files); results come back as plain dicts and lists
(the reports of ``strata match --json`` and ``strata experiment --json``). A configuration
that cannot be used raises ``ValueError`` naming the field; a run that fails raises
``RuntimeError``. Matches and experiments run without the GIL.

The Gymnasium environment is in :mod:`strata.gym` (it needs ``gymnasium`` and ``numpy``).
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Mapping
from typing import Any

from . import _native

__all__ = [
    "EXPERIMENTS",
    "load_config",
    "log_info",
    "read_log",
    "run_experiment",
    "run_match",
]

#: The experiments :func:`run_experiment` knows.
EXPERIMENTS: tuple[str, ...] = tuple(_native.experiments())

Config = Mapping[str, Any] | str | os.PathLike[str] | None


def load_config(config: Config) -> dict[str, Any]:
    """A configuration as a dict: a mapping as it is, a path as the TOML file it names."""
    if config is None:
        return {}
    if isinstance(config, Mapping):
        return dict(config)
    with open(config, "rb") as file:
        return tomllib.load(file)


def run_match(config: Config = None, **overrides: Any) -> dict[str, Any]:
    """Plays a match on the built-in simulator and returns its report.

    ``config`` (a dict or a TOML file) and ``overrides`` take the options of ``strata match``:
    ``players``, ``seed``, ``home``, ``away`` (built-in teams or team files), ``half``,
    ``duration`` (simulated seconds), ``noise``, ``field``, ``packet_loss``, ``no_delay`` and
    ``log`` (an MCAP file to record into).
    """
    settings = load_config(config) | overrides
    return json.loads(_native.run_match(json.dumps(settings)))


def run_experiment(
    name: str, scenario: Config = None, **options: Any
) -> dict[str, Any]:
    """Runs one of the paper's experiments and returns its outcome.

    ``scenario``: a dict (the scenario TOML's tables; written to ``OUT/scenario.toml``) or a
    scenario TOML file; the built-in scenario when left out. ``options``: ``runs``, ``seed``,
    ``out`` (output directory, ``results/NAME`` by default), ``threads``, ``log``. The outcome
    has ``experiment``, ``out_dir``, ``files`` and ``summary`` (``summary.json``).
    """
    settings = dict(options)
    if isinstance(scenario, Mapping):
        settings["scenario"] = dict(scenario)
    elif scenario is not None:
        settings["scenario_file"] = os.fspath(scenario)
    for key in ("out", "log"):
        if key in settings and settings[key] is not None:
            settings[key] = os.fspath(settings[key])
    return json.loads(_native.run_experiment(name, json.dumps(settings)))


def log_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a log holds (``strata log info --json``): topics, counts, duration, metadata."""
    return json.loads(_native.log_info(os.fspath(path)))


def read_log(
    path: str | os.PathLike[str],
    topics: list[str] | None = None,
    limit: int | None = None,
) -> list[dict[str, Any]]:
    """A log's messages as records (``strata log cat``): ``topic``, ``time`` (log time, s),
    ``stamp`` (s), ``seq`` and the decoded ``value``; only ``topics`` when given, at most
    ``limit``."""
    return json.loads(_native.read_log(os.fspath(path), topics, limit))
