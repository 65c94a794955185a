//! Logging and replay for Strata (docs/architecture.md, Principles, 8: observable by default).
//!
//! - [`McapTap`] is a [`strata_runtime::Tap`] that records every package a host delivers into
//!   an [MCAP](https://mcap.dev) file: one channel per connection writer (`"{module}/{output}"`),
//!   MessagePack (or JSON) messages with a JSON Schema per Rust type, so generic tools
//!   (Foxglove, the `mcap` CLI) open the logs. The sending module only clones a package; the
//!   writer thread encodes it. A bounded background thread writes the file; a full queue drops and
//!   counts (by default), it never blocks a real-time layer; simulated-time runs can ask it to
//!   wait instead, for a complete log. It can sync each chunk to the disk, reports a failed
//!   write at once, and splits a long log into files at a size cap. The graph description and
//!   the run's metadata (seed, command line, configuration, version) travel in the file, so a
//!   module can be rebuilt and replayed from it.
//! - A [`Derive`] set on the log works out, on the writer thread, the records it makes of
//!   the packages (a match's game state and behavior paths): the sending modules pay nothing
//!   for them.
//! - [`LogReader`] reads a log: a complete one through its summary, a truncated one (killed
//!   process) by scanning its chunks up to the first incomplete one, passing over damaged
//!   ones.
//! - [`replay`] re-runs modules of a logged graph on the lockstep host from their logged
//!   inputs, seed and (optionally overridden) parameters, and lists where their outputs differ
//!   from the logged ones.

mod error;
mod info;
mod mcap_file;
pub mod overrides;
mod reader;
pub mod replay;
mod schema;
mod writer;

pub use error::LogError;
pub use info::{LogInfo, TopicSummary};
pub use reader::{
    LogMessage, LogReader, LoggedAttachment, LoggedGraph, LoggedMetadata, LoggedStats, Messages,
    Recovery, TopicInfo,
};
pub use schema::infer_json_schema;
pub use writer::{
    ConfigFormat, Derive, DerivedRecords, LogCompression, LogSummary, McapTap, McapTapOptions,
    RecordSchema, RunInfo, ScopedTap, WhenFull,
};

/// Metadata record holding [`RunInfo`] (seed, version, command line, configuration format).
pub const RUN_METADATA: &str = "strata.run";
/// Metadata record holding one graph description (`Graph::describe()` as JSON) and the topic
/// prefix (`scope`) its packages were logged under. A log may hold several (one per host).
pub const GRAPH_METADATA: &str = "strata.graph";
/// Metadata record written when a log is finished: messages written, packages dropped.
pub const STATS_METADATA: &str = "strata.log_stats";
/// Attachment holding the run's configuration text, as given (`config.toml` or `config.json`).
pub const CONFIG_ATTACHMENT_PREFIX: &str = "config.";
/// Channel metadata key telling what an MCAP message's `publish_time` holds in Strata logs:
/// the package's stamp (when its data was measured), not when it was sent.
pub const PUBLISH_TIME_KEY: &str = "strata.publish_time";

/// Channel metadata key present on channels whose values are not maps (objects): each message
/// is then `{"value": <the value>}` (generic tools expect objects); the key's value names the
/// field. [`LogReader`] unwraps them.
pub const WRAPPED_KEY: &str = "strata.wrapped";
/// The field wrapped values are stored in.
pub const WRAP_FIELD: &str = "value";

/// Channel metadata key of CDR channels: the values' [`strata_runtime::cdr::Format`] as JSON,
/// which Strata's readers use to show values without their Rust types (the schema itself is
/// OMG IDL, for generic tools).
pub const FORMAT_KEY: &str = "strata.format";

/// Channel metadata key (value `true`) of the channels that hold shared values' records
/// (`shared/...`), which packages refer to by id (see [`strata_runtime::shared`]).
pub const SHARED_KEY: &str = "strata.shared";

/// The topic a package of `output` of module `module` is logged under.
pub fn package_topic(module: &str, output: &str) -> String {
    format!("{module}/{output}")
}
