//! Fuzzing every decoder of bytes from outside, on stable Rust.
//!
//! No nightly toolchain (and so no libFuzzer or sanitizer coverage) is available, so this is
//! property-based fuzzing with a driver of our own: each [`targets::Target`] is one decoder reached
//! through its crate's public API; its seed corpus (`tests/fuzz/corpus/NAME/`, made by the real
//! encoders with `formation-fuzz seed`) holds valid inputs; each case is a seed with one to four
//! mutations drawn with `arbitrary` ([`mutate`]), so most cases get past the decoder's first
//! check. The property is the same for every decoder: it returns (decoded or refused with an
//! error), it does not panic, it does not hang, and it stays within a memory limit
//! ([`campaign`]). A case that breaks it is saved, and becomes a regression test
//! (`fuzz/tests/regressions.rs`) once the decoder is fixed.

pub mod campaign;
pub mod corpus;
pub mod driver;
pub mod mutate;
pub mod targets;

use std::path::PathBuf;

/// Why the fuzzer itself could not run (not a finding: findings are in a campaign's report).
#[derive(Debug, thiserror::Error)]
pub enum FuzzError {
    /// No target of that name.
    #[error("no fuzz target named {name:?}; the targets are: {known}")]
    UnknownTarget {
        /// The name asked for.
        name: String,
        /// The known names.
        known: String,
    },
    /// A corpus folder or file could not be read or written.
    #[error("{action} {path}: {source}")]
    Corpus {
        /// What was being done.
        action: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A target's corpus folder holds no seed.
    #[error(
        "the corpus of {target} ({dir}) holds no seed; write the corpora with `formation-fuzz seed`"
    )]
    EmptyCorpus {
        /// The target.
        target: &'static str,
        /// Its folder.
        dir: PathBuf,
    },
    /// A seed file is larger than a case may be.
    #[error("seed {path} is larger than {max} bytes; keep seeds small (a few KiB)")]
    SeedTooLarge {
        /// The file.
        path: PathBuf,
        /// The cap, [`mutate::MAX_CASE_BYTES`].
        max: usize,
    },
    /// A target's real encoder failed to make a seed.
    #[error("making the seeds of {target}: {source}")]
    Seed {
        /// The target.
        target: &'static str,
        /// The encoder's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The scratch folder for decoders that read files could not be made.
    #[error("making a scratch folder for the fuzz cases: {source}")]
    Scratch {
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A finding could not be saved.
    #[error("saving a finding to {path}: {source}")]
    SaveFinding {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}
