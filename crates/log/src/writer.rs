//! [`McapTap`]: records every package a host delivers into an MCAP file, from a background
//! thread fed by a bounded queue.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use serde::{Deserialize, Serialize};
use strata_runtime::{Encoding, ErasedPackage, GraphDescription, Tap, TapRecord, Time};

use crate::error::LogError;
use crate::schema::infer_json_schema;
use crate::{
    CONFIG_ATTACHMENT_PREFIX, GRAPH_METADATA, PUBLISH_TIME_KEY, RUN_METADATA, STATS_METADATA,
    WRAP_FIELD, WRAPPED_KEY,
};

/// How a wrapped message is framed in each encoding (see `WriterThread::channel`): the bytes
/// of a one-entry map with the key [`WRAP_FIELD`] in front of the value, and what closes it.
pub(crate) fn wrap_frame(encoding: Encoding) -> (&'static [u8], &'static [u8]) {
    match encoding {
        Encoding::Json => (b"{\"value\":", b"}"),
        // fixmap of one entry, then fixstr "value".
        Encoding::MessagePack => (b"\x81\xa5value", b""),
    }
}

/// Whether an encoded value is a map (an object), as generic tools expect messages to be.
fn is_map(encoding: Encoding, bytes: &[u8]) -> bool {
    match (encoding, bytes.first()) {
        (Encoding::Json, Some(first)) => *first == b'{',
        // fixmap, map 16, map 32.
        (Encoding::MessagePack, Some(first)) => matches!(first, 0x80..=0x8f | 0xde | 0xdf),
        (_, None) => false,
    }
}

/// How chunks are compressed: zstd at its fastest level by default, on the writer thread only
/// (no compression worker threads competing with the real-time layers for the robot's cores).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogCompression {
    #[default]
    Zstd,
    Lz4,
    None,
}

impl std::str::FromStr for LogCompression {
    type Err = String;

    fn from_str(text: &str) -> Result<LogCompression, String> {
        match text {
            "zstd" => Ok(LogCompression::Zstd),
            "lz4" => Ok(LogCompression::Lz4),
            "none" => Ok(LogCompression::None),
            _ => Err(format!("unknown compression `{text}` (zstd, lz4 or none)")),
        }
    }
}

/// What a record does when the writer's queue is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WhenFull {
    /// Dropped and counted: the sending module never waits for the disk. For real-time hosts.
    #[default]
    Drop,
    /// The sender waits for room. For simulated-time runs (the lockstep host), where waiting
    /// costs no deadline and a complete log is what replay needs.
    Wait,
}

/// How a [`McapTap`] buffers and writes.
#[derive(Clone, Debug, PartialEq)]
pub struct McapTapOptions {
    /// Records the queue between the tap and the writer thread holds.
    pub capacity: usize,
    /// What happens to a record that finds the queue full.
    pub when_full: WhenFull,
    /// Log only packages of modules whose full name (topic prefix included) starts with one of
    /// these, e.g. `["home/3/"]` for one robot; empty: every module. Application records
    /// ([`McapTap::record`]) are always logged.
    pub modules: Vec<String>,
    /// A chunk is closed once this many uncompressed bytes are in it.
    pub chunk_size: u64,
    /// ... or once it spans this much log time: a killed process loses at most the open chunk,
    /// so this bounds the loss in match time.
    pub max_chunk_span: Duration,
    /// ... or once it has been open this long in real time (a quiet real-time robot).
    pub max_chunk_age: Duration,
    pub compression: LogCompression,
    /// How package values are encoded (MCAP's `message_encoding`).
    pub encoding: Encoding,
}

impl Default for McapTapOptions {
    fn default() -> Self {
        McapTapOptions {
            capacity: 65_536,
            when_full: WhenFull::Drop,
            modules: Vec::new(),
            chunk_size: 1 << 20,
            max_chunk_span: Duration::from_millis(200),
            max_chunk_age: Duration::from_millis(500),
            compression: LogCompression::Zstd,
            encoding: Encoding::MessagePack,
        }
    }
}

/// What a finished log holds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LogSummary {
    /// Messages written (packages and application records).
    pub messages: u64,
    /// Records dropped because the queue was full, the writer had failed or the log was
    /// already finished.
    pub dropped: u64,
    /// Packages whose value could not be encoded (not written).
    pub serialize_errors: u64,
    /// Size of the file.
    pub bytes: u64,
    /// Number of topics (channels).
    pub topics: usize,
    /// Drops per topic, for the topics that had any.
    pub dropped_by_topic: BTreeMap<String, u64>,
}

/// The format of the configuration text stored with a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConfigFormat {
    Toml,
    Json,
}

impl ConfigFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ConfigFormat::Toml => "toml",
            ConfigFormat::Json => "json",
        }
    }

    fn media_type(self) -> &'static str {
        match self {
            ConfigFormat::Toml => "application/toml",
            ConfigFormat::Json => "application/json",
        }
    }
}

/// What replay needs to rebuild a run besides the graph: the seed, the configuration the
/// modules were built from (store the effective one, defaults filled in, so `--set` can reach
/// every parameter), and where it came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    pub seed: u64,
    pub command_line: Vec<String>,
    /// The program's version (no git: a release's crate version and build profile).
    pub version: String,
    /// The configuration text as given, and its format.
    pub config: Option<(ConfigFormat, String)>,
}

impl RunInfo {
    /// A run of this process: its command line and the version of this crate.
    pub fn current(seed: u64) -> RunInfo {
        RunInfo {
            seed,
            command_line: std::env::args().collect(),
            version: format!(
                "strata {} ({})",
                env!("CARGO_PKG_VERSION"),
                if cfg!(debug_assertions) { "debug" } else { "release" }
            ),
            config: None,
        }
    }

    pub fn with_config(mut self, format: ConfigFormat, text: impl Into<String>) -> RunInfo {
        self.config = Some((format, text.into()));
        self
    }
}

/// One logged stream: the channel a topic gets in the file.
#[derive(Debug)]
struct Topic {
    id: u32,
    name: String,
    type_name: String,
    /// Records handed to the queue (or refused by it) on this topic.
    offered: AtomicU64,
    dropped: AtomicU64,
    /// Sequence numbers of application records (packages carry their own).
    next_seq: AtomicU64,
}

/// A message's value on its way to the writer thread.
enum Payload {
    /// A package, encoded by the writer thread: the sending module only pays for a clone.
    Package(Box<dyn ErasedPackage>),
    /// An application record, already encoded.
    Encoded(Vec<u8>),
}

enum Command {
    Message { topic: Arc<Topic>, log_time: u64, stamp: u64, seq: u64, payload: Payload },
    Metadata { name: String, entries: BTreeMap<String, String> },
    Attachment { name: String, media_type: String, time: u64, data: Vec<u8> },
    Finish(Sender<Result<LogSummary, LogError>>),
}

/// State shared by the tap handles and the writer thread.
struct Shared {
    path: PathBuf,
    sender: Sender<Command>,
    /// Cleared by `finish`: later records are counted as dropped instead of queued.
    accepting: AtomicBool,
    when_full: WhenFull,
    encoding: Encoding,
    /// Records the queue holds.
    capacity: usize,
    /// Module-name prefixes to log (empty: all).
    modules: Vec<String>,
    /// Records offered to the queue: what was not written of them was dropped. Counting
    /// offers, not failures, keeps the finished summary exact even for a record that raced
    /// with `finish`.
    offered: AtomicU64,
    /// Records refused so far (live figure; the summary's is exact).
    dropped: AtomicU64,
    serialize_errors: AtomicU64,
    next_topic_id: AtomicU32,
    /// Every topic ever created, for the per-topic drop report.
    topics: Mutex<Vec<Arc<Topic>>>,
    /// Application record topics, by name.
    record_topics: RwLock<HashMap<String, Arc<Topic>>>,
    #[cfg(test)]
    gate: Arc<test_gate::Gate>,
}

impl Shared {
    fn new_topic(&self, name: String, type_name: &str) -> Arc<Topic> {
        let topic = Arc::new(Topic {
            id: self.next_topic_id.fetch_add(1, Ordering::Relaxed),
            name,
            type_name: type_name.to_owned(),
            offered: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            next_seq: AtomicU64::new(0),
        });
        self.topics.lock().unwrap_or_else(PoisonError::into_inner).push(Arc::clone(&topic));
        topic
    }

    fn drop_record(&self, topic: &Topic) {
        self.dropped.fetch_add(1, Ordering::Relaxed);
        topic.dropped.fetch_add(1, Ordering::Relaxed);
    }

    /// Queues a message; a full queue costs the record (counted) or, in [`WhenFull::Wait`]
    /// mode, the sender's time.
    fn submit(&self, topic: &Arc<Topic>, log_time: Time, stamp: Time, seq: u64, payload: Payload) {
        self.offered.fetch_add(1, Ordering::Relaxed);
        topic.offered.fetch_add(1, Ordering::Relaxed);
        if !self.accepting.load(Ordering::Acquire) {
            self.drop_record(topic);
            return;
        }
        let command = Command::Message {
            topic: Arc::clone(topic),
            log_time: log_time.as_nanos(),
            stamp: stamp.as_nanos(),
            seq,
            payload,
        };
        let refused = match self.when_full {
            WhenFull::Drop => match self.sender.try_send(command) {
                Ok(()) => None,
                Err(TrySendError::Full(command) | TrySendError::Disconnected(command)) => {
                    Some(command)
                }
            },
            WhenFull::Wait => self.sender.send(command).err().map(|e| e.into_inner()),
        };
        if refused.is_some() {
            self.drop_record(topic);
        }
    }

    fn tap_package(&self, topics: &TopicCache, record: &TapRecord<'_>) {
        let Some(topic) = topics.get(self, record) else { return };
        let (stamp, seq) = (record.package.stamp(), record.package.seq());
        // A sender that may wait for the writer anyway (simulated time) shares its work once
        // the writer falls behind: it encodes, the writer only compresses and writes. The
        // bytes are the same either way. A real-time sender never does: it only clones.
        let payload = if self.when_full == WhenFull::Wait && self.sender.len() >= self.capacity / 2
        {
            let mut bytes = Vec::with_capacity(1024);
            if record.package.encode(self.encoding, &mut bytes).is_err() {
                self.serialize_errors.fetch_add(1, Ordering::Relaxed);
                return;
            }
            Payload::Encoded(bytes)
        } else {
            Payload::Package(record.package.clone_boxed())
        };
        self.submit(&topic, record.time, stamp, seq, payload);
    }

    /// A value that could not be encoded: an error, not a drop.
    fn unencodable(&self, topic: &Topic) {
        self.serialize_errors.fetch_add(1, Ordering::Relaxed);
        self.offered.fetch_sub(1, Ordering::Relaxed);
        topic.offered.fetch_sub(1, Ordering::Relaxed);
    }

    /// Queues a command that must not be lost (metadata): waits for room in the queue.
    fn send_control(&self, command: Command) -> Result<(), LogError> {
        if !self.accepting.load(Ordering::Acquire) {
            return Err(LogError::Invalid {
                path: self.path.clone(),
                what: "the log is already finished".to_owned(),
            });
        }
        self.sender.send(command).map_err(|_| LogError::WriterGone { path: self.path.clone() })
    }
}

/// Per output name, its topic (`None`: the module is not logged).
type OutputTopics = HashMap<String, Option<Arc<Topic>>>;

/// One module's topics, as the fast path finds them.
#[derive(Default)]
struct ModuleTopics {
    name: String,
    outputs: Vec<(String, Option<Arc<Topic>>)>,
}

impl ModuleTopics {
    fn get(&self, module_name: &str, output: &str) -> Option<&Option<Arc<Topic>>> {
        if self.name != module_name {
            return None;
        }
        self.outputs.iter().find(|(name, _)| name == output).map(|(_, topic)| topic)
    }
}

/// Topics of packages by module and output name. Every package of a match passes here on the
/// sending module's thread, so the usual lookup goes by module id and a short list of outputs,
/// without hashing; the map by name is where topics are created, once each.
#[derive(Default)]
struct TopicCache {
    prefix: String,
    /// By module id; the name is checked too, in case one tap serves several graphs.
    by_id: RwLock<Vec<ModuleTopics>>,
    by_name: Mutex<HashMap<String, OutputTopics>>,
}

impl TopicCache {
    /// The topic of a record's output; `None` for modules the options leave out.
    fn get(&self, shared: &Shared, record: &TapRecord<'_>) -> Option<Arc<Topic>> {
        let index = record.module.index();
        {
            let modules = self.by_id.read().unwrap_or_else(PoisonError::into_inner);
            if let Some(topic) =
                modules.get(index).and_then(|m| m.get(record.module_name, record.output))
            {
                return topic.clone();
            }
        }
        let topic = {
            let mut by_name = self.by_name.lock().unwrap_or_else(PoisonError::into_inner);
            let outputs = by_name.entry(record.module_name.to_owned()).or_default();
            outputs
                .entry(record.output.to_owned())
                .or_insert_with(|| {
                    let name = format!(
                        "{}{}",
                        self.prefix,
                        crate::package_topic(record.module_name, record.output)
                    );
                    let wanted = shared.modules.is_empty()
                        || shared.modules.iter().any(|prefix| name.starts_with(prefix.as_str()));
                    wanted.then(|| shared.new_topic(name, record.type_name))
                })
                .clone()
        };
        let mut modules = self.by_id.write().unwrap_or_else(PoisonError::into_inner);
        if modules.len() <= index {
            modules.resize_with(index + 1, ModuleTopics::default);
        }
        let module = &mut modules[index];
        if module.name != record.module_name {
            // Another graph's module with the same id: the slot follows the latest one.
            *module = ModuleTopics { name: record.module_name.to_owned(), outputs: Vec::new() };
        }
        module.outputs.push((record.output.to_owned(), topic.clone()));
        topic
    }
}

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
    topics: TopicCache,
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
        let write_options = mcap::WriteOptions::new()
            .profile("strata")
            .library(format!("strata-log {}", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(options.chunk_size.max(1024)))
            .compression(match options.compression {
                LogCompression::Zstd => Some(mcap::Compression::Zstd),
                LogCompression::Lz4 => Some(mcap::Compression::Lz4),
                LogCompression::None => None,
            })
            .compression_level(1)
            .compression_threads(0);
        let writer = write_options
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|source| LogError::Write { path: path.clone(), source })?;
        let (sender, receiver) = crossbeam_channel::bounded(options.capacity.max(1));
        let when_full = options.when_full;
        let shared = Arc::new(Shared {
            path: path.clone(),
            sender,
            accepting: AtomicBool::new(true),
            when_full,
            encoding: options.encoding,
            capacity: options.capacity.max(1),
            modules: options.modules.clone(),
            offered: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            serialize_errors: AtomicU64::new(0),
            next_topic_id: AtomicU32::new(0),
            topics: Mutex::new(Vec::new()),
            record_topics: RwLock::new(HashMap::new()),
            #[cfg(test)]
            gate: Arc::new(test_gate::Gate::default()),
        });
        let thread = WriterThread {
            shared: Arc::clone(&shared),
            writer: Some(writer),
            options,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            scratch: Vec::new(),
            encoded: Vec::new(),
            chunk: None,
            messages: 0,
            written_by_topic: HashMap::new(),
            error: None,
        };
        let handle = std::thread::Builder::new()
            .name("strata-log-writer".to_owned())
            .spawn(move || thread.run(receiver))
            .map_err(|source| LogError::Spawn { path: path.clone(), source })?;
        Ok(McapTap {
            shared,
            topics: TopicCache::default(),
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
            topics: TopicCache { prefix: prefix.into(), ..TopicCache::default() },
        }
    }

    /// Logs an application record (ground truth, game state, a behavior path) on `topic`.
    /// Handled like packages: with [`WhenFull::Drop`] it never blocks, and a record that
    /// finds the queue full is dropped and counted.
    pub fn record(&self, topic: &str, type_name: &str, time: Time, value: &serde_json::Value) {
        self.record_encoded(topic, type_name, time, value);
    }

    /// [`McapTap::record`] for any serializable value, named by its Rust type.
    pub fn record_value<T: Serialize>(&self, topic: &str, time: Time, value: &T) {
        self.record_encoded(topic, std::any::type_name::<T>(), time, value);
    }

    /// Records are few (a game state, a behavior path when it changes): encoded right here.
    fn record_encoded<T: Serialize + ?Sized>(
        &self,
        topic: &str,
        type_name: &str,
        time: Time,
        value: &T,
    ) {
        let mut bytes = Vec::with_capacity(256);
        if self.shared.encoding.encode(value, &mut bytes).is_err() {
            self.shared.serialize_errors.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let existing = self
            .shared
            .record_topics
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .get(topic)
            .cloned();
        let topic = existing.unwrap_or_else(|| {
            let mut map = self.shared.record_topics.write().unwrap_or_else(PoisonError::into_inner);
            Arc::clone(
                map.entry(topic.to_owned())
                    .or_insert_with(|| self.shared.new_topic(topic.to_owned(), type_name)),
            )
        });
        let seq = topic.next_seq.fetch_add(1, Ordering::Relaxed);
        self.shared.submit(&topic, time, time, seq, Payload::Encoded(bytes));
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
        // Queued before `accepting` is cleared, so everything accepted so far precedes it.
        let sent = self.shared.sender.send(Command::Finish(reply));
        self.shared.accepting.store(false, Ordering::Release);
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
    fn package(&self, record: &TapRecord<'_>) {
        self.shared.tap_package(&self.topics, record);
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
    topics: TopicCache,
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
    fn package(&self, record: &TapRecord<'_>) {
        self.tap.shared.tap_package(&self.topics, record);
    }
}

struct OpenChunk {
    first_log_time: u64,
    opened: Instant,
}

struct WriterThread {
    shared: Arc<Shared>,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    options: McapTapOptions,
    /// MCAP channel id per topic id, and whether its messages are wrapped.
    channels: HashMap<u32, (u16, bool)>,
    /// MCAP schema id per type name (and wrapping): the first sample of a type defines its
    /// schema.
    schemas: HashMap<(String, bool), u16>,
    /// Where wrapped messages are assembled.
    scratch: Vec<u8>,
    /// Where packages are encoded (one buffer, reused).
    encoded: Vec<u8>,
    chunk: Option<OpenChunk>,
    messages: u64,
    written_by_topic: HashMap<u32, u64>,
    /// The first write error; afterwards records are only counted as dropped.
    error: Option<mcap::McapError>,
}

impl WriterThread {
    fn run(mut self, receiver: Receiver<Command>) {
        loop {
            let command = match &self.chunk {
                Some(chunk) => {
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
                None => match receiver.recv() {
                    Ok(command) => command,
                    Err(_) => break,
                },
            };
            #[cfg(test)]
            self.shared.gate.wait_open();
            match command {
                Command::Message { topic, log_time, stamp, seq, payload } => match payload {
                    Payload::Package(package) => {
                        let mut encoded = std::mem::take(&mut self.encoded);
                        encoded.clear();
                        match package.encode(self.shared.encoding, &mut encoded) {
                            Ok(()) => self.write_message(&topic, log_time, stamp, seq, &encoded),
                            Err(_) => self.shared.unencodable(&topic),
                        }
                        self.encoded = encoded;
                    }
                    Payload::Encoded(bytes) => {
                        self.write_message(&topic, log_time, stamp, seq, &bytes);
                    }
                },
                Command::Metadata { name, entries } => {
                    let metadata = mcap::records::Metadata { name, metadata: entries };
                    self.apply(|w| w.write_metadata(&metadata));
                }
                Command::Attachment { name, media_type, time, data } => {
                    let attachment = mcap::Attachment {
                        log_time: time,
                        create_time: time,
                        name,
                        media_type,
                        data: data.into(),
                    };
                    self.apply(|w| w.attach(&attachment));
                }
                Command::Finish(reply) => {
                    // Whatever was queued after the finish request is late: count it.
                    while let Ok(late) = receiver.try_recv() {
                        if let Command::Message { topic, .. } = late {
                            self.shared.drop_record(&topic);
                        }
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
    fn apply(
        &mut self,
        write: impl FnOnce(&mut mcap::Writer<BufWriter<File>>) -> mcap::McapResult<()>,
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

    fn write_message(&mut self, topic: &Topic, log_time: u64, stamp: u64, seq: u64, value: &[u8]) {
        if self.error.is_some() {
            self.shared.drop_record(topic);
            return;
        }
        let result = self.channel(topic, value).and_then(|(channel_id, wrapped)| {
            let header = mcap::records::MessageHeader {
                channel_id,
                // MCAP sequences are 32 bits; readers unwrap them per channel.
                sequence: seq as u32,
                log_time,
                publish_time: stamp,
            };
            let payload = if wrapped {
                let (prefix, suffix) = wrap_frame(self.shared.encoding);
                self.scratch.clear();
                self.scratch.extend_from_slice(prefix);
                self.scratch.extend_from_slice(value);
                self.scratch.extend_from_slice(suffix);
                &self.scratch[..]
            } else {
                value
            };
            match self.writer.as_mut() {
                Some(writer) => writer.write_to_known_channel(&header, payload),
                None => Ok(()),
            }
        });
        match result {
            Ok(()) => {
                self.messages += 1;
                *self.written_by_topic.entry(topic.id).or_default() += 1;
            }
            Err(error) => {
                self.error = Some(error);
                self.shared.drop_record(topic);
                return;
            }
        }
        let chunk = self
            .chunk
            .get_or_insert(OpenChunk { first_log_time: log_time, opened: Instant::now() });
        let span = Duration::from_nanos(log_time.saturating_sub(chunk.first_log_time));
        if span >= self.options.max_chunk_span
            || chunk.opened.elapsed() >= self.options.max_chunk_age
        {
            self.close_chunk();
        }
    }

    /// The channel of a topic and whether its messages are wrapped, created on its first
    /// message. Generic tools (Foxglove) take messages that are objects (maps): a topic whose
    /// first value is not one (a number, a tuple, a unit enum variant) has every value
    /// wrapped as `{"value": ...}`, which the channel's metadata records and readers undo.
    fn channel(&mut self, topic: &Topic, sample: &[u8]) -> mcap::McapResult<(u16, bool)> {
        if let Some(&channel) = self.channels.get(&topic.id) {
            return Ok(channel);
        }
        let Some(writer) = self.writer.as_mut() else { return Ok((0, false)) };
        let encoding = self.shared.encoding;
        let wrapped = !is_map(encoding, sample);
        let schema_id = match self.schemas.get(&(topic.type_name.clone(), wrapped)) {
            Some(&id) => id,
            None => {
                let sample = encoding.decode(sample).unwrap_or(serde_json::Value::Null);
                let sample =
                    if wrapped { serde_json::json!({ WRAP_FIELD: sample }) } else { sample };
                let schema = infer_json_schema(&topic.type_name, &sample);
                let data = serde_json::to_vec(&schema).unwrap_or_default();
                let id = writer.add_schema(&topic.type_name, "jsonschema", &data)?;
                self.schemas.insert((topic.type_name.clone(), wrapped), id);
                id
            }
        };
        let mut metadata = BTreeMap::from([
            ("type_name".to_owned(), topic.type_name.clone()),
            (PUBLISH_TIME_KEY.to_owned(), "stamp".to_owned()),
        ]);
        if wrapped {
            metadata.insert(WRAPPED_KEY.to_owned(), WRAP_FIELD.to_owned());
        }
        let id = writer.add_channel(schema_id, &topic.name, encoding.mcap_name(), &metadata)?;
        self.channels.insert(topic.id, (id, wrapped));
        Ok((id, wrapped))
    }

    fn close_chunk(&mut self) {
        self.chunk = None;
        if self.error.is_some() {
            return;
        }
        if let Some(writer) = self.writer.as_mut()
            && let Err(error) = writer.flush()
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
                let written = self.written_by_topic.get(&t.id).copied().unwrap_or(0);
                let n = t.offered.load(Ordering::Relaxed).saturating_sub(written);
                (n > 0).then(|| (t.name.clone(), n))
            })
            .collect();
        let mut summary = LogSummary {
            messages: self.messages,
            dropped: self.shared.offered.load(Ordering::Relaxed).saturating_sub(self.messages),
            serialize_errors: self.shared.serialize_errors.load(Ordering::Relaxed),
            bytes: 0,
            topics: self.channels.len(),
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
        self.apply(|w| {
            w.write_metadata(&mcap::records::Metadata {
                name: STATS_METADATA.to_owned(),
                metadata: stats,
            })
        });
        let Some(mut writer) = self.writer.take() else {
            return Err(LogError::WriterGone { path });
        };
        if let Some(source) = self.error.take() {
            return Err(LogError::Write { path, source });
        }
        writer.finish().map_err(|source| LogError::Write { path: path.clone(), source })?;
        let file = writer.into_inner().into_inner().map_err(|e| LogError::Write {
            path: path.clone(),
            source: mcap::McapError::Io(e.into_error()),
        })?;
        summary.bytes = file
            .metadata()
            .map(|m| m.len())
            .map_err(|e| LogError::Write { path: path.clone(), source: mcap::McapError::Io(e) })?;
        Ok(summary)
    }
}

#[cfg(test)]
mod test_gate {
    use std::sync::{Condvar, Mutex, PoisonError};

    /// Holds the writer thread before it handles each record, so a test can fill the queue.
    #[derive(Default)]
    pub(super) struct Gate {
        closed: Mutex<bool>,
        changed: Condvar,
    }

    impl Gate {
        pub(super) fn set_closed(&self, closed: bool) {
            *self.closed.lock().unwrap_or_else(PoisonError::into_inner) = closed;
            self.changed.notify_all();
        }

        pub(super) fn wait_open(&self) {
            let guard = self.closed.lock().unwrap_or_else(PoisonError::into_inner);
            let _guard = self
                .changed
                .wait_while(guard, |closed| *closed)
                .unwrap_or_else(PoisonError::into_inner);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_and_counts_instead_of_blocking() {
        let dir = std::env::temp_dir().join(format!("strata-log-drop-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        let path = dir.join("drop.mcap");
        let options = McapTapOptions { capacity: 4, ..McapTapOptions::default() };
        let tap = McapTap::create(&path, options).expect("create");
        tap.gate().set_closed(true);
        let sent = 100u64;
        for i in 0..sent {
            tap.record("test/values", "u64", Time::from_nanos(i * 1000), &serde_json::json!(i));
        }
        let dropped = tap.dropped();
        // The queue holds 4 and the paused writer at most one more.
        assert!(dropped >= sent - 5, "dropped {dropped}");
        tap.gate().set_closed(false);
        let summary = tap.finish().expect("finish");
        assert_eq!(summary.messages + summary.dropped, sent);
        assert_eq!(summary.dropped_by_topic.get("test/values").copied(), Some(summary.dropped));
        let reader = crate::LogReader::open(&path).expect("open");
        assert!(reader.is_complete());
        assert_eq!(reader.message_count(), summary.messages);
        assert_eq!(reader.stats().map(|s| s.dropped), Some(summary.dropped));
        std::fs::remove_dir_all(&dir).unwrap_or_default();
    }

    #[test]
    fn a_waiting_sender_encodes_once_the_writer_falls_behind() {
        use strata_runtime::{ModuleId, Package};
        let dir = std::env::temp_dir().join(format!("strata-log-share-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        let path = dir.join("share.mcap");
        let options =
            McapTapOptions { capacity: 8, when_full: WhenFull::Wait, ..McapTapOptions::default() };
        let tap = McapTap::create(&path, options).expect("create");
        // The writer takes the first record and stops: the queue fills past half, and the
        // later packages are encoded here.
        tap.gate().set_closed(true);
        let values: Vec<(u32, String)> = (0..7).map(|i| (i, format!("v{i}"))).collect();
        for (i, value) in values.iter().enumerate() {
            let package = Package::new(
                value.clone(),
                Time::from_nanos(i as u64 * 1_000_000),
                i as u64,
                ModuleId(0),
            );
            tap.package(&TapRecord {
                time: Time::from_nanos(i as u64 * 1_000_000),
                module: ModuleId(0),
                module_name: "m",
                output: "out",
                type_name: "(u32, String)",
                package: &package,
            });
        }
        assert!(tap.shared.sender.len() >= 4, "the queue is past half full");
        tap.gate().set_closed(false);
        let summary = tap.finish().expect("finish");
        assert_eq!((summary.messages, summary.dropped), (7, 0));
        let reader = crate::LogReader::open(&path).expect("open");
        let read: Vec<(u32, String)> =
            reader.messages().map(|m| m.expect("ok").decode().expect("decodes")).collect();
        assert_eq!(read, values);
        std::fs::remove_dir_all(&dir).unwrap_or_default();
    }

    #[test]
    fn wait_mode_loses_nothing_through_a_tiny_queue() {
        let dir = std::env::temp_dir().join(format!("strata-log-wait-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        let path = dir.join("wait.mcap");
        let options =
            McapTapOptions { capacity: 2, when_full: WhenFull::Wait, ..McapTapOptions::default() };
        let tap = McapTap::create(&path, options).expect("create");
        for i in 0..2000u64 {
            tap.record("test/values", "u64", Time::from_nanos(i), &serde_json::json!(i));
        }
        let summary = tap.finish().expect("finish");
        assert_eq!((summary.messages, summary.dropped), (2000, 0));
        std::fs::remove_dir_all(&dir).unwrap_or_default();
    }
}
