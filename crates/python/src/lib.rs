//! `strata._native`: the Rust side of the Python package `strata` (python/strata). Configs
//! come in and results go out as JSON text: the reports are serde types already, and the
//! Python side's `json` turns them into plain dicts and lists without another dependency.

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

mod experiment;
mod gym;
mod log;
mod matches;

/// A configuration that cannot be used (the message names the field): `ValueError`.
pub(crate) fn config_error(error: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(error.to_string())
}

/// A run that failed: `RuntimeError`, with the whole chain of causes.
pub(crate) fn run_error(error: anyhow::Error) -> PyErr {
    PyRuntimeError::new_err(format!("{error:#}"))
}

/// Parses JSON into `T`; errors name the field's path (`home`, `log.path`).
pub(crate) fn from_json<T: serde::de::DeserializeOwned>(text: &str, what: &str) -> PyResult<T> {
    let mut deserializer = serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(&mut deserializer).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        if path.is_empty() || path == "." {
            config_error(format!("{what}: {inner}"))
        } else {
            config_error(format!("{what}: field `{path}`: {inner}"))
        }
    })
}

pub(crate) fn to_json(value: &impl serde::Serialize) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(matches::run_match, m)?)?;
    m.add_function(wrap_pyfunction!(experiment::run_experiment, m)?)?;
    m.add_function(wrap_pyfunction!(experiment::experiments, m)?)?;
    m.add_function(wrap_pyfunction!(log::log_info, m)?)?;
    m.add_function(wrap_pyfunction!(log::read_log, m)?)?;
    m.add_class::<gym::GazeEnv>()?;
    Ok(())
}
