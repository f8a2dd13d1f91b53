//! Plain CDR (XCDR1, little-endian) as rmw_zenoh puts it on the wire: a bounded reader and a writer.
//!
//! A payload starts with the 4-byte encapsulation header `00 01 00 00` (representation
//! `CDR_LE`, options zero): rmw_zenoh_cpp serialises with Fast CDR in `DDS_CDR` mode and the host's
//! (little) endianness, and writes the encapsulation first (`TypeSupport::serialize_ros_message`).
//! After the header, every primitive is aligned to its own size (at most 8) relative to the first
//! byte *after* the header, padding with zeros. A string is a `u32` length that counts its
//! terminating NUL, the bytes, and the NUL; a sequence is a `u32` element count and the elements;
//! a fixed-size array is just its elements.
//!
//! The reader is total: every read checks the bytes that remain, a declared string or sequence
//! length is checked against both the bytes present and a cap ([`DecodeLimits`]) *before* anything
//! is allocated, and every failure is a [`CdrError`] naming the field. Trailing bytes after a
//! message are ignored, as Fast CDR ignores them.

use thiserror::Error;

/// The encapsulation header of a little-endian plain-CDR payload.
pub const ENCAPSULATION_CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Length of the encapsulation header.
const HEADER_LEN: usize = 4;

/// Caps on what a decoder accepts, beyond the bytes actually present.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Most elements one sequence (for example `LaserScan.ranges`) may declare.
    pub max_sequence_len: u32,
    /// Most bytes one string (for example `Header.frame_id`), NUL included, may declare.
    pub max_string_len: u32,
}

impl Default for DecodeLimits {
    /// One million elements per sequence (a 4 MB range array, far beyond any planar LIDAR) and
    /// 4 KiB per string (frame ids are a few dozen bytes).
    fn default() -> Self {
        DecodeLimits {
            max_sequence_len: 1_000_000,
            max_string_len: 4096,
        }
    }
}

/// Why a CDR payload could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    /// Fewer than 4 bytes: not even an encapsulation header.
    #[error("CDR payload of {len} bytes is too short for the 4-byte encapsulation header")]
    MissingHeader {
        /// Bytes present.
        len: usize,
    },
    /// The header names another representation (big-endian CDR, XCDR2, ...).
    #[error(
        "unsupported CDR encapsulation {found:02x?}: expected little-endian plain CDR {:02x?}",
        ENCAPSULATION_CDR_LE
    )]
    UnsupportedEncapsulation {
        /// The first four bytes of the payload.
        found: [u8; 4],
    },
    /// The payload ends inside a field.
    #[error(
        "CDR payload truncated in `{field}`: needs {needed} more bytes at offset {offset}, {remaining} left"
    )]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Offset in the payload (after the header) where the read started, padding included.
        offset: usize,
        /// Bytes the read needed.
        needed: usize,
        /// Bytes that were left.
        remaining: usize,
    },
    /// A sequence declares more elements than the bytes left could hold.
    #[error(
        "sequence `{field}` declares {declared} elements of {element_size} bytes but only {remaining} bytes remain"
    )]
    SequenceBeyondInput {
        /// The sequence.
        field: &'static str,
        /// Element count it declared.
        declared: u32,
        /// Size of one element.
        element_size: usize,
        /// Bytes that were left.
        remaining: usize,
    },
    /// A sequence declares more elements than [`DecodeLimits::max_sequence_len`].
    #[error("sequence `{field}` declares {declared} elements, more than the cap of {cap}")]
    SequenceTooLong {
        /// The sequence.
        field: &'static str,
        /// Element count it declared.
        declared: u32,
        /// The cap.
        cap: u32,
    },
    /// A string declares more bytes than remain or than [`DecodeLimits::max_string_len`].
    #[error(
        "string `{field}` declares {declared} bytes but the cap is {cap} and {remaining} bytes remain"
    )]
    StringTooLong {
        /// The string.
        field: &'static str,
        /// Length it declared, NUL included.
        declared: u32,
        /// The cap.
        cap: u32,
        /// Bytes that were left.
        remaining: usize,
    },
    /// A string's last byte is not NUL.
    #[error("string `{field}` is not NUL-terminated")]
    StringNotTerminated {
        /// The string.
        field: &'static str,
    },
    /// A string is not UTF-8.
    #[error("string `{field}` is not valid UTF-8")]
    StringNotUtf8 {
        /// The string.
        field: &'static str,
        /// Where the UTF-8 check failed.
        #[source]
        source: std::str::Utf8Error,
    },
}

/// Why a message could not be encoded (its strings and sequences must fit CDR's `u32` lengths,
/// and a string must not hold a NUL, which would cut it short for a C++ reader).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrEncodeError {
    /// A string holds a NUL byte.
    #[error("string `{field}` contains a NUL byte at {index}, which CDR strings cannot carry")]
    StringContainsNul {
        /// The string.
        field: &'static str,
        /// Byte index of the first NUL.
        index: usize,
    },
    /// A string or sequence is longer than a `u32` length can say.
    #[error("`{field}` has {len} elements, more than CDR's u32 length allows")]
    TooLong {
        /// The string or sequence.
        field: &'static str,
        /// Its length.
        len: usize,
    },
}

/// Builds one CDR payload, header first.
#[derive(Debug)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    /// A payload holding only the encapsulation header.
    pub fn new() -> Self {
        let mut buf = Vec::with_capacity(64);
        buf.extend_from_slice(&ENCAPSULATION_CDR_LE);
        CdrWriter { buf }
    }

    /// The finished payload.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    fn align(&mut self, alignment: usize) {
        let offset = self.buf.len() - HEADER_LEN;
        let padding = (alignment - offset % alignment) % alignment;
        self.buf.resize(self.buf.len() + padding, 0);
    }

    /// Writes a primitive's little-endian bytes, aligned to its size.
    fn write_aligned<const N: usize>(&mut self, bytes: [u8; N]) {
        self.align(N);
        self.buf.extend_from_slice(&bytes);
    }

    /// A payload holding only the encapsulation header, with room for `capacity` bytes in all
    /// (a writer that knows its message's size allocates once).
    pub fn with_capacity(capacity: usize) -> Self {
        let mut buf = Vec::with_capacity(capacity.max(HEADER_LEN));
        buf.extend_from_slice(&ENCAPSULATION_CDR_LE);
        CdrWriter { buf }
    }

    /// Writes a `uint8` (or a `bool`, as 0 or 1).
    pub fn write_u8(&mut self, value: u8) {
        self.buf.push(value);
    }

    /// Writes a `bool` as one byte, 0 or 1.
    pub fn write_bool(&mut self, value: bool) {
        self.buf.push(u8::from(value));
    }

    /// Writes a `u64`, aligned to 8.
    pub fn write_u64(&mut self, value: u64) {
        self.write_aligned(value.to_le_bytes());
    }

    /// Writes a `u32`, aligned to 4.
    pub fn write_u32(&mut self, value: u32) {
        self.write_aligned(value.to_le_bytes());
    }

    /// Writes an `i32`, aligned to 4.
    pub fn write_i32(&mut self, value: i32) {
        self.write_aligned(value.to_le_bytes());
    }

    /// Writes an `f32`, aligned to 4.
    pub fn write_f32(&mut self, value: f32) {
        self.write_aligned(value.to_le_bytes());
    }

    /// Writes an `f64`, aligned to 8.
    pub fn write_f64(&mut self, value: f64) {
        self.write_aligned(value.to_le_bytes());
    }

    /// Writes a fixed-size `float64[N]` array (no length).
    pub fn write_f64_array(&mut self, values: &[f64]) {
        for &v in values {
            self.write_f64(v);
        }
    }

    /// Writes a string: `u32` length counting the NUL, the bytes, the NUL.
    pub fn write_string(&mut self, field: &'static str, value: &str) -> Result<(), CdrEncodeError> {
        if let Some(index) = value.bytes().position(|b| b == 0) {
            return Err(CdrEncodeError::StringContainsNul { field, index });
        }
        let len = u32::try_from(value.len() + 1).map_err(|_| CdrEncodeError::TooLong {
            field,
            len: value.len(),
        })?;
        self.write_u32(len);
        self.buf.extend_from_slice(value.as_bytes());
        self.buf.push(0);
        Ok(())
    }

    /// Writes the `u32` element count of a sequence whose elements the caller writes next.
    pub fn write_sequence_len(
        &mut self,
        field: &'static str,
        len: usize,
    ) -> Result<(), CdrEncodeError> {
        let count = u32::try_from(len).map_err(|_| CdrEncodeError::TooLong { field, len })?;
        self.write_u32(count);
        Ok(())
    }

    /// Writes a sequence of messages: `u32` count, then each element as `write_element` writes it.
    pub fn write_sequence<T>(
        &mut self,
        field: &'static str,
        elements: &[T],
        mut write_element: impl FnMut(&mut Self, &T) -> Result<(), CdrEncodeError>,
    ) -> Result<(), CdrEncodeError> {
        self.write_sequence_len(field, elements.len())?;
        for element in elements {
            write_element(self, element)?;
        }
        Ok(())
    }

    /// Writes a `sequence<float32>`: `u32` count, then the values.
    pub fn write_f32_sequence(
        &mut self,
        field: &'static str,
        values: &[f32],
    ) -> Result<(), CdrEncodeError> {
        self.write_sequence(field, values, |w, &v| {
            w.write_f32(v);
            Ok(())
        })
    }

    /// Writes a `sequence<uint8>`: `u32` count, then the bytes.
    pub fn write_u8_sequence(
        &mut self,
        field: &'static str,
        values: &[u8],
    ) -> Result<(), CdrEncodeError> {
        self.write_sequence_len(field, values.len())?;
        self.buf.extend_from_slice(values);
        Ok(())
    }
}

/// Reads one CDR payload field by field, never past its end.
#[derive(Debug)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
    limits: DecodeLimits,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header and positions the reader on the first field.
    pub fn new(payload: &'a [u8], limits: DecodeLimits) -> Result<Self, CdrError> {
        let Some((header, body)) = payload.split_first_chunk::<HEADER_LEN>() else {
            return Err(CdrError::MissingHeader { len: payload.len() });
        };
        if *header != ENCAPSULATION_CDR_LE {
            return Err(CdrError::UnsupportedEncapsulation { found: *header });
        }
        Ok(CdrReader {
            body,
            pos: 0,
            limits,
        })
    }

    /// Bytes not yet read (after the current position).
    pub fn remaining(&self) -> usize {
        self.body.len() - self.pos
    }

    /// Skips the padding before a value of `alignment` bytes and takes `len` bytes.
    fn take(
        &mut self,
        field: &'static str,
        alignment: usize,
        len: usize,
    ) -> Result<&'a [u8], CdrError> {
        let padding = (alignment - self.pos % alignment) % alignment;
        let needed = padding.saturating_add(len);
        if needed > self.remaining() {
            return Err(CdrError::Truncated {
                field,
                offset: self.pos,
                needed,
                remaining: self.remaining(),
            });
        }
        let start = self.pos + padding;
        self.pos = start + len;
        Ok(&self.body[start..self.pos])
    }

    fn take_array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let bytes = self.take(field, N, N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    /// Reads a `u32`.
    pub fn read_u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        self.take_array::<4>(field).map(u32::from_le_bytes)
    }

    /// Reads a `uint8`.
    pub fn read_u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        self.take_array::<1>(field).map(|[b]| b)
    }

    /// Reads a `bool`: one byte, where anything but 0 is true (as Fast CDR reads it).
    pub fn read_bool(&mut self, field: &'static str) -> Result<bool, CdrError> {
        self.read_u8(field).map(|b| b != 0)
    }

    /// Reads a `u64`.
    pub fn read_u64(&mut self, field: &'static str) -> Result<u64, CdrError> {
        self.take_array::<8>(field).map(u64::from_le_bytes)
    }

    /// Reads an `i32`.
    pub fn read_i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        self.take_array::<4>(field).map(i32::from_le_bytes)
    }

    /// Reads an `f32`.
    pub fn read_f32(&mut self, field: &'static str) -> Result<f32, CdrError> {
        self.take_array::<4>(field).map(f32::from_le_bytes)
    }

    /// Reads an `f64`.
    pub fn read_f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        self.take_array::<8>(field).map(f64::from_le_bytes)
    }

    /// Reads a fixed-size `float64[N]` array.
    pub fn read_f64_array<const N: usize>(
        &mut self,
        field: &'static str,
    ) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.read_f64(field)?;
        }
        Ok(out)
    }

    /// Reads a string. A declared length of 0 (no NUL) is read as the empty string, as Fast CDR
    /// does.
    pub fn read_string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let declared = self.read_u32(field)?;
        if declared == 0 {
            return Ok(String::new());
        }
        let cap = self.limits.max_string_len;
        let remaining = self.remaining();
        if declared > cap || declared as usize > remaining {
            return Err(CdrError::StringTooLong {
                field,
                declared,
                cap,
                remaining,
            });
        }
        let bytes = self.take(field, 1, declared as usize)?;
        let Some((&0, text)) = bytes.split_last() else {
            return Err(CdrError::StringNotTerminated { field });
        };
        std::str::from_utf8(text)
            .map(str::to_owned)
            .map_err(|source| CdrError::StringNotUtf8 { field, source })
    }

    /// Reads the `u32` element count of a sequence of messages whose elements take at least
    /// `min_element_size` bytes each; the count is checked against the cap and the bytes present,
    /// so the caller may allocate for it.
    pub fn read_sequence_len(
        &mut self,
        field: &'static str,
        min_element_size: usize,
    ) -> Result<usize, CdrError> {
        let declared = self.read_u32(field)?;
        let cap = self.limits.max_sequence_len;
        if declared > cap {
            return Err(CdrError::SequenceTooLong {
                field,
                declared,
                cap,
            });
        }
        let remaining = self.remaining();
        if (declared as usize).saturating_mul(min_element_size) > remaining {
            return Err(CdrError::SequenceBeyondInput {
                field,
                declared,
                element_size: min_element_size,
                remaining,
            });
        }
        Ok(declared as usize)
    }

    /// Reads a sequence of messages whose elements take at least `min_element_size` bytes each,
    /// each as `read_element` reads it; the count is checked as [`CdrReader::read_sequence_len`]
    /// checks it before anything is allocated.
    pub fn read_sequence<T>(
        &mut self,
        field: &'static str,
        min_element_size: usize,
        mut read_element: impl FnMut(&mut Self) -> Result<T, CdrError>,
    ) -> Result<Vec<T>, CdrError> {
        let count = self.read_sequence_len(field, min_element_size)?;
        let mut elements = Vec::with_capacity(count);
        for _ in 0..count {
            elements.push(read_element(self)?);
        }
        Ok(elements)
    }

    /// Reads a `sequence<uint8>`; the count is checked against the cap and the bytes present
    /// before anything is allocated.
    pub fn read_u8_sequence(&mut self, field: &'static str) -> Result<Vec<u8>, CdrError> {
        let declared = self.read_sequence_len(field, 1)?;
        Ok(self.take(field, 1, declared)?.to_vec())
    }

    /// Reads a `sequence<float32>`; the count is checked against the cap and the bytes present
    /// before anything is allocated.
    pub fn read_f32_sequence(&mut self, field: &'static str) -> Result<Vec<f32>, CdrError> {
        const ELEMENT_SIZE: usize = 4;
        // After the u32 count the position is 4-aligned, so float32 elements need no padding.
        let declared = self.read_sequence_len(field, ELEMENT_SIZE)?;
        let bytes = self.take(field, ELEMENT_SIZE, declared * ELEMENT_SIZE)?;
        Ok(bytes
            .chunks_exact(ELEMENT_SIZE)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reader(body: &[u8]) -> Vec<u8> {
        let mut payload = ENCAPSULATION_CDR_LE.to_vec();
        payload.extend_from_slice(body);
        payload
    }

    #[test]
    fn alignment_is_relative_to_the_byte_after_the_header() {
        let mut w = CdrWriter::new();
        w.write_u32(1);
        w.write_f64(2.0);
        let bytes = w.into_bytes();
        // header (4) + u32 (4) + 4 bytes padding + f64 (8): the f64 starts at body offset 8.
        assert_eq!(bytes.len(), 20);
        assert_eq!(&bytes[8..12], &[0, 0, 0, 0]);
        assert_eq!(&bytes[12..20], &2.0f64.to_le_bytes());
    }

    #[test]
    fn header_errors_are_typed() {
        assert_eq!(
            CdrReader::new(&[0, 1], DecodeLimits::default()).unwrap_err(),
            CdrError::MissingHeader { len: 2 }
        );
        assert_eq!(
            CdrReader::new(&[0, 0, 0, 0, 1, 2, 3, 4], DecodeLimits::default()).unwrap_err(),
            CdrError::UnsupportedEncapsulation {
                found: [0, 0, 0, 0]
            }
        );
    }

    /// The error of reading `body` as the float sequence `ranges` under a cap of
    /// `max_sequence_len` elements.
    fn ranges_error(body: &[u8], max_sequence_len: u32) -> CdrError {
        let payload = reader(body);
        let limits = DecodeLimits {
            max_sequence_len,
            ..DecodeLimits::default()
        };
        let mut r = CdrReader::new(&payload, limits).unwrap();
        r.read_f32_sequence("ranges").unwrap_err()
    }

    #[test]
    fn sequence_count_beyond_input_is_refused_before_allocating() {
        assert_eq!(
            ranges_error(&u32::MAX.to_le_bytes(), u32::MAX),
            CdrError::SequenceBeyondInput {
                field: "ranges",
                declared: u32::MAX,
                element_size: 4,
                remaining: 0
            }
        );
    }

    #[test]
    fn sequence_count_beyond_the_cap_is_refused() {
        let mut body = 3u32.to_le_bytes().to_vec();
        body.extend_from_slice(&[0; 12]);
        assert_eq!(
            ranges_error(&body, 2),
            CdrError::SequenceTooLong {
                field: "ranges",
                declared: 3,
                cap: 2
            }
        );
    }

    #[test]
    fn strings_must_fit_be_terminated_and_be_utf8() {
        let limits = DecodeLimits::default();
        let payload = reader(&[10, 0, 0, 0, b'a']);
        assert!(matches!(
            CdrReader::new(&payload, limits)
                .unwrap()
                .read_string("frame_id"),
            Err(CdrError::StringTooLong {
                declared: 10,
                remaining: 1,
                ..
            })
        ));
        let payload = reader(&[2, 0, 0, 0, b'a', b'b']);
        assert_eq!(
            CdrReader::new(&payload, limits)
                .unwrap()
                .read_string("frame_id"),
            Err(CdrError::StringNotTerminated { field: "frame_id" })
        );
        let payload = reader(&[2, 0, 0, 0, 0xff, 0]);
        assert!(matches!(
            CdrReader::new(&payload, limits)
                .unwrap()
                .read_string("frame_id"),
            Err(CdrError::StringNotUtf8 {
                field: "frame_id",
                ..
            })
        ));
        let payload = reader(&[0, 0, 0, 0]);
        assert_eq!(
            CdrReader::new(&payload, limits)
                .unwrap()
                .read_string("frame_id"),
            Ok(String::new())
        );
    }

    #[test]
    fn truncation_names_the_field_and_offset() {
        let payload = reader(&[1, 2, 3, 4, 5]);
        let mut r = CdrReader::new(&payload, DecodeLimits::default()).unwrap();
        assert_eq!(
            r.read_f64("linear.x").unwrap_err(),
            CdrError::Truncated {
                field: "linear.x",
                offset: 0,
                needed: 8,
                remaining: 5
            }
        );
    }

    #[test]
    fn encoding_refuses_a_nul_inside_a_string() {
        let mut w = CdrWriter::new();
        assert_eq!(
            w.write_string("frame_id", "a\0b"),
            Err(CdrEncodeError::StringContainsNul {
                field: "frame_id",
                index: 1
            })
        );
    }
}
