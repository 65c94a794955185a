//! Opening a log: a complete file through its summary, one cut short by scanning its records
//! up to the first incomplete one, passing over damaged chunks.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek};
use std::path::Path;

use mcap::records::op;
use strata_runtime::Time;

use crate::error::LogError;

use super::records::ChunkContents;
use super::resync::{self, Resumed};
use super::{
    ChannelInfo, ChunkLocation, LogReader, LoggedAttachment, LoggedMetadata, MAGIC, RECORD_HEADER,
    RecordFile, Recovery, TopicInfo, check_chunk_records, decode_chunk, parse_attachment,
    parse_metadata,
};

impl LogReader {
    /// Opens a log. A complete file is read through its summary; a file cut short is scanned
    /// up to its last complete chunk, passing over damaged ones ([`LogReader::recovery`] says
    /// how much was kept and skipped). Only a file that is not MCAP at all, or cannot be read,
    /// is an error.
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
    /// file then scanned like one without a summary). So is a summary record that does not end
    /// before the footer: the streaming reader would take a chunk's records from whatever
    /// follows it in the file, unchecked.
    fn check_summary_chunks(records: &mut RecordFile) -> Result<(), LogError> {
        // The footer record: opcode, length, summary_start, summary_offset_start, summary_crc.
        const FOOTER_BODY: u64 = 8 + 8 + 4;
        let Some(footer) =
            records.len.checked_sub(MAGIC.len() as u64 + RECORD_HEADER + FOOTER_BODY)
        else {
            return Ok(());
        };
        // Read as mcap reads it: a fixed-size body whatever its length field says (a footer
        // whose length field is wrong still points mcap at a summary).
        let mut head = [0u8; (RECORD_HEADER + 8) as usize];
        records.read_exact_at(footer, &mut head)?;
        if head[0] != op::FOOTER {
            return Ok(());
        }
        let mut start = [0u8; 8];
        start.copy_from_slice(&head[RECORD_HEADER as usize..]);
        let start = u64::from_le_bytes(start);
        let mut offset = start;
        while offset != 0 && offset < footer {
            let record = records.record_at(offset)?.filter(|(_, body)| {
                offset.saturating_add(RECORD_HEADER + body.len() as u64) <= footer
            });
            let Some((opcode, body)) = record else {
                return Err(LogError::Invalid {
                    path: records.path.clone(),
                    what: format!("the summary record at byte {offset} runs past the footer"),
                });
            };
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

    /// Reads the data section record by record up to its end or its first incomplete record,
    /// passing over damaged chunks.
    fn scan(records: &mut RecordFile, why: &str) -> Result<LogReader, LogError> {
        let mut scan = Scan::default();
        let mut offset = MAGIC.len() as u64;
        let stopped = loop {
            let (damage, next) = match records.record_at(offset) {
                Ok(Some((opcode, body))) => {
                    let next = offset + RECORD_HEADER + body.len() as u64;
                    match scan.record(&records.path, offset, opcode, &body) {
                        Step::On => (None, next),
                        Step::End(end) => {
                            offset = next;
                            break end.to_owned();
                        }
                        Step::Damaged(what) => (Some((what, opcode == op::CHUNK)), next),
                    }
                }
                Ok(None) if offset == records.len => break "end of file".to_owned(),
                Ok(None) => {
                    // A chunk cut short, or one whose length was damaged.
                    let mut opcode = [0u8];
                    let chunk = records.read_exact_at(offset, &mut opcode).is_ok()
                        && opcode[0] == op::CHUNK;
                    (Some((format!("incomplete record at byte {offset}"), chunk)), offset)
                }
                Err(error) => break error.to_string(),
            };
            let Some((what, chunk)) = damage else {
                offset = next;
                continue;
            };
            match resync::next_good_chunk(records, offset + 1) {
                Ok(Resumed { at: Some(at), damaged_chunks }) => {
                    scan.skipped(offset, at, usize::from(chunk) + damaged_chunks, what);
                    offset = at;
                }
                Ok(Resumed { at: None, .. }) => break what,
                Err(error) => break format!("{what}; looking for a chunk after it: {error}"),
            }
        };
        Ok(scan.into_reader(records, why, offset, &stopped))
    }
}

/// What a scanned record means for the scan.
enum Step {
    On,
    /// The data section ends here.
    End(&'static str),
    /// The record is damaged: the scan goes on at the next good chunk, if any.
    Damaged(String),
}

/// What the scan of a file without a usable summary found.
#[derive(Default)]
struct Scan {
    chunks: Vec<ChunkLocation>,
    channels: HashMap<u16, ChannelInfo>,
    topics: BTreeMap<String, TopicInfo>,
    counts: HashMap<u16, u64>,
    metadata: Vec<LoggedMetadata>,
    attachments: Vec<LoggedAttachment>,
    message_count: u64,
    time_range: Option<(u64, u64)>,
    skipped_chunks: usize,
    skipped_bytes: u64,
    /// Where the first damage was, and what it was.
    first_damage: Option<(u64, String)>,
}

impl Scan {
    fn record(&mut self, path: &Path, offset: u64, opcode: u8, body: &[u8]) -> Step {
        match opcode {
            op::CHUNK => match decode_chunk(path, offset, body) {
                Ok(contents) => {
                    let length = RECORD_HEADER + body.len() as u64;
                    self.chunk(ChunkLocation { offset, length }, contents);
                    Step::On
                }
                Err(error) => Step::Damaged(format!("damaged chunk: {error}")),
            },
            op::METADATA => match parse_metadata(path, offset, body) {
                Ok(m) => {
                    self.metadata.push(m);
                    Step::On
                }
                Err(error) => Step::Damaged(error.to_string()),
            },
            op::ATTACHMENT => match parse_attachment(path, offset, body) {
                Ok(a) => {
                    self.attachments.push(a);
                    Step::On
                }
                Err(error) => Step::Damaged(error.to_string()),
            },
            op::MESSAGE_INDEX if !resync::message_index_fits(body) => {
                Step::Damaged(format!("damaged message index at byte {offset}"))
            }
            // The data section is whole; what follows (the summary) was cut.
            op::DATA_END => {
                Step::End("end of the data section (the summary after it is incomplete)")
            }
            op::FOOTER => Step::End("footer"),
            // Opcodes MCAP reserves and no writer uses: not a record boundary.
            0x00 | 0x10..=0x7f => {
                Step::Damaged(format!("no record at byte {offset} (opcode {opcode:#04x})"))
            }
            // Other records (and private ones, 0x80 and up) are skipped, as MCAP says.
            _ => Step::On,
        }
    }

    fn chunk(&mut self, location: ChunkLocation, contents: ChunkContents) {
        for (id, info, encoding, schema_encoding) in contents.channels {
            self.topics.entry(info.topic.to_string()).or_insert_with(|| TopicInfo {
                name: info.topic.to_string(),
                type_name: info.type_name.to_string(),
                message_encoding: encoding,
                schema_encoding,
                messages: 0,
            });
            self.channels.insert(id, info);
        }
        for (header, _) in &contents.messages {
            *self.counts.entry(header.channel_id).or_default() += 1;
            let t = header.log_time;
            self.time_range = Some(self.time_range.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
        }
        self.message_count += contents.messages.len() as u64;
        self.chunks.push(location);
    }

    /// The damaged stretch from `from` to `to` (the next good chunk) was passed over.
    fn skipped(&mut self, from: u64, to: u64, chunks: usize, what: String) {
        self.skipped_chunks += chunks;
        self.skipped_bytes += to - from;
        self.first_damage.get_or_insert((from, what));
    }

    fn into_reader(self, records: &RecordFile, why: &str, offset: u64, stopped: &str) -> LogReader {
        let Scan { chunks, channels, mut topics, counts, metadata, attachments, .. } = self;
        for (id, n) in &counts {
            if let Some(info) = channels.get(id)
                && let Some(topic) = topics.get_mut(&*info.topic)
            {
                topic.messages += n;
            }
        }
        let mut stopped = format!("{why}; read up to byte {offset}: stopped at {stopped}");
        if let Some((at, what)) = &self.first_damage {
            stopped.push_str(&format!(
                "; skipped {} damaged chunks ({} bytes), the first at byte {at}: {what}",
                self.skipped_chunks, self.skipped_bytes
            ));
        }
        LogReader {
            path: records.path.clone(),
            file_bytes: records.len,
            complete: false,
            recovery: Some(Recovery {
                valid_bytes: offset,
                file_bytes: records.len,
                chunks: chunks.len(),
                messages: self.message_count,
                skipped_chunks: self.skipped_chunks,
                skipped_bytes: self.skipped_bytes,
                stopped,
            }),
            chunks,
            channels,
            topics: topics.into_values().collect(),
            message_count: self.message_count,
            time_range: self.time_range.map(|(a, b)| (Time::from_nanos(a), Time::from_nanos(b))),
            metadata,
            attachments,
        }
    }
}
