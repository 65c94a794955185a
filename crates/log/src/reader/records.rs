//! The records of an MCAP file as the reader meets them: read by offset, chunks decompressed
//! and checked, metadata and attachments parsed.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::{Record, op};

use crate::error::LogError;

use super::{ChannelInfo, LoggedAttachment, LoggedMetadata};

pub(super) const MAGIC: &[u8] = mcap::MAGIC;
/// Opcode (1) and length (8) in front of every record.
pub(super) const RECORD_HEADER: u64 = 9;

/// Reads records by offset from an open file, with errors that name the file and offset.
pub(super) struct RecordFile {
    pub(super) path: PathBuf,
    pub(super) file: File,
    pub(super) len: u64,
}

impl RecordFile {
    pub(super) fn read_exact_at(&mut self, offset: u64, buf: &mut [u8]) -> Result<(), LogError> {
        let path = &self.path;
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(buf))
            .map_err(|source| LogError::Read { path: path.clone(), offset, source })
    }

    /// The opcode and body of the record at `offset`, if it lies wholly inside the file.
    pub(super) fn record_at(&mut self, offset: u64) -> Result<Option<(u8, Vec<u8>)>, LogError> {
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

/// Refuses an uncompressed chunk whose records overrun it. mcap 0.26's streaming reader takes
/// each record of an uncompressed chunk off the chunk's remaining length without checking that
/// the record fits (`sans_io/linear_reader.rs`): with overflow checks on (debug builds, the fuzz
/// targets) that panics, without them the length wraps and the reader runs on past the chunk.
/// `body` is a chunk record's body. A chunk header cut short passes (the reader reports it); a
/// record header cut by the end of the body does not (the reader would read on past it).
pub(super) fn check_chunk_records(body: &[u8]) -> Result<(), String> {
    // message_start_time, message_end_time, uncompressed_size, uncompressed_crc.
    const FIXED: usize = 8 + 8 + 8 + 4;
    let u32_at =
        |at: usize| body.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let u64_at = |at: usize| {
        body.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0xff; 8])))
    };
    let Some(compression_len) = u32_at(FIXED) else { return Ok(()) };
    let Some(records_at) = (FIXED + 4).checked_add(compression_len as usize) else { return Ok(()) };
    if compression_len != 0 {
        return Ok(());
    }
    let Some(records_len) = u64_at(records_at) else { return Ok(()) };
    let mut position = 0u64;
    while position < records_len {
        let header = records_at as u64 + 8 + position;
        // A record header the chunk's body cuts: mcap would read the rest from whatever
        // follows the chunk in the file.
        let Some(len) = usize::try_from(header).ok().and_then(|at| u64_at(at + 1)) else {
            return Err(format!(
                "its record at offset {position} is cut by the end of its {records_len} bytes \
                 of records"
            ));
        };
        let end = position.checked_add(RECORD_HEADER).and_then(|p| p.checked_add(len));
        match end {
            Some(end) if end <= records_len => position = end,
            _ => {
                return Err(format!(
                    "its record at offset {position} ({len} bytes) overruns its {records_len} \
                     bytes of records"
                ));
            }
        }
    }
    Ok(())
}

/// What a chunk holds once decompressed and checked.
pub(super) struct ChunkContents {
    pub(super) channels: Vec<(u16, ChannelInfo, String, Option<String>)>,
    pub(super) messages: Vec<(mcap::records::MessageHeader, Vec<u8>)>,
}

/// The largest record (or decompressed chunk) a log may hold. A damaged length field must
/// give an error, not an attempt to allocate exabytes.
pub(super) const MAX_RECORD_BYTES: usize = 256 << 20;

pub(super) fn decode_chunk(
    path: &Path,
    offset: u64,
    body: &[u8],
) -> Result<ChunkContents, LogError> {
    let bad = |source| LogError::Record { path: path.to_path_buf(), offset, source };
    check_chunk_records(body).map_err(|what| LogError::Invalid {
        path: path.to_path_buf(),
        what: format!("chunk at byte {offset}: {what}"),
    })?;
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

pub(super) fn parse_metadata(
    path: &Path,
    offset: u64,
    body: &[u8],
) -> Result<LoggedMetadata, LogError> {
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
pub(super) fn parse_attachment(
    path: &Path,
    offset: u64,
    body: &[u8],
) -> Result<LoggedAttachment, LogError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An uncompressed chunk's body holding `records`, declared `records_len` bytes long.
    fn chunk_body(records: &[u8], records_len: u64) -> Vec<u8> {
        let mut body = vec![0u8; 8 + 8 + 8 + 4];
        body.extend_from_slice(&0u32.to_le_bytes()); // compression: "" (none)
        body.extend_from_slice(&records_len.to_le_bytes());
        body.extend_from_slice(records);
        body
    }

    fn record(opcode: u8, body_len: u64) -> Vec<u8> {
        let mut bytes = vec![opcode];
        bytes.extend_from_slice(&body_len.to_le_bytes());
        bytes.resize(bytes.len() + body_len as usize, 0);
        bytes
    }

    #[test]
    fn uncompressed_records_must_fit_their_chunk() {
        let records = [record(op::MESSAGE, 4), record(op::MESSAGE, 2)].concat();
        let len = records.len() as u64;
        assert_eq!(check_chunk_records(&chunk_body(&records, len)), Ok(()));
        // The chunk claims one byte less than its records take: the last one overruns it.
        let error = check_chunk_records(&chunk_body(&records, len - 1)).expect_err("overrun");
        assert!(error.contains("offset 13 (2 bytes)"), "{error}");
        // A length near u64::MAX must not wrap around into "fits".
        let huge = [vec![op::MESSAGE], u64::MAX.to_le_bytes().to_vec()].concat();
        assert!(check_chunk_records(&chunk_body(&huge, 9)).is_err());
        // Records that end with the body, the last one's header cut.
        let cut = [record(op::MESSAGE, 4), vec![op::MESSAGE, 1, 0]].concat();
        let error = check_chunk_records(&chunk_body(&cut, cut.len() as u64)).expect_err("cut");
        assert!(error.contains("offset 13 is cut"), "{error}");
    }

    #[test]
    fn a_cut_header_or_a_compressed_chunk_is_left_to_the_reader() {
        assert_eq!(check_chunk_records(&[0; 10]), Ok(()));
        let mut compressed = vec![0u8; 28];
        compressed.extend_from_slice(&3u32.to_le_bytes());
        compressed.extend_from_slice(b"lz4");
        compressed.extend_from_slice(&100u64.to_le_bytes());
        assert_eq!(check_chunk_records(&compressed), Ok(()));
    }
}
