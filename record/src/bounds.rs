//! The declared lengths inside an MCAP record, checked against the record's own bytes before the
//! `mcap` crate parses it.
//!
//! `mcap::parse_record` allocates a string's declared length before it reads the string, so a
//! record of a few bytes that declares a 4 GiB string asks for 4 GiB (found by formation-fuzz's
//! `recording` target; the regression test is `fuzz/tests/regressions.rs`). [`check`] walks the
//! layout of the records a replay reads (schema, channel, message, attachment, metadata) and
//! refuses any string, map or byte field that declares more bytes than the record has left, so
//! what the parser allocates is bounded by the record, which the reader has already bounded.
//!
//! The records inside a chunk are read by [`ChunkRecords`], a second MCAP reader over that
//! chunk's bytes alone: `mcap`'s reader of a whole file subtracts an inner record's declared
//! length from the bytes its uncompressed chunk has left without checking it, which overflows
//! (a panic with overflow checks, and records read past the chunk without them) when the
//! length runs past the chunk but not past the file (also found by the `recording` target).
//! Over the chunk alone, such a record runs past the end of the input and is refused.

use mcap::McapError;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// The largest record inside a chunk (a tick's message; the recorder closes a chunk at 16 MiB):
/// the chunk's reader refuses a longer one before it allocates room to decompress it.
pub const MAX_CHUNK_RECORD_BYTES: usize = 16 << 20;

/// The opcode of a chunk.
pub const CHUNK: u8 = 0x06;

/// Opcodes of the records a replay reads; the reader skips the others without parsing them.
pub const READ_OPCODES: [u8; 5] = [SCHEMA, CHANNEL, MESSAGE, ATTACHMENT, METADATA];

const SCHEMA: u8 = 0x03;
const CHANNEL: u8 = 0x04;
const MESSAGE: u8 = 0x05;
const ATTACHMENT: u8 = 0x09;
const METADATA: u8 = 0x0C;

/// A field of a record that declares more bytes than the record holds.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "its {record} record declares {declared} bytes for its {field} at byte {at} of the record, \
     but the record has {available} bytes left"
)]
pub struct LengthError {
    /// The record's kind.
    pub record: &'static str,
    /// The field.
    pub field: &'static str,
    /// Where the field's length prefix starts in the record.
    pub at: usize,
    /// The length it declares.
    pub declared: u64,
    /// The bytes left after the prefix.
    pub available: usize,
}

/// A walk over one record's fields.
struct Walk<'a> {
    record: &'static str,
    body: &'a [u8],
    at: usize,
}

impl Walk<'_> {
    fn short(&self, field: &'static str, declared: u64) -> LengthError {
        LengthError {
            record: self.record,
            field,
            at: self.at,
            declared,
            available: self.body.len().saturating_sub(self.at),
        }
    }

    /// Skips `n` fixed bytes.
    fn skip(&mut self, field: &'static str, n: usize) -> Result<(), LengthError> {
        if self.body.len() - self.at < n {
            return Err(self.short(field, n as u64));
        }
        self.at += n;
        Ok(())
    }

    /// Reads a little-endian length prefix of `N` bytes.
    fn prefix<const N: usize>(&mut self, field: &'static str) -> Result<u64, LengthError> {
        let bytes = self
            .body
            .get(self.at..self.at + N)
            .ok_or_else(|| self.short(field, N as u64))?;
        let mut le = [0u8; 8];
        le[..N].copy_from_slice(bytes);
        Ok(u64::from_le_bytes(le))
    }

    /// Skips a field of a `u32` (or `u64`) length prefix and that many bytes.
    fn sized<const N: usize>(&mut self, field: &'static str) -> Result<(), LengthError> {
        let declared = self.prefix::<N>(field)?;
        let left = self.body.len() - self.at - N;
        if declared > left as u64 {
            return Err(self.short(field, declared));
        }
        self.at += N + declared as usize;
        Ok(())
    }

    /// Skips a string-to-string map: its `u32` byte length, then every key and value.
    fn map(&mut self, field: &'static str) -> Result<(), LengthError> {
        let declared = self.prefix::<4>(field)?;
        if declared > (self.body.len() - self.at - 4) as u64 {
            return Err(self.short(field, declared));
        }
        self.at += 4;
        let end = self.at + declared as usize;
        while self.at < end {
            self.sized::<4>(field)?;
            self.sized::<4>(field)?;
        }
        Ok(())
    }
}

/// Checks the lengths record `opcode` declares against `body`; records a replay does not read
/// pass unchecked.
pub fn check(opcode: u8, body: &[u8]) -> Result<(), LengthError> {
    let walk = |record| Walk {
        record,
        body,
        at: 0,
    };
    match opcode {
        SCHEMA => {
            let mut w = walk("schema");
            w.skip("id", 2)?;
            w.sized::<4>("name")?;
            w.sized::<4>("encoding")?;
            w.sized::<4>("data")
        }
        CHANNEL => {
            let mut w = walk("channel");
            w.skip("ids", 4)?;
            w.sized::<4>("topic")?;
            w.sized::<4>("message encoding")?;
            w.map("metadata")
        }
        MESSAGE => walk("message").skip("header", 22),
        ATTACHMENT => {
            let mut w = walk("attachment");
            w.skip("times", 16)?;
            w.sized::<4>("name")?;
            w.sized::<4>("media type")?;
            w.sized::<8>("data")?;
            w.skip("crc", 4)
        }
        METADATA => {
            let mut w = walk("metadata");
            w.sized::<4>("name")?;
            w.map("metadata")
        }
        _ => Ok(()),
    }
}

/// Where a chunk's compressed records end in its record `body` (bytes after them, which a
/// chunk record may carry, would be read as records by `mcap`'s reader): the times and the
/// uncompressed size and CRC (28 bytes), the compression's name, the records' length and the
/// records. `None` when the body is too short to say.
fn chunk_end(body: &[u8]) -> Option<usize> {
    let word = |at: usize, n: usize| -> Option<u64> {
        let bytes = body.get(at..at.checked_add(n)?)?;
        let mut le = [0u8; 8];
        le[..n].copy_from_slice(bytes);
        Some(u64::from_le_bytes(le))
    };
    let name = usize::try_from(word(28, 4)?).ok()?;
    let records_at = 32usize.checked_add(name)?;
    let records = usize::try_from(word(records_at, 8)?).ok()?;
    records_at.checked_add(8)?.checked_add(records)
}

/// The records of one chunk, read by an MCAP reader that is given the chunk's bytes and nothing
/// more (its CRC is checked as the file's reader checks it).
pub struct ChunkRecords {
    reader: LinearReader,
}

impl std::fmt::Debug for ChunkRecords {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChunkRecords").finish_non_exhaustive()
    }
}

impl ChunkRecords {
    /// A reader of the chunk whose record body is `body`, with the file reader's `options` but
    /// records of at most [`MAX_CHUNK_RECORD_BYTES`].
    pub fn new(body: &[u8], options: LinearReaderOptions) -> ChunkRecords {
        let body = &body[..chunk_end(body).map_or(body.len(), |end| end.min(body.len()))];
        let options = options
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_emit_chunks(false)
            .with_record_length_limit(MAX_CHUNK_RECORD_BYTES);
        let mut reader = LinearReader::new_with_options(options);
        let len = 9 + body.len();
        let buf = reader.insert(len);
        buf[0] = CHUNK;
        buf[1..9].copy_from_slice(&(body.len() as u64).to_le_bytes());
        buf[9..].copy_from_slice(body);
        reader.notify_read(len);
        ChunkRecords { reader }
    }

    /// The next record of the chunk (its opcode and body), `None` after the last; a record that
    /// runs past the chunk is [`McapError::UnexpectedEoc`].
    pub fn next_record(&mut self) -> Option<Result<(u8, Vec<u8>), McapError>> {
        loop {
            match self.reader.next_event()? {
                Ok(LinearReadEvent::ReadRequest(_)) => {
                    // Everything was given: the chunk's end.
                    let _ = self.reader.insert(0);
                    self.reader.notify_read(0);
                }
                Ok(LinearReadEvent::Record { opcode, data }) => {
                    return Some(Ok((opcode, data.to_vec())));
                }
                Err(McapError::UnexpectedEof) => return Some(Err(McapError::UnexpectedEoc)),
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &str) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s.as_bytes());
        out
    }

    #[test]
    fn a_metadata_record_that_fits_passes_and_one_that_declares_more_is_refused() {
        let mut body = string("formation.run");
        let entries = [string("k"), string("v")].concat();
        body.extend_from_slice(&(entries.len() as u32).to_le_bytes());
        body.extend_from_slice(&entries);
        assert_eq!(check(METADATA, &body), Ok(()));

        let mut huge = string("formation.run");
        huge.extend_from_slice(&8u32.to_le_bytes());
        huge.extend_from_slice(&0xffff_fff0u32.to_le_bytes());
        huge.extend_from_slice(b"abcd");
        let err = check(METADATA, &huge).unwrap_err();
        assert_eq!((err.field, err.declared), ("metadata", 0xffff_fff0));
        assert!(
            err.to_string()
                .contains("4294967280 bytes for its metadata")
        );
        for cut in 0..body.len() {
            assert!(check(METADATA, &body[..cut]).is_err(), "cut at {cut}");
        }
    }

    #[test]
    fn every_read_record_is_walked_to_its_end() {
        let mut attachment = vec![0u8; 16];
        attachment.extend(string("models/x.onnx"));
        attachment.extend(string("application/octet-stream"));
        attachment.extend(3u64.to_le_bytes());
        attachment.extend([1, 2, 3, 0, 0, 0, 0]);
        assert_eq!(check(ATTACHMENT, &attachment), Ok(()));
        attachment[16 + 4 + 13 + 4 + 24] = 200;
        assert!(check(ATTACHMENT, &attachment).is_err());
        assert!(check(MESSAGE, &[0; 21]).is_err());
        assert_eq!(check(0x0B, &[]), Ok(()));
    }
}
