//! The model files a recording stores or references, as its writer and its reader both see
//! them: the most bytes of a model a recording stores as an attachment, the SHA-256 that names
//! and checks a model, and the writer's bounded, piece-by-piece read of a model file.
//!
//! It sits below both sides ([`crate::file`] writes, [`crate::read`] and [`crate::models`] read),
//! so that neither reaches into the other. Its public items are re-exported where they have
//! always been named: [`crate::file::MAX_ATTACHED_MODEL_BYTES`], [`crate::models::sha256_hex`]
//! and [`crate::models::sha256_file`].

use std::fs::File;
use std::io::Read as _;
use std::path::Path;

use sha2::Digest as _;

use crate::error::RecordError;

/// The most bytes of a model a recording stores as an attachment.
pub const MAX_ATTACHED_MODEL_BYTES: u64 = 256 << 20;

/// How much of a model is read at a time, to hash and store it.
const MODEL_PIECE: usize = 64 << 10;

/// What takes a model's bytes piece by piece: a hasher, or the attachment being written.
pub(crate) type PieceSink<'a> = dyn FnMut(&[u8]) -> Result<(), RecordError> + 'a;

/// The SHA-256 of `bytes`, as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&sha2::Sha256::digest(bytes))
}

/// The SHA-256 of the file at `path`, read piece by piece, as lowercase hex.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = sha2::Sha256::new();
    let mut piece = vec![0u8; MODEL_PIECE];
    loop {
        let n = file.read(&mut piece)?;
        if n == 0 {
            return Ok(hex(&hasher.finalize()));
        }
        hasher.update(&piece[..n]);
    }
}

fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Opens a model to read, refusing one larger than a recording stores (`recording` names the
/// file in errors).
pub(crate) fn open_model(recording: &Path, model: &Path) -> Result<(File, u64), RecordError> {
    let model_error = |source| RecordError::Model {
        path: recording.to_path_buf(),
        model: model.to_path_buf(),
        source,
    };
    let file = File::open(model).map_err(model_error)?;
    let size = file.metadata().map_err(model_error)?.len();
    if size > MAX_ATTACHED_MODEL_BYTES {
        return Err(RecordError::ModelTooLarge {
            path: recording.to_path_buf(),
            model: model.to_path_buf(),
            size,
            limit: MAX_ATTACHED_MODEL_BYTES,
        });
    }
    Ok((file, size))
}

/// Reads `model` piece by piece, handing each piece to `each`; returns the bytes read.
pub(crate) fn read_model(
    recording: &Path,
    model: &Path,
    each: &mut PieceSink<'_>,
) -> Result<u64, RecordError> {
    let (file, size) = open_model(recording, model)?;
    let mut file = file.take(size);
    let mut piece = vec![0u8; MODEL_PIECE];
    let mut total = 0;
    loop {
        let n = file.read(&mut piece).map_err(|source| RecordError::Model {
            path: recording.to_path_buf(),
            model: model.to_path_buf(),
            source,
        })?;
        if n == 0 {
            return Ok(total);
        }
        total += n as u64;
        each(&piece[..n])?;
    }
}

/// The SHA-256 of `model`, as hex (`recording` names the file in errors).
pub(crate) fn hash_model(recording: &Path, model: &Path) -> Result<String, RecordError> {
    let mut hasher = sha2::Sha256::new();
    read_model(recording, model, &mut |piece| {
        hasher.update(piece);
        Ok(())
    })?;
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}
