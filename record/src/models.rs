//! The model files a replay loads: the recording's own, found and checked against its hashes.
//!
//! A shipped model is referenced by its path and SHA-256: the file at that path is hashed
//! (piece by piece) and refused when it differs or is missing. A stored model comes from its
//! attachment, which is written into a folder of the caller's and checked against its hash too.
//! Each file is placed under its recorded file name, so that the model id an agent derives from
//! it (file stem and content) is the id the recording's steps carry. A model swapped in during the
//! run is found the same way from its record ([`swapped_model_file`]), placed under the file stem
//! of its recorded model id.

use std::path::{Path, PathBuf};

use formation_proto::model_id::split_model_id;

pub use crate::model_files::{sha256_file, sha256_hex};
use crate::read::{ModelStorage, RunInfo};
use crate::swap::{SwapStorage, SwappedModel};

/// Why a recording's model cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    /// A shipped model is not at its recorded path.
    #[error(
        "{}: the recording's model {} (SHA-256 {sha256}) is not there: run the replay from the \
         folder the run was recorded in, or give the model with --model",
        recording.display(), model.display()
    )]
    Missing {
        /// The recording.
        recording: PathBuf,
        /// The recorded path.
        model: PathBuf,
        /// Its recorded hash.
        sha256: String,
    },
    /// A model's bytes are not the ones the recording names.
    #[error(
        "{}: the model {} has SHA-256 {found}, but the run used {expected}: it changed since the \
         recording; restore it, or replay against it on purpose with --model {}",
        recording.display(), model.display(), model.display()
    )]
    HashMismatch {
        /// The recording.
        recording: PathBuf,
        /// The file.
        model: PathBuf,
        /// The recorded hash.
        expected: String,
        /// The file's hash.
        found: String,
    },
    /// A recording made from outside the team does not hold a model that is not shipped, and it
    /// is not at its recorded path here.
    #[error(
        "{}: the model {} is not stored in this recording (it was recorded from outside the \
         team, and the model stayed on the world's host; the world's own --record stores it) \
         and is not at that path here: give the model with --model",
        recording.display(), model.display()
    )]
    NotStored {
        /// The recording.
        recording: PathBuf,
        /// The recorded path.
        model: PathBuf,
    },
    /// A stored model's attachment is not in the file.
    #[error(
        "{}: the model {} should be stored as the attachment {name}, which the file does not \
         hold: give the model with --model",
        recording.display(), model.display()
    )]
    AttachmentMissing {
        /// The recording.
        recording: PathBuf,
        /// The recorded path.
        model: PathBuf,
        /// The attachment's name.
        name: String,
    },
    /// A model could not be read or written.
    #[error("{}: cannot read or write the model file {}", recording.display(), model.display())]
    Io {
        /// The recording.
        recording: PathBuf,
        /// The file.
        model: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

/// Where the attachment `name` is kept in `dir` until the metadata names its model.
pub fn attachment_path(dir: &Path, name: &str) -> PathBuf {
    let flat: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    dir.join("attachments").join(flat)
}

/// An I/O error on `model`, a file of `recording`'s models.
fn io_error(
    recording: &Path,
    model: &Path,
) -> impl FnOnce(std::io::Error) -> ModelFileError + use<> {
    let (recording, model) = (recording.to_path_buf(), model.to_path_buf());
    move |source| ModelFileError::Io {
        recording,
        model,
        source,
    }
}

/// `file`, if its SHA-256 is the one the recording gives for it.
fn with_hash(recording: &Path, file: PathBuf, expected: &str) -> Result<PathBuf, ModelFileError> {
    let found = sha256_file(&file).map_err(io_error(recording, &file))?;
    if found == expected {
        Ok(file)
    } else {
        Err(ModelFileError::HashMismatch {
            recording: recording.to_path_buf(),
            model: file,
            expected: expected.to_string(),
            found,
        })
    }
}

/// A model the recording names by its path (shipped, or not stored), which must be on disk here.
fn file_on_disk(recording: &Path, model: &Path, sha256: &str) -> Result<PathBuf, ModelFileError> {
    if model.is_file() {
        Ok(model.to_path_buf())
    } else {
        Err(ModelFileError::Missing {
            recording: recording.to_path_buf(),
            model: model.to_path_buf(),
            sha256: sha256.to_string(),
        })
    }
}

/// Keeps the attachment `name` in `dir` (see [`attachment_path`]).
pub fn save_attachment(
    recording: &Path,
    dir: &Path,
    name: &str,
    bytes: &[u8],
) -> Result<(), ModelFileError> {
    let path = attachment_path(dir, name);
    let io = |source| ModelFileError::Io {
        recording: recording.to_path_buf(),
        model: path.clone(),
        source,
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    std::fs::write(&path, bytes).map_err(io)
}

/// The file to load for each of `info`'s models (in its order), each checked against its
/// recorded hash: a shipped one where it was, a stored one from `dir` (where
/// [`save_attachment`] kept it), moved to `dir/model-<k>/<its recorded file name>`.
pub fn recorded_model_files(
    recording: &Path,
    info: &RunInfo,
    dir: &Path,
) -> Result<Vec<PathBuf>, ModelFileError> {
    let mut files = Vec::with_capacity(info.models.len());
    for (k, model) in info.models.iter().enumerate() {
        let io = |path: &Path| io_error(recording, path);
        let file = match &model.storage {
            ModelStorage::NotStored if !model.path.is_file() => {
                return Err(ModelFileError::NotStored {
                    recording: recording.to_path_buf(),
                    model: model.path.clone(),
                });
            }
            ModelStorage::Shipped | ModelStorage::NotStored => {
                file_on_disk(recording, &model.path, &model.sha256)?
            }
            ModelStorage::Attachment(name) => {
                let kept = attachment_path(dir, name);
                if !kept.is_file() {
                    return Err(ModelFileError::AttachmentMissing {
                        recording: recording.to_path_buf(),
                        model: model.path.clone(),
                        name: name.clone(),
                    });
                }
                let file_name = model
                    .path
                    .file_name()
                    .map_or_else(|| "model.onnx".into(), ToOwned::to_owned);
                let place = dir.join(format!("model-{k}"));
                std::fs::create_dir_all(&place).map_err(io(&place))?;
                let target = place.join(file_name);
                std::fs::rename(&kept, &target).map_err(io(&kept))?;
                target
            }
        };
        files.push(with_hash(recording, file, &model.sha256)?);
    }
    Ok(files)
}

/// The file to load for a model swapped in during the run, checked against its recorded hash:
/// a stored one from `dir` (where [`save_attachment`] kept it, or among `loaded`, the files
/// already placed, when an earlier model had the same bytes), copied to
/// `dir/swapped-<request id>/<the file stem of its model id>.onnx` so that an agent loading it
/// gets the recorded model id; a shipped one where it was. `None` when the recording does not
/// hold it.
pub fn swapped_model_file(
    recording: &Path,
    swapped: &SwappedModel,
    dir: &Path,
    loaded: &[PathBuf],
) -> Result<Option<PathBuf>, ModelFileError> {
    let io = |path: &Path| io_error(recording, path);
    let file = match &swapped.storage {
        SwapStorage::NotStored(_) => return Ok(None),
        SwapStorage::Shipped => file_on_disk(recording, &swapped.path, &swapped.sha256)?,
        SwapStorage::Attachment(name) => {
            let kept = attachment_path(dir, name);
            let source = if kept.is_file() {
                kept
            } else {
                let same = loaded
                    .iter()
                    .find(|f| sha256_file(f).is_ok_and(|sha| sha == swapped.sha256));
                same.cloned()
                    .ok_or_else(|| ModelFileError::AttachmentMissing {
                        recording: recording.to_path_buf(),
                        model: swapped.path.clone(),
                        name: name.clone(),
                    })?
            };
            let stem = split_model_id(&swapped.model_id).map_or("model", |(stem, _)| stem);
            let place = dir.join(format!("swapped-{}", swapped.request_id));
            std::fs::create_dir_all(&place).map_err(io(&place))?;
            let target = place.join(format!("{stem}.onnx"));
            std::fs::copy(&source, &target).map_err(io(&source))?;
            target
        }
    };
    with_hash(recording, file, &swapped.sha256).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn info(path: &Path, sha: &str, stored: &str) -> RunInfo {
        let mut raw = BTreeMap::new();
        raw.insert("model.0.path".into(), path.display().to_string());
        raw.insert("model.0.sha256".into(), sha.into());
        raw.insert("model.0.stored".into(), stored.into());
        raw.insert("robot_models".into(), "0,0".into());
        RunInfo::parse(Path::new("rec.mcap"), raw).unwrap()
    }

    #[test]
    fn a_shipped_model_is_checked_against_its_hash_and_refused_missing_or_changed() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("policy.onnx");
        std::fs::write(&model, b"model bytes").unwrap();
        let sha = sha256_hex(b"model bytes");
        assert_eq!(sha256_file(&model).unwrap(), sha);
        let good = info(&model, &sha, "shipped");
        assert_eq!(good.robot_models, [0, 0]);
        let files = recorded_model_files(Path::new("rec.mcap"), &good, dir.path()).unwrap();
        assert_eq!(files, std::slice::from_ref(&model));
        std::fs::write(&model, b"changed").unwrap();
        let err = recorded_model_files(Path::new("rec.mcap"), &good, dir.path()).unwrap_err();
        assert!(matches!(err, ModelFileError::HashMismatch { .. }), "{err}");
        assert!(err.to_string().contains("--model"), "{err}");
        std::fs::remove_file(&model).unwrap();
        let err = recorded_model_files(Path::new("rec.mcap"), &good, dir.path()).unwrap_err();
        assert!(matches!(err, ModelFileError::Missing { .. }), "{err}");
    }

    #[test]
    fn a_stored_model_is_placed_under_its_recorded_name_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let sha = sha256_hex(b"stored");
        let name = format!("models/{sha}.onnx");
        let recorded = info(
            Path::new("/elsewhere/tiny-seed0.onnx"),
            &sha,
            &format!("attachment {name}"),
        );
        let err = recorded_model_files(Path::new("r"), &recorded, dir.path()).unwrap_err();
        assert!(
            matches!(err, ModelFileError::AttachmentMissing { .. }),
            "{err}"
        );
        save_attachment(Path::new("r"), dir.path(), &name, b"stored").unwrap();
        let files = recorded_model_files(Path::new("r"), &recorded, dir.path()).unwrap();
        assert_eq!(files[0].file_name().unwrap(), "tiny-seed0.onnx");
        assert_eq!(std::fs::read(&files[0]).unwrap(), b"stored");
    }

    #[test]
    fn a_model_a_live_recording_did_not_store_is_taken_from_its_path_or_asked_for() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("tiny-seed0.onnx");
        let sha = sha256_hex(b"kept on the world's host");
        let stored = format!(
            "{}attachment models/{sha}.onnx)",
            crate::read::NOT_STORED_PREFIX
        );
        let recorded = info(&model, &sha, &stored);
        assert_eq!(recorded.models[0].storage, ModelStorage::NotStored);
        let err = recorded_model_files(Path::new("r"), &recorded, dir.path()).unwrap_err();
        assert!(matches!(err, ModelFileError::NotStored { .. }), "{err}");
        assert!(err.to_string().contains("--model"), "{err}");
        std::fs::write(&model, b"kept on the world's host").unwrap();
        let files = recorded_model_files(Path::new("r"), &recorded, dir.path()).unwrap();
        assert_eq!(files, std::slice::from_ref(&model));
        std::fs::write(&model, b"another model").unwrap();
        let err = recorded_model_files(Path::new("r"), &recorded, dir.path()).unwrap_err();
        assert!(matches!(err, ModelFileError::HashMismatch { .. }), "{err}");
    }

    #[test]
    fn a_swapped_in_model_is_placed_under_its_id_stem_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let bytes = b"swapped in";
        let sha = sha256_hex(bytes);
        let name = format!("models/{sha}.onnx");
        let model_id = formation_proto::model_id::model_id(Path::new("swap-9.onnx"), bytes);
        let mut swapped = SwappedModel {
            robot: 1,
            tick: 120,
            request_id: 9,
            model_id,
            path: PathBuf::from("sent-over-zenoh/second.onnx"),
            sha256: sha.clone(),
            storage: SwapStorage::Attachment(name.clone()),
        };
        let err = swapped_model_file(Path::new("r"), &swapped, dir.path(), &[]).unwrap_err();
        assert!(
            matches!(err, ModelFileError::AttachmentMissing { .. }),
            "{err}"
        );
        // The same bytes as a model placed already (stored once in the file).
        let earlier = dir.path().join("earlier.onnx");
        std::fs::write(&earlier, bytes).unwrap();
        let file = swapped_model_file(Path::new("r"), &swapped, dir.path(), &[earlier])
            .unwrap()
            .unwrap();
        assert_eq!(file.file_name().unwrap(), "swap-9.onnx");
        assert_eq!(std::fs::read(&file).unwrap(), bytes);
        // Kept from its attachment; bytes that are not the recorded ones are refused.
        save_attachment(Path::new("r"), dir.path(), &name, b"other bytes").unwrap();
        let err = swapped_model_file(Path::new("r"), &swapped, dir.path(), &[]).unwrap_err();
        assert!(matches!(err, ModelFileError::HashMismatch { .. }), "{err}");
        swapped.storage = SwapStorage::NotStored("the file changed".into());
        assert_eq!(
            swapped_model_file(Path::new("r"), &swapped, dir.path(), &[]).unwrap(),
            None
        );
    }

    #[test]
    fn malformed_metadata_is_a_typed_error() {
        let mut raw = BTreeMap::new();
        raw.insert("model.0.path".into(), "m.onnx".into());
        raw.insert("model.0.sha256".into(), "ab".into());
        raw.insert("model.0.stored".into(), "somewhere".into());
        let err = RunInfo::parse(Path::new("r"), raw.clone()).unwrap_err();
        assert!(err.to_string().contains("model.0.stored"), "{err}");
        raw.insert("model.0.stored".into(), "shipped".into());
        raw.insert("robot_models".into(), "0,1".into());
        let err = RunInfo::parse(Path::new("r"), raw).unwrap_err();
        assert!(err.to_string().contains("robot_models"), "{err}");
    }

    #[test]
    fn the_wheels_the_agents_were_told_are_read_and_a_bad_limit_is_named() {
        let mut raw = BTreeMap::new();
        let info = RunInfo::parse(Path::new("r"), raw.clone()).unwrap();
        assert_eq!(info.wheels, formation_proto::WheelLimits::default());
        raw.insert("max_wheel_speed_mps".into(), "0.9".into());
        raw.insert("max_wheel_accel_mps2".into(), "1".into());
        let info = RunInfo::parse(Path::new("r"), raw.clone()).unwrap();
        assert_eq!(info.wheels.max_speed, Some(0.9));
        assert_eq!(info.wheels.max_accel, Some(1.0));
        for bad in ["fast", "0", "-1", "NaN"] {
            raw.insert("max_wheel_speed_mps".into(), bad.into());
            let err = RunInfo::parse(Path::new("r"), raw.clone()).unwrap_err();
            assert!(
                err.to_string().contains("max_wheel_speed_mps"),
                "{bad}: {err}"
            );
        }
    }
}
