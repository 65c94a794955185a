//! The writer thread: takes the queue's commands, writes them into the MCAP file, closes
//! chunks by size, log time and age, and finishes the file.

use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError};
use strata_runtime::Encoding;
use strata_runtime::shared::Recorder;

use crate::STATS_METADATA;
use crate::error::LogError;
use crate::mcap_file::McapFile;

use super::{
    CdrSchema, ChannelState, Command, LogSummary, McapTapOptions, Parts, Payload, Preamble, Queued,
    Shared, Topic, WhenFull, sync,
};

/// How long the writer of a sender that waits looks for the next command before sleeping.
pub(super) const SPIN: Duration = Duration::from_micros(300);

/// The next command if one comes within [`SPIN`].
pub(super) fn spin_recv(receiver: &Receiver<Command>) -> Option<Command> {
    let start = Instant::now();
    loop {
        for _ in 0..64 {
            if let Ok(command) = receiver.try_recv() {
                return Some(command);
            }
            std::hint::spin_loop();
        }
        if start.elapsed() >= SPIN {
            return None;
        }
    }
}

pub(super) struct OpenChunk {
    pub(super) first_log_time: u64,
    pub(super) opened: Instant,
    pub(super) messages: u32,
}

pub(super) struct WriterThread {
    pub(super) shared: Arc<Shared>,
    pub(super) writer: Option<McapFile<BufWriter<File>>>,
    /// The file being written: the log's path, or its current part past the size cap.
    pub(super) path: PathBuf,
    pub(super) options: McapTapOptions,
    /// Whether chunks are synced to the disk: the options', until the file turns out to be one
    /// that cannot be (`/dev/null`, a pipe).
    pub(super) sync: bool,
    /// The files of a log split at its size cap.
    pub(super) parts: Parts,
    /// What the writer knows of each topic, by topic id (ids are dense).
    pub(super) topics: Vec<TopicState>,
    /// MCAP schema id per type name, encoding and wrapping.
    pub(super) schemas: HashMap<(String, Encoding, bool), u16>,
    /// The CDR schema of each package type, `None` for types CDR cannot describe.
    pub(super) cdr_schemas: HashMap<String, Option<Arc<CdrSchema>>>,
    /// The channel of each shared value type, and the sequence number of its next record.
    pub(super) shared_channels: HashMap<&'static str, (u16, u64)>,
    /// Their topics.
    pub(super) shared_topics: Vec<String>,
    /// Where wrapped messages are assembled.
    pub(super) scratch: Vec<u8>,
    /// Where packages are encoded (one buffer, reused).
    pub(super) encoded: Vec<u8>,
    pub(super) chunk: Option<OpenChunk>,
    pub(super) messages: u64,
    /// The first write error; afterwards records are only counted as dropped.
    pub(super) error: Option<std::io::Error>,
}

/// A topic as the writer thread knows it.
#[derive(Default)]
pub(super) struct TopicState {
    pub(super) handle: Option<Arc<Topic>>,
    /// The encoding its packages are written in, decided by its first package.
    pub(super) encoding: Option<Encoding>,
    /// Its type's CDR schema, when it is written in CDR.
    pub(super) cdr: Option<Arc<CdrSchema>>,
    /// Its channel per encoding (JSON, MessagePack, CDR) in the current file: a topic whose
    /// values CDR cannot write has a second, MessagePack channel.
    pub(super) channels: [Option<ChannelState>; 3],
    /// It had a channel in some file of the log.
    pub(super) logged: bool,
}

impl TopicState {
    pub(super) fn channel(&mut self, encoding: Encoding) -> &mut Option<ChannelState> {
        &mut self.channels[match encoding {
            Encoding::Json => 0,
            Encoding::MessagePack => 1,
            Encoding::Cdr => 2,
        }]
    }
}

/// Messages between two looks at the clock for the age of the open chunk: reading the clock
/// for each of thousands of messages per second showed in profiles.
pub(super) const AGE_CHECK_EVERY: u32 = 64;

impl WriterThread {
    /// The topic with this id (the shared list is looked at once per topic).
    pub(super) fn topic_handle(&mut self, id: u32) -> Option<Arc<Topic>> {
        if let Some(handle) = &self.topic(id).handle {
            return Some(Arc::clone(handle));
        }
        let handle = self.shared.topic(id)?;
        self.topic(id).handle = Some(Arc::clone(&handle));
        Some(handle)
    }

    pub(super) fn topic(&mut self, id: u32) -> &mut TopicState {
        let index = id as usize;
        if self.topics.len() <= index {
            self.topics.resize_with(index + 1, TopicState::default);
        }
        &mut self.topics[index]
    }

    pub(super) fn run(mut self, receiver: Receiver<Command>) {
        // Shared values in the packages this thread encodes become references to records the
        // log holds once each (see `strata_runtime::shared`).
        Recorder::default().install();
        loop {
            // A sender that waits hands a batch over every fraction of a millisecond: looking
            // for it for a while before sleeping spares it waking this thread (a system call
            // and an interrupt of the other core, measured at about 2.5 % of a match's time).
            let spun =
                if self.shared.when_full == WhenFull::Wait { spin_recv(&receiver) } else { None };
            let command = match (spun, &self.chunk) {
                (Some(command), _) => command,
                (None, Some(chunk)) => {
                    let left = self.options.max_chunk_age.saturating_sub(chunk.opened.elapsed());
                    match receiver.recv_timeout(left) {
                        Ok(command) => command,
                        Err(RecvTimeoutError::Timeout) => {
                            self.close_chunk();
                            continue;
                        }
                        Err(RecvTimeoutError::Disconnected) => break,
                    }
                }
                (None, None) => match receiver.recv() {
                    Ok(command) => command,
                    Err(_) => break,
                },
            };
            #[cfg(test)]
            self.shared.gate.wait_open();
            match command {
                Command::Messages(batch) => {
                    for &Queued { topic, log_time, stamp, seq, ref payload } in &batch.messages {
                        let Some(topic) = self.topic_handle(topic) else { continue };
                        match *payload {
                            Payload::Package(ref package) => {
                                if topic.derived {
                                    self.derive(&topic, log_time, package.as_ref());
                                }
                                self.write_package(&topic, log_time, stamp, seq, package.as_ref());
                            }
                            Payload::Encoded(ref record) => {
                                self.write_record(&topic, log_time, stamp, seq, record);
                            }
                            Payload::Bytes { start, len } => {
                                let schema = topic.cdr.get().cloned();
                                let bytes = batch.bytes.get(start..start + len).unwrap_or_default();
                                self.write_message(
                                    &topic,
                                    Encoding::Cdr,
                                    schema,
                                    log_time,
                                    stamp,
                                    seq,
                                    bytes,
                                );
                            }
                        }
                    }
                    self.shared.recycle(batch);
                }
                Command::Metadata { name, entries } => {
                    self.preamble(Preamble::Metadata { name, entries });
                }
                Command::Attachment { name, media_type, time, data } => {
                    self.preamble(Preamble::Attachment { name, media_type, time, data });
                }
                Command::Finish(reply) => {
                    // Whatever was queued after the finish request is late: count it.
                    while let Ok(late) = receiver.try_recv() {
                        self.shared.refused(late);
                    }
                    let _ = reply.send(self.finish());
                    return;
                }
            }
        }
        // Every tap handle is gone without `finish` (cannot happen through `McapTap`, whose
        // drop finishes): still close the file properly.
        let _ = self.finish();
    }

    /// Runs a write, remembering the first failure; a failed writer only counts drops.
    pub(super) fn apply(
        &mut self,
        write: impl FnOnce(&mut McapFile<BufWriter<File>>) -> std::io::Result<()>,
    ) {
        if self.error.is_some() {
            return;
        }
        if let Some(writer) = self.writer.as_mut()
            && let Err(error) = write(writer)
        {
            self.fail(error);
        }
        // Metadata and attachments close the open chunk.
        self.chunk = None;
    }

    /// Remembers the first write error, and has the tap report it and stop taking records at
    /// once: a full disk must not go unnoticed until the log is finished.
    pub(super) fn fail(&mut self, error: std::io::Error) {
        if self.error.is_none() {
            self.shared.fail(&self.path, &error);
            self.error = Some(error);
        }
    }

    /// Closes the open chunk; past the size cap, the log goes on in a new file.
    pub(super) fn close_chunk(&mut self) {
        if !self.end_chunk() {
            return;
        }
        let position = self.writer.as_ref().map_or(0, McapFile::position);
        if self.options.max_file_size.is_some_and(|max| position >= max) {
            self.next_part();
        }
    }

    /// Closes the open chunk and makes it [durable](WriterThread::make_durable); `false`:
    /// there was none, or the writer has failed.
    pub(super) fn end_chunk(&mut self) -> bool {
        self.chunk = None;
        if self.error.is_some() {
            return false;
        }
        let Some(writer) = self.writer.as_mut() else { return false };
        match writer.close_chunk() {
            Ok(true) => {
                self.make_durable();
                self.error.is_none()
            }
            Ok(false) => false,
            Err(error) => {
                self.fail(error);
                false
            }
        }
    }

    /// Hands what was written to the operating system (a killed process then loses at most
    /// the open chunk) and, when asked, syncs it to the disk (so does a power cut).
    pub(super) fn make_durable(&mut self) {
        if self.error.is_some() {
            return;
        }
        let Some(writer) = self.writer.as_mut() else { return };
        if let Err(error) = writer.flush() {
            return self.fail(error);
        }
        if self.sync {
            match sync(writer.get_ref().get_ref()) {
                Ok(true) => self.count_sync(),
                Ok(false) => self.sync = false,
                Err(error) => self.fail(error),
            }
        }
    }

    pub(super) fn finish(&mut self) -> Result<LogSummary, LogError> {
        let path = self.path.clone();
        // The last chunk is synced like the others, before the statistics.
        self.end_chunk();
        let counts = self.counts();
        let stats = counts.since(&self.parts.start).metadata();
        self.apply(|w| w.write_metadata(STATS_METADATA, &stats));
        if let Some(source) = self.error.take() {
            self.writer = None;
            return Err(LogError::Write { path, source });
        }
        let Some(writer) = self.writer.take() else {
            return Err(LogError::WriterGone { path });
        };
        let bytes = self.finish_file(writer).map_err(|source| LogError::Write { path, source })?;
        let mut files = std::mem::take(&mut self.parts.finished);
        files.push(self.path.clone());
        Ok(LogSummary {
            messages: counts.messages,
            dropped: counts.dropped,
            serialize_errors: counts.serialize_errors,
            bytes: self.parts.bytes + bytes,
            files,
            topics: self.topics.iter().filter(|t| t.logged).count(),
            dropped_by_topic: counts.dropped_by_topic,
        })
    }
}
