//! Reading on past damage: the next chunk after a damaged or cut record, found by its header
//! and checked whole (its CRC), so that one bad chunk in the middle of a file does not cost
//! the chunks after it.

use mcap::records::op;

use crate::error::LogError;

use super::{MAX_RECORD_BYTES, RECORD_HEADER, RecordFile, decode_chunk};

/// Bytes looked through at a time.
const WINDOW: u64 = 1 << 20;

/// A chunk record's header up to its records: opcode and length (9), start and end times,
/// uncompressed size and CRC (28), compression name's length (4), name (at most
/// [`MAX_COMPRESSION_NAME`]), records' length (8).
const CHUNK_HEADER_MAX: u64 = RECORD_HEADER + 28 + 4 + MAX_COMPRESSION_NAME as u64 + 8;

/// MCAP's compressions are named `""`, `"zstd"` and `"lz4"`.
const MAX_COMPRESSION_NAME: usize = 16;

/// Where the scan goes on after damage.
#[derive(Debug, Default)]
pub(super) struct Resumed {
    /// The offset of the next chunk that reads back whole; `None`: none follows.
    pub(super) at: Option<u64>,
    /// Chunks passed on the way whose header looked right but whose contents did not read.
    pub(super) damaged_chunks: usize,
}

/// Looks from `from` on for the next chunk that reads back whole.
pub(super) fn next_good_chunk(records: &mut RecordFile, from: u64) -> Result<Resumed, LogError> {
    let mut resumed = Resumed::default();
    let mut window = Vec::new();
    let mut start = from;
    while start < records.len {
        // A candidate near the end of the window has its header in the overlap.
        let end = start.saturating_add(WINDOW + CHUNK_HEADER_MAX).min(records.len);
        window.resize(usize::try_from(end - start).unwrap_or(0), 0);
        records.read_exact_at(start, &mut window)?;
        let scanned = window.len().min(WINDOW as usize);
        for at in (0..scanned).filter(|&at| window[at] == op::CHUNK) {
            let offset = start + at as u64;
            if !plausible_chunk(&window[at..], records.len - offset) {
                continue;
            }
            match records.record_at(offset)? {
                Some((_, body)) if decode_chunk(&records.path, offset, &body).is_ok() => {
                    resumed.at = Some(offset);
                    return Ok(resumed);
                }
                _ => resumed.damaged_chunks += 1,
            }
        }
        start += WINDOW;
    }
    Ok(resumed)
}

/// Whether `bytes` (`left` of them up to the end of the file) start like a chunk record whose
/// fields agree with each other and with its length: random bytes practically never do.
fn plausible_chunk(bytes: &[u8], left: u64) -> bool {
    let u64_at =
        |at: usize| bytes.get(at..at + 8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes);
    let u32_at =
        |at: usize| bytes.get(at..at + 4).and_then(|b| b.try_into().ok()).map(u32::from_le_bytes);
    let (Some(length), Some(start), Some(end), Some(name_len)) =
        (u64_at(1), u64_at(9), u64_at(17), u32_at(37))
    else {
        return false;
    };
    let name_len = name_len as usize;
    if name_len > MAX_COMPRESSION_NAME
        || length > left.saturating_sub(RECORD_HEADER)
        || length > MAX_RECORD_BYTES as u64
        || start > end
    {
        return false;
    }
    let name_ok =
        bytes.get(41..41 + name_len).is_some_and(|name| name.iter().all(u8::is_ascii_alphanumeric));
    let fixed = 28 + 4 + name_len as u64 + 8;
    name_ok
        && u64_at(41 + name_len).is_some_and(|records| Some(records) == length.checked_sub(fixed))
}

/// Whether a message index record's body is what its length says: a channel id, then a
/// `u32` byte length of 16-byte entries filling the rest. A damaged length would otherwise
/// send the scan to a wrong place without a sign.
pub(super) fn message_index_fits(body: &[u8]) -> bool {
    let entries = body.get(2..6).and_then(|b| b.try_into().ok()).map(u32::from_le_bytes);
    entries.is_some_and(|n| n.is_multiple_of(16) && body.len() == 6 + n as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk record with `records` uncompressed.
    fn chunk(records: &[u8]) -> Vec<u8> {
        let mut body = vec![0u8; 8 + 8 + 8 + 4];
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(records);
        let mut record = vec![op::CHUNK];
        record.extend_from_slice(&(body.len() as u64).to_le_bytes());
        record.extend_from_slice(&body);
        record
    }

    #[test]
    fn a_chunk_header_is_told_from_random_bytes() {
        let record = chunk(&[1, 2, 3]);
        assert!(plausible_chunk(&record, record.len() as u64));
        // Cut short, or claiming more than the file holds.
        assert!(!plausible_chunk(&record[..20], record.len() as u64));
        assert!(!plausible_chunk(&record, record.len() as u64 - 1));
        // The records' length disagrees with the record's.
        let mut wrong = record.clone();
        wrong[41] ^= 1;
        assert!(!plausible_chunk(&wrong, wrong.len() as u64));
        let mut noise = vec![op::CHUNK];
        noise.extend((0..200u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8));
        assert!(!plausible_chunk(&noise, noise.len() as u64));
    }

    #[test]
    fn a_message_index_must_fill_its_record() {
        let mut body = vec![0, 0];
        body.extend_from_slice(&32u32.to_le_bytes());
        body.extend_from_slice(&[0; 32]);
        assert!(message_index_fits(&body));
        assert!(!message_index_fits(&body[..30]));
        body[2] = 31;
        assert!(!message_index_fits(&body));
    }
}
