//! [`LogReader`]: reads a Strata MCAP log, complete or cut short.
//!
//! A complete file is read through its summary (channels, statistics, chunk and metadata
//! indexes at the end). A file without a valid footer (the process was killed) is scanned from
//! the start, record by record, up to its end or its first incomplete record: every complete
//! chunk is kept, and a damaged one is passed over, the scan going on at the next chunk that
//! reads back whole. The writer closes chunks often (see [`crate::McapTapOptions`]), so little
//! is lost.

mod messages;
mod open;
mod records;
mod resync;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use strata_runtime::cdr::{self, Format};
use strata_runtime::{Encoding, EncodingError, GraphDescription, Time};

use crate::error::LogError;
use crate::writer::{ConfigFormat, RunInfo};
use crate::{CONFIG_ATTACHMENT_PREFIX, GRAPH_METADATA, RUN_METADATA, STATS_METADATA};

pub use messages::Messages;

use messages::ChannelInfo;
use records::{
    MAGIC, MAX_RECORD_BYTES, RECORD_HEADER, RecordFile, check_chunk_records, decode_chunk,
    parse_attachment, parse_metadata,
};

/// One logged message.
#[derive(Clone, Debug, PartialEq)]
pub struct LogMessage {
    pub topic: Arc<str>,
    pub type_name: Arc<str>,
    /// When the package became visible to its readers (host time).
    pub log_time: Time,
    /// When its data was measured (the package's stamp).
    pub stamp: Time,
    pub seq: u64,
    /// How `data` is encoded (its channel's `message_encoding`).
    pub encoding: Encoding,
    /// The value, encoded.
    pub data: Vec<u8>,
    /// The value's format, for CDR (from the channel's metadata).
    pub format: Option<Arc<Format>>,
}

impl LogMessage {
    /// The value as a JSON value, whatever its encoding (CDR through its format).
    pub fn json(&self) -> Result<serde_json::Value, EncodingError> {
        match (self.encoding, &self.format) {
            (Encoding::Cdr, Some(format)) => Ok(cdr::to_json(format, &self.data)?),
            (Encoding::Cdr, None) => Err(cdr::CdrError::NotSelfDescribing(
                "a CDR message of a channel without `strata.format`",
            )
            .into()),
            (encoding, _) => encoding.decode(&self.data),
        }
    }

    /// The value as its Rust type.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, EncodingError> {
        self.encoding.decode(&self.data)
    }
}

/// A topic of the log.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopicInfo {
    pub name: String,
    /// The Rust type of its messages.
    pub type_name: String,
    pub message_encoding: String,
    pub schema_encoding: Option<String>,
    pub messages: u64,
}

/// A metadata record.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedMetadata {
    pub name: String,
    pub entries: BTreeMap<String, String>,
}

/// An attachment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoggedAttachment {
    pub name: String,
    pub media_type: String,
    pub data: Vec<u8>,
}

/// A logged graph description and the topic prefix its packages were logged under.
#[derive(Clone, Debug)]
pub struct LoggedGraph {
    pub scope: String,
    pub description: GraphDescription,
}

/// The writer's own account, stored when the log was finished.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedStats {
    pub messages: u64,
    pub dropped: u64,
    pub serialize_errors: u64,
    pub dropped_by_topic: BTreeMap<String, u64>,
}

/// How much of a file without a valid footer could be read.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Recovery {
    /// Bytes read, up to the end of the last complete record (damaged stretches skipped on the
    /// way included: see `skipped_bytes`).
    pub valid_bytes: u64,
    pub file_bytes: u64,
    /// Chunks read.
    pub chunks: usize,
    pub messages: u64,
    /// Damaged chunks passed over, reading on at the next chunk that reads back whole.
    #[serde(default)]
    pub skipped_chunks: usize,
    /// The bytes of the damaged stretches passed over.
    #[serde(default)]
    pub skipped_bytes: u64,
    /// Why reading stopped there, and what was skipped.
    pub stopped: String,
}

/// Where a chunk is, and what it spans.
#[derive(Clone, Copy, Debug)]
struct ChunkLocation {
    offset: u64,
    length: u64,
}

/// An opened log: its topics, metadata and where its messages are; messages are read on demand,
/// one chunk at a time.
#[derive(Debug)]
pub struct LogReader {
    path: PathBuf,
    file_bytes: u64,
    complete: bool,
    recovery: Option<Recovery>,
    chunks: Vec<ChunkLocation>,
    channels: HashMap<u16, ChannelInfo>,
    topics: Vec<TopicInfo>,
    message_count: u64,
    time_range: Option<(Time, Time)>,
    metadata: Vec<LoggedMetadata>,
    attachments: Vec<LoggedAttachment>,
}

impl LogReader {
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the file was finished (summary and footer present and readable).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// For a file that was not finished: how much of it was recovered.
    pub fn recovery(&self) -> Option<&Recovery> {
        self.recovery.as_ref()
    }

    pub fn file_bytes(&self) -> u64 {
        self.file_bytes
    }

    pub fn message_count(&self) -> u64 {
        self.message_count
    }

    pub fn chunk_count(&self) -> usize {
        self.chunks.len()
    }

    /// First and last log time of the messages.
    pub fn time_range(&self) -> Option<(Time, Time)> {
        self.time_range
    }

    /// Topics, by name.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    pub fn metadata(&self) -> &[LoggedMetadata] {
        &self.metadata
    }

    pub fn attachments(&self) -> &[LoggedAttachment] {
        &self.attachments
    }

    fn invalid(&self, what: String) -> LogError {
        LogError::Invalid { path: self.path.clone(), what }
    }

    /// The run's seed, command line, version and configuration text, if stored.
    pub fn run_info(&self) -> Result<Option<RunInfo>, LogError> {
        let Some(run) = self.metadata.iter().find(|m| m.name == RUN_METADATA) else {
            return Ok(None);
        };
        let get = |key: &str| run.entries.get(key);
        let seed = match get("seed") {
            Some(seed) => seed
                .parse()
                .map_err(|e| self.invalid(format!("{RUN_METADATA}: bad seed `{seed}`: {e}")))?,
            None => return Err(self.invalid(format!("{RUN_METADATA} has no seed"))),
        };
        let command_line = match get("command_line") {
            Some(text) => serde_json::from_str(text).map_err(|source| LogError::Json {
                path: self.path.clone(),
                what: "the command line".into(),
                source,
            })?,
            None => Vec::new(),
        };
        let config = match get("config_format").map(String::as_str) {
            None => None,
            Some(ext) => {
                let format = match ext {
                    "toml" => ConfigFormat::Toml,
                    "json" => ConfigFormat::Json,
                    other => {
                        return Err(self.invalid(format!("unknown configuration format `{other}`")));
                    }
                };
                let name = format!("{CONFIG_ATTACHMENT_PREFIX}{ext}");
                let attachment =
                    self.attachments.iter().find(|a| a.name == name).ok_or_else(|| {
                        self.invalid(format!("the configuration attachment `{name}` is missing"))
                    })?;
                let text = String::from_utf8(attachment.data.clone()).map_err(|_| {
                    self.invalid(format!("the configuration attachment `{name}` is not UTF-8"))
                })?;
                Some((format, text))
            }
        };
        Ok(Some(RunInfo {
            seed,
            command_line,
            version: get("version").cloned().unwrap_or_default(),
            config,
        }))
    }

    /// The run's configuration as a JSON value (TOML is converted), if stored.
    pub fn config(&self) -> Result<Option<serde_json::Value>, LogError> {
        let Some(RunInfo { config: Some((format, text)), .. }) = self.run_info()? else {
            return Ok(None);
        };
        match format {
            ConfigFormat::Json => serde_json::from_str(&text).map(Some).map_err(|source| {
                LogError::Json { path: self.path.clone(), what: "the configuration".into(), source }
            }),
            ConfigFormat::Toml => {
                let table: toml::Table = toml::from_str(&text)
                    .map_err(|source| LogError::Toml { path: self.path.clone(), source })?;
                serde_json::to_value(table).map(Some).map_err(|source| LogError::Json {
                    path: self.path.clone(),
                    what: "the configuration".into(),
                    source,
                })
            }
        }
    }

    /// Every graph description stored in the log.
    pub fn graphs(&self) -> Result<Vec<LoggedGraph>, LogError> {
        self.metadata
            .iter()
            .filter(|m| m.name == GRAPH_METADATA)
            .map(|m| {
                let text = m
                    .entries
                    .get("graph")
                    .ok_or_else(|| self.invalid(format!("{GRAPH_METADATA} has no graph")))?;
                let description = serde_json::from_str(text).map_err(|source| LogError::Json {
                    path: self.path.clone(),
                    what: "a graph description".into(),
                    source,
                })?;
                Ok(LoggedGraph {
                    scope: m.entries.get("scope").cloned().unwrap_or_default(),
                    description,
                })
            })
            .collect()
    }

    /// The writer's statistics, present when the log was finished.
    pub fn stats(&self) -> Option<LoggedStats> {
        let m = self.metadata.iter().rev().find(|m| m.name == STATS_METADATA)?;
        let number = |key: &str| m.entries.get(key).and_then(|v| v.parse().ok()).unwrap_or(0);
        Some(LoggedStats {
            messages: number("messages"),
            dropped: number("dropped"),
            serialize_errors: number("serialize_errors"),
            dropped_by_topic: m
                .entries
                .get("dropped_by_topic")
                .and_then(|v| serde_json::from_str(v).ok())
                .unwrap_or_default(),
        })
    }

    /// Every message, in file order.
    pub fn messages(&self) -> Messages<'_> {
        Messages::new(self, None)
    }

    /// The messages of the given topics, in file order.
    pub fn messages_on<'t>(&self, topics: impl IntoIterator<Item = &'t str>) -> Messages<'_> {
        let wanted: Vec<&str> = topics.into_iter().collect();
        let ids =
            self.channels.iter().filter(|(_, c)| wanted.contains(&&*c.topic)).map(|(id, _)| *id);
        Messages::new(self, Some(ids.collect()))
    }
}
