//! `strata.run_experiment`: one of the paper's experiments, as `strata experiment NAME` runs it.

use std::path::{Path, PathBuf};

use pyo3::prelude::*;
use serde::Deserialize;
use strata_experiments::records::{RecordMode, Records};
use strata_experiments::{EXPERIMENTS, Options, ScenarioError};

use crate::{config_error, from_json, run_error, to_json};

/// `strata experiment`'s options of the same names.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct ExperimentSpec {
    runs: Option<usize>,
    seed: Option<u64>,
    /// Output directory; `results/NAME/` by default.
    out: Option<PathBuf>,
    /// A scenario TOML file.
    scenario_file: Option<PathBuf>,
    /// A scenario given as a table (a Python dict), written as TOML to `OUT/scenario.toml`.
    scenario: Option<toml::Table>,
    threads: Option<usize>,
    log: Option<PathBuf>,
    /// A records directory (`strata.sweep`): with `record_mode`, what to do with it.
    records: Option<PathBuf>,
    /// `plan` (count the jobs), `run` (the jobs `only` lists, or all) or `merge`.
    record_mode: Option<String>,
    only: Option<Vec<usize>>,
}

/// The experiments' names.
#[pyfunction]
pub fn experiments() -> Vec<&'static str> {
    EXPERIMENTS.to_vec()
}

/// Runs experiment `name` with the options `options_json` holds (without the GIL); returns its
/// outcome as JSON: the output directory, the files written and the summary.
#[pyfunction]
pub fn run_experiment(py: Python<'_>, name: &str, options_json: &str) -> PyResult<String> {
    if !EXPERIMENTS.contains(&name) {
        return Err(config_error(format!(
            "no experiment `{name}` (try: {})",
            EXPERIMENTS.join(", ")
        )));
    }
    let spec: ExperimentSpec = from_json(options_json, "experiment options")?;
    if spec.scenario.is_some() && spec.scenario_file.is_some() {
        return Err(config_error(
            "field `scenario`: give the scenario as a table or as `scenario_file`, not both",
        ));
    }
    if spec.runs == Some(0) {
        return Err(config_error("field `runs`: must be at least 1"));
    }
    let records = match (&spec.records, spec.record_mode.as_deref()) {
        (None, None) if spec.only.is_none() => None,
        (Some(dir), Some(mode)) => {
            let mode = match (mode, &spec.only) {
                ("plan", None) => RecordMode::Plan,
                ("run", only) => RecordMode::Run { only: only.clone() },
                ("merge", None) => RecordMode::Merge,
                ("plan" | "merge", Some(_)) => {
                    return Err(config_error(format!(
                        "field `only`: lists the jobs of record_mode `run`, not `{mode}`"
                    )));
                }
                (other, _) => {
                    return Err(config_error(format!(
                        "field `record_mode`: `{other}` is not one of plan, run, merge"
                    )));
                }
            };
            // Real-time experiments cannot be split: the caller's choice, not a failed run.
            strata_experiments::check_recordable(name, strata_games::physics::Engine::Sim)
                .map_err(|e| config_error(format!("{e:#}")))?;
            Some(Records { dir: dir.clone(), mode })
        }
        _ => {
            return Err(config_error(
                "fields `records`, `record_mode`: give both (and `only` with `run`), or none",
            ));
        }
    };
    let out = spec.out.clone().unwrap_or_else(|| Path::new("results").join(name));
    let mut options = Options {
        runs: spec.runs,
        seed: spec.seed.unwrap_or(1),
        out: Some(out.clone()),
        scenario: spec.scenario_file.clone(),
        log: spec.log.clone(),
        records,
        ..Options::default()
    };
    if let Some(threads) = spec.threads {
        options.threads = threads.max(1);
    }
    let outcome = py.detach(|| -> anyhow::Result<_> {
        if let Some(table) = &spec.scenario {
            // The experiments read their scenario from a file (its directory resolves relative
            // team files): the table becomes one, kept beside the results it produced.
            std::fs::create_dir_all(&out)?;
            let path = out.join("scenario.toml");
            std::fs::write(&path, toml::to_string(table)?)?;
            options.scenario = Some(path);
        }
        strata_experiments::run(name, &options)
    });
    // A scenario the experiment refuses is the caller's configuration, not a failed run.
    let outcome = outcome.map_err(|e| match e.downcast_ref::<ScenarioError>() {
        Some(scenario) => config_error(scenario),
        None => run_error(e),
    })?;
    to_json(&outcome)
}
