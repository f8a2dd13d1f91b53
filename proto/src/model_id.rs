//! A model's id: what an agent reports for the model it runs, and what a recording's replay steps
//! name. It is `<file stem>-<8 hex digits of FNV-1a over the file's bytes>` ([`model_id`]): the
//! same file always gets the same id, a retrained model with the same name a different one. The
//! content hash is a short fingerprint, not a security hash; a recording checks a model file
//! against it ([`content_hash_of_id`]) before storing the file as the model an id names.

use std::path::Path;

/// The id of the model file at `path` whose bytes are `bytes`.
pub fn model_id(path: &Path, bytes: &[u8]) -> String {
    let stem = path
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    format!("{stem}-{:08x}", content_hash(bytes))
}

/// The content hash a model id carries: 32-bit FNV-1a over the model's bytes.
pub fn content_hash(bytes: &[u8]) -> u32 {
    bytes.iter().fold(0x811c_9dc5_u32, |hash, &b| {
        (hash ^ u32::from(b)).wrapping_mul(0x0100_0193)
    })
}

/// The file stem and content hash of the model id `id`; `None` when it is not of the form
/// [`model_id`] makes.
pub fn split_model_id(id: &str) -> Option<(&str, u32)> {
    let (stem, hash) = id.rsplit_once('-')?;
    if hash.len() != 8 || !hash.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    Some((stem, u32::from_str_radix(hash, 16).ok()?))
}

/// The content hash the model id `id` carries (see [`split_model_id`]).
pub fn content_hash_of_id(id: &str) -> Option<u32> {
    split_model_id(id).map(|(_, hash)| hash)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_reference_vectors() {
        assert_eq!(content_hash(b""), 0x811c_9dc5);
        assert_eq!(content_hash(b"a"), 0xe40c_292c);
        assert_eq!(content_hash(b"foobar"), 0xbf9c_f968);
    }

    #[test]
    fn model_id_is_stem_and_content_hash_and_splits_back() {
        let id = model_id(Path::new("/models/dagger-2.onnx"), b"foobar");
        assert_eq!(id, "dagger-2-bf9cf968");
        assert_ne!(model_id(Path::new("dagger-2.onnx"), b"foobaz"), id);
        assert_eq!(split_model_id(&id), Some(("dagger-2", 0xbf9c_f968)));
        assert_eq!(content_hash_of_id(&id), Some(content_hash(b"foobar")));
        for bad in [
            "",
            "policy",
            "policy-",
            "policy-xyz12345",
            "policy-abc",
            "-bf9cf9680",
        ] {
            assert_eq!(split_model_id(bad), None, "{bad}");
        }
    }
}
