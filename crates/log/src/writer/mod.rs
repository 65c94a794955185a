//! [`McapTap`]: records every package a host delivers into an MCAP file, from a background
//! thread fed by a bounded queue.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError};
use strata_runtime::cdr::{Format, idl_schema};
use strata_runtime::shared::{NewRecord, Recorder};
use strata_runtime::{Encoding, ErasedPackage, Time};

use crate::error::LogError;
use crate::mcap_file::McapFile;
use crate::schema::infer_json_schema;
use crate::{FORMAT_KEY, PUBLISH_TIME_KEY, SHARED_KEY, STATS_METADATA, WRAP_FIELD, WRAPPED_KEY};

mod derive;
mod encoding;
mod gather;
mod options;
mod run_info;
mod scoped;
mod sender;
mod shared;
mod tap;
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
pub use scoped::ScopedTap;
use sender::McapSender;
use shared::{Command, Shared};
pub use tap::McapTap;
use topics::{Topic, TopicCache};

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
