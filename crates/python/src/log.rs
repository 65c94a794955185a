//! `strata.read_log`, `strata.log_info`: a log's records (`strata log cat`, `strata log info`).

use std::path::PathBuf;

use anyhow::Context as _;
use pyo3::prelude::*;
use strata_log::{LogInfo, LogReader};

use crate::{run_error, to_json};

/// What the log holds, as JSON (`strata log info --json`).
#[pyfunction]
pub fn log_info(path: PathBuf) -> PyResult<String> {
    let reader = LogReader::open(&path).map_err(|e| run_error(e.into()))?;
    to_json(&LogInfo::of(&reader))
}

/// The log's messages as a JSON list of records (topic, log time, stamp, sequence number,
/// decoded value), only those of `topics` when given, at most `limit`.
#[pyfunction]
#[pyo3(signature = (path, topics=None, limit=None))]
pub fn read_log(
    py: Python<'_>,
    path: PathBuf,
    topics: Option<Vec<String>>,
    limit: Option<usize>,
) -> PyResult<String> {
    let records = py.detach(|| -> anyhow::Result<Vec<serde_json::Value>> {
        let reader = LogReader::open(&path)?;
        let topics = topics.unwrap_or_default();
        if let Some(missing) = topics.iter().find(|t| reader.topic(t).is_none()) {
            anyhow::bail!("{} has no topic `{missing}`", path.display());
        }
        let messages = if topics.is_empty() {
            reader.messages()
        } else {
            reader.messages_on(topics.iter().map(String::as_str))
        };
        let mut records = Vec::new();
        for message in messages.take(limit.unwrap_or(usize::MAX)) {
            let message = message?;
            let value: serde_json::Value = message.json().with_context(|| {
                format!("message {} of `{}` does not decode", message.seq, message.topic)
            })?;
            records.push(serde_json::json!({
                "topic": &*message.topic,
                "time": message.log_time.as_secs_f64(),
                "stamp": message.stamp.as_secs_f64(),
                "seq": message.seq,
                "value": value,
            }));
        }
        Ok(records)
    });
    to_json(&records.map_err(run_error)?)
}
