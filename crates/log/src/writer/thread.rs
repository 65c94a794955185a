//! The writer thread: takes the queue's commands, writes them into the MCAP file, closes
//! chunks by size, log time and age, and finishes the file.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError};
use strata_runtime::Encoding;
use strata_runtime::shared::Recorder;

use crate::STATS_METADATA;
use crate::error::LogError;
use crate::mcap_file::McapFile;

use super::{
    CdrSchema, ChannelState, Command, LogSummary, McapTapOptions, Payload, Queued, Shared, Topic,
    WhenFull,
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
    pub(super) options: McapTapOptions,
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
    /// Its channel per encoding (JSON, MessagePack, CDR): a topic whose values CDR cannot
    /// write has a second, MessagePack channel.
    pub(super) channels: [Option<ChannelState>; 3],
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
                    self.apply(|w| w.write_metadata(&name, &entries));
                }
                Command::Attachment { name, media_type, time, data } => {
                    self.apply(|w| w.write_attachment(time, time, &name, &media_type, &data));
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
            self.error = Some(error);
        }
        // Metadata and attachments close the open chunk.
        self.chunk = None;
    }

    pub(super) fn close_chunk(&mut self) {
        self.chunk = None;
        if self.error.is_some() {
            return;
        }
        if let Some(writer) = self.writer.as_mut()
            && let Err(error) = writer.close_chunk().and_then(|()| writer.flush())
        {
            self.error = Some(error);
        }
    }

    pub(super) fn finish(&mut self) -> Result<LogSummary, LogError> {
        let path = self.shared.path.clone();
        let dropped_by_topic: BTreeMap<String, u64> = self
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
        let mut summary = LogSummary {
            messages: self.messages,
            dropped: self.shared.dropped.load(Ordering::Relaxed),
            serialize_errors: self.shared.serialize_errors.load(Ordering::Relaxed),
            bytes: 0,
            topics: self.topics.iter().filter(|t| t.channels.iter().any(Option::is_some)).count(),
            dropped_by_topic,
        };
        let stats = BTreeMap::from([
            ("messages".to_owned(), summary.messages.to_string()),
            ("dropped".to_owned(), summary.dropped.to_string()),
            ("serialize_errors".to_owned(), summary.serialize_errors.to_string()),
            (
                "dropped_by_topic".to_owned(),
                serde_json::to_string(&summary.dropped_by_topic).unwrap_or_default(),
            ),
        ]);
        self.apply(|w| w.write_metadata(STATS_METADATA, &stats));
        let Some(writer) = self.writer.take() else {
            return Err(LogError::WriterGone { path });
        };
        if let Some(source) = self.error.take() {
            return Err(LogError::Write { path, source });
        }
        let buffered =
            writer.finish().map_err(|source| LogError::Write { path: path.clone(), source })?;
        let file = buffered
            .into_inner()
            .map_err(|e| LogError::Write { path: path.clone(), source: e.into_error() })?;
        summary.bytes = file
            .metadata()
            .map(|m| m.len())
            .map_err(|source| LogError::Write { path: path.clone(), source })?;
        Ok(summary)
    }
}
