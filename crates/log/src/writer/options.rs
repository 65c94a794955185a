//! How a log is configured (queue, chunking, compression, encoding) and what a finished one
//! holds.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_runtime::Encoding;

/// How chunks are compressed: zstd at a fast level by default, on the writer thread only (no
/// compression worker threads competing with the real-time layers for the robot's cores).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogCompression {
    #[default]
    Zstd,
    Lz4,
    None,
}

impl std::str::FromStr for LogCompression {
    type Err = String;

    fn from_str(text: &str) -> Result<LogCompression, String> {
        match text {
            "zstd" => Ok(LogCompression::Zstd),
            "lz4" => Ok(LogCompression::Lz4),
            "none" => Ok(LogCompression::None),
            _ => Err(format!("unknown compression `{text}` (zstd, lz4 or none)")),
        }
    }
}

/// What a record does when the writer's queue is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WhenFull {
    /// Dropped and counted: the sending module never waits for the disk. For real-time hosts.
    #[default]
    Drop,
    /// The sender waits for room. For simulated-time runs (the lockstep host), where waiting
    /// costs no deadline and a complete log is what replay needs.
    Wait,
}

/// The zstd level of compressed logs: one of zstd's fast negative levels, whose ratio on
/// logged packages is close to level 1's at about 1.5 times its speed (`docs/logging.md`).
pub(super) const ZSTD_LEVEL: i32 = -1;

/// How a [`McapTap`](crate::McapTap) buffers and writes.
#[derive(Clone, Debug, PartialEq)]
pub struct McapTapOptions {
    /// Records the queue between the tap and the writer thread holds (with
    /// [`WhenFull::Wait`], at most 2048, in batches of 512).
    pub capacity: usize,
    /// What happens to a record that finds the queue full.
    pub when_full: WhenFull,
    /// Log only packages of modules whose full name (topic prefix included) starts with one of
    /// these, e.g. `["home/3/"]` for one robot; empty: every module. Application records
    /// ([`McapTap::record`](crate::McapTap::record)) are always logged.
    pub modules: Vec<String>,
    /// A chunk is closed once this many uncompressed bytes are in it.
    pub chunk_size: u64,
    /// ... or once it spans this much log time: a killed process loses at most the open chunk,
    /// so this bounds the loss in match time.
    pub max_chunk_span: Duration,
    /// ... or once it has been open this long in real time (a quiet real-time robot).
    pub max_chunk_age: Duration,
    pub compression: LogCompression,
    /// How package values are encoded (MCAP's `message_encoding`). With CDR (the default), a
    /// package type that CDR cannot describe (see [`strata_runtime::cdr`]) is logged as
    /// MessagePack, and so are application records.
    pub encoding: Encoding,
    /// Each chunk, once written, is synced to the disk (`File::sync_data`, on the writer
    /// thread): a power cut or a crash of the machine then loses at most the open chunk, not
    /// whatever the operating system had not written yet. Off by default: a simulated match
    /// writes hundreds of chunks per second of real time and loses nothing a rerun would not
    /// give back; `strata robot` turns it on.
    pub sync_chunks: bool,
    /// A log that grows past this many bytes goes on in a new file, each file finished and
    /// whole on its own (see [`McapTap::part_path`](crate::McapTap::part_path)): checked when a
    /// chunk is written, so a file exceeds it by at most a chunk and its summary. `None`: one
    /// file, however long the run.
    pub max_file_size: Option<u64>,
}

impl Default for McapTapOptions {
    fn default() -> Self {
        McapTapOptions {
            capacity: 65_536,
            when_full: WhenFull::Drop,
            modules: Vec::new(),
            chunk_size: 1 << 20,
            max_chunk_span: Duration::from_millis(200),
            max_chunk_age: Duration::from_millis(500),
            compression: LogCompression::Zstd,
            encoding: Encoding::Cdr,
            sync_chunks: false,
            max_file_size: None,
        }
    }
}

/// What a finished log holds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LogSummary {
    /// Messages written (packages and application records).
    pub messages: u64,
    /// Records dropped because the queue was full, the writer had failed or the log was
    /// already finished.
    pub dropped: u64,
    /// Packages whose value could not be encoded (not written).
    pub serialize_errors: u64,
    /// Size of the file (of all its files, when it was split at its size cap).
    pub bytes: u64,
    /// The files written, in order: the log's path, then its parts past the size cap
    /// ([`McapTapOptions::max_file_size`]).
    #[serde(default)]
    pub files: Vec<PathBuf>,
    /// Number of topics (channels).
    pub topics: usize,
    /// Drops per topic, for the topics that had any.
    pub dropped_by_topic: BTreeMap<String, u64>,
}
