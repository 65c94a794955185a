//! A log split into files at its size cap ([`McapTapOptions::max_file_size`]): each file is
//! finished like a whole log (the writer's statistics for it, summary, footer), and the next
//! starts with the run, graph and configuration the log was given, then its channels and shared
//! values again as they come up, so that every file reads, shows and replays on its own.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, ErrorKind, IntoInnerError};
use std::path::{Path, PathBuf};
use std::sync::PoisonError;
use std::sync::atomic::Ordering;

use strata_runtime::shared::Recorder;

use crate::STATS_METADATA;
use crate::mcap_file::{ChunkCompression, McapFile};

use super::{LogCompression, McapTapOptions, WriterThread, ZSTD_LEVEL};

/// The files of a log split at its size cap.
#[derive(Default)]
pub(super) struct Parts {
    /// The files finished before the current one.
    pub(super) finished: Vec<PathBuf>,
    /// Their bytes.
    pub(super) bytes: u64,
    /// What every file starts with: the metadata and attachments written through the tap, in
    /// order (kept only when the log has a size cap).
    pub(super) preamble: Vec<Preamble>,
    /// The counts when the current file was started: its statistics are what they grew by.
    pub(super) start: Counts,
}

/// A metadata record or an attachment every file of the log holds.
pub(super) enum Preamble {
    Metadata { name: String, entries: BTreeMap<String, String> },
    Attachment { name: String, media_type: String, time: u64, data: Vec<u8> },
}

impl Preamble {
    fn write(&self, writer: &mut McapFile<BufWriter<File>>) -> io::Result<()> {
        match self {
            Preamble::Metadata { name, entries } => writer.write_metadata(name, entries),
            Preamble::Attachment { name, media_type, time, data } => {
                writer.write_attachment(*time, *time, name, media_type, data)
            }
        }
    }
}

/// What the writer wrote and what was dropped, as stored in a file's `strata.log_stats`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) struct Counts {
    pub(super) messages: u64,
    pub(super) dropped: u64,
    pub(super) serialize_errors: u64,
    pub(super) dropped_by_topic: BTreeMap<String, u64>,
}

impl Counts {
    /// What these counts grew by since `start`.
    pub(super) fn since(&self, start: &Counts) -> Counts {
        let dropped_by_topic = self
            .dropped_by_topic
            .iter()
            .filter_map(|(topic, &n)| {
                let before = start.dropped_by_topic.get(topic).copied().unwrap_or(0);
                (n > before).then(|| (topic.clone(), n - before))
            })
            .collect();
        Counts {
            messages: self.messages.saturating_sub(start.messages),
            dropped: self.dropped.saturating_sub(start.dropped),
            serialize_errors: self.serialize_errors.saturating_sub(start.serialize_errors),
            dropped_by_topic,
        }
    }

    /// The entries of a `strata.log_stats` metadata record.
    pub(super) fn metadata(&self) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("messages".to_owned(), self.messages.to_string()),
            ("dropped".to_owned(), self.dropped.to_string()),
            ("serialize_errors".to_owned(), self.serialize_errors.to_string()),
            (
                "dropped_by_topic".to_owned(),
                serde_json::to_string(&self.dropped_by_topic).unwrap_or_default(),
            ),
        ])
    }
}

/// The path of file `part` of a log whose first file is `path`: `path` itself for part 0, then
/// `-1`, `-2`... after its stem (`robot.mcap`, `robot-1.mcap`, `robot-2.mcap`).
pub(super) fn part_path(path: &Path, part: u32) -> PathBuf {
    if part == 0 {
        return path.to_path_buf();
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match path.extension() {
        Some(extension) => format!("{stem}-{part}.{}", extension.to_string_lossy()),
        None => format!("{stem}-{part}"),
    };
    path.with_file_name(name)
}

/// Starts an MCAP file in `file`: its magic and header.
pub(super) fn start_file(
    file: File,
    options: &McapTapOptions,
) -> io::Result<McapFile<BufWriter<File>>> {
    let compression = match options.compression {
        LogCompression::Zstd => ChunkCompression::Zstd(ZSTD_LEVEL),
        LogCompression::Lz4 => ChunkCompression::Lz4,
        LogCompression::None => ChunkCompression::None,
    };
    McapFile::new(
        BufWriter::with_capacity(1 << 20, file),
        "strata",
        &format!("strata-log {}", env!("CARGO_PKG_VERSION")),
        compression,
        usize::try_from(options.chunk_size.max(1024)).unwrap_or(usize::MAX),
    )
}

/// Syncs `file` to the disk; `false`: the file cannot be synced (`/dev/null`, a pipe), which
/// is no failure of the log.
pub(super) fn sync(file: &File) -> io::Result<bool> {
    match file.sync_data() {
        Ok(()) => Ok(true),
        Err(error) if matches!(error.kind(), ErrorKind::InvalidInput | ErrorKind::Unsupported) => {
            Ok(false)
        }
        Err(error) => Err(error),
    }
}

impl WriterThread {
    /// What was written and dropped so far.
    pub(super) fn counts(&self) -> Counts {
        let dropped_by_topic = self
            .shared
            .topics
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .filter_map(|t| {
                let n = t.dropped.load(Ordering::Relaxed);
                (n > 0).then(|| (t.name.clone(), n))
            })
            .collect();
        Counts {
            messages: self.messages,
            dropped: self.shared.dropped.load(Ordering::Relaxed),
            serialize_errors: self.shared.serialize_errors.load(Ordering::Relaxed),
            dropped_by_topic,
        }
    }

    /// Writes a record of the preamble (the run, a graph, the configuration), after the
    /// chunk it closes, both made durable: what a reader needs to make sense of the chunks
    /// after it. Every later file of the log starts with it too.
    pub(super) fn preamble(&mut self, record: Preamble) {
        self.end_chunk();
        self.apply(|w| record.write(w));
        self.make_durable();
        if self.options.max_file_size.is_some() {
            self.parts.preamble.push(record);
        }
    }

    /// Writes the footer and summary of a file, syncs it when asked, and says how long it is.
    pub(super) fn finish_file(&mut self, writer: McapFile<BufWriter<File>>) -> io::Result<u64> {
        let file = writer.finish()?.into_inner().map_err(IntoInnerError::into_error)?;
        if self.sync {
            if sync(&file)? {
                self.count_sync();
            } else {
                self.sync = false;
            }
        }
        Ok(file.metadata()?.len())
    }

    pub(super) fn count_sync(&self) {
        #[cfg(test)]
        self.shared.syncs.fetch_add(1, Ordering::Relaxed);
    }

    /// Finishes the current file with its own statistics and goes on in the next one.
    pub(super) fn next_part(&mut self) {
        let counts = self.counts();
        let stats = counts.since(&self.parts.start).metadata();
        self.apply(|w| w.write_metadata(STATS_METADATA, &stats));
        if self.error.is_some() {
            return;
        }
        let Some(writer) = self.writer.take() else { return };
        match self.finish_file(writer) {
            Ok(bytes) => self.parts.bytes += bytes,
            Err(error) => return self.fail(error),
        }
        self.parts.start = counts;
        let part = u32::try_from(self.parts.finished.len() + 1).unwrap_or(u32::MAX);
        let next = part_path(&self.shared.path, part);
        self.parts.finished.push(std::mem::replace(&mut self.path, next));
        match File::create(&self.path).and_then(|file| start_file(file, &self.options)) {
            Ok(writer) => self.writer = Some(writer),
            Err(error) => return self.fail(error),
        }
        self.forget_channels();
        let preamble = std::mem::take(&mut self.parts.preamble);
        for record in &preamble {
            self.apply(|w| record.write(w));
        }
        self.parts.preamble = preamble;
        if let Some(derive) =
            self.shared.derive.lock().unwrap_or_else(PoisonError::into_inner).as_mut()
        {
            derive.next_file();
        }
    }

    /// A new file has none of the channels, schemas and shared values' records of the last
    /// one: each is written again before its first message in this file.
    fn forget_channels(&mut self) {
        for topic in &mut self.topics {
            topic.channels = Default::default();
        }
        self.schemas.clear();
        self.shared_channels.clear();
        self.shared_topics.clear();
        self.chunk = None;
        Recorder::default().install();
    }
}
