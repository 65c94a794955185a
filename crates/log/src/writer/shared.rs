//! The state the tap handles and the writer thread share, and the queue between them.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, RwLock};

use crossbeam_channel::Sender;
use strata_runtime::Encoding;
use strata_runtime::cdr::Format;

use crate::error::LogError;

#[cfg(test)]
use super::test_gate;
use super::{
    BATCH, Batch, CdrSchema, Derive, Gathering, LogSummary, SPARE_BATCHES, Topic, WhenFull,
};

pub(super) enum Command {
    /// Messages in the order they were sent: one at a time from a real-time sender, in
    /// batches from one that waits (see [`Shared::submit`]).
    Messages(Batch),
    Metadata {
        name: String,
        entries: BTreeMap<String, String>,
    },
    Attachment {
        name: String,
        media_type: String,
        time: u64,
        data: Vec<u8>,
    },
    Finish(Sender<Result<LogSummary, LogError>>),
}

/// State shared by the tap handles and the writer thread.
pub(super) struct Shared {
    pub(super) path: PathBuf,
    pub(super) sender: Sender<Command>,
    /// Cleared by `finish`: later records are counted as dropped instead of queued.
    pub(super) accepting: AtomicBool,
    pub(super) when_full: WhenFull,
    pub(super) encoding: Encoding,
    /// Module-name prefixes to log (empty: all).
    pub(super) modules: Vec<String>,
    /// Records refused: by a full queue (in [`WhenFull::Drop`] mode), after `finish`, or by a
    /// writer that failed.
    pub(super) dropped: AtomicU64,
    /// Messages of a sender that waits for the writer (simulated time), gathered into
    /// batches of [`BATCH`]: one hand-off to the writer thread per batch instead of one per
    /// package, which would cost the sender a queue operation, and often a wake-up of the
    /// writer, for each of ten thousand packages per simulated second.
    pub(super) pending: Mutex<Gathering>,
    /// Batches the writer thread is done with, for the sender to fill again (their buffers
    /// keep their size).
    pub(super) spare: Mutex<Vec<Batch>>,
    pub(super) serialize_errors: AtomicU64,
    /// Every topic ever created, by id.
    pub(super) topics: Mutex<Vec<Arc<Topic>>>,
    /// Application record topics, by name.
    pub(super) record_topics: RwLock<HashMap<String, Arc<Topic>>>,
    /// The CDR schemas of the types senders encode, by type name: worked out once per type
    /// (the IDL text of a type takes a few hundred thousand instructions), not per robot.
    pub(super) sender_schemas: Mutex<HashMap<String, Option<Arc<CdrSchema>>>>,
    /// What the log derives from its packages (see
    /// [`McapTap::set_derive`](crate::McapTap::set_derive)); asked about each package topic when it
    /// is created, run on the writer thread.
    pub(super) derive: Mutex<Option<Box<dyn Derive>>>,
    /// The writer thread's first write error, set the moment it happens.
    pub(super) failure: OnceLock<Failure>,
    #[cfg(test)]
    pub(super) gate: Arc<test_gate::Gate>,
    /// Chunks synced to the disk.
    #[cfg(test)]
    pub(super) syncs: AtomicU64,
}

/// A write that failed: the file and the error. Kept as text, since `io::Error` does not
/// clone and the error is reported to every caller of [`McapTap::error`](crate::McapTap::error).
#[derive(Debug)]
pub(super) struct Failure {
    pub(super) path: PathBuf,
    pub(super) kind: std::io::ErrorKind,
    pub(super) message: String,
}

impl Failure {
    pub(super) fn error(&self) -> LogError {
        LogError::Write {
            path: self.path.clone(),
            source: std::io::Error::new(self.kind, self.message.clone()),
        }
    }
}

impl Shared {
    /// A new topic; `package`: of packages (which the log's [`Derive`] may want), not of
    /// application records.
    pub(super) fn new_topic(&self, name: String, type_name: &str, package: bool) -> Arc<Topic> {
        let mut topics = self.topics.lock().unwrap_or_else(PoisonError::into_inner);
        let id = u32::try_from(topics.len()).unwrap_or(u32::MAX);
        let derived = package
            && self
                .derive
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .as_mut()
                .is_some_and(|derive| derive.wants(id, &name, type_name));
        let topic = Arc::new(Topic {
            id,
            name,
            type_name: type_name.to_owned(),
            dropped: AtomicU64::new(0),
            next_seq: AtomicU64::new(0),
            handover: AtomicU8::new(0),
            cdr: OnceLock::new(),
            derived,
        });
        topics.push(Arc::clone(&topic));
        topic
    }

    /// The topic of application records named `name`, created on its first record.
    pub(super) fn record_topic(&self, name: &str, type_name: &str) -> Arc<Topic> {
        let existing =
            self.record_topics.read().unwrap_or_else(PoisonError::into_inner).get(name).cloned();
        existing.unwrap_or_else(|| {
            let mut map = self.record_topics.write().unwrap_or_else(PoisonError::into_inner);
            Arc::clone(
                map.entry(name.to_owned())
                    .or_insert_with(|| self.new_topic(name.to_owned(), type_name, false)),
            )
        })
    }

    /// Whether packages on the topic named `name` are logged (the options' module prefixes).
    pub(super) fn logs(&self, name: &str) -> bool {
        self.modules.is_empty()
            || self.modules.iter().any(|prefix| name.starts_with(prefix.as_str()))
    }

    /// The topic with this id.
    pub(super) fn topic(&self, id: u32) -> Option<Arc<Topic>> {
        self.topics.lock().unwrap_or_else(PoisonError::into_inner).get(id as usize).cloned()
    }

    pub(super) fn drop_record(&self, topic: &Topic) {
        self.dropped.fetch_add(1, Ordering::Relaxed);
        topic.dropped.fetch_add(1, Ordering::Relaxed);
    }

    /// Hands a batch to the writer thread, unless it is empty.
    pub(super) fn send_batch(&self, batch: Option<Batch>) {
        if let Some(batch) = batch.filter(|batch| !batch.messages.is_empty())
            && let Err(refused) = self.sender.send(Command::Messages(batch))
        {
            self.refused(refused.into_inner());
        }
    }

    /// An empty batch to gather into, with the buffers of one the writer is done with. The
    /// packages the writer left in it are dropped here, on the sender's thread.
    pub(super) fn spare(&self) -> Batch {
        let spare = self.spare.lock().unwrap_or_else(PoisonError::into_inner).pop();
        let emptied = spare.map(|mut batch| {
            batch.messages.clear();
            batch
        });
        emptied.unwrap_or_else(|| Batch {
            messages: Vec::with_capacity(BATCH),
            bytes: Vec::with_capacity(BATCH * 256),
        })
    }

    /// Takes back a batch the writer is done with. Its messages stay in it: the packages
    /// handed over whole go back to the thread that allocated them, to be dropped there when
    /// it takes the batch again. Freed on the writer thread, each would cost the sender's
    /// allocator a trip to the writer's cache when it allocated again (mimalloc's
    /// `_mi_page_free_collect`, up to 6 % of a logging match's time).
    pub(super) fn recycle(&self, mut batch: Batch) {
        // A real-time sender hands its packages over one by one, in batches it never reuses.
        if self.when_full == WhenFull::Drop {
            return;
        }
        batch.bytes.clear();
        let mut spare = self.spare.lock().unwrap_or_else(PoisonError::into_inner);
        if spare.len() < SPARE_BATCHES {
            spare.push(batch);
        }
    }

    /// Counts the messages of a command the queue refused as dropped.
    pub(super) fn refused(&self, command: Command) {
        if let Command::Messages(batch) = command {
            for message in &batch.messages {
                self.drop_id(message.topic);
            }
        }
    }

    pub(super) fn drop_id(&self, topic: u32) {
        match self.topic(topic) {
            Some(topic) => self.drop_record(&topic),
            None => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Hands the messages gathered so far to the writer thread, ahead of what follows.
    pub(super) fn flush(&self) {
        let batch =
            std::mem::take(&mut self.pending.lock().unwrap_or_else(PoisonError::into_inner).batch);
        self.send_batch(Some(batch));
    }

    /// The CDR schema of a type a sender encodes (`None`: CDR cannot describe it).
    pub(super) fn sender_schema(&self, format: &Format, type_name: &str) -> Option<Arc<CdrSchema>> {
        let mut schemas = self.sender_schemas.lock().unwrap_or_else(PoisonError::into_inner);
        schemas
            .entry(type_name.to_owned())
            .or_insert_with(|| CdrSchema::of(format, type_name))
            .clone()
    }

    /// The self-describing encoding of records: of those without a type to trace (a
    /// `serde_json::Value`), and of those CDR cannot describe.
    pub(super) fn record_encoding(&self) -> Encoding {
        if self.encoding.is_self_describing() { self.encoding } else { Encoding::MessagePack }
    }

    /// A value that could not be encoded: an error, not a drop.
    pub(super) fn unencodable(&self) {
        self.serialize_errors.fetch_add(1, Ordering::Relaxed);
    }

    /// Records the writer's first write error and stops taking records: they are counted as
    /// dropped from now on, at the sender, instead of queued for a writer that cannot write.
    pub(super) fn fail(&self, path: &std::path::Path, error: &std::io::Error) {
        let failure =
            Failure { path: path.to_path_buf(), kind: error.kind(), message: error.to_string() };
        let _ = self.failure.set(failure);
        self.accepting.store(false, Ordering::Release);
    }

    /// Queues a command that must not be lost (metadata): waits for room in the queue.
    pub(super) fn send_control(&self, command: Command) -> Result<(), LogError> {
        if let Some(failure) = self.failure.get() {
            return Err(failure.error());
        }
        if !self.accepting.load(Ordering::Acquire) {
            return Err(LogError::Invalid {
                path: self.path.clone(),
                what: "the log is already finished".to_owned(),
            });
        }
        self.flush();
        self.sender.send(command).map_err(|_| LogError::WriterGone { path: self.path.clone() })
    }
}
