//! Writing an MCAP file: records, chunks and the summary, as the MCAP specification lays them
//! out (<https://mcap.dev/spec>). Reading stays with the `mcap` crate.
//!
//! Why not the `mcap` crate's writer: it serializes each message through a fresh buffer and
//! hands it to the compressor in several small writes, about 0.4 µs per message, measured on
//! a match log, as much as a match's own work per package at ten thousand packages per
//! simulated second. Here a message is appended to the open chunk's buffer (its header, its
//! bytes and an index entry); the chunk is compressed in one call when it closes, at any
//! zstd level including the fast negative ones, or with LZ4.
//!
//! Schemas and channels go into the chunk open when they are added (before their first
//! message), so a file cut short still holds, in its complete chunks, everything needed to
//! read them; the summary repeats them with the chunk, metadata and attachment indexes and
//! the statistics.

use std::collections::BTreeMap;
use std::io::{self, Write};

/// MCAP's magic bytes, at both ends of a file.
pub(crate) const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const ATTACHMENT: u8 = 0x09;
    pub const ATTACHMENT_INDEX: u8 = 0x0A;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// How chunks are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ChunkCompression {
    None,
    /// zstd at this level (negative levels trade ratio for speed).
    Zstd(i32),
    Lz4,
}

impl ChunkCompression {
    fn name(self) -> &'static str {
        match self {
            ChunkCompression::None => "",
            ChunkCompression::Zstd(_) => "zstd",
            ChunkCompression::Lz4 => "lz4",
        }
    }
}

/// Little-endian record fields, appended to a buffer.
trait Put {
    fn u8(&mut self, v: u8);
    fn u16(&mut self, v: u16);
    fn u32(&mut self, v: u32);
    fn u64(&mut self, v: u64);
    fn string(&mut self, s: &str);
    /// A record's opcode and a place for its length, filled in by [`Put::end_record`].
    fn begin_record(&mut self, op: u8) -> usize;
    fn end_record(&mut self, at: usize);
    /// A `u32` byte length before a map or array, filled in by [`Put::end_prefix`].
    fn begin_prefix(&mut self) -> usize;
    fn end_prefix(&mut self, at: usize);
}

impl Put for Vec<u8> {
    fn u8(&mut self, v: u8) {
        self.push(v);
    }

    fn u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }

    fn u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }

    fn u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.extend_from_slice(s.as_bytes());
    }

    fn begin_record(&mut self, op: u8) -> usize {
        self.push(op);
        let at = self.len();
        self.u64(0);
        at
    }

    fn end_record(&mut self, at: usize) {
        let len = (self.len() - at - 8) as u64;
        self[at..at + 8].copy_from_slice(&len.to_le_bytes());
    }

    fn begin_prefix(&mut self) -> usize {
        let at = self.len();
        self.u32(0);
        at
    }

    fn end_prefix(&mut self, at: usize) {
        let len = (self.len() - at - 4) as u32;
        self[at..at + 4].copy_from_slice(&len.to_le_bytes());
    }
}

fn string_map(out: &mut Vec<u8>, map: &BTreeMap<String, String>) {
    let at = out.begin_prefix();
    for (key, value) in map {
        out.string(key);
        out.string(value);
    }
    out.end_prefix(at);
}

/// The bytes written so far: their count and CRC (the data section's and the summary's).
struct Counted<W> {
    inner: W,
    position: u64,
    crc: crc32fast::Hasher,
}

impl<W: Write> Counted<W> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.inner.write_all(bytes)?;
        self.crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// The CRC so far, starting a new one.
    fn take_crc(&mut self) -> u32 {
        std::mem::take(&mut self.crc).finalize()
    }
}

struct ChunkIndex {
    start: u64,
    end: u64,
    offset: u64,
    length: u64,
    message_index_offsets: Vec<(u16, u64)>,
    message_index_length: u64,
    compression: &'static str,
    compressed_size: u64,
    uncompressed_size: u64,
}

/// The open chunk: its records uncompressed, its time span and its message index.
#[derive(Default)]
struct OpenChunk {
    records: Vec<u8>,
    times: Option<(u64, u64)>,
    /// Per channel id: (log time, offset in `records`) of each of its messages.
    index: Vec<Vec<(u64, u64)>>,
    /// Channels with messages in this chunk, in the order they first appeared.
    channels: Vec<u16>,
}

/// An MCAP file being written.
pub(crate) struct McapFile<W: Write> {
    out: Counted<W>,
    compression: ChunkCompression,
    /// A chunk is closed once its records reach this many bytes.
    chunk_size: usize,
    chunk: OpenChunk,
    compressor: Option<zstd::bulk::Compressor<'static>>,
    /// Where compressed chunks are made and records outside chunks assembled.
    scratch: Vec<u8>,
    // The summary.
    schemas: Vec<Vec<u8>>,
    channels: Vec<Vec<u8>>,
    chunk_indexes: Vec<ChunkIndex>,
    attachment_indexes: Vec<Vec<u8>>,
    metadata_indexes: Vec<Vec<u8>>,
    message_count: u64,
    channel_counts: Vec<u64>,
    times: Option<(u64, u64)>,
}

impl<W: Write> McapFile<W> {
    /// Writes the magic and the header record.
    pub(crate) fn new(
        inner: W,
        profile: &str,
        library: &str,
        compression: ChunkCompression,
        chunk_size: usize,
    ) -> io::Result<McapFile<W>> {
        let compressor = match compression {
            ChunkCompression::Zstd(level) => Some(zstd::bulk::Compressor::new(level)?),
            _ => None,
        };
        let mut file = McapFile {
            out: Counted { inner, position: 0, crc: crc32fast::Hasher::new() },
            compression,
            chunk_size,
            chunk: OpenChunk::default(),
            compressor,
            scratch: Vec::new(),
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk_indexes: Vec::new(),
            attachment_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            message_count: 0,
            channel_counts: Vec::new(),
            times: None,
        };
        file.out.write(MAGIC)?;
        let mut record = Vec::new();
        let at = record.begin_record(op::HEADER);
        record.string(profile);
        record.string(library);
        record.end_record(at);
        file.out.write(&record)?;
        Ok(file)
    }

    /// Adds a schema; its record goes into the open chunk (and the summary).
    pub(crate) fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> u16 {
        let id = self.schemas.len() as u16 + 1;
        let mut record = Vec::new();
        let at = record.begin_record(op::SCHEMA);
        record.u16(id);
        record.string(name);
        record.string(encoding);
        record.u32(data.len() as u32);
        record.extend_from_slice(data);
        record.end_record(at);
        self.chunk.records.extend_from_slice(&record);
        self.schemas.push(record);
        id
    }

    /// Adds a channel; its record goes into the open chunk (and the summary).
    pub(crate) fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> u16 {
        let id = self.channels.len() as u16;
        let mut record = Vec::new();
        let at = record.begin_record(op::CHANNEL);
        record.u16(id);
        record.u16(schema_id);
        record.string(topic);
        record.string(message_encoding);
        string_map(&mut record, metadata);
        record.end_record(at);
        self.chunk.records.extend_from_slice(&record);
        self.channels.push(record);
        self.channel_counts.push(0);
        id
    }

    /// Appends a message to the open chunk. The caller closes the chunk once it is
    /// [full](McapFile::chunk_full): closing a chunk is where it flushes, syncs and may start a
    /// new file.
    pub(crate) fn write_message(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) {
        let chunk = &mut self.chunk;
        let offset = chunk.records.len() as u64;
        let records = &mut chunk.records;
        records.push(op::MESSAGE);
        records.u64(2 + 4 + 8 + 8 + data.len() as u64);
        records.u16(channel);
        records.u32(sequence);
        records.u64(log_time);
        records.u64(publish_time);
        records.extend_from_slice(data);
        let c = usize::from(channel);
        if chunk.index.len() <= c {
            chunk.index.resize_with(c + 1, Vec::new);
        }
        if chunk.index[c].is_empty() {
            chunk.channels.push(channel);
        }
        chunk.index[c].push((log_time, offset));
        chunk.times = Some(
            chunk.times.map_or((log_time, log_time), |(a, b)| (a.min(log_time), b.max(log_time))),
        );
        self.message_count += 1;
        if let Some(count) = self.channel_counts.get_mut(c) {
            *count += 1;
        }
    }

    /// Whether the open chunk's records have reached the chunk size.
    pub(crate) fn chunk_full(&self) -> bool {
        self.chunk.records.len() >= self.chunk_size
    }

    /// Bytes written so far (the open chunk not included).
    pub(crate) fn position(&self) -> u64 {
        self.out.position
    }

    /// The underlying writer.
    pub(crate) fn get_ref(&self) -> &W {
        &self.out.inner
    }

    /// Compresses and writes the open chunk and its message indexes; `false`: the chunk was
    /// empty, nothing was written.
    pub(crate) fn close_chunk(&mut self) -> io::Result<bool> {
        if self.chunk.records.is_empty() {
            return Ok(false);
        }
        let chunk = std::mem::take(&mut self.chunk);
        let uncompressed_crc = crc32fast::hash(&chunk.records);
        let compressed: &[u8] = match self.compression {
            ChunkCompression::None => &chunk.records,
            ChunkCompression::Zstd(_) => {
                let bound = zstd::zstd_safe::compress_bound(chunk.records.len());
                self.scratch.clear();
                self.scratch.reserve(bound);
                if let Some(compressor) = self.compressor.as_mut() {
                    compressor.compress_to_buffer(&chunk.records, &mut self.scratch)?;
                }
                &self.scratch
            }
            ChunkCompression::Lz4 => {
                self.scratch.clear();
                // One independent block per chunk and no content checksum (the chunk record
                // has its CRC): with the frame defaults (linked 64 KiB blocks, a checksum of
                // the content) lz4 cost the writer more than zstd at level -1 and slowed a
                // logged match to 155x against 200x (docs/performance.md).
                let mut encoder = lz4::EncoderBuilder::new()
                    .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
                    .checksum(lz4::liblz4::ContentChecksum::NoChecksum)
                    .block_size(lz4::liblz4::BlockSize::Max4MB)
                    .block_mode(lz4::liblz4::BlockMode::Independent)
                    .build(std::mem::take(&mut self.scratch))?;
                encoder.write_all(&chunk.records)?;
                let (buffer, result) = encoder.finish();
                result?;
                self.scratch = buffer;
                &self.scratch
            }
        };
        let (start, end) = chunk.times.unwrap_or((0, 0));
        let compression = self.compression.name();
        let mut header = Vec::with_capacity(64);
        header.push(op::CHUNK);
        let body = 8 + 8 + 8 + 4 + 4 + compression.len() + 8 + compressed.len();
        header.u64(body as u64);
        header.u64(start);
        header.u64(end);
        header.u64(chunk.records.len() as u64);
        header.u32(uncompressed_crc);
        header.string(compression);
        header.u64(compressed.len() as u64);
        let offset = self.out.position;
        self.out.write(&header)?;
        self.out.write(compressed)?;
        let length = self.out.position - offset;
        let compressed_size = compressed.len() as u64;
        // Message indexes, one record per channel.
        let mut indexes = Vec::new();
        let mut message_index_offsets = Vec::with_capacity(chunk.channels.len());
        let index_start = self.out.position;
        for &channel in &chunk.channels {
            message_index_offsets.push((channel, index_start + indexes.len() as u64));
            let at = indexes.begin_record(op::MESSAGE_INDEX);
            indexes.u16(channel);
            let entries = &chunk.index[usize::from(channel)];
            indexes.u32((entries.len() * 16) as u32);
            for (time, offset) in entries {
                indexes.u64(*time);
                indexes.u64(*offset);
            }
            indexes.end_record(at);
        }
        self.out.write(&indexes)?;
        self.chunk_indexes.push(ChunkIndex {
            start,
            end,
            offset,
            length,
            message_index_offsets,
            message_index_length: indexes.len() as u64,
            compression,
            compressed_size,
            uncompressed_size: chunk.records.len() as u64,
        });
        self.times = Some(self.times.map_or((start, end), |(a, b)| (a.min(start), b.max(end))));
        // The buffers of this chunk serve the next one.
        let OpenChunk { mut records, mut index, .. } = chunk;
        records.clear();
        index.iter_mut().for_each(Vec::clear);
        self.chunk.records = records;
        self.chunk.index = index;
        Ok(true)
    }

    /// Writes a metadata record (closing the open chunk first, to keep the file in order).
    pub(crate) fn write_metadata(
        &mut self,
        name: &str,
        entries: &BTreeMap<String, String>,
    ) -> io::Result<()> {
        self.close_chunk()?;
        let mut record = Vec::new();
        let at = record.begin_record(op::METADATA);
        record.string(name);
        string_map(&mut record, entries);
        record.end_record(at);
        let offset = self.out.position;
        self.out.write(&record)?;
        let mut index = Vec::new();
        let at = index.begin_record(op::METADATA_INDEX);
        index.u64(offset);
        index.u64(record.len() as u64);
        index.string(name);
        index.end_record(at);
        self.metadata_indexes.push(index);
        Ok(())
    }

    /// Writes an attachment record (closing the open chunk first).
    pub(crate) fn write_attachment(
        &mut self,
        log_time: u64,
        create_time: u64,
        name: &str,
        media_type: &str,
        data: &[u8],
    ) -> io::Result<()> {
        self.close_chunk()?;
        let mut record = Vec::new();
        let at = record.begin_record(op::ATTACHMENT);
        record.u64(log_time);
        record.u64(create_time);
        record.string(name);
        record.string(media_type);
        record.u64(data.len() as u64);
        record.extend_from_slice(data);
        // The CRC covers the fields before it.
        let crc = crc32fast::hash(&record[at + 8..]);
        record.u32(crc);
        record.end_record(at);
        let offset = self.out.position;
        self.out.write(&record)?;
        let mut index = Vec::new();
        let at = index.begin_record(op::ATTACHMENT_INDEX);
        index.u64(offset);
        index.u64(record.len() as u64);
        index.u64(log_time);
        index.u64(create_time);
        index.u64(data.len() as u64);
        index.string(name);
        index.string(media_type);
        index.end_record(at);
        self.attachment_indexes.push(index);
        Ok(())
    }

    /// Flushes what was written to the underlying writer.
    pub(crate) fn flush(&mut self) -> io::Result<()> {
        self.out.inner.flush()
    }

    /// Closes the open chunk, writes the data end, the summary and the footer; returns the
    /// underlying writer.
    pub(crate) fn finish(mut self) -> io::Result<W> {
        self.close_chunk()?;
        // The data section's CRC covers everything before the data end record; the summary's
        // starts after it.
        let data_crc = self.out.take_crc();
        let mut record = Vec::new();
        let at = record.begin_record(op::DATA_END);
        record.u32(data_crc);
        record.end_record(at);
        self.out.write(&record)?;
        self.out.take_crc();
        let summary_start = self.out.position;
        let mut groups: Vec<(u8, u64, u64)> = Vec::new();
        let mut group = |file: &mut McapFile<W>, op: u8, records: &[Vec<u8>]| -> io::Result<()> {
            if records.is_empty() {
                return Ok(());
            }
            let start = file.out.position;
            for record in records {
                file.out.write(record)?;
            }
            groups.push((op, start, file.out.position - start));
            Ok(())
        };
        let schemas = std::mem::take(&mut self.schemas);
        group(&mut self, op::SCHEMA, &schemas)?;
        let channels = std::mem::take(&mut self.channels);
        group(&mut self, op::CHANNEL, &channels)?;
        let statistics = self.statistics(schemas.len(), channels.len());
        group(&mut self, op::STATISTICS, &[statistics])?;
        let chunk_indexes: Vec<Vec<u8>> = self.chunk_indexes.iter().map(chunk_index).collect();
        group(&mut self, op::CHUNK_INDEX, &chunk_indexes)?;
        let attachments = std::mem::take(&mut self.attachment_indexes);
        group(&mut self, op::ATTACHMENT_INDEX, &attachments)?;
        let metadata = std::mem::take(&mut self.metadata_indexes);
        group(&mut self, op::METADATA_INDEX, &metadata)?;
        let summary_offset_start = self.out.position;
        let mut offsets = Vec::new();
        for (op_code, start, length) in groups {
            let at = offsets.begin_record(op::SUMMARY_OFFSET);
            offsets.u8(op_code);
            offsets.u64(start);
            offsets.u64(length);
            offsets.end_record(at);
        }
        self.out.write(&offsets)?;
        // The footer's CRC covers the summary and the footer up to the CRC itself.
        let mut footer = Vec::new();
        footer.u8(op::FOOTER);
        footer.u64(8 + 8 + 4);
        footer.u64(summary_start);
        footer.u64(summary_offset_start);
        self.out.write(&footer)?;
        let summary_crc = self.out.take_crc();
        self.out.write(&summary_crc.to_le_bytes())?;
        self.out.write(MAGIC)?;
        self.out.inner.flush()?;
        Ok(self.out.inner)
    }

    fn statistics(&self, schemas: usize, channels: usize) -> Vec<u8> {
        let mut record = Vec::new();
        let at = record.begin_record(op::STATISTICS);
        record.u64(self.message_count);
        record.u16(schemas as u16);
        record.u32(channels as u32);
        record.u32(self.attachment_indexes.len() as u32);
        record.u32(self.metadata_indexes.len() as u32);
        record.u32(self.chunk_indexes.len() as u32);
        let (start, end) = self.times.unwrap_or((0, 0));
        record.u64(start);
        record.u64(end);
        let map = record.begin_prefix();
        for (id, count) in self.channel_counts.iter().enumerate() {
            record.u16(id as u16);
            record.u64(*count);
        }
        record.end_prefix(map);
        record.end_record(at);
        record
    }
}

fn chunk_index(index: &ChunkIndex) -> Vec<u8> {
    let mut record = Vec::new();
    let at = record.begin_record(op::CHUNK_INDEX);
    record.u64(index.start);
    record.u64(index.end);
    record.u64(index.offset);
    record.u64(index.length);
    let map = record.begin_prefix();
    for (channel, offset) in &index.message_index_offsets {
        record.u16(*channel);
        record.u64(*offset);
    }
    record.end_prefix(map);
    record.u64(index.message_index_length);
    record.string(index.compression);
    record.u64(index.compressed_size);
    record.u64(index.uncompressed_size);
    record.end_record(at);
    record
}
