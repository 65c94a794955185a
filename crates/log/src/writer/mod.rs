//! [`McapTap`]: records every package a host delivers into an MCAP file, from a background
//! thread fed by a bounded queue.
//!
//! One room per file: the log's [`options`] and [`run_info`]; the [`tap`] hosts hand their
//! packages to, with its [`scoped`] form and a host's own [`sender`]; [`gather`], how packages
//! are handed over and batched for the writer thread; the state they [`shared`] with it, and
//! the [`topics`]; the writer [`thread`], how it [`write`](mod@write)s messages and the
//! [`channels`] it creates, and how a long log is split into [`parts`]; the [`encoding`]
//! helpers, and what a log may [`derive`](mod@derive) from its packages.

mod channels;
mod derive;
mod encoding;
mod gather;
mod options;
mod parts;
mod run_info;
mod scoped;
mod sender;
mod shared;
mod tap;
#[cfg(test)]
mod test_gate;
#[cfg(test)]
mod tests;
mod thread;
mod topics;
mod write;

use channels::{ChannelState, shared_channel};
pub use derive::{Derive, DerivedRecords};
pub use encoding::RecordSchema;
pub(crate) use encoding::wrap_frame;
use encoding::{CdrSchema, EncodedRecord, is_map};
use gather::{
    BATCH, Batch, Gather, Gathering, Locked, Offered, Payload, Queued, SPARE_BATCHES, WAIT_QUEUE,
};
use options::ZSTD_LEVEL;
pub use options::{LogCompression, LogSummary, McapTapOptions, WhenFull};
use parts::{Parts, Preamble, part_path, start_file, sync};
pub use run_info::{ConfigFormat, RunInfo};
pub use scoped::ScopedTap;
use sender::McapSender;
use shared::{Command, Failure, Shared};
pub use tap::McapTap;
use thread::{AGE_CHECK_EVERY, OpenChunk, WriterThread};
use topics::{Topic, TopicCache};
