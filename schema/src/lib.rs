//! The files formation writes and reads, defined once: the serde types of each file, its format
//! name and schema version, and a bounded reader per format.
//!
//! | file | type | `format` | `schema_version` |
//! |---|---|---|---|
//! | `runs/run-NNNN.json` | [`RunLog`] | [`RunLog::FORMAT`] | [`RunLog::VERSION`] |
//! | `timing/run-NNNN.json` | [`TimingLog`] | [`TimingLog::FORMAT`] | [`TimingLog::VERSION`] |
//! | `summary.json`, `formation eval --json` | [`EvalOutput`] | [`EvalOutput::FORMAT`] | [`EvalOutput::VERSION`] |
//! | `profile.json` | [`LatencyProfile`] | [`LatencyProfile::FORMAT`] | [`LatencyProfile::VERSION`] |
//! | `formation eval --robots ... --json` | [`ScalingTable`] | [`ScalingTable::FORMAT`] | [`ScalingTable::VERSION`] |
//! | `formation eval --ladder PROFILE --json` | [`LadderTable`] | [`LadderTable::FORMAT`] | [`LadderTable::VERSION`] |
//! | `formation eval --shard FILE` (a share of the runs, for `formation merge`) | [`EvalShard`] | [`EvalShard::FORMAT`] | [`EvalShard::VERSION`] |
//! | `formation replay --json` | [`ReplayReport`] | [`ReplayReport::FORMAT`] | [`ReplayReport::VERSION`] |
//! | `formation gauge --json`, `response.json` | [`ResponseCurve`] | [`ResponseCurve::FORMAT`] | [`ResponseCurve::VERSION`] |
//!
//! A format may read older versions than it writes ([`SchemaFile::OLDEST_VERSION`]): the run log
//! is written as version 2 (its trajectory names its neighbour rule) and version 1 files still
//! read, as the all-pairs formation they were; a build that reads only version 1 refuses a
//! version 2 file with the message that says which versions it reads.
//!
//! Every file is one JSON object whose first two keys are `format` and `schema_version`, followed
//! by the type's own fields: [`to_json`] and [`to_json_pretty`] write them, [`from_json`] and the
//! readers ([`read_run_log`], [`read_timing_log`], [`read_summary`], [`read_profile`]) check them
//! before reading the rest, so a file of another format or version is refused with an error that
//! names the file, what it is and the version this build reads ([`SchemaError`]). A file without
//! either key was written before files carried them; it reads as version 1, whose shape is the
//! one those files have.
//!
//! The types are plain data; what computes them (metrics, summaries, percentiles) lives with
//! the code that needs it (`formation-world`, `formation-cli`). The run journal, written line by
//! line while a run plays, has its own format and version in `formation_world::runlog`.
//!
//! Floats a writer could not compute are NaN, which JSON has no word for: serde_json writes
//! `null`, and the readers read `null` back as NaN wherever a float may be NaN (the metrics and
//! the trajectory). Every other float reads back bit for bit (`float_roundtrip`).

mod goal_speed;
mod ladder;
mod model_input;
mod nan;
mod profile;
mod replay;
mod response;
mod run;
mod scaling;
mod shard;
mod summary;
mod team_size;
mod timing;

use std::fmt;
use std::path::{Path, PathBuf};

use formation_proto::files::{FileRefusal, read_bounded};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

pub use goal_speed::ModelGoalSpeed;
pub use ladder::{LadderRung, LadderTable};
pub use model_input::{ModelInput, trim_decimals, trim_number};
pub use profile::{LatencyProfile, StageStats};
pub use replay::{ReplayReport, ReplayRobot};
pub use response::{
    MIN_JUDGED_SAMPLES, RESPONSE_BIN_EDGES, ResponseBin, ResponseCurve, ResponseRow,
};
pub use run::{RunLog, RunMetrics, TeamMetrics, TicksPlayed, Trajectory};
pub use scaling::{ScalingRow, ScalingTable};
pub use shard::EvalShard;
pub use summary::{Coverage, EvalOutput, IncompleteRun, MediansOver, Quantiles, Summary};
pub use team_size::ModelTeamSize;
pub use timing::TimingLog;

/// A file format: its name, its version and how large a file of it may be.
pub trait SchemaFile: Serialize + DeserializeOwned {
    /// The `format` key of every file of this kind.
    const FORMAT: &'static str;
    /// The `schema_version` this build writes (and the newest it reads).
    const VERSION: u32;
    /// The oldest `schema_version` this build still reads (by default only [`Self::VERSION`]).
    const OLDEST_VERSION: u32 = Self::VERSION;
    /// What the file is, for messages (`"formation run log"`).
    const WHAT: &'static str;
    /// The largest file read \[bytes\].
    const MAX_BYTES: u64;
}

/// Implements [`SchemaFile`] for each format of the table below, one row a format:
/// `Type: "format", versions OLDEST..=VERSION (or version VERSION), "what it is", MAX_BYTES;`.
macro_rules! schema_files {
    ($($(#[$doc:meta])* $file:ty: $format:literal, $(version $version:literal)? $(versions $oldest:literal..=$newest:literal)?, $what:literal, $max_bytes:expr;)*) => {
        $(
            $(#[$doc])*
            impl SchemaFile for $file {
                const FORMAT: &'static str = $format;
                $(const VERSION: u32 = $version;)?
                $(const VERSION: u32 = $newest;
                const OLDEST_VERSION: u32 = $oldest;)?
                const WHAT: &'static str = $what;
                const MAX_BYTES: u64 = $max_bytes;
            }
        )*
    };
}

schema_files! {
    /// Version 2 names its trajectory's neighbour rule; version 1 reads as all pairs.
    RunLog: "formation-run-log", versions 1..=2, "formation run log", 2 << 30;
    /// Version 2 times each used command from the scan it answered (version 1 from the current
    /// tick's scan, which under lag understated the round trip) and may hold the outcome
    /// `agent_down`; version 1 files read unchanged.
    TimingLog: "formation-timing-log", versions 1..=2, "formation timing log", 2 << 30;
    EvalOutput: "formation-eval-summary", version 1, "formation evaluation summary", 256 << 20;
    LatencyProfile: "formation-latency-profile", version 1, "formation latency profile", 256 << 20;
    ScalingTable: "formation-scaling-table", version 1, "formation scaling table", 16 << 20;
    LadderTable: "formation-ladder", version 1, "formation reality ladder", 16 << 20;
    EvalShard: "formation-eval-shard", version 1, "formation evaluation shard", 256 << 20;
    ReplayReport: "formation-replay", version 1, "formation replay report", 64 << 20;
    ResponseCurve: "formation-response-curve", version 1, "formation response curve", 4 << 20;
}

/// The JSON bytes of `value`, with its `format` and `schema_version` first.
pub fn to_json<F: SchemaFile>(value: &F) -> Result<Vec<u8>, serde_json::Error> {
    serde_json::to_vec(&Versioned::of(value))
}

/// [`to_json`], indented for people to read.
pub fn to_json_pretty<F: SchemaFile>(value: &F) -> Result<Vec<u8>, serde_json::Error> {
    serde_json::to_vec_pretty(&Versioned::of(value))
}

/// Reads a file of format `F` from `bytes`; `path` is where they came from, for messages.
pub fn from_json<F: SchemaFile>(bytes: &[u8], path: &Path) -> Result<F, SchemaError> {
    let parse_error = |source| SchemaError::Parse {
        path: path.to_path_buf(),
        what: F::WHAT,
        source,
    };
    let probe: Probe = serde_json::from_slice(bytes).map_err(parse_error)?;
    // A file with neither key predates them: version 1 of this format.
    let (format, version) = match (probe.format, probe.schema_version) {
        (None, None) => (F::FORMAT.to_owned(), 1),
        (format, version) => (format.unwrap_or_default(), version.unwrap_or(0)),
    };
    if format != F::FORMAT {
        return Err(SchemaError::Format {
            path: path.to_path_buf(),
            what: F::WHAT,
            expected: F::FORMAT,
            found: format,
        });
    }
    if !(u64::from(F::OLDEST_VERSION)..=u64::from(F::VERSION)).contains(&version) {
        return Err(SchemaError::Version {
            path: path.to_path_buf(),
            what: F::WHAT,
            oldest: F::OLDEST_VERSION,
            expected: F::VERSION,
            found: version,
        });
    }
    serde_json::from_slice(bytes).map_err(parse_error)
}

/// Reads the file of format `F` at `path`: only a regular file of at most [`SchemaFile::MAX_BYTES`].
pub fn read<F: SchemaFile>(path: &Path) -> Result<F, SchemaError> {
    let bytes = read_bounded(path, F::MAX_BYTES).map_err(|refusal| match refusal {
        FileRefusal::NotAFile { kind } => SchemaError::NotAFile {
            path: path.to_path_buf(),
            what: F::WHAT,
            kind,
        },
        FileRefusal::TooLarge { .. } => SchemaError::TooLarge {
            path: path.to_path_buf(),
            what: F::WHAT,
            limit: F::MAX_BYTES,
        },
        FileRefusal::Io(source) => SchemaError::Read {
            path: path.to_path_buf(),
            what: F::WHAT,
            source,
        },
    })?;
    from_json(&bytes, path)
}

/// Reads a run log (`runs/run-NNNN.json`).
pub fn read_run_log(path: &Path) -> Result<RunLog, SchemaError> {
    read(path)
}

/// Reads a timing log (`timing/run-NNNN.json`).
pub fn read_timing_log(path: &Path) -> Result<TimingLog, SchemaError> {
    read(path)
}

/// Reads an evaluation summary (`summary.json`, or what `formation eval --json` wrote).
pub fn read_summary(path: &Path) -> Result<EvalOutput, SchemaError> {
    read(path)
}

/// Reads a scaling table (what `formation eval --robots ... --json` wrote).
pub fn read_scaling(path: &Path) -> Result<ScalingTable, SchemaError> {
    read(path)
}

/// Reads a reality ladder (what `formation eval --ladder PROFILE --json` wrote).
pub fn read_ladder(path: &Path) -> Result<LadderTable, SchemaError> {
    read(path)
}

/// Reads a latency profile (`profile.json`).
pub fn read_profile(path: &Path) -> Result<LatencyProfile, SchemaError> {
    read(path)
}

/// Reads a response curve (what `formation gauge --json` wrote).
pub fn read_response(path: &Path) -> Result<ResponseCurve, SchemaError> {
    read(path)
}

/// Reads a replay report (what `formation replay --json` wrote).
pub fn read_replay(path: &Path) -> Result<ReplayReport, SchemaError> {
    read(path)
}

/// A value written with its format and version ahead of its own fields.
#[derive(Serialize)]
struct Versioned<'a, F> {
    format: &'static str,
    schema_version: u32,
    #[serde(flatten)]
    body: &'a F,
}

impl<'a, F: SchemaFile> Versioned<'a, F> {
    fn of(body: &'a F) -> Versioned<'a, F> {
        Versioned {
            format: F::FORMAT,
            schema_version: F::VERSION,
            body,
        }
    }
}

/// The two keys alone, read before the rest.
#[derive(Deserialize)]
struct Probe {
    #[serde(default)]
    format: Option<String>,
    #[serde(default)]
    schema_version: Option<u64>,
}

/// Why a file could not be read. Every variant names the file and what it was read as.
#[derive(Debug)]
pub enum SchemaError {
    /// The operating system refused (missing file, permissions, ...).
    Read {
        /// The file.
        path: PathBuf,
        /// What it was read as.
        what: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// The path is not a regular file.
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it was read as.
        what: &'static str,
        /// What it is instead (`"a directory"`, ...).
        kind: &'static str,
    },
    /// The file is larger than any file of its format.
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What it was read as.
        what: &'static str,
        /// The limit \[bytes\].
        limit: u64,
    },
    /// The file is not JSON of the expected shape (often a truncated file).
    Parse {
        /// The file.
        path: PathBuf,
        /// What it was read as.
        what: &'static str,
        /// The parser's error, with line and column.
        source: serde_json::Error,
    },
    /// The file is of another format.
    Format {
        /// The file.
        path: PathBuf,
        /// What it was read as.
        what: &'static str,
        /// The format expected.
        expected: &'static str,
        /// Its `format` (empty when it has none).
        found: String,
    },
    /// The file is of this format, in another schema version.
    Version {
        /// The file.
        path: PathBuf,
        /// What it is.
        what: &'static str,
        /// The oldest version this build reads.
        oldest: u32,
        /// The newest version this build reads (the one it writes).
        expected: u32,
        /// Its `schema_version` (0 when it has none).
        found: u64,
    },
}

impl SchemaError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            SchemaError::Read { path, .. }
            | SchemaError::NotAFile { path, .. }
            | SchemaError::TooLarge { path, .. }
            | SchemaError::Parse { path, .. }
            | SchemaError::Format { path, .. }
            | SchemaError::Version { path, .. } => path,
        }
    }
}

impl fmt::Display for SchemaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let path = self.path().display();
        match self {
            SchemaError::Read { what, source, .. } => {
                write!(f, "could not read the {what} {path}: {source}")
            }
            SchemaError::NotAFile { what, kind, .. } => {
                write!(f, "{path} is {kind}, not a {what}")
            }
            SchemaError::TooLarge { what, limit, .. } => write!(
                f,
                "{path} is larger than {limit} bytes, more than any {what}; is it the right file?"
            ),
            SchemaError::Parse { what, source, .. } => write!(
                f,
                "could not parse the {what} {path}: {source} (is the file truncated? re-run the command that wrote it)"
            ),
            SchemaError::Format {
                what,
                expected,
                found,
                ..
            } if found.is_empty() => write!(
                f,
                "{path} is not a {what}: it has a `schema_version` but no `format` (expected `{expected}`)"
            ),
            SchemaError::Format {
                what,
                expected,
                found,
                ..
            } => write!(
                f,
                "{path} is not a {what}: its format is `{found}`, expected `{expected}`"
            ),
            SchemaError::Version {
                what,
                oldest,
                expected,
                found: 0,
                ..
            } => write!(
                f,
                "{path} is a {what} without a schema version; this build reads {}: re-run it or use the matching formation version",
                versions(*oldest, *expected)
            ),
            SchemaError::Version {
                what,
                oldest,
                expected,
                found,
                ..
            } => write!(
                f,
                "{path} is a {what} of schema version {found}; this build reads {}: re-run it or use the matching formation version",
                versions(*oldest, *expected)
            ),
        }
    }
}

/// `version N` or `versions A to B`.
pub fn versions(oldest: u32, newest: u32) -> String {
    if oldest == newest {
        format!("version {newest}")
    } else {
        format!("versions {oldest} to {newest}")
    }
}

/// The message already says what the OS or the parser said, so no error is given as the source
/// (an error chain would say it twice).
impl std::error::Error for SchemaError {}

#[cfg(test)]
mod tests;
