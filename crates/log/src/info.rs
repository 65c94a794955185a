//! What `strata log info` says about a log.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::reader::{LogReader, LoggedStats, Recovery};

/// A summary of a log for people (Display) and scripts (serde).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogInfo {
    pub path: String,
    pub file_bytes: u64,
    /// Finished properly: summary and footer present.
    pub complete: bool,
    /// For an unfinished file: what could be read.
    pub recovery: Option<Recovery>,
    pub messages: u64,
    pub chunks: usize,
    /// First and last log time, seconds.
    pub start_s: Option<f64>,
    pub end_s: Option<f64>,
    pub topics: Vec<TopicSummary>,
    /// Metadata record names and their keys.
    pub metadata: Vec<(String, Vec<String>)>,
    pub attachments: Vec<String>,
    pub seed: Option<u64>,
    pub version: Option<String>,
    pub command_line: Option<Vec<String>>,
    /// The writer's account (finished logs only).
    pub writer: Option<LoggedStats>,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopicSummary {
    pub name: String,
    pub type_name: String,
    pub messages: u64,
}

impl LogInfo {
    pub fn of(reader: &LogReader) -> LogInfo {
        // A damaged run record should not hide the rest of what the file holds.
        let run = reader.run_info().ok().flatten();
        LogInfo {
            path: reader.path().display().to_string(),
            file_bytes: reader.file_bytes(),
            complete: reader.is_complete(),
            recovery: reader.recovery().cloned(),
            messages: reader.message_count(),
            chunks: reader.chunk_count(),
            start_s: reader.time_range().map(|(a, _)| a.as_secs_f64()),
            end_s: reader.time_range().map(|(_, b)| b.as_secs_f64()),
            topics: reader
                .topics()
                .iter()
                .map(|t| TopicSummary {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    messages: t.messages,
                })
                .collect(),
            metadata: reader
                .metadata()
                .iter()
                .map(|m| (m.name.clone(), m.entries.keys().cloned().collect()))
                .collect(),
            attachments: reader.attachments().iter().map(|a| a.name.clone()).collect(),
            seed: run.as_ref().map(|r| r.seed),
            version: run.as_ref().map(|r| r.version.clone()),
            command_line: run.map(|r| r.command_line),
            writer: reader.stats(),
        }
    }

    pub fn duration_s(&self) -> f64 {
        match (self.start_s, self.end_s) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }
}

impl fmt::Display for LogInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "file:      {} ({} bytes)", self.path, self.file_bytes)?;
        match &self.recovery {
            None if self.complete => {
                writeln!(f, "status:    complete (summary and footer present)")?
            }
            None => writeln!(f, "status:    incomplete")?,
            Some(r) => {
                writeln!(
                    f,
                    "status:    TRUNCATED: recovered {} messages in {} complete chunks ({} of {} bytes)",
                    r.messages, r.chunks, r.valid_bytes, r.file_bytes
                )?;
                if r.skipped_chunks > 0 || r.skipped_bytes > 0 {
                    writeln!(
                        f,
                        "           DAMAGED: skipped {} damaged chunks ({} bytes) and read on",
                        r.skipped_chunks, r.skipped_bytes
                    )?;
                }
                writeln!(f, "           {}", r.stopped)?;
            }
        }
        match (self.start_s, self.end_s) {
            (Some(a), Some(b)) => writeln!(
                f,
                "time:      {a:.3} s to {b:.3} s ({:.3} s), {} messages in {} chunks",
                b - a,
                self.messages,
                self.chunks
            )?,
            _ => writeln!(f, "time:      no messages")?,
        }
        if let Some(seed) = self.seed {
            writeln!(f, "seed:      {seed}")?;
        }
        if let Some(version) = &self.version {
            writeln!(f, "version:   {version}")?;
        }
        if let Some(command) = &self.command_line {
            writeln!(f, "command:   {}", command.join(" "))?;
        }
        match &self.writer {
            Some(w) => {
                writeln!(
                    f,
                    "writer:    {} written, {} dropped, {} unserializable",
                    w.messages, w.dropped, w.serialize_errors
                )?;
                for (topic, n) in &w.dropped_by_topic {
                    writeln!(f, "           dropped {n} on {topic}")?;
                }
            }
            None => writeln!(f, "writer:    no statistics (the log was not finished)")?,
        }
        writeln!(f, "topics:    {}", self.topics.len())?;
        let width = self.topics.iter().map(|t| t.name.len()).max().unwrap_or(0);
        for topic in &self.topics {
            writeln!(f, "  {:<width$}  {:>9}  {}", topic.name, topic.messages, topic.type_name)?;
        }
        if !self.metadata.is_empty() {
            writeln!(f, "metadata:")?;
            for (name, keys) in &self.metadata {
                writeln!(f, "  {name}: {}", keys.join(", "))?;
            }
        }
        if !self.attachments.is_empty() {
            writeln!(f, "attachments: {}", self.attachments.join(", "))?;
        }
        Ok(())
    }
}
