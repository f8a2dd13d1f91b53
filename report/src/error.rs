//! Errors of building a report: every variant names the file or directory at fault and says how to
//! fix it.

use std::path::PathBuf;

/// Why a report could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The input directory does not exist.
    #[error(
        "input directory {} does not exist: pass the directory that `formation eval --out DIR/...` or `formation demo --out DIR` wrote",
        dir.display()
    )]
    MissingInputDir {
        /// The directory given.
        dir: PathBuf,
    },
    /// The input path is not a directory.
    #[error(
        "{} is not a directory: pass the directory holding the eval outputs (each with a summary.json)",
        path.display()
    )]
    NotADirectory {
        /// The path given.
        path: PathBuf,
    },
    /// No `summary.json` (nor `scaling*.json`, `response*.json` or `ladder*.json`) anywhere under
    /// the input directory.
    #[error(
        "no eval or run output under {}: run `formation eval --out {}/...`, `formation eval --robots 3,5,8 --json .../scaling.json`, `formation eval --ladder pioneer-p3dx --json .../ladder.json` or `formation demo` first",
        dir.display(),
        dir.display()
    )]
    NoEvalOutput {
        /// The directory searched.
        dir: PathBuf,
    },
    /// A file or directory could not be read.
    #[error("could not read {}: {source}", path.display())]
    Read {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A run log, summary or profile could not be read: another format or schema version, not
    /// JSON of its shape, too large, or unreadable (the error names the file).
    #[error(transparent)]
    Schema(#[from] formation_schema::SchemaError),
    /// A JSON input parsed but holds values the report cannot draw.
    #[error("{} holds invalid data: {reason}", path.display())]
    InvalidData {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A training loss CSV is malformed.
    #[error(
        "{} line {line}: {reason} (expected a header `epoch,train_loss,val_loss[,seconds]` and one row of numbers per epoch)",
        path.display()
    )]
    LossCsv {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The report or a figure could not be written: what stood in the way (a file where a
    /// folder should be, a full disk, ...).
    #[error(transparent)]
    Output(#[from] formation_proto::files::WriteError),
    /// A stale output file could not be removed.
    #[error("could not write {}: {source}", path.display())]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// `--out` names a file the report reads (or would read, the next time it is built from
    /// the same folder): writing the page there would destroy an input.
    #[error(
        "--out {}: that is the name of one of the report's inputs ({what}): the HTML page would \
         overwrite it and the next report would fail: name an .html file instead (for example \
         {})",
        out.display(), example.display()
    )]
    OutIsInput {
        /// The output file given.
        out: PathBuf,
        /// What input such a file is.
        what: &'static str,
        /// A file name that is no input.
        example: PathBuf,
    },
    /// Plotting a figure failed.
    #[error("could not draw figure {figure}: {message}")]
    Plot {
        /// The figure's id.
        figure: String,
        /// The plotting library's message.
        message: String,
    },
}
