//! [`McapTap`]: records every package a host delivers into an MCAP file, from a background
//! thread fed by a bounded queue.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError};
use serde::Serialize;
use strata_runtime::cdr::{Format, idl_schema};
use strata_runtime::shared::{NewRecord, Recorder};
use strata_runtime::{
    Encoding, ErasedPackage, GraphDescription, Tap, TapOutput, TapRecord, TapSender, Time,
};

use crate::error::LogError;
use crate::mcap_file::{ChunkCompression, McapFile};
use crate::schema::infer_json_schema;
use crate::{
    CONFIG_ATTACHMENT_PREFIX, FORMAT_KEY, GRAPH_METADATA, PUBLISH_TIME_KEY, RUN_METADATA,
    SHARED_KEY, STATS_METADATA, WRAP_FIELD, WRAPPED_KEY,
};

mod derive;
mod encoding;
mod gather;
mod options;
mod run_info;
mod shared;
#[cfg(test)]
mod test_gate;
#[cfg(test)]
mod tests;
mod topics;

pub use derive::{Derive, DerivedRecords};
pub(crate) use encoding::wrap_frame;
use encoding::{CdrSchema, EncodedRecord, is_map};
use gather::{
    BATCH, Batch, Gather, Gathering, Locked, Offered, Payload, Queued, SPARE_BATCHES, WAIT_QUEUE,
};
use options::ZSTD_LEVEL;
pub use options::{LogCompression, LogSummary, McapTapOptions, WhenFull};
pub use run_info::{ConfigFormat, RunInfo};
use shared::{Command, Shared};
use topics::{Topic, TopicCache};

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
    shared: Arc<Shared>,
    topics: Arc<TopicCache>,
    writer: Mutex<Option<JoinHandle<()>>>,
    summary: Mutex<Option<LogSummary>>,
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
    /// Creates (truncates) `path` and starts the writer thread.
    pub fn create(path: impl AsRef<Path>, options: McapTapOptions) -> Result<McapTap, LogError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path)
            .map_err(|source| LogError::Create { path: path.clone(), source })?;
        let compression = match options.compression {
            LogCompression::Zstd => ChunkCompression::Zstd(ZSTD_LEVEL),
            LogCompression::Lz4 => ChunkCompression::Lz4,
            LogCompression::None => ChunkCompression::None,
        };
        let writer = McapFile::new(
            BufWriter::with_capacity(1 << 20, file),
            "strata",
            &format!("strata-log {}", env!("CARGO_PKG_VERSION")),
            compression,
            usize::try_from(options.chunk_size.max(1024)).unwrap_or(usize::MAX),
        )
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
            #[cfg(test)]
            gate: Arc::new(test_gate::Gate::default()),
        });
        let thread = WriterThread {
            shared: Arc::clone(&shared),
            writer: Some(writer),
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

    pub fn path(&self) -> &Path {
        &self.shared.path
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
    fn submit_record(
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
    /// same summary.
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
    fn gate(&self) -> &test_gate::Gate {
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

/// A log's sender for one host ([`Tap::sender`]): the batches of a sender that waits
/// ([`WhenFull::Wait`]) gathered without the lock of the log's shared batch. A real-time
/// sender hands each package over at once and has none. Application records
/// ([`McapTap::record`]) still go to the shared batch, which is handed over ahead of each of
/// the host's: records written between two runs of the host come after the packages of the
/// first and before those of the second, as they would through the tap itself.
struct McapSender {
    shared: Arc<Shared>,
    topics: Arc<TopicCache>,
    gathering: Gathering,
}

impl McapSender {
    fn boxed(shared: &Arc<Shared>, topics: &Arc<TopicCache>) -> Option<Box<dyn TapSender>> {
        (shared.when_full == WhenFull::Wait).then(|| {
            Box::new(McapSender {
                shared: Arc::clone(shared),
                topics: Arc::clone(topics),
                gathering: Gathering { batch: shared.spare(), modules: Vec::new() },
            }) as Box<dyn TapSender>
        })
    }
}

impl TapSender for McapSender {
    fn package(&mut self, record: &TapRecord<'_>) {
        let shown = Offered::Shown(record.package);
        let output = record.sent_on;
        self.shared.tap_package(&mut self.gathering, &self.topics, &output, record.time, shown);
    }

    fn package_owned(
        &mut self,
        output: &TapOutput<'_>,
        time: Time,
        package: Box<dyn ErasedPackage>,
    ) {
        let given = Offered::Given(package);
        self.shared.tap_package(&mut self.gathering, &self.topics, output, time, given);
    }

    fn flush(&mut self) {
        if !self.gathering.batch.messages.is_empty() {
            let batch = std::mem::replace(&mut self.gathering.batch, self.shared.spare());
            self.gathering.send(&self.shared, Some(batch));
        }
    }
}

impl Drop for McapSender {
    fn drop(&mut self) {
        self.flush();
    }
}

impl Drop for McapTap {
    /// A log dropped without `finish` (an early return, an error) is still finalized.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

/// A tap logging under a topic prefix into a shared [`McapTap`] (see [`McapTap::scoped`]).
pub struct ScopedTap {
    tap: Arc<McapTap>,
    topics: Arc<TopicCache>,
}

impl std::fmt::Debug for ScopedTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScopedTap").field("prefix", &self.topics.prefix).finish()
    }
}

impl ScopedTap {
    pub fn prefix(&self) -> &str {
        &self.topics.prefix
    }

    pub fn log(&self) -> &Arc<McapTap> {
        &self.tap
    }
}

impl Tap for ScopedTap {
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        self.topics.wants(&self.tap.shared, output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        let shown = Offered::Shown(record.package);
        let shared = &self.tap.shared;
        let output = record.sent_on;
        shared.tap_package(&mut Locked(&shared.pending), &self.topics, &output, record.time, shown);
    }

    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        let shared = &self.tap.shared;
        let given = Offered::Given(package);
        shared.tap_package(&mut Locked(&shared.pending), &self.topics, output, time, given);
    }

    fn sender(&self) -> Option<Box<dyn TapSender>> {
        McapSender::boxed(&self.tap.shared, &self.topics)
    }
}

/// Creates the channel of a shared value type: `shared/{type}` (the type's last path segment;
/// `_2`, `_3`… when another type has that name), its record's schema, metadata
/// `strata.shared`.
fn shared_channel(
    writer: &mut McapFile<BufWriter<File>>,
    record: &NewRecord,
    taken: &[String],
) -> (u16, String) {
    let short = record.type_name.split('<').next().unwrap_or(record.type_name);
    let short = short.rsplit("::").next().unwrap_or(short);
    let mut topic = format!("shared/{short}");
    let mut k = 2;
    while taken.contains(&topic) {
        topic = format!("shared/{short}_{k}");
        k += 1;
    }
    let mut metadata = BTreeMap::from([
        ("type_name".to_owned(), format!("strata_runtime::shared::Record<{}>", record.type_name)),
        (SHARED_KEY.to_owned(), "true".to_owned()),
    ]);
    let idl = record.format.as_ref().and_then(|format| {
        let json = serde_json::to_string(format).ok()?;
        Some((idl_schema(format, "SharedRecord").ok()?, json))
    });
    let schema_id = match (idl, record.encoding) {
        (Some((idl, json)), Encoding::Cdr) => {
            metadata.insert(FORMAT_KEY.to_owned(), json);
            writer.add_schema(&idl.name, "omgidl", idl.text.as_bytes())
        }
        _ => {
            let sample = record.encoding.decode(&record.bytes).unwrap_or(serde_json::Value::Null);
            let schema = infer_json_schema(record.type_name, &sample);
            let data = serde_json::to_vec(&schema).unwrap_or_default();
            writer.add_schema(record.type_name, "jsonschema", &data)
        }
    };
    let id = writer.add_channel(schema_id, &topic, record.encoding.mcap_name(), &metadata);
    (id, topic)
}

/// How long the writer of a sender that waits looks for the next command before sleeping.
const SPIN: Duration = Duration::from_micros(300);

/// The next command if one comes within [`SPIN`].
fn spin_recv(receiver: &Receiver<Command>) -> Option<Command> {
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

struct OpenChunk {
    first_log_time: u64,
    opened: Instant,
    messages: u32,
}

/// A topic's channel in one encoding, and whether its messages are wrapped.
#[derive(Clone, Copy, Debug)]
struct ChannelState {
    id: u16,
    wrapped: bool,
}

struct WriterThread {
    shared: Arc<Shared>,
    writer: Option<McapFile<BufWriter<File>>>,
    options: McapTapOptions,
    /// What the writer knows of each topic, by topic id (ids are dense).
    topics: Vec<TopicState>,
    /// MCAP schema id per type name, encoding and wrapping.
    schemas: HashMap<(String, Encoding, bool), u16>,
    /// The CDR schema of each package type, `None` for types CDR cannot describe.
    cdr_schemas: HashMap<String, Option<Arc<CdrSchema>>>,
    /// The channel of each shared value type, and the sequence number of its next record.
    shared_channels: HashMap<&'static str, (u16, u64)>,
    /// Their topics.
    shared_topics: Vec<String>,
    /// Where wrapped messages are assembled.
    scratch: Vec<u8>,
    /// Where packages are encoded (one buffer, reused).
    encoded: Vec<u8>,
    chunk: Option<OpenChunk>,
    messages: u64,
    /// The first write error; afterwards records are only counted as dropped.
    error: Option<std::io::Error>,
}

/// A topic as the writer thread knows it.
#[derive(Default)]
struct TopicState {
    handle: Option<Arc<Topic>>,
    /// The encoding its packages are written in, decided by its first package.
    encoding: Option<Encoding>,
    /// Its type's CDR schema, when it is written in CDR.
    cdr: Option<Arc<CdrSchema>>,
    /// Its channel per encoding (JSON, MessagePack, CDR): a topic whose values CDR cannot
    /// write has a second, MessagePack channel.
    channels: [Option<ChannelState>; 3],
}

impl TopicState {
    fn channel(&mut self, encoding: Encoding) -> &mut Option<ChannelState> {
        &mut self.channels[match encoding {
            Encoding::Json => 0,
            Encoding::MessagePack => 1,
            Encoding::Cdr => 2,
        }]
    }
}

/// Messages between two looks at the clock for the age of the open chunk: reading the clock
/// for each of thousands of messages per second showed in profiles.
const AGE_CHECK_EVERY: u32 = 64;

impl WriterThread {
    /// The topic with this id (the shared list is looked at once per topic).
    fn topic_handle(&mut self, id: u32) -> Option<Arc<Topic>> {
        if let Some(handle) = &self.topic(id).handle {
            return Some(Arc::clone(handle));
        }
        let handle = self.shared.topic(id)?;
        self.topic(id).handle = Some(Arc::clone(&handle));
        Some(handle)
    }

    fn topic(&mut self, id: u32) -> &mut TopicState {
        let index = id as usize;
        if self.topics.len() <= index {
            self.topics.resize_with(index + 1, TopicState::default);
        }
        &mut self.topics[index]
    }

    fn run(mut self, receiver: Receiver<Command>) {
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
    fn apply(&mut self, write: impl FnOnce(&mut McapFile<BufWriter<File>>) -> std::io::Result<()>) {
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

    /// The CDR schema of a topic's type (a package's or a record's), worked out from `format`
    /// on its first value.
    fn cdr_schema(
        &mut self,
        topic: &Topic,
        format: impl FnOnce() -> Option<Format>,
    ) -> Option<Arc<CdrSchema>> {
        if let Some(known) = self.cdr_schemas.get(&topic.type_name) {
            return known.clone();
        }
        let schema = format().and_then(|format| CdrSchema::of(&format, &topic.type_name));
        self.cdr_schemas.insert(topic.type_name.clone(), schema.clone());
        schema
    }

    /// Writes the records the log's [`Derive`] makes of `package`, ahead of it.
    fn derive(&mut self, topic: &Topic, log_time: u64, package: &dyn ErasedPackage) {
        let mut records = DerivedRecords::new(self.options.encoding, self.shared.record_encoding());
        if let Some(derive) =
            self.shared.derive.lock().unwrap_or_else(PoisonError::into_inner).as_mut()
        {
            derive.package(topic.id, Time::from_nanos(log_time), package, &mut records);
        }
        self.shared.serialize_errors.fetch_add(records.unencodable, Ordering::Relaxed);
        for record in records.records {
            let topic = self.shared.record_topic(&record.topic, record.type_name);
            let seq = topic.next_seq.fetch_add(1, Ordering::Relaxed);
            let time = record.time.as_nanos();
            self.write_record(&topic, time, time, seq, &record.value);
        }
    }

    /// Writes a record encoded where it was made, with its type's IDL schema when in CDR.
    fn write_record(
        &mut self,
        topic: &Topic,
        log_time: u64,
        stamp: u64,
        seq: u64,
        record: &EncodedRecord,
    ) {
        let schema = match record.encoding {
            Encoding::Cdr => self.cdr_schema(topic, record.format),
            _ => None,
        };
        if record.encoding == Encoding::Cdr && schema.is_none() {
            // `cdr_describes` found one: cannot happen.
            self.shared.unencodable();
            return;
        }
        self.write_message(topic, record.encoding, schema, log_time, stamp, seq, &record.bytes);
    }

    fn write_package(
        &mut self,
        topic: &Topic,
        log_time: u64,
        stamp: u64,
        seq: u64,
        package: &dyn ErasedPackage,
    ) {
        let wanted = self.options.encoding;
        let (mut encoding, mut schema) = match self.topic(topic.id).encoding {
            Some(encoding) => (encoding, self.topic(topic.id).cdr.clone()),
            None => {
                let schema = if wanted == Encoding::Cdr {
                    self.cdr_schema(topic, || package.format().ok())
                } else {
                    None
                };
                let encoding = match (wanted, &schema) {
                    (Encoding::Cdr, None) => Encoding::MessagePack,
                    _ => wanted,
                };
                let state = self.topic(topic.id);
                (state.encoding, state.cdr) = (Some(encoding), schema.clone());
                (encoding, schema)
            }
        };
        let mut encoded = std::mem::take(&mut self.encoded);
        encoded.clear();
        let mut result = package.encode(encoding, &mut encoded);
        if result.is_err() && encoding == Encoding::Cdr {
            // A value CDR cannot write (a field left out when serializing): this topic goes on
            // in MessagePack, on a channel of its own.
            encoding = Encoding::MessagePack;
            schema = None;
            let state = self.topic(topic.id);
            (state.encoding, state.cdr) = (Some(encoding), None);
            encoded.clear();
            result = package.encode(encoding, &mut encoded);
        }
        // Records of shared values seen for the first time go before the package.
        self.write_shared_records(log_time);
        match result {
            Ok(()) => self.write_message(topic, encoding, schema, log_time, stamp, seq, &encoded),
            Err(_) => self.shared.unencodable(),
        }
        self.encoded = encoded;
    }

    /// Writes the records of shared values the last encoding saw for the first time, each on
    /// the channel of its type (`shared/{type}`, metadata `strata.shared`).
    fn write_shared_records(&mut self, log_time: u64) {
        for record in Recorder::take_new() {
            if self.error.is_some() {
                return;
            }
            self.write_shared_record(&record, log_time);
        }
    }

    fn write_shared_record(&mut self, record: &NewRecord, log_time: u64) {
        let Some(writer) = self.writer.as_mut() else { return };
        let (channel, seq) = match self.shared_channels.get(record.type_name) {
            Some(&known) => known,
            None => {
                let (id, topic) = shared_channel(writer, record, &self.shared_topics);
                self.shared_topics.push(topic);
                (id, 0)
            }
        };
        self.shared_channels.insert(record.type_name, (channel, seq + 1));
        match writer.write_message(channel, seq as u32, log_time, log_time, &record.bytes) {
            Ok(()) => self.messages += 1,
            Err(error) => self.error = Some(error),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn write_message(
        &mut self,
        topic: &Topic,
        encoding: Encoding,
        schema: Option<Arc<CdrSchema>>,
        log_time: u64,
        stamp: u64,
        seq: u64,
        value: &[u8],
    ) {
        if self.error.is_some() {
            self.shared.drop_record(topic);
            return;
        }
        let channel = self.channel(topic, encoding, schema.as_deref(), value);
        let result = {
            let payload = if channel.wrapped {
                let (prefix, suffix) = wrap_frame(encoding);
                self.scratch.clear();
                self.scratch.extend_from_slice(prefix);
                self.scratch.extend_from_slice(value);
                self.scratch.extend_from_slice(suffix);
                &self.scratch[..]
            } else {
                value
            };
            match self.writer.as_mut() {
                // MCAP sequences are 32 bits; readers unwrap them per channel.
                Some(writer) => {
                    writer.write_message(channel.id, seq as u32, log_time, stamp, payload)
                }
                None => Ok(()),
            }
        };
        match result {
            Ok(()) => self.messages += 1,
            Err(error) => {
                self.error = Some(error);
                self.shared.drop_record(topic);
                return;
            }
        }
        let chunk = self.chunk.get_or_insert_with(|| OpenChunk {
            first_log_time: log_time,
            opened: Instant::now(),
            messages: 0,
        });
        chunk.messages += 1;
        let span = Duration::from_nanos(log_time.saturating_sub(chunk.first_log_time));
        if span >= self.options.max_chunk_span
            || (chunk.messages.is_multiple_of(AGE_CHECK_EVERY)
                && chunk.opened.elapsed() >= self.options.max_chunk_age)
        {
            self.close_chunk();
        }
    }

    /// The channel of a topic in an encoding, created on its first message. A CDR channel
    /// has the type's IDL schema and its format (metadata `strata.format`, for Strata's own
    /// readers). Generic tools take self-describing messages that are objects (maps): a topic
    /// whose first value is not one (a number, a tuple, a unit enum variant) has every value
    /// wrapped as `{"value": ...}`, which the channel's metadata records and readers undo.
    fn channel(
        &mut self,
        topic: &Topic,
        encoding: Encoding,
        cdr: Option<&CdrSchema>,
        sample: &[u8],
    ) -> ChannelState {
        if let Some(channel) = *self.topic(topic.id).channel(encoding) {
            return channel;
        }
        let Some(writer) = self.writer.as_mut() else {
            return ChannelState { id: 0, wrapped: false };
        };
        let mut metadata = BTreeMap::from([
            ("type_name".to_owned(), topic.type_name.clone()),
            (PUBLISH_TIME_KEY.to_owned(), "stamp".to_owned()),
        ]);
        let (schema_id, wrapped) = match (encoding, cdr) {
            (Encoding::Cdr, Some(cdr)) => {
                metadata.insert(FORMAT_KEY.to_owned(), cdr.format_json.clone());
                let key = (topic.type_name.clone(), encoding, false);
                let id = match self.schemas.get(&key) {
                    Some(&id) => id,
                    None => {
                        let id =
                            writer.add_schema(&cdr.idl.name, "omgidl", cdr.idl.text.as_bytes());
                        self.schemas.insert(key, id);
                        id
                    }
                };
                (id, false)
            }
            _ => {
                let wrapped = !is_map(encoding, sample);
                let key = (topic.type_name.clone(), encoding, wrapped);
                let id = match self.schemas.get(&key) {
                    Some(&id) => id,
                    None => {
                        let sample = encoding.decode(sample).unwrap_or(serde_json::Value::Null);
                        let sample = if wrapped {
                            serde_json::json!({ WRAP_FIELD: sample })
                        } else {
                            sample
                        };
                        let schema = infer_json_schema(&topic.type_name, &sample);
                        let data = serde_json::to_vec(&schema).unwrap_or_default();
                        let id = writer.add_schema(&topic.type_name, "jsonschema", &data);
                        self.schemas.insert(key, id);
                        id
                    }
                };
                if wrapped {
                    metadata.insert(WRAPPED_KEY.to_owned(), WRAP_FIELD.to_owned());
                }
                (id, wrapped)
            }
        };
        let id = writer.add_channel(schema_id, &topic.name, encoding.mcap_name(), &metadata);
        let channel = ChannelState { id, wrapped };
        *self.topic(topic.id).channel(encoding) = Some(channel);
        channel
    }

    fn close_chunk(&mut self) {
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

    fn finish(&mut self) -> Result<LogSummary, LogError> {
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
