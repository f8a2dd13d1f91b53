//! Model bytes for a swap over the network: a remote agent cannot open the path of the host that
//! asked, so `formation swap --transport zenoh` sends the model itself, after the swap request,
//! and the world forwards it after the control request to the agent.
//!
//! The bytes follow the fixed-size message in the same Zenoh payload: the model's length
//! (`u64`, little-endian), its SHA-256, then the model. A payload whose length field exceeds
//! [`MAX_MODEL_BYTES`], disagrees with the bytes that came, or whose checksum does not match is
//! refused with the reason (the old model keeps driving); the agent writes an accepted model to a
//! private file (0600, in a 0700 folder of its own) and loads it from there as any swap model.

use sha2::{Digest, Sha256};

/// The largest model a swap sends (the Zenoh message limit is larger, so that a model just over
/// this limit still arrives whole and is refused with this reason rather than lost).
pub const MAX_MODEL_BYTES: usize = 32 << 20;

const HEADER: usize = 8 + 32;

/// Model bytes that cannot be sent or were not accepted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModelPayloadError {
    /// Over the limit.
    #[error(
        "the model is {size} bytes; a swap over the network sends at most {MAX_MODEL_BYTES} bytes \
         (32 MiB)"
    )]
    TooLarge {
        /// Its size.
        size: u64,
    },
    /// Cut short, or longer than it says.
    #[error("the model bytes are damaged: {0}")]
    Damaged(String),
    /// The checksum does not match.
    #[error("the model's SHA-256 does not match the bytes that arrived; send it again")]
    Checksum,
}

/// Appends `model` (length, SHA-256, bytes) to `payload`.
pub fn append_model(payload: &mut Vec<u8>, model: &[u8]) -> Result<(), ModelPayloadError> {
    if model.len() > MAX_MODEL_BYTES {
        return Err(ModelPayloadError::TooLarge {
            size: model.len() as u64,
        });
    }
    payload.reserve(HEADER + model.len());
    payload.extend_from_slice(&(model.len() as u64).to_le_bytes());
    payload.extend_from_slice(&Sha256::digest(model));
    payload.extend_from_slice(model);
    Ok(())
}

/// Splits a payload into its fixed-size message of `message_len` bytes and the model after it
/// (`None` when none follows), checking the model's length and checksum.
pub fn split_model(
    payload: &[u8],
    message_len: usize,
) -> Result<(&[u8], Option<&[u8]>), ModelPayloadError> {
    if payload.len() <= message_len {
        return Ok((payload, None));
    }
    let (message, rest) = payload.split_at(message_len);
    let Some((length, rest)) = rest.split_first_chunk::<8>() else {
        return Err(ModelPayloadError::Damaged("the length field is cut".into()));
    };
    let length = u64::from_le_bytes(*length);
    if length > MAX_MODEL_BYTES as u64 {
        return Err(ModelPayloadError::TooLarge { size: length });
    }
    let Some((checksum, model)) = rest.split_first_chunk::<32>() else {
        return Err(ModelPayloadError::Damaged("the checksum is cut".into()));
    };
    if model.len() as u64 != length {
        return Err(ModelPayloadError::Damaged(format!(
            "{} bytes arrived for a model of {length}",
            model.len()
        )));
    }
    if Sha256::digest(model).as_slice() != checksum {
        return Err(ModelPayloadError::Checksum);
    }
    Ok((message, Some(model)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_round_trips_and_damage_or_size_is_refused() {
        let mut payload = vec![7u8; 16];
        append_model(&mut payload, b"onnx bytes").unwrap();
        let (message, model) = split_model(&payload, 16).unwrap();
        assert_eq!(message, &[7u8; 16]);
        assert_eq!(model, Some(&b"onnx bytes"[..]));
        assert_eq!(split_model(&payload[..16], 16).unwrap().1, None);

        let mut flipped = payload.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert_eq!(split_model(&flipped, 16), Err(ModelPayloadError::Checksum));
        assert!(matches!(
            split_model(&payload[..payload.len() - 1], 16),
            Err(ModelPayloadError::Damaged(_))
        ));
        let mut huge = vec![0u8; 16];
        huge.extend_from_slice(&(MAX_MODEL_BYTES as u64 + 1).to_le_bytes());
        assert!(matches!(
            split_model(&huge, 16),
            Err(ModelPayloadError::TooLarge { .. })
        ));
        let e = append_model(&mut Vec::new(), &vec![0u8; MAX_MODEL_BYTES + 1]).unwrap_err();
        assert!(e.to_string().contains("32 MiB"), "{e}");
    }
}
