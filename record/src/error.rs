//! Why a recording could not be made, with the path and the fix in every message.

use std::path::PathBuf;

use formation_proto::files::WriteError;

/// Why a recording could not be started, written or finished.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The folder to record into does not exist.
    #[error(
        "--record {}: the folder {} does not exist: create it first (mkdir -p {}) or record \
         somewhere else",
        path.display(), dir.display(), dir.display()
    )]
    MissingFolder {
        /// What `--record` named.
        path: PathBuf,
        /// The folder that is missing.
        dir: PathBuf,
    },
    /// The file to record into exists and is not a regular file (a device, a FIFO, a socket).
    #[error(
        "--record {}: it is {what}, not a regular file: name a file to record into (for example \
         run.mcap)",
        path.display()
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is.
        what: &'static str,
    },
    /// A file or folder could not be written (a full disk, a folder that is a file, no
    /// permission): the explanation names the path and the fix.
    #[error("recording: {0}")]
    Write(#[source] WriteError),
    /// The MCAP writer refused something other than an I/O failure.
    #[error("recording {}: the MCAP writer failed", path.display())]
    Mcap {
        /// The recording.
        path: PathBuf,
        /// The writer's error.
        #[source]
        source: mcap::McapError,
    },
    /// A message could not be encoded (a string with a NUL, a sequence too long for CDR).
    #[error("recording {}: a {topic} message could not be encoded", path.display())]
    Encode {
        /// The recording.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Why.
        #[source]
        source: formation_ros2::CdrEncodeError,
    },
    /// A model to reference or store could not be read.
    #[error(
        "recording {}: the model {} could not be read to hash or store it",
        path.display(), model.display()
    )]
    Model {
        /// The recording.
        path: PathBuf,
        /// The model file.
        model: PathBuf,
        /// The read's error.
        #[source]
        source: std::io::Error,
    },
    /// A model is larger than a recording stores.
    #[error(
        "recording {}: the model {} has {size} bytes, more than the {limit} a recording stores; \
         record with a model under onnx/models/ (referenced by its hash) or a smaller one",
        path.display(), model.display()
    )]
    ModelTooLarge {
        /// The recording.
        path: PathBuf,
        /// The model file.
        model: PathBuf,
        /// Its size.
        size: u64,
        /// The cap.
        limit: u64,
    },
    /// A recorder's settings file could not be read or written.
    #[error("recording settings {}", path.display())]
    Settings {
        /// The settings file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A recorder's settings file is not valid.
    #[error("recording settings {}: not valid settings JSON", path.display())]
    SettingsFormat {
        /// The settings file.
        path: PathBuf,
        /// Why.
        #[source]
        source: serde_json::Error,
    },
    /// The recording's thread ended without saying why (it panicked).
    #[error("recording {}: the recorder's thread stopped unexpectedly", path.display())]
    ThreadGone {
        /// The recording.
        path: PathBuf,
    },
}

impl RecordError {
    /// The MCAP writer's error on `path`: an I/O failure is explained from the path (a full
    /// disk, a folder that is a file, ...).
    pub fn from_mcap(path: &std::path::Path, error: mcap::McapError) -> RecordError {
        match error {
            mcap::McapError::Io(io) => RecordError::Write(WriteError::new(path, io)),
            other => RecordError::Mcap {
                path: path.to_path_buf(),
                source: other,
            },
        }
    }

    /// True for a full disk or a spent quota.
    pub fn is_out_of_space(&self) -> bool {
        matches!(self, RecordError::Write(e) if e.is_out_of_space())
    }
}
