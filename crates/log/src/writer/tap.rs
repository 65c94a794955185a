//! [`McapTap`]: the tap hosts hand their packages to, and the log's records, metadata and
//! attachments.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, RwLock};
use std::thread::JoinHandle;

use serde::Serialize;
use strata_runtime::{ErasedPackage, GraphDescription, Tap, TapOutput, TapRecord, TapSender, Time};

use crate::error::LogError;
use crate::{CONFIG_ATTACHMENT_PREFIX, GRAPH_METADATA, RUN_METADATA};

#[cfg(test)]
use super::test_gate;
use super::{
    BATCH, Command, Derive, EncodedRecord, Failure, Gathering, Locked, LogSummary, McapSender,
    McapTapOptions, Offered, Parts, Payload, RunInfo, ScopedTap, Shared, TopicCache, WAIT_QUEUE,
    WhenFull, WriterThread, part_path, start_file,
};

/// A [`Tap`] that logs every package into an MCAP file.
///
/// ```no_run
/// # use std::sync::Arc;
/// # fn demo(graph: strata_runtime::Graph) -> Result<(), Box<dyn std::error::Error>> {
/// use strata_log::{McapTap, McapTapOptions, RunInfo};
/// use strata_runtime::{HostConfig, LockstepHost, Time};
/// let tap = Arc::new(McapTap::create("match.mcap", McapTapOptions::default())?);
/// tap.write_run_info(&RunInfo::current(7))?;
/// tap.write_graph("", &graph.describe())?;
/// let mut host = LockstepHost::new(graph, HostConfig::with_seed(7));
/// host.set_tap(tap.clone());
/// host.run_until(Time::from_secs_f64(60.0))?;
/// let summary = tap.finish()?;
/// println!("{} messages, {} dropped", summary.messages, summary.dropped);
/// # Ok(()) }
/// ```
pub struct McapTap {
    pub(super) shared: Arc<Shared>,
    pub(super) topics: Arc<TopicCache>,
    pub(super) writer: Mutex<Option<JoinHandle<()>>>,
    pub(super) summary: Mutex<Option<LogSummary>>,
}

impl std::fmt::Debug for McapTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapTap")
            .field("path", &self.shared.path)
            .field("dropped", &self.shared.dropped.load(Ordering::Relaxed))
            .finish()
    }
}

impl McapTap {
    /// Creates (truncates) `path` and starts the writer thread. With a size cap
    /// ([`McapTapOptions::max_file_size`]) the log goes on in [`McapTap::part_path`]s.
    pub fn create(path: impl AsRef<Path>, options: McapTapOptions) -> Result<McapTap, LogError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path)
            .map_err(|source| LogError::Create { path: path.clone(), source })?;
        let writer = start_file(file, &options)
            .map_err(|source| LogError::Write { path: path.clone(), source })?;
        // A sender that waits gets a short queue: it waits anyway when the writer falls
        // behind, and the fewer packages the queue holds, the fewer buffers (world states'
        // object lists, for one) stay out of their modules' reuse.
        let batches = match options.when_full {
            WhenFull::Wait => (options.capacity.min(WAIT_QUEUE) / BATCH).max(1),
            WhenFull::Drop => options.capacity.max(1),
        };
        let (sender, receiver) = crossbeam_channel::bounded(batches);
        let when_full = options.when_full;
        let shared = Arc::new(Shared {
            path: path.clone(),
            sender,
            accepting: AtomicBool::new(true),
            when_full,
            encoding: options.encoding,
            modules: options.modules.clone(),
            dropped: AtomicU64::new(0),
            pending: Mutex::new(Gathering::default()),
            spare: Mutex::new(Vec::new()),
            serialize_errors: AtomicU64::new(0),
            topics: Mutex::new(Vec::new()),
            record_topics: RwLock::new(HashMap::new()),
            sender_schemas: Mutex::new(HashMap::new()),
            derive: Mutex::new(None),
            failure: OnceLock::new(),
            #[cfg(test)]
            gate: Arc::new(test_gate::Gate::default()),
            #[cfg(test)]
            syncs: AtomicU64::new(0),
        });
        let thread = WriterThread {
            shared: Arc::clone(&shared),
            writer: Some(writer),
            path: path.clone(),
            sync: options.sync_chunks,
            parts: Parts::default(),
            options,
            topics: Vec::new(),
            schemas: HashMap::new(),
            cdr_schemas: HashMap::new(),
            shared_channels: HashMap::new(),
            shared_topics: Vec::new(),
            scratch: Vec::new(),
            encoded: Vec::new(),
            chunk: None,
            messages: 0,
            error: None,
        };
        let handle = std::thread::Builder::new()
            .name("strata-log-writer".to_owned())
            .spawn(move || thread.run(receiver))
            .map_err(|source| LogError::Spawn { path: path.clone(), source })?;
        Ok(McapTap {
            shared,
            topics: Arc::default(),
            writer: Mutex::new(Some(handle)),
            summary: Mutex::new(None),
        })
    }

    /// The log's (first) file.
    pub fn path(&self) -> &Path {
        &self.shared.path
    }

    /// The path of file `part` of a log whose first file is `path`, when the log is split at
    /// its size cap ([`McapTapOptions::max_file_size`]): `path` itself for part 0, then `-1`,
    /// `-2`... after its stem (`robot.mcap`, `robot-1.mcap`, `robot-2.mcap`).
    pub fn part_path(path: impl AsRef<Path>, part: u32) -> PathBuf {
        part_path(path.as_ref(), part)
    }

    /// The error of the first write that failed (a full disk, a file size limit, a removed
    /// drive), from the moment the writer thread met it: from then on nothing more is written,
    /// records are counted as dropped, metadata is refused with this error, and
    /// [`McapTap::finish`] returns it. The complete chunks written before it stay readable
    /// ([`LogReader`](crate::LogReader) recovers them).
    pub fn error(&self) -> Option<LogError> {
        self.shared.failure.get().map(Failure::error)
    }

    /// A tap that logs under `prefix` (e.g. `"blue3/"`), sharing this log: for several hosts
    /// (one per robot) whose module names repeat. Write each host's graph with
    /// [`McapTap::write_graph`] under the same prefix.
    pub fn scoped(self: &Arc<Self>, prefix: impl Into<String>) -> ScopedTap {
        ScopedTap {
            tap: Arc::clone(self),
            topics: Arc::new(TopicCache { prefix: prefix.into(), ..TopicCache::default() }),
        }
    }

    /// Has the writer thread derive records from the packages of the topics `derive` wants
    /// (see [`Derive`]). Set it before the first package: a topic created earlier is not
    /// asked about.
    pub fn set_derive(&self, derive: Box<dyn Derive>) {
        *self.shared.derive.lock().unwrap_or_else(PoisonError::into_inner) = Some(derive);
    }

    /// Logs an application record on `topic` whose type is named `type_name`, from a value
    /// without a type to trace: in a self-describing encoding (MessagePack, or the log's own
    /// when that is JSON) with a JSON Schema inferred from its first value. Handled like
    /// packages: with [`WhenFull::Drop`] it never blocks, and a record that finds the queue
    /// full is dropped and counted.
    pub fn record(&self, topic: &str, type_name: &str, time: Time, value: &serde_json::Value) {
        let record = EncodedRecord::untyped(value, self.shared.record_encoding());
        self.submit_record(topic, type_name, time, record);
    }

    /// [`McapTap::record`] for a value of a Rust type, named by it: in CDR with its OMG IDL
    /// schema, like a package of its type (so that Foxglove decodes it), when the log is CDR
    /// and CDR describes the type; otherwise self-describing.
    pub fn record_value<T>(&self, topic: &str, time: Time, value: &T)
    where
        T: Serialize + serde::de::DeserializeOwned + 'static,
    {
        let record = EncodedRecord::of(value, self.shared.encoding, self.shared.record_encoding());
        self.submit_record(topic, std::any::type_name::<T>(), time, record);
    }

    /// Application records are few (a scenario's ground truth, a marker): encoded by the
    /// caller, handed over like packages.
    pub(super) fn submit_record(
        &self,
        topic: &str,
        type_name: &str,
        time: Time,
        record: Option<EncodedRecord>,
    ) {
        let Some(record) = record else {
            self.shared.serialize_errors.fetch_add(1, Ordering::Relaxed);
            return;
        };
        let topic = self.shared.record_topic(topic, type_name);
        let seq = topic.next_seq.fetch_add(1, Ordering::Relaxed);
        let mut shared_batch = Locked(&self.shared.pending);
        let payload = Payload::Encoded(Box::new(record));
        self.shared.submit(&mut shared_batch, topic.id, time, time, seq, payload);
    }

    /// Writes a metadata record. Waits for room in the queue (metadata is never dropped): call
    /// it from setup code, not from a real-time cycle.
    pub fn write_metadata(
        &self,
        name: &str,
        entries: BTreeMap<String, String>,
    ) -> Result<(), LogError> {
        self.shared.send_control(Command::Metadata { name: name.to_owned(), entries })
    }

    /// Writes an attachment (a file carried inside the log).
    pub fn write_attachment(
        &self,
        name: &str,
        media_type: &str,
        time: Time,
        data: Vec<u8>,
    ) -> Result<(), LogError> {
        self.shared.send_control(Command::Attachment {
            name: name.to_owned(),
            media_type: media_type.to_owned(),
            time: time.as_nanos(),
            data,
        })
    }

    /// Stores the seed, command line, version and configuration text of the run.
    pub fn write_run_info(&self, info: &RunInfo) -> Result<(), LogError> {
        let command_line =
            serde_json::to_string(&info.command_line).map_err(|source| LogError::Json {
                path: self.shared.path.clone(),
                what: "the command line".into(),
                source,
            })?;
        let mut entries = BTreeMap::from([
            ("seed".to_owned(), info.seed.to_string()),
            ("version".to_owned(), info.version.clone()),
            ("command_line".to_owned(), command_line),
        ]);
        if let Some((format, text)) = &info.config {
            entries.insert("config_format".to_owned(), format.extension().to_owned());
            self.write_attachment(
                &format!("{CONFIG_ATTACHMENT_PREFIX}{}", format.extension()),
                format.media_type(),
                Time::ZERO,
                text.clone().into_bytes(),
            )?;
        }
        self.write_metadata(RUN_METADATA, entries)
    }

    /// Stores a graph description; `scope` is the topic prefix its packages are logged under
    /// (`""` for this tap, the prefix of a [`ScopedTap`]).
    pub fn write_graph(&self, scope: &str, graph: &GraphDescription) -> Result<(), LogError> {
        let json = serde_json::to_string(graph).map_err(|source| LogError::Json {
            path: self.shared.path.clone(),
            what: "the graph description".into(),
            source,
        })?;
        self.write_metadata(
            GRAPH_METADATA,
            BTreeMap::from([("scope".to_owned(), scope.to_owned()), ("graph".to_owned(), json)]),
        )
    }

    /// Records dropped so far (queue full, writer failed, or after `finish`).
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Writes what is queued, the drop statistics and the summary and footer, and closes the
    /// file. Records arriving afterwards are counted as dropped. Calling it again returns the
    /// same summary. After a failed write ([`McapTap::error`]) the file is left as it is and
    /// the error is returned.
    pub fn finish(&self) -> Result<LogSummary, LogError> {
        let mut stored = self.summary.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(summary) = stored.as_ref() {
            return Ok(summary.clone());
        }
        let path = self.shared.path.clone();
        let (reply, answer) = crossbeam_channel::bounded(1);
        // Cleared under the lock of the gathered messages (see `Shared::submit`); what was
        // accepted so far goes ahead of the finish request.
        let last = {
            let mut pending = self.shared.pending.lock().unwrap_or_else(PoisonError::into_inner);
            self.shared.accepting.store(false, Ordering::Release);
            std::mem::take(&mut pending.batch)
        };
        self.shared.send_batch(Some(last));
        let sent = self.shared.sender.send(Command::Finish(reply));
        let result = match sent {
            Ok(()) => answer.recv().unwrap_or(Err(LogError::WriterGone { path: path.clone() })),
            Err(_) => Err(LogError::WriterGone { path: path.clone() }),
        };
        let handle = self.writer.lock().unwrap_or_else(PoisonError::into_inner).take();
        if let Some(handle) = handle
            && handle.join().is_err()
            && result.is_ok()
        {
            return Err(LogError::WriterGone { path });
        }
        let summary = result?;
        *stored = Some(summary.clone());
        Ok(summary)
    }

    #[cfg(test)]
    pub(super) fn gate(&self) -> &test_gate::Gate {
        &self.shared.gate
    }
}

impl Tap for McapTap {
    /// Only the outputs of the modules the options log: the host does not even show the
    /// others' packages (a log of one robot of a match costs the other robots nothing).
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        self.topics.wants(&self.shared, output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        let shown = Offered::Shown(record.package);
        let shared_batch = &mut Locked(&self.shared.pending);
        self.shared.tap_package(shared_batch, &self.topics, &record.sent_on, record.time, shown);
    }

    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        let shared_batch = &mut Locked(&self.shared.pending);
        self.shared.tap_package(shared_batch, &self.topics, output, time, Offered::Given(package));
    }

    /// A sender that waits for the writer gathers in a batch of its own, without a lock.
    fn sender(&self) -> Option<Box<dyn TapSender>> {
        McapSender::boxed(&self.shared, &self.topics)
    }
}

impl Drop for McapTap {
    /// A log dropped without `finish` (an early return, an error) is still finalized.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
