//! Opening a log: a complete file through its summary, one cut short by scanning its records
//! up to the first incomplete or damaged one.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek};
use std::path::Path;

use mcap::records::op;
use strata_runtime::Time;

use crate::error::LogError;

use super::{
    ChannelInfo, ChunkLocation, LogReader, MAGIC, RECORD_HEADER, RecordFile, Recovery, TopicInfo,
    check_chunk_records, decode_chunk, parse_attachment, parse_metadata,
};

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

    /// mcap's summary reader reads whatever records the footer points at, chunks included, with
    /// the streaming reader that trusts an uncompressed chunk's records to fit
    /// ([`check_chunk_records`]); a footer pointing at such a chunk is refused here (and the
    /// file then scanned like one without a summary).
    fn check_summary_chunks(records: &mut RecordFile) -> Result<(), LogError> {
        // The footer record: opcode, length, summary_start, summary_offset_start, summary_crc.
        const FOOTER_BODY: u64 = 8 + 8 + 4;
        let Some(footer) =
            records.len.checked_sub(MAGIC.len() as u64 + RECORD_HEADER + FOOTER_BODY)
        else {
            return Ok(());
        };
        let Some((op::FOOTER, body)) = records.record_at(footer)? else { return Ok(()) };
        let Some(start) = body.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes)
        else {
            return Ok(());
        };
        let mut offset = start;
        while offset != 0 && offset < footer {
            let Some((opcode, body)) = records.record_at(offset)? else { return Ok(()) };
            if opcode == op::CHUNK {
                check_chunk_records(&body).map_err(|what| LogError::Invalid {
                    path: records.path.clone(),
                    what: format!("chunk in the summary at byte {offset}: {what}"),
                })?;
            }
            offset = offset.saturating_add(RECORD_HEADER + body.len() as u64);
        }
        Ok(())
    }

    /// The summary of a complete file, `None` if it has no footer.
    fn read_summary(records: &mut RecordFile) -> Result<Option<LogReader>, LogError> {
        let path = records.path.clone();
        Self::check_summary_chunks(records)?;
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
}
