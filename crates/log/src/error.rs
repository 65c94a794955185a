//! Errors of log writing, reading and replay, each naming the file and, where it matters, the
//! byte offset.

use std::io;
use std::path::PathBuf;

/// What went wrong with a log file.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("cannot create log file {}: {source}", path.display())]
    Create { path: PathBuf, source: io::Error },
    #[error("cannot open log file {}: {source}", path.display())]
    Open { path: PathBuf, source: io::Error },
    #[error("cannot read {} at byte {offset}: {source}", path.display())]
    Read { path: PathBuf, offset: u64, source: io::Error },
    #[error("{} is not an MCAP file (no MCAP magic at its start)", path.display())]
    NotMcap { path: PathBuf },
    #[error("{}: bad MCAP record at byte {offset}: {source}", path.display())]
    Record { path: PathBuf, offset: u64, source: mcap::McapError },
    #[error("{}: the chunk index points past the end of the file (byte {offset})", path.display())]
    BadIndex { path: PathBuf, offset: u64 },
    #[error("writing log {} failed: {source}", path.display())]
    Write { path: PathBuf, source: io::Error },
    #[error("{}: {what} is not valid JSON: {source}", path.display())]
    Json { path: PathBuf, what: String, source: serde_json::Error },
    #[error("{}: the configuration is not valid TOML: {source}", path.display())]
    Toml { path: PathBuf, source: toml::de::Error },
    #[error("{}: {what}", path.display())]
    Invalid { path: PathBuf, what: String },
    #[error("the writer thread of log {} stopped unexpectedly", path.display())]
    WriterGone { path: PathBuf },
    #[error("cannot start the writer thread of log {}: {source}", path.display())]
    Spawn { path: PathBuf, source: io::Error },
}
