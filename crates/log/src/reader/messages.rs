//! [`Messages`]: a log's messages read back, one chunk at a time, and the channels they are on.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::sync::Arc;

use strata_runtime::cdr::Format;
use strata_runtime::shared;
use strata_runtime::{Encoding, Time};

use crate::error::LogError;
use crate::writer::wrap_frame;
use crate::{FORMAT_KEY, SHARED_KEY, WRAP_FIELD, WRAPPED_KEY};

use super::{LogMessage, LogReader, RecordFile, decode_chunk};

#[derive(Clone, Debug)]
pub(super) struct ChannelInfo {
    pub(super) topic: Arc<str>,
    pub(super) type_name: Arc<str>,
    /// Values are stored as `{"value": ...}`.
    pub(super) wrapped: bool,
    /// `None`: an encoding Strata does not read (its messages are an error when read).
    pub(super) encoding: Option<Encoding>,
    /// The channel's `message_encoding`, for the error.
    pub(super) encoding_name: Arc<str>,
    /// The values' format (CDR channels written by Strata).
    pub(super) format: Option<Arc<Format>>,
    /// The channel holds shared values' records, which readers register as they pass.
    pub(super) shared: bool,
}

impl ChannelInfo {
    pub(super) fn new(
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
    pub(super) fn new(reader: &'a LogReader, channels: Option<Vec<u16>>) -> Messages<'a> {
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
