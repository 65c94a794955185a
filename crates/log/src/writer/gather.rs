//! Batching: how a sender hands packages over to the writer thread, one at a time (real time)
//! or gathered into batches (a sender that waits), cloned or encoded on the sender's side.

use std::sync::atomic::Ordering;
use std::sync::{Mutex, PoisonError};

use crossbeam_channel::TrySendError;
use strata_runtime::shared;
use strata_runtime::{Encoding, ErasedPackage, TapOutput, Time};

use super::{Command, EncodedRecord, Shared, Topic, TopicCache, WhenFull};

/// Messages handed to the writer thread at once by a sender that waits for it.
pub(super) const BATCH: usize = 512;

/// At most this many messages wait in the queue of a sender that waits for the writer.
pub(super) const WAIT_QUEUE: usize = 4 * BATCH;

/// Batches kept for reuse.
pub(super) const SPARE_BATCHES: usize = 12;

/// The sender clones the package; the writer thread encodes it. For large packages (a world
/// state: cloning one copies a few pointers to its shared parts, encoding it writes them
/// all) and those holding [`strata_runtime::Shared`] values (a reactive report: measured, the
/// sender's match ran 7 % slower encoding them with a recorder of its own than cloning them).
pub(super) const HANDOVER_CLONE: u8 = 1;
/// The sender encodes the package (CDR) into the batch. For small packages without shared
/// values: encoding one costs its sender about what cloning it would, and spares the
/// allocation of the clone, freeing it on the other thread (which shows in both threads'
/// profiles) and encoding it there.
pub(super) const HANDOVER_ENCODE: u8 = 2;

/// Packages whose first one encodes to at most this many bytes may be encoded by a sender
/// that waits; larger ones are cloned.
pub(super) const SENDER_ENCODES_UP_TO: usize = 1024;

/// What became of a package offered to a batch (see [`Shared::gather_package`]).
pub(super) enum Gathered<'a> {
    /// In the batch (or its output is not logged), and the batch, if that filled it.
    Done(Option<Batch>),
    /// The log is finished: counted as dropped on this topic.
    Refused(u32),
    /// Its output is new to this sender.
    Unknown(Offered<'a>),
    /// CDR could not write it: the writer thread encodes this topic's packages from now on.
    Declined(u32, Offered<'a>),
}

/// A package as a tap gets it: shown (the sending module keeps it; the log clones or encodes
/// it) or given (of an output nobody reads: the log keeps it, the sender is spared a clone and
/// a drop; the writer thread encodes it).
pub(super) enum Offered<'a> {
    Shown(&'a dyn ErasedPackage),
    Given(Box<dyn ErasedPackage>),
}

impl Offered<'_> {
    pub(super) fn get(&self) -> &dyn ErasedPackage {
        match self {
            Offered::Shown(package) => *package,
            Offered::Given(package) => package.as_ref(),
        }
    }

    /// The package for the writer thread: the given one, or a clone of the shown one.
    pub(super) fn keep(self) -> Box<dyn ErasedPackage> {
        match self {
            Offered::Shown(package) => package.clone_boxed(),
            Offered::Given(package) => package,
        }
    }
}

/// A message's value on its way to the writer thread.
pub(super) enum Payload {
    /// A package, encoded by the writer thread: the sending module only pays for a clone.
    Package(Box<dyn ErasedPackage>),
    /// An application record, encoded by its sender (boxed: records are few, and every
    /// package's entry would pay for the room).
    Encoded(Box<EncodedRecord>),
    /// A package the sender encoded in CDR: these bytes of its batch.
    Bytes { start: usize, len: usize },
}

/// What a sender works with under one lock: the batch being gathered, and the topics of the
/// outputs it has seen, by host, module id and port (found without comparing or hashing names;
/// a host number is unique in the process, so scoped taps share this).
#[derive(Default)]
pub(super) struct Gathering {
    pub(super) batch: Batch,
    /// By module id: the host the entry is for, and by port the topic id and its handover
    /// (`None`: not looked up yet; `Some(None)`: not logged).
    pub(super) modules: Vec<(u64, Vec<Option<KnownOutput>>)>,
}

/// An output as the sender knows it: its topic id and handover, `None` when it is not logged.
pub(super) type KnownOutput = Option<(u32, u8)>;

impl Gathering {
    pub(super) fn topic(&self, record: &TapOutput<'_>) -> Option<Option<(u32, u8)>> {
        let (host, outputs) = self.modules.get(record.module.index())?;
        if *host != record.host {
            return None;
        }
        *outputs.get(usize::from(record.port))?
    }

    /// Adds a message to the batch; the batch, when that filled it (replaced by a spare one).
    pub(super) fn push(&mut self, queued: Queued, shared: &Shared) -> Option<Batch> {
        self.batch.messages.push(queued);
        (self.batch.messages.len() >= BATCH)
            .then(|| std::mem::replace(&mut self.batch, shared.spare()))
    }

    pub(super) fn remember(&mut self, record: &TapOutput<'_>, topic: Option<(u32, u8)>) {
        let index = record.module.index();
        if self.modules.len() <= index {
            self.modules.resize_with(index + 1, || (u64::MAX, Vec::new()));
        }
        let (host, outputs) = &mut self.modules[index];
        if *host != record.host {
            // Another host's module with the same id: the entry follows the latest one.
            *host = record.host;
            outputs.clear();
        }
        let port = usize::from(record.port);
        if outputs.len() <= port {
            outputs.resize(port + 1, None);
        }
        outputs[port] = Some(topic);
    }
}

/// Where a sender gathers its messages: the log's shared batch, under its lock, or a host's
/// own ([`McapSender`](super::McapSender)), which needs none.
pub(super) trait Gather {
    fn with<R>(&mut self, f: impl FnOnce(&mut Gathering) -> R) -> R;

    /// Hands a batch this filled to the writer thread.
    fn send(&mut self, shared: &Shared, batch: Option<Batch>) {
        shared.send_batch(batch);
    }
}

/// The shared batch of a log, locked for each use.
pub(super) struct Locked<'a>(pub(super) &'a Mutex<Gathering>);

impl Gather for Locked<'_> {
    fn with<R>(&mut self, f: impl FnOnce(&mut Gathering) -> R) -> R {
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }
}

impl Gather for Gathering {
    fn with<R>(&mut self, f: impl FnOnce(&mut Gathering) -> R) -> R {
        f(self)
    }

    /// A host's own batch goes after the records gathered in the shared one meanwhile
    /// (application records written between two runs of the host, before its next packages).
    fn send(&mut self, shared: &Shared, batch: Option<Batch>) {
        if batch.is_some() {
            shared.flush();
        }
        shared.send_batch(batch);
    }
}

/// Messages handed over together, with the bytes of those the sender encoded.
#[derive(Default)]
pub(super) struct Batch {
    pub(super) messages: Vec<Queued>,
    pub(super) bytes: Vec<u8>,
}

impl Batch {
    pub(super) fn one(message: Queued) -> Batch {
        Batch { messages: vec![message], bytes: Vec::new() }
    }
}

/// A message on its way to the writer thread. Its topic goes by id, not by a shared handle:
/// counting references to it from two threads would move its cache line between the cores
/// for every package.
pub(super) struct Queued {
    pub(super) topic: u32,
    pub(super) log_time: u64,
    pub(super) stamp: u64,
    pub(super) seq: u64,
    pub(super) payload: Payload,
}

impl Shared {
    /// Queues a message; a full queue costs the record (counted) or, in [`WhenFull::Wait`]
    /// mode, the sender's time.
    pub(super) fn submit(
        &self,
        gathering: &mut impl Gather,
        topic: u32,
        log_time: Time,
        stamp: Time,
        seq: u64,
        payload: Payload,
    ) {
        let queued =
            Queued { topic, log_time: log_time.as_nanos(), stamp: stamp.as_nanos(), seq, payload };
        match self.when_full {
            WhenFull::Drop => {
                if !self.accepting.load(Ordering::Acquire) {
                    self.drop_id(topic);
                    return;
                }
                if let Err(TrySendError::Full(refused) | TrySendError::Disconnected(refused)) =
                    self.sender.try_send(Command::Messages(Batch::one(queued)))
                {
                    self.refused(refused);
                }
            }
            WhenFull::Wait => self.gather(gathering, queued),
        }
    }

    /// Adds `queued` to the batch being gathered (a sender that waits). A full batch goes to
    /// the writer thread.
    pub(super) fn gather(&self, gathering: &mut impl Gather, queued: Queued) {
        let topic = queued.topic;
        let full = gathering.with(|pending| {
            // Checked under the lock `finish` takes to clear it (for the shared batch): a
            // record is either in the last batch or counted as dropped.
            self.accepting.load(Ordering::Acquire).then(|| pending.push(queued, self))
        });
        match full {
            None => self.drop_id(topic),
            Some(full) => gathering.send(self, full),
        }
    }

    pub(super) fn tap_package(
        &self,
        gathering: &mut impl Gather,
        topics: &TopicCache,
        output: &TapOutput<'_>,
        time: Time,
        package: Offered<'_>,
    ) {
        let package = match self.when_full {
            WhenFull::Wait => match self.gather_package(gathering, output, time, package) {
                Ok(()) => return,
                Err(declined) => declined,
            },
            WhenFull::Drop => package,
        };
        // The first package of an output, one the fast path declined, or a real-time sender.
        let known = gathering.with(|gathering| gathering.topic(output));
        let (topic, handover) = match known {
            Some(Some(known)) => known,
            Some(None) => return,
            None => {
                let Some(topic) = topics.topic(self, output) else {
                    gathering.with(|gathering| gathering.remember(output, None));
                    return;
                };
                let handover = self.decide_handover(&topic, package.get());
                let known = Some((topic.id, handover));
                gathering.with(|gathering| gathering.remember(output, known));
                if self.when_full == WhenFull::Wait {
                    match self.gather_package(gathering, output, time, package) {
                        Ok(()) => return,
                        Err(declined) => {
                            return self.hand_over(gathering, topic.id, time, declined);
                        }
                    }
                }
                (topic.id, handover)
            }
        };
        if handover == HANDOVER_ENCODE && !self.accepting.load(Ordering::Acquire) {
            self.drop_id(topic);
            return;
        }
        self.hand_over(gathering, topic, time, package);
    }

    /// Queues the package for the writer thread to encode.
    pub(super) fn hand_over(
        &self,
        gathering: &mut impl Gather,
        topic: u32,
        time: Time,
        package: Offered<'_>,
    ) {
        let (stamp, seq) = (package.get().stamp(), package.get().seq());
        self.submit(gathering, topic, time, stamp, seq, Payload::Package(package.keep()));
    }

    /// The usual way of a package from a sender that waits: under one lock, its topic is
    /// found and the package goes into the batch (encoded, kept or cloned: see
    /// [`Offered`]). The package back when it did not (the output is new, or a value CDR
    /// cannot write, which sends its topic to the writer from then on).
    pub(super) fn gather_package<'a>(
        &self,
        gathering: &mut impl Gather,
        output: &TapOutput<'_>,
        time: Time,
        package: Offered<'a>,
    ) -> Result<(), Offered<'a>> {
        let gathered = gathering.with(|pending| {
            let topic = match pending.topic(output) {
                Some(Some(topic)) => topic,
                // Not logged.
                Some(None) => return Gathered::Done(None),
                None => return Gathered::Unknown(package),
            };
            if !self.accepting.load(Ordering::Acquire) {
                return Gathered::Refused(topic.0);
            }
            let (id, handover) = topic;
            let (stamp, seq) = (package.get().stamp(), package.get().seq());
            let (log_time, stamp) = (time.as_nanos(), stamp.as_nanos());
            let batch = &mut pending.batch;
            let payload = match package {
                // A given package goes over whole: the writer encodes it, and it comes back
                // with its batch to be dropped here (see `Shared::recycle`).
                Offered::Shown(shown) if handover == HANDOVER_ENCODE => {
                    let start = batch.bytes.len();
                    if shown.encode(Encoding::Cdr, &mut batch.bytes).is_err() {
                        batch.bytes.truncate(start);
                        Err(package)
                    } else {
                        Ok(Payload::Bytes { start, len: batch.bytes.len() - start })
                    }
                }
                _ => Ok(Payload::Package(package.keep())),
            };
            match payload {
                Ok(payload) => {
                    let queued = Queued { topic: id, log_time, stamp, seq, payload };
                    Gathered::Done(pending.push(queued, self))
                }
                Err(package) => {
                    // From now on the writer encodes this topic's packages.
                    pending.remember(output, Some((id, HANDOVER_CLONE)));
                    Gathered::Declined(id, package)
                }
            }
        });
        match gathered {
            Gathered::Done(full) => {
                gathering.send(self, full);
                Ok(())
            }
            Gathered::Refused(topic) => {
                self.drop_id(topic);
                Ok(())
            }
            Gathered::Unknown(package) => Err(package),
            Gathered::Declined(id, package) => {
                if let Some(topic) = self.topic(id) {
                    topic.handover.store(HANDOVER_CLONE, Ordering::Relaxed);
                }
                Err(package)
            }
        }
    }

    /// How a topic's packages are handed over, from its first package: encoded by a sender
    /// that waits when CDR describes the type, it holds no shared value, its first package
    /// is small and the log derives nothing from it; cloned otherwise.
    pub(super) fn decide_handover(&self, topic: &Topic, package: &dyn ErasedPackage) -> u8 {
        let decided = topic.handover.load(Ordering::Relaxed);
        if decided != 0 {
            return decided;
        }
        let format =
            (self.when_full == WhenFull::Wait && self.encoding == Encoding::Cdr && !topic.derived)
                .then(|| package.format().ok())
                .flatten();
        let handover = match format {
            Some(format) if !shared::appears_in(&format) => {
                let mut trial = Vec::new();
                let small = package.encode(Encoding::Cdr, &mut trial).is_ok()
                    && trial.len() <= SENDER_ENCODES_UP_TO;
                match small.then(|| self.sender_schema(&format, &topic.type_name)).flatten() {
                    Some(schema) => {
                        let _ = topic.cdr.set(schema);
                        HANDOVER_ENCODE
                    }
                    None => HANDOVER_CLONE,
                }
            }
            _ => HANDOVER_CLONE,
        };
        topic.handover.store(handover, Ordering::Relaxed);
        handover
    }
}
