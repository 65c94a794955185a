//! Framing of rcssservermj's TCP streams (agent and monitor ports alike): every message is a
//! 4-byte big-endian length followed by that many bytes of payload (an S-expression text).

use std::io::{self, Read, Write};

use thiserror::Error;

/// Largest agent (perception) frame accepted, in bytes.
///
/// Measured with rcsssmj 0.2.1 (`--rules fifa`, 11 T1s a side, all in view of each other): the
/// largest perception was 3,362 bytes, seeing 16 robots (about 110 bytes each: `(P (team T)(id
/// N)` and three parts) besides the field markers; 21 robots in view stay under 4 KB. 64 KiB is
/// sixteen times that and still bounds what a broken or hostile length field can make us
/// allocate.
pub const MAX_PERCEPTION_FRAME: usize = 64 * 1024;

/// Largest monitor-port frame accepted, in bytes.
///
/// Measured with rcsssmj 0.2.1: a full scene graph is 9.9 KB for the field and ball and grows
/// by about 10 KB per T1 (meshes, materials, transforms): 230,935 bytes with 22 T1s. Diffs are
/// a few KB. 4 MiB leaves room for bigger robots and fields.
pub const MAX_MONITOR_FRAME: usize = 4 * 1024 * 1024;

/// Why a frame could not be read or written.
#[derive(Debug, Error)]
pub enum FrameError {
    /// The stream ended cleanly between two frames (the peer closed the connection).
    #[error("the connection was closed between frames")]
    Closed,
    /// The stream ended inside the 4-byte length prefix.
    #[error("the stream ended inside a frame's length prefix ({got} of 4 bytes)")]
    TruncatedLength {
        /// Bytes of the prefix that arrived.
        got: usize,
    },
    /// The stream ended inside a payload.
    #[error("the stream ended inside a frame: {got} of {expected} payload bytes arrived")]
    TruncatedPayload {
        /// Bytes of the payload that arrived.
        got: usize,
        /// The length the prefix announced.
        expected: usize,
    },
    /// The length prefix announces more than the caller's maximum.
    #[error("a frame announces {length} bytes, more than the maximum of {max}")]
    Oversized {
        /// The announced length.
        length: usize,
        /// The maximum the reader accepts.
        max: usize,
    },
    /// A payload to write does not fit a 32-bit length prefix.
    #[error("a payload of {length} bytes does not fit a 4-byte length prefix")]
    TooLongToWrite {
        /// The payload length.
        length: usize,
    },
    /// The underlying stream failed (including read timeouts).
    #[error("i/o error on the server connection: {0}")]
    Io(#[from] io::Error),
}

/// Reads one frame from `reader` into `buffer` (cleared first, reused across calls so a steady
/// stream of frames allocates nothing) and returns the payload.
///
/// `max` bounds the announced length before anything is allocated: [`MAX_PERCEPTION_FRAME`] on
/// the agent port, [`MAX_MONITOR_FRAME`] on the monitor port. An end of stream before the first
/// byte of a frame is [`FrameError::Closed`]; anywhere later it is a truncation error.
pub fn read_frame<'b, R: Read + ?Sized>(
    reader: &mut R,
    buffer: &'b mut Vec<u8>,
    max: usize,
) -> Result<&'b [u8], FrameError> {
    let mut prefix = [0u8; 4];
    let got = read_full(reader, &mut prefix)?;
    if got == 0 {
        return Err(FrameError::Closed);
    }
    if got < prefix.len() {
        return Err(FrameError::TruncatedLength { got });
    }
    // A u32 always fits usize on the targets we build for (64-bit and 32-bit).
    let length = u32::from_be_bytes(prefix) as usize;
    if length > max {
        return Err(FrameError::Oversized { length, max });
    }
    buffer.clear();
    buffer.resize(length, 0);
    let got = read_full(reader, buffer)?;
    if got < length {
        return Err(FrameError::TruncatedPayload { got, expected: length });
    }
    Ok(buffer)
}

/// Writes `payload` as one frame (length prefix and payload in a single `write_all`, so a
/// frame is one TCP segment when it fits and the server, which reads prefix then payload, never
/// waits on a half-sent frame because of Nagle).
pub fn write_frame<W: Write + ?Sized>(writer: &mut W, payload: &[u8]) -> Result<(), FrameError> {
    let length = u32::try_from(payload.len())
        .map_err(|_| FrameError::TooLongToWrite { length: payload.len() })?;
    let mut frame = Vec::with_capacity(4 + payload.len());
    frame.extend_from_slice(&length.to_be_bytes());
    frame.extend_from_slice(payload);
    writer.write_all(&frame)?;
    writer.flush()?;
    Ok(())
}

/// Reads until `buf` is full or the stream ends; returns how many bytes arrived.
fn read_full<R: Read + ?Sized>(reader: &mut R, buf: &mut [u8]) -> Result<usize, io::Error> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}
