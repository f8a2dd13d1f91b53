//! Why a recording could not be read ([`ReadError`], named `crate::read::ReadError`).
//!
//! It sits below the reader ([`crate::read`]) so that the values the reader decodes (a run's end
//! in [`crate::tick`], a swapped model's record in [`crate::swap`]) can say why they do not
//! parse without depending on the reader itself.

use std::path::PathBuf;

use crate::replay::{self, ReplayError};

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be opened or read.
    #[error("{}: cannot read the recording: check the path and its permissions", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The path is a folder, a device or another non-file.
    #[error("{}: it is {kind}, not a recording: name an .mcap file", path.display())]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The file does not start as an MCAP file does.
    #[error(
        "{}: not an MCAP file (it does not start with the MCAP magic): name a recording made \
         with --record",
        path.display()
    )]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// The file starts with the MCAP magic but ends before its first record: cut short (or
    /// still being written) before anything readable.
    #[error(
        "{}: the recording is too short to hold anything ({size} bytes, starting with the MCAP \
         magic): it was truncated before its first record (a crash, a full disk or an \
         interrupted copy), or is still being written: record the run again, or wait for the \
         recorder to finish",
        path.display()
    )]
    TooShort {
        /// The file.
        path: PathBuf,
        /// Its size \[bytes\].
        size: u64,
    },
    /// The file ends before the MCAP footer: it was cut short.
    #[error(
        "{}: the recording is truncated: {} (a crash, a full disk or an interrupted copy); the \
         steps before byte {read} were read, the rest of the run is missing: record the run \
         again for a full replay",
        path.display(),
        match unclosed_chunk {
            Some(at) => format!(
                "its last whole chunk ends at byte {read}, followed by a chunk the writer never \
                 closed (its header at byte {at} still holds the placeholder length)"
            ),
            _ => format!("it ends at byte {read} inside an MCAP record, before the footer"),
        }
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes read: where the readable part of the file ends.
        read: u64,
        /// Where a chunk the writer never closed begins, if the file ends with one.
        unclosed_chunk: Option<u64>,
    },
    /// The MCAP structure is broken (a bad CRC, a record that does not parse).
    #[error(
        "{}: the recording is corrupt near byte {read}: record the run again",
        path.display()
    )]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Bytes read when it was noticed.
        read: u64,
        /// The MCAP reader's error.
        #[source]
        source: mcap::McapError,
    },
    /// A record declares a string, map or data longer than the record itself (checked before
    /// the MCAP parser allocates it; [`crate::bounds`]).
    #[error(
        "{}: the recording is corrupt near byte {read}: record the run again",
        path.display()
    )]
    BadLength {
        /// The file.
        path: PathBuf,
        /// Bytes read when it was noticed.
        read: u64,
        /// The field and its lengths.
        #[source]
        source: crate::bounds::LengthError,
    },
    /// A replay step could not be decoded (another format version, bad CDR).
    #[error("{}: {topic}", path.display())]
    Step {
        /// The file.
        path: PathBuf,
        /// The replay channel.
        topic: String,
        /// Why.
        #[source]
        source: ReplayError,
    },
    /// The run's metadata record has a malformed key.
    #[error(
        "{}: the metadata record {record} has a bad {key} ({why}): the recording was not \
         written by formation, or was edited",
        path.display()
    )]
    Metadata {
        /// The file.
        path: PathBuf,
        /// The metadata record's name.
        record: &'static str,
        /// The key.
        key: String,
        /// What is wrong with it.
        why: String,
    },
    /// The file holds no replay channel: it was not recorded by formation's `--record` (or by a
    /// version before the replay channel).
    #[error(
        "{}: no formation replay channel ({} on /robot_<i>/replay) among its {} channels{}: \
         replay a recording made with formation's --record",
        path.display(), replay::TYPE_NAME, topics.len(), topic_list(topics)
    )]
    NoReplayChannel {
        /// The file.
        path: PathBuf,
        /// The topics it has.
        topics: Vec<String>,
    },
}

fn topic_list(topics: &[String]) -> String {
    if topics.is_empty() {
        return String::new();
    }
    let shown: Vec<&str> = topics.iter().take(8).map(String::as_str).collect();
    let more = if topics.len() > shown.len() {
        ", ..."
    } else {
        ""
    };
    format!(" ({}{more})", shown.join(", "))
}
