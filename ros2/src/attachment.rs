//! The attachment rmw_zenoh puts on every published sample, and reads from every received one.
//!
//! rmw_zenoh_cpp (`attachment_helpers.cpp`, `AttachmentData::serialize_to_zbytes`) writes, with
//! `zenoh::ext::Serializer`:
//!
//! ```text
//! int64 sequence_number             8 bytes, little-endian
//! int64 source_timestamp            8 bytes, little-endian, nanoseconds (system clock)
//! std::array<uint8_t, 16> gid       LEB128 length (0x10), then the 16 bytes
//! ```
//!
//! 33 bytes in all. The Zenoh serialization format writes numbers little-endian and every
//! sequence, fixed-size arrays included, as a LEB128 length and its elements; zenoh-cpp's
//! deserializer refuses an array whose length is not 16. A subscriber drops a sample that has no
//! attachment (`rmw_subscription_data.cpp`). Publishers number their samples from 1.

use thiserror::Error;

/// Size of a ROS 2 GID in rmw_zenoh (`RMW_GID_STORAGE_SIZE`).
pub const GID_LEN: usize = 16;

/// Length of an encoded attachment.
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + GID_LEN;

/// The metadata of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// Per-publisher sequence number, starting at 1.
    pub sequence_number: i64,
    /// When the sample was published, nanoseconds since the Unix epoch.
    pub source_timestamp_ns: i64,
    /// The publisher's GID.
    pub source_gid: [u8; GID_LEN],
}

/// Why an attachment could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AttachmentError {
    /// The bytes end inside a field.
    #[error("attachment truncated in `{field}`: {len} bytes, rmw_zenoh writes {ATTACHMENT_LEN}")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Bytes present.
        len: usize,
    },
    /// The GID's length prefix is not 16.
    #[error("attachment GID declares {declared} bytes; rmw_zenoh GIDs have {GID_LEN}")]
    GidLength {
        /// The declared length (saturated at `u64::MAX` for an overlong LEB128).
        declared: u64,
    },
}

impl Attachment {
    /// The 33 bytes rmw_zenoh_cpp writes.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut out = [0u8; ATTACHMENT_LEN];
        out[0..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out[16] = GID_LEN as u8; // LEB128 of 16 is the single byte 0x10.
        out[17..].copy_from_slice(&self.source_gid);
        out
    }

    /// Decodes an attachment. Bytes after the GID are ignored, as zenoh-cpp's deserializer in
    /// rmw_zenoh ignores them.
    pub fn decode(bytes: &[u8]) -> Result<Attachment, AttachmentError> {
        let truncated = |field| AttachmentError::Truncated {
            field,
            len: bytes.len(),
        };
        let (sequence, rest) = bytes
            .split_first_chunk::<8>()
            .ok_or_else(|| truncated("sequence_number"))?;
        let (timestamp, rest) = rest
            .split_first_chunk::<8>()
            .ok_or_else(|| truncated("source_timestamp"))?;
        let (declared, rest) = read_leb128(rest).ok_or_else(|| truncated("source_gid length"))?;
        if declared != GID_LEN as u64 {
            return Err(AttachmentError::GidLength { declared });
        }
        let (gid, _) = rest
            .split_first_chunk::<GID_LEN>()
            .ok_or_else(|| truncated("source_gid"))?;
        Ok(Attachment {
            sequence_number: i64::from_le_bytes(*sequence),
            source_timestamp_ns: i64::from_le_bytes(*timestamp),
            source_gid: *gid,
        })
    }
}

/// Reads an unsigned LEB128 number, at most 10 bytes; a value beyond `u64` saturates. `None`
/// if the bytes end before the number does.
fn read_leb128(bytes: &[u8]) -> Option<(u64, &[u8])> {
    let mut value: u64 = 0;
    for (i, &byte) in bytes.iter().enumerate().take(10) {
        let chunk = u64::from(byte & 0x7f);
        value = if i == 9 && chunk > 1 {
            u64::MAX
        } else {
            value | chunk << (7 * i)
        };
        if byte & 0x80 == 0 {
            return Some((value, &bytes[i + 1..]));
        }
    }
    if bytes.len() >= 10 {
        // Ten continuation bytes: longer than any u64; report it as an absurd length.
        return Some((u64::MAX, &bytes[10..]));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Attachment {
        Attachment {
            sequence_number: 1,
            source_timestamp_ns: -5,
            source_gid: [7; GID_LEN],
        }
    }

    #[test]
    fn round_trips() {
        let a = sample();
        assert_eq!(Attachment::decode(&a.encode()), Ok(a));
    }

    #[test]
    fn every_truncation_is_an_error_naming_the_field() {
        let bytes = sample().encode();
        for len in 0..ATTACHMENT_LEN {
            let err = Attachment::decode(&bytes[..len]).unwrap_err();
            let field = match len {
                0..8 => "sequence_number",
                8..16 => "source_timestamp",
                16 => "source_gid length",
                _ => "source_gid",
            };
            assert_eq!(err, AttachmentError::Truncated { field, len });
        }
    }

    #[test]
    fn a_gid_of_another_length_is_refused() {
        let mut bytes = sample().encode().to_vec();
        bytes[16] = 15;
        assert_eq!(
            Attachment::decode(&bytes),
            Err(AttachmentError::GidLength { declared: 15 })
        );
        // A multi-byte LEB128 length: 0x90 0x01 = 144.
        bytes[16] = 0x90;
        bytes.insert(17, 0x01);
        assert_eq!(
            Attachment::decode(&bytes),
            Err(AttachmentError::GidLength { declared: 144 })
        );
        // Endless continuation bytes.
        let mut endless = bytes[..16].to_vec();
        endless.extend_from_slice(&[0xff; 12]);
        assert_eq!(
            Attachment::decode(&endless),
            Err(AttachmentError::GidLength { declared: u64::MAX })
        );
    }

    #[test]
    fn trailing_bytes_are_ignored_as_rmw_zenoh_does() {
        let mut bytes = sample().encode().to_vec();
        bytes.push(0xaa);
        assert_eq!(Attachment::decode(&bytes), Ok(sample()));
    }
}
