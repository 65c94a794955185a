//! [`LogReader`]: reads a Strata MCAP log, complete or cut short.
//!
//! A complete file is read through its summary (channels, statistics, chunk and metadata
//! indexes at the end). A file without a valid footer (the process was killed) is scanned from
//! the start, record by record, up to the first record that is incomplete or damaged:
//! everything in the complete chunks before it is kept. The writer closes chunks often (see
//! [`crate::McapTapOptions`]), so little is lost.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{Record, op};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use strata_runtime::cdr::{self, Format};
use strata_runtime::shared;
use strata_runtime::{Encoding, EncodingError, GraphDescription, Time};

use crate::error::LogError;
use crate::writer::{ConfigFormat, RunInfo, wrap_frame};
use crate::{
    CONFIG_ATTACHMENT_PREFIX, FORMAT_KEY, GRAPH_METADATA, RUN_METADATA, SHARED_KEY, STATS_METADATA,
    WRAP_FIELD, WRAPPED_KEY,
};

const MAGIC: &[u8] = mcap::MAGIC;
/// Opcode (1) and length (8) in front of every record.
const RECORD_HEADER: u64 = 9;

/// One logged message.
#[derive(Clone, Debug, PartialEq)]
pub struct LogMessage {
    pub topic: Arc<str>,
    pub type_name: Arc<str>,
    /// When the package became visible to its readers (host time).
    pub log_time: Time,
    /// When its data was measured (the package's stamp).
    pub stamp: Time,
    pub seq: u64,
    /// How `data` is encoded (its channel's `message_encoding`).
    pub encoding: Encoding,
    /// The value, encoded.
    pub data: Vec<u8>,
    /// The value's format, for CDR (from the channel's metadata).
    pub format: Option<Arc<Format>>,
}

impl LogMessage {
    /// The value as a JSON value, whatever its encoding (CDR through its format).
    pub fn json(&self) -> Result<serde_json::Value, EncodingError> {
        match (self.encoding, &self.format) {
            (Encoding::Cdr, Some(format)) => Ok(cdr::to_json(format, &self.data)?),
            (Encoding::Cdr, None) => Err(cdr::CdrError::NotSelfDescribing(
                "a CDR message of a channel without `strata.format`",
            )
            .into()),
            (encoding, _) => encoding.decode(&self.data),
        }
    }

    /// The value as its Rust type.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, EncodingError> {
        self.encoding.decode(&self.data)
    }
}

/// A topic of the log.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TopicInfo {
    pub name: String,
    /// The Rust type of its messages.
    pub type_name: String,
    pub message_encoding: String,
    pub schema_encoding: Option<String>,
    pub messages: u64,
}

/// A metadata record.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedMetadata {
    pub name: String,
    pub entries: BTreeMap<String, String>,
}

/// An attachment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoggedAttachment {
    pub name: String,
    pub media_type: String,
    pub data: Vec<u8>,
}

/// A logged graph description and the topic prefix its packages were logged under.
#[derive(Clone, Debug)]
pub struct LoggedGraph {
    pub scope: String,
    pub description: GraphDescription,
}

/// The writer's own account, stored when the log was finished.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LoggedStats {
    pub messages: u64,
    pub dropped: u64,
    pub serialize_errors: u64,
    pub dropped_by_topic: BTreeMap<String, u64>,
}

/// How much of a file without a valid footer could be read.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Recovery {
    /// Bytes up to the end of the last complete record kept.
    pub valid_bytes: u64,
    pub file_bytes: u64,
    pub chunks: usize,
    pub messages: u64,
    /// Why reading stopped there.
    pub stopped: String,
}

/// Where a chunk is, and what it spans.
#[derive(Clone, Copy, Debug)]
struct ChunkLocation {
    offset: u64,
    length: u64,
}

#[derive(Clone, Debug)]
struct ChannelInfo {
    topic: Arc<str>,
    type_name: Arc<str>,
    /// Values are stored as `{"value": ...}`.
    wrapped: bool,
    /// `None`: an encoding Strata does not read (its messages are an error when read).
    encoding: Option<Encoding>,
    /// The channel's `message_encoding`, for the error.
    encoding_name: Arc<str>,
    /// The values' format (CDR channels written by Strata).
    format: Option<Arc<Format>>,
    /// The channel holds shared values' records, which readers register as they pass.
    shared: bool,
}

impl ChannelInfo {
    fn new(
        topic: &str,
        type_name: &str,
        encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Self {
        ChannelInfo {
            topic: topic.into(),
            type_name: type_name.into(),
            wrapped: metadata.get(WRAPPED_KEY).is_some_and(|field| field == WRAP_FIELD),
            encoding: Encoding::from_mcap_name(encoding),
            encoding_name: encoding.into(),
            // A format that does not parse leaves the channel readable as its Rust type only.
            format: metadata
                .get(FORMAT_KEY)
                .and_then(|json| serde_json::from_str(json).ok())
                .map(Arc::new),
            shared: metadata.get(SHARED_KEY).is_some_and(|v| v == "true"),
        }
    }
}

/// The id of a shared value's record (its first field, `id`).
fn record_id(encoding: Encoding, data: &[u8]) -> Option<u64> {
    match encoding {
        // Header, then the id at the start of the payload (aligned already).
        Encoding::Cdr => data.get(4..12).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes),
        _ => encoding.decode::<serde_json::Value>(data).ok()?.get("id")?.as_u64(),
    }
}

/// The value inside a wrapped message, exactly as the writer framed it.
fn unwrap_value(encoding: Encoding, data: &[u8]) -> Option<&[u8]> {
    let (prefix, suffix) = wrap_frame(encoding);
    data.strip_prefix(prefix)?.strip_suffix(suffix)
}

/// An opened log: its topics, metadata and where its messages are; messages are read on demand,
/// one chunk at a time.
#[derive(Debug)]
pub struct LogReader {
    path: PathBuf,
    file_bytes: u64,
    complete: bool,
    recovery: Option<Recovery>,
    chunks: Vec<ChunkLocation>,
    channels: HashMap<u16, ChannelInfo>,
    topics: Vec<TopicInfo>,
    message_count: u64,
    time_range: Option<(Time, Time)>,
    metadata: Vec<LoggedMetadata>,
    attachments: Vec<LoggedAttachment>,
}

/// Reads records by offset from an open file, with errors that name the file and offset.
struct RecordFile {
    path: PathBuf,
    file: File,
    len: u64,
}

impl RecordFile {
    fn read_exact_at(&mut self, offset: u64, buf: &mut [u8]) -> Result<(), LogError> {
        let path = &self.path;
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(buf))
            .map_err(|source| LogError::Read { path: path.clone(), offset, source })
    }

    /// The opcode and body of the record at `offset`, if it lies wholly inside the file.
    fn record_at(&mut self, offset: u64) -> Result<Option<(u8, Vec<u8>)>, LogError> {
        if offset.saturating_add(RECORD_HEADER) > self.len {
            return Ok(None);
        }
        let mut header = [0u8; RECORD_HEADER as usize];
        self.read_exact_at(offset, &mut header)?;
        let opcode = header[0];
        let mut length = [0u8; 8];
        length.copy_from_slice(&header[1..]);
        let length = u64::from_le_bytes(length);
        let end = offset.saturating_add(RECORD_HEADER).saturating_add(length);
        if end > self.len {
            return Ok(None);
        }
        let size = usize::try_from(length).map_err(|_| LogError::Invalid {
            path: self.path.clone(),
            what: format!("record at byte {offset} is too large ({length} bytes)"),
        })?;
        let mut body = vec![0u8; size];
        self.read_exact_at(offset + RECORD_HEADER, &mut body)?;
        Ok(Some((opcode, body)))
    }
}

/// What a chunk holds once decompressed and checked.
struct ChunkContents {
    channels: Vec<(u16, ChannelInfo, String, Option<String>)>,
    messages: Vec<(mcap::records::MessageHeader, Vec<u8>)>,
}

/// The largest record (or decompressed chunk) a log may hold. A damaged length field must
/// give an error, not an attempt to allocate exabytes.
const MAX_RECORD_BYTES: usize = 256 << 20;

fn decode_chunk(path: &Path, offset: u64, body: &[u8]) -> Result<ChunkContents, LogError> {
    let bad = |source| LogError::Record { path: path.to_path_buf(), offset, source };
    // The chunk is fed to the streaming reader as the one record of a data section, which lets
    // it bound every length it reads and check the CRC of the whole chunk before yielding any
    // record of it: a damaged chunk yields an error and none of its messages.
    let options = mcap::sans_io::LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_record_length_limit(MAX_RECORD_BYTES)
        .with_validate_chunk_crcs(true)
        .with_prevalidate_chunk_crcs(true);
    let mut reader = mcap::sans_io::LinearReader::new_with_options(options);
    let mut header = [0u8; RECORD_HEADER as usize];
    header[0] = op::CHUNK;
    header[1..].copy_from_slice(&(body.len() as u64).to_le_bytes());
    let mut input = std::io::Read::chain(&header[..], body);
    let mut schemas: HashMap<u16, (String, String)> = HashMap::new();
    let mut contents = ChunkContents { channels: Vec::new(), messages: Vec::new() };
    while let Some(event) = reader.next_event() {
        match event.map_err(bad)? {
            mcap::sans_io::LinearReadEvent::ReadRequest(wanted) => {
                let buffer = reader.insert(wanted.min(1 << 16));
                let read = input.read(buffer).map_err(|source| LogError::Read {
                    path: path.to_path_buf(),
                    offset,
                    source,
                })?;
                reader.notify_read(read);
            }
            mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                match mcap::parse_record(opcode, data).map_err(bad)? {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, (header.name, header.encoding));
                    }
                    Record::Channel(channel) => {
                        let schema = schemas.get(&channel.schema_id);
                        let type_name = channel
                            .metadata
                            .get("type_name")
                            .cloned()
                            .or_else(|| schema.map(|s| s.0.clone()))
                            .unwrap_or_default();
                        contents.channels.push((
                            channel.id,
                            ChannelInfo::new(
                                &channel.topic,
                                &type_name,
                                &channel.message_encoding,
                                &channel.metadata,
                            ),
                            channel.message_encoding,
                            schema.map(|s| s.1.clone()),
                        ));
                    }
                    Record::Message { header, data } => {
                        contents.messages.push((header, data.into_owned()))
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(contents)
}

fn parse_metadata(path: &Path, offset: u64, body: &[u8]) -> Result<LoggedMetadata, LogError> {
    match mcap::parse_record(op::METADATA, body) {
        Ok(Record::Metadata(m)) => Ok(LoggedMetadata { name: m.name, entries: m.metadata }),
        Ok(_) => Err(LogError::Invalid {
            path: path.to_path_buf(),
            what: format!("record at byte {offset} is not metadata"),
        }),
        Err(source) => Err(LogError::Record { path: path.to_path_buf(), offset, source }),
    }
}

/// Parses an attachment record. Done here rather than by `mcap::parse_record`, which slices
/// the body by its length fields before checking them (a damaged file must not panic).
fn parse_attachment(path: &Path, offset: u64, body: &[u8]) -> Result<LoggedAttachment, LogError> {
    let invalid = |what: &str| LogError::Invalid {
        path: path.to_path_buf(),
        what: format!("attachment at byte {offset}: {what}"),
    };
    let mut rest = body;
    let mut take = |n: usize| -> Result<&[u8], LogError> {
        if rest.len() < n {
            return Err(invalid("shorter than its fields say"));
        }
        let (head, tail) = rest.split_at(n);
        rest = tail;
        Ok(head)
    };
    // Little-endian integer of any width.
    let le = |bytes: &[u8]| bytes.iter().rev().fold(0u64, |n, b| (n << 8) | u64::from(*b));
    take(16)?; // log time, create time
    let name_len = le(take(4)?);
    let name = take(usize::try_from(name_len).map_err(|_| invalid("name too long"))?)?.to_vec();
    let media_len = le(take(4)?);
    let media_type =
        take(usize::try_from(media_len).map_err(|_| invalid("media type too long"))?)?.to_vec();
    let data_len = le(take(8)?);
    let data = take(usize::try_from(data_len).map_err(|_| invalid("data too long"))?)?.to_vec();
    let crc = le(take(4)?);
    // The CRC covers everything before it.
    let checked = body.len() - rest.len() - 4;
    if crc != 0 && body.get(..checked).map(crc32).map(u64::from) != Some(crc) {
        return Err(invalid("CRC mismatch"));
    }
    Ok(LoggedAttachment {
        name: String::from_utf8(name).map_err(|_| invalid("name is not UTF-8"))?,
        media_type: String::from_utf8(media_type)
            .map_err(|_| invalid("media type is not UTF-8"))?,
        data,
    })
}

/// CRC-32 (IEEE), as MCAP uses for attachments.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

impl LogReader {
    /// Opens a log. A complete file is read through its summary; a file cut short is scanned
    /// up to its last complete chunk ([`LogReader::recovery`] says how much was kept). Only a
    /// file that is not MCAP at all, or cannot be read, is an error.
    pub fn open(path: impl AsRef<Path>) -> Result<LogReader, LogError> {
        let path = path.as_ref().to_path_buf();
        let file =
            File::open(&path).map_err(|source| LogError::Open { path: path.clone(), source })?;
        let len =
            file.metadata().map_err(|source| LogError::Open { path: path.clone(), source })?.len();
        let mut records = RecordFile { path: path.clone(), file, len };
        let mut magic = [0u8; 8];
        if len < MAGIC.len() as u64 {
            return Err(LogError::NotMcap { path });
        }
        records.read_exact_at(0, &mut magic)?;
        if magic != MAGIC {
            return Err(LogError::NotMcap { path });
        }
        let mut end_magic = [0u8; 8];
        if len >= 2 * MAGIC.len() as u64 {
            records.read_exact_at(len - MAGIC.len() as u64, &mut end_magic)?;
        }
        if end_magic != MAGIC {
            return Self::scan(&mut records, "no footer: the file was cut short");
        }
        match Self::read_summary(&mut records) {
            Ok(Some(reader)) => Ok(reader),
            Ok(None) => Self::scan(&mut records, "the file has no summary"),
            Err(error) => Self::scan(&mut records, &format!("its summary is unreadable: {error}")),
        }
    }

    /// The summary of a complete file, `None` if it has no footer.
    fn read_summary(records: &mut RecordFile) -> Result<Option<LogReader>, LogError> {
        let path = records.path.clone();
        let summary = {
            let mut reader = mcap::sans_io::SummaryReader::new_with_options(
                mcap::sans_io::SummaryReaderOptions::default().with_file_size(records.len),
            );
            let mut position = 0u64;
            while let Some(event) = reader.next_event() {
                let event = event.map_err(|source| LogError::Record {
                    path: path.clone(),
                    offset: position,
                    source,
                })?;
                match event {
                    mcap::sans_io::SummaryReadEvent::ReadRequest(n) => {
                        let read = records.file.read(reader.insert(n)).map_err(|source| {
                            LogError::Read { path: path.clone(), offset: position, source }
                        })?;
                        position += read as u64;
                        reader.notify_read(read);
                    }
                    mcap::sans_io::SummaryReadEvent::SeekRequest(to) => {
                        position = records.file.seek(to).map_err(|source| LogError::Read {
                            path: path.clone(),
                            offset: position,
                            source,
                        })?;
                        reader.notify_seeked(position);
                    }
                }
            }
            reader.finish()
        };
        let Some(summary) = summary else { return Ok(None) };
        // A summary without chunk indexes or statistics cannot say where messages are.
        let Some(stats) = summary.stats.as_ref() else { return Ok(None) };
        if summary.chunk_indexes.is_empty() && stats.message_count > 0 {
            return Ok(None);
        }
        let mut chunks: Vec<ChunkLocation> = summary
            .chunk_indexes
            .iter()
            .map(|c| ChunkLocation { offset: c.chunk_start_offset, length: c.chunk_length })
            .collect();
        chunks.sort_by_key(|c| c.offset);
        if let Some(last) = chunks.last()
            && last.offset.saturating_add(last.length) > records.len
        {
            return Err(LogError::BadIndex { path, offset: last.offset });
        }
        let mut channels = HashMap::new();
        let mut topics = BTreeMap::new();
        for (id, channel) in &summary.channels {
            let type_name = channel
                .metadata
                .get("type_name")
                .cloned()
                .or_else(|| channel.schema.as_ref().map(|s| s.name.clone()))
                .unwrap_or_default();
            channels.insert(
                *id,
                ChannelInfo::new(
                    &channel.topic,
                    &type_name,
                    &channel.message_encoding,
                    &channel.metadata,
                ),
            );
            let entry = topics.entry(channel.topic.clone()).or_insert_with(|| TopicInfo {
                name: channel.topic.clone(),
                type_name,
                message_encoding: channel.message_encoding.clone(),
                schema_encoding: channel.schema.as_ref().map(|s| s.encoding.clone()),
                messages: 0,
            });
            entry.messages += stats.channel_message_counts.get(id).copied().unwrap_or(0);
        }
        let mut metadata = Vec::new();
        for index in &summary.metadata_indexes {
            let Some((_, body)) = records.record_at(index.offset)? else {
                return Err(LogError::BadIndex { path, offset: index.offset });
            };
            metadata.push(parse_metadata(&path, index.offset, &body)?);
        }
        let mut attachments = Vec::new();
        for index in &summary.attachment_indexes {
            let Some((_, body)) = records.record_at(index.offset)? else {
                return Err(LogError::BadIndex { path, offset: index.offset });
            };
            attachments.push(parse_attachment(&path, index.offset, &body)?);
        }
        let time_range = (stats.message_count > 0).then(|| {
            (Time::from_nanos(stats.message_start_time), Time::from_nanos(stats.message_end_time))
        });
        Ok(Some(LogReader {
            path,
            file_bytes: records.len,
            complete: true,
            recovery: None,
            chunks,
            channels,
            topics: topics.into_values().collect(),
            message_count: stats.message_count,
            time_range,
            metadata,
            attachments,
        }))
    }

    /// Reads the data section record by record until the first incomplete or damaged one.
    fn scan(records: &mut RecordFile, why: &str) -> Result<LogReader, LogError> {
        let path = records.path.clone();
        let mut offset = MAGIC.len() as u64;
        let mut chunks = Vec::new();
        let mut channels: HashMap<u16, ChannelInfo> = HashMap::new();
        let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut counts: HashMap<u16, u64> = HashMap::new();
        let mut metadata = Vec::new();
        let mut attachments = Vec::new();
        let mut message_count = 0u64;
        let mut time_range: Option<(u64, u64)> = None;
        let stopped = loop {
            let record = match records.record_at(offset) {
                Ok(Some(record)) => record,
                Ok(None) if offset == records.len => break "end of file".to_owned(),
                Ok(None) => break format!("incomplete record at byte {offset}"),
                Err(error) => break error.to_string(),
            };
            let (opcode, body) = record;
            let length = RECORD_HEADER + body.len() as u64;
            match opcode {
                op::CHUNK => {
                    let contents = match decode_chunk(&path, offset, &body) {
                        Ok(contents) => contents,
                        Err(error) => break format!("damaged chunk: {error}"),
                    };
                    for (id, info, encoding, schema_encoding) in contents.channels {
                        topics.entry(info.topic.to_string()).or_insert_with(|| TopicInfo {
                            name: info.topic.to_string(),
                            type_name: info.type_name.to_string(),
                            message_encoding: encoding,
                            schema_encoding,
                            messages: 0,
                        });
                        channels.insert(id, info);
                    }
                    for (header, _) in &contents.messages {
                        *counts.entry(header.channel_id).or_default() += 1;
                        let t = header.log_time;
                        time_range = Some(time_range.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
                    }
                    message_count += contents.messages.len() as u64;
                    chunks.push(ChunkLocation { offset, length });
                }
                op::METADATA => match parse_metadata(&path, offset, &body) {
                    Ok(m) => metadata.push(m),
                    Err(error) => break error.to_string(),
                },
                op::ATTACHMENT => match parse_attachment(&path, offset, &body) {
                    Ok(a) => attachments.push(a),
                    Err(error) => break error.to_string(),
                },
                // The data section is whole; what follows (the summary) was cut.
                op::DATA_END => {
                    offset += length;
                    break "end of the data section (the summary after it is incomplete)"
                        .to_owned();
                }
                op::FOOTER => {
                    offset += length;
                    break "footer".to_owned();
                }
                _ => {}
            }
            offset += length;
        };
        for (id, n) in &counts {
            if let Some(info) = channels.get(id)
                && let Some(topic) = topics.get_mut(&*info.topic)
            {
                topic.messages += n;
            }
        }
        Ok(LogReader {
            path,
            file_bytes: records.len,
            complete: false,
            recovery: Some(Recovery {
                valid_bytes: offset,
                file_bytes: records.len,
                chunks: chunks.len(),
                messages: message_count,
                stopped: format!("{why}; read up to byte {offset}: stopped at {stopped}"),
            }),
            chunks,
            channels,
            topics: topics.into_values().collect(),
            message_count,
            time_range: time_range.map(|(a, b)| (Time::from_nanos(a), Time::from_nanos(b))),
            metadata,
            attachments,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the file was finished (summary and footer present and readable).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// For a file that was not finished: how much of it was recovered.
    pub fn recovery(&self) -> Option<&Recovery> {
        self.recovery.as_ref()
    }

    pub fn file_bytes(&self) -> u64 {
        self.file_bytes
    }

    pub fn message_count(&self) -> u64 {
        self.message_count
    }

    pub fn chunk_count(&self) -> usize {
        self.chunks.len()
    }

    /// First and last log time of the messages.
    pub fn time_range(&self) -> Option<(Time, Time)> {
        self.time_range
    }

    /// Topics, by name.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    pub fn metadata(&self) -> &[LoggedMetadata] {
        &self.metadata
    }

    pub fn attachments(&self) -> &[LoggedAttachment] {
        &self.attachments
    }

    fn invalid(&self, what: String) -> LogError {
        LogError::Invalid { path: self.path.clone(), what }
    }

    /// The run's seed, command line, version and configuration text, if stored.
    pub fn run_info(&self) -> Result<Option<RunInfo>, LogError> {
        let Some(run) = self.metadata.iter().find(|m| m.name == RUN_METADATA) else {
            return Ok(None);
        };
        let get = |key: &str| run.entries.get(key);
        let seed = match get("seed") {
            Some(seed) => seed
                .parse()
                .map_err(|e| self.invalid(format!("{RUN_METADATA}: bad seed `{seed}`: {e}")))?,
            None => return Err(self.invalid(format!("{RUN_METADATA} has no seed"))),
        };
        let command_line = match get("command_line") {
            Some(text) => serde_json::from_str(text).map_err(|source| LogError::Json {
                path: self.path.clone(),
                what: "the command line".into(),
                source,
            })?,
            None => Vec::new(),
        };
        let config = match get("config_format").map(String::as_str) {
            None => None,
            Some(ext) => {
                let format = match ext {
                    "toml" => ConfigFormat::Toml,
                    "json" => ConfigFormat::Json,
                    other => {
                        return Err(self.invalid(format!("unknown configuration format `{other}`")));
                    }
                };
                let name = format!("{CONFIG_ATTACHMENT_PREFIX}{ext}");
                let attachment =
                    self.attachments.iter().find(|a| a.name == name).ok_or_else(|| {
                        self.invalid(format!("the configuration attachment `{name}` is missing"))
                    })?;
                let text = String::from_utf8(attachment.data.clone()).map_err(|_| {
                    self.invalid(format!("the configuration attachment `{name}` is not UTF-8"))
                })?;
                Some((format, text))
            }
        };
        Ok(Some(RunInfo {
            seed,
            command_line,
            version: get("version").cloned().unwrap_or_default(),
            config,
        }))
    }

    /// The run's configuration as a JSON value (TOML is converted), if stored.
    pub fn config(&self) -> Result<Option<serde_json::Value>, LogError> {
        let Some(RunInfo { config: Some((format, text)), .. }) = self.run_info()? else {
            return Ok(None);
        };
        match format {
            ConfigFormat::Json => serde_json::from_str(&text).map(Some).map_err(|source| {
                LogError::Json { path: self.path.clone(), what: "the configuration".into(), source }
            }),
            ConfigFormat::Toml => {
                let table: toml::Table = toml::from_str(&text)
                    .map_err(|source| LogError::Toml { path: self.path.clone(), source })?;
                serde_json::to_value(table).map(Some).map_err(|source| LogError::Json {
                    path: self.path.clone(),
                    what: "the configuration".into(),
                    source,
                })
            }
        }
    }

    /// Every graph description stored in the log.
    pub fn graphs(&self) -> Result<Vec<LoggedGraph>, LogError> {
        self.metadata
            .iter()
            .filter(|m| m.name == GRAPH_METADATA)
            .map(|m| {
                let text = m
                    .entries
                    .get("graph")
                    .ok_or_else(|| self.invalid(format!("{GRAPH_METADATA} has no graph")))?;
                let description = serde_json::from_str(text).map_err(|source| LogError::Json {
                    path: self.path.clone(),
                    what: "a graph description".into(),
                    source,
                })?;
                Ok(LoggedGraph {
                    scope: m.entries.get("scope").cloned().unwrap_or_default(),
                    description,
                })
            })
            .collect()
    }

    /// The writer's statistics, present when the log was finished.
    pub fn stats(&self) -> Option<LoggedStats> {
        let m = self.metadata.iter().rev().find(|m| m.name == STATS_METADATA)?;
        let number = |key: &str| m.entries.get(key).and_then(|v| v.parse().ok()).unwrap_or(0);
        Some(LoggedStats {
            messages: number("messages"),
            dropped: number("dropped"),
            serialize_errors: number("serialize_errors"),
            dropped_by_topic: m
                .entries
                .get("dropped_by_topic")
                .and_then(|v| serde_json::from_str(v).ok())
                .unwrap_or_default(),
        })
    }

    /// Every message, in file order.
    pub fn messages(&self) -> Messages<'_> {
        Messages::new(self, None)
    }

    /// The messages of the given topics, in file order.
    pub fn messages_on<'t>(&self, topics: impl IntoIterator<Item = &'t str>) -> Messages<'_> {
        let wanted: Vec<&str> = topics.into_iter().collect();
        let ids =
            self.channels.iter().filter(|(_, c)| wanted.contains(&&*c.topic)).map(|(id, _)| *id);
        Messages::new(self, Some(ids.collect()))
    }
}

/// Iterates over a log's messages, decompressing one chunk at a time.
pub struct Messages<'a> {
    reader: &'a LogReader,
    file: Option<RecordFile>,
    next_chunk: usize,
    channels: Option<Vec<u16>>,
    /// Per channel, the last full sequence number: MCAP stores 32 bits.
    last_seq: HashMap<u16, u64>,
    /// Channels first defined inside chunks (files read by scanning, or foreign files).
    chunk_channels: HashMap<u16, ChannelInfo>,
    pending: VecDeque<LogMessage>,
    failed: bool,
}

impl std::fmt::Debug for Messages<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Messages")
            .field("path", &self.reader.path)
            .field("next_chunk", &self.next_chunk)
            .finish()
    }
}

impl<'a> Messages<'a> {
    fn new(reader: &'a LogReader, channels: Option<Vec<u16>>) -> Messages<'a> {
        Messages {
            reader,
            file: None,
            next_chunk: 0,
            channels,
            last_seq: HashMap::new(),
            chunk_channels: HashMap::new(),
            pending: VecDeque::new(),
            failed: false,
        }
    }

    fn unwrap_seq(&mut self, channel: u16, sequence: u32) -> u64 {
        let seq = match self.last_seq.get(&channel) {
            None => u64::from(sequence),
            Some(&last) => {
                let candidate = (last & !0xFFFF_FFFF) | u64::from(sequence);
                if candidate < last && last - candidate > 0x8000_0000 {
                    candidate + (1 << 32)
                } else {
                    candidate
                }
            }
        };
        self.last_seq.insert(channel, seq);
        seq
    }

    fn load_chunk(&mut self) -> Result<bool, LogError> {
        let Some(location) = self.reader.chunks.get(self.next_chunk).copied() else {
            return Ok(false);
        };
        self.next_chunk += 1;
        let path = &self.reader.path;
        if self.file.is_none() {
            let file =
                File::open(path).map_err(|source| LogError::Open { path: path.clone(), source })?;
            self.file = Some(RecordFile { path: path.clone(), file, len: self.reader.file_bytes });
        }
        let Some(file) = self.file.as_mut() else { return Ok(false) };
        let Some((_, body)) = file.record_at(location.offset)? else {
            return Err(LogError::BadIndex { path: path.clone(), offset: location.offset });
        };
        let contents = decode_chunk(path, location.offset, &body)?;
        for (id, info, _, _) in contents.channels {
            self.chunk_channels.insert(id, info);
        }
        for (header, data) in contents.messages {
            let wanted = self.channels.as_ref().is_none_or(|c| c.contains(&header.channel_id));
            let info = self
                .reader
                .channels
                .get(&header.channel_id)
                .or_else(|| self.chunk_channels.get(&header.channel_id));
            // Records of shared values are registered as they pass, wanted or not: the
            // packages after them refer to them.
            if let Some(info) = info
                && info.shared
                && let Some(encoding) = info.encoding
                && let Some(id) = record_id(encoding, &data)
            {
                shared::register(id, encoding, &data);
            }
            if !wanted {
                continue;
            }
            let info = info.cloned().ok_or_else(|| LogError::Invalid {
                path: path.clone(),
                what: format!(
                    "chunk at byte {} has a message on unknown channel {}",
                    location.offset, header.channel_id
                ),
            })?;
            let seq = self.unwrap_seq(header.channel_id, header.sequence);
            let Some(encoding) = info.encoding else {
                return Err(LogError::Invalid {
                    path: path.clone(),
                    what: format!(
                        "topic `{}` is encoded as `{}`: Strata reads cdr, json and msgpack",
                        info.topic, info.encoding_name
                    ),
                });
            };
            let data = if info.wrapped {
                match unwrap_value(encoding, &data) {
                    Some(value) => value.to_vec(),
                    None => {
                        return Err(LogError::Invalid {
                            path: path.clone(),
                            what: format!(
                                "message {seq} of `{}` in the chunk at byte {} is not wrapped as its channel says",
                                info.topic, location.offset
                            ),
                        });
                    }
                }
            } else {
                data
            };
            self.pending.push_back(LogMessage {
                topic: info.topic,
                type_name: info.type_name,
                log_time: Time::from_nanos(header.log_time),
                stamp: Time::from_nanos(header.publish_time),
                seq,
                encoding,
                data,
                format: info.format,
            });
        }
        Ok(true)
    }
}

impl Iterator for Messages<'_> {
    type Item = Result<LogMessage, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(message) = self.pending.pop_front() {
                return Some(Ok(message));
            }
            if self.failed {
                return None;
            }
            match self.load_chunk() {
                Ok(true) => {}
                Ok(false) => return None,
                Err(error) => {
                    self.failed = true;
                    return Some(Err(error));
                }
            }
        }
    }
}
