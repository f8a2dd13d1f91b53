//! The run logs of the multi-process runtime, and the run journal that keeps a run that ends
//! abnormally.
//!
//! Layout under an output directory:
//!
//! * `runs/run-NNNN.json`: a [`RunLog`], the trajectory with its metrics (the format
//!   `formation eval --out` writes too, so the report reads both). `complete` is false for a run
//!   that stopped early (its metrics are over the ticks it played), with the reason in
//!   `stop_reason`.
//! * `timing/run-NNNN.json`: a [`TimingLog`], the per-tick timing of one run.
//!
//!   Both are defined, with their format names and schema versions, in [`formation_schema`],
//!   which reads them ([`formation_schema::read_run_log`]); [`write_json_atomic`] writes them.
//! * `runs/run-NNNN.journal`: the run journal, present only while a run plays (or after a world
//!   that was killed). It is JSON Lines, written as the run goes by [`RunJournal`]:
//!
//!   ```text
//!   {"format":"formation-run-journal","version":1,"index":0,"clock":"lockstep","dt":0.05,
//!    "d_star":2.0,"v_star":0.7,"edges":[[0,1],[0,2],[1,2]],"n_robots":3,"ticks":1200,
//!    "seed":7,"models":["m-1a2b"]}
//!   {"k":0,"time":0.0,"phi_star":3.76,"poses":[{"x":..,"y":..,"theta":..},..]}
//!   {"k":1,"time":0.05,"phi_star":3.76,"poses":[..],"commands":[{"left":..,"right":..},..]}
//!   {"k":2,"time":0.1,"phi_star":3.76,"poses":[..],"commands":[..],"collisions":[[0,1]]}
//!   ```
//!
//!   The first line is the [`JournalHeader`] (format name, [`JOURNAL_VERSION`] and the run's
//!   static data); then one [`JournalSample`] line per recorded state `k = 0, 1, ..`: its time,
//!   desired heading and poses, the commands the world applied at tick `k - 1` that led to it
//!   (absent for `k = 0`) and the robot pairs found overlapping in it. Numbers are written so
//!   that they read back bit for bit. [`recover_journal`] turns a journal back into a
//!   [`RunLog`] (`complete = false`), dropping a torn last line.
//!
//! Files other than the journal are written to a temporary name in the same directory and
//! renamed ([`write_atomic`]), so a reader never sees half a file, and a failed write removes its
//! temporary file. Every read is bounded ([`MAX_FILE_BYTES`], [`MAX_LINE_BYTES`]).

use std::fs::{self, File};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use formation_proto::{NeighbourRule, Pose, WheelCmd};
use formation_schema::SchemaFile;
use serde::{Deserialize, Serialize};

use crate::episode::Trajectory;
use crate::metrics::{MetricsConfig, run_metrics};
use crate::scenario::RunSpec;

/// The `format` of a run journal's header line.
pub const JOURNAL_FORMAT: &str = "formation-run-journal";
/// The journal version this build writes and reads.
pub const JOURNAL_VERSION: u32 = 1;
/// The largest journal read \[bytes\].
pub const MAX_FILE_BYTES: u64 = 2 << 30;
/// The longest journal line read \[bytes\].
pub const MAX_LINE_BYTES: usize = 64 << 20;
/// A journal is flushed to the operating system at least this often while appended to.
pub const FLUSH_PERIOD: Duration = Duration::from_secs(1);
/// ... and whenever this much is buffered \[bytes\].
const FLUSH_BYTES: usize = 64 << 10;
/// Directory levels [`find_run_dirs`] searches.
const MAX_SEARCH_DEPTH: usize = 12;

/// The run log (`runs/run-NNNN.json`) and the timing log (`timing/run-NNNN.json`), defined in
/// [`formation_schema`].
pub use formation_schema::{RunLog, TimingLog};

/// Why a run log or journal could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum RunLogError {
    /// Writing failed: what stood in the way (a full disk, a file where a folder should be, ...).
    #[error(transparent)]
    Write(Box<WriteError>),
    /// Reading failed.
    #[error("could not read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is larger than this build reads.
    #[error("{} is larger than {limit} bytes; it is not a run log or journal of this tool", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit \[bytes\].
        limit: u64,
    },
    /// A JSON value could not be parsed.
    #[error("could not parse {}{}: {source}", path.display(), line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line, for a journal.
        line: Option<usize>,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// The file is not a run journal.
    #[error(
        "{} is not a run journal (its first line should be a `{JOURNAL_FORMAT}` header); was it written by formation-world?",
        path.display()
    )]
    NotAJournal {
        /// The file.
        path: PathBuf,
    },
    /// A journal of another format version.
    #[error(
        "{} is a run journal of version {found}, but this build reads version {JOURNAL_VERSION}; recover it with the formation version that wrote it",
        path.display()
    )]
    Version {
        /// The file.
        path: PathBuf,
        /// Its version.
        found: u32,
    },
    /// A journal that records no state: there is no run to keep.
    #[error(
        "{} records no state (the world stopped before its first tick was saved); there is no run to keep",
        path.display()
    )]
    NoSamples {
        /// The journal.
        path: PathBuf,
    },
    /// A running world still writes the journal.
    #[error("{} is being written by a running world; left alone", path.display())]
    InUse {
        /// The journal.
        path: PathBuf,
    },
    /// A journal line contradicts the header or the lines before it.
    #[error("{} line {line}: {reason}; the journal is damaged", path.display())]
    Inconsistent {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The journal was written to before and failed; it takes no more lines.
    #[error("the run journal {} failed earlier and takes no more lines", path.display())]
    Failed {
        /// The journal.
        path: PathBuf,
    },
}

/// A file that could not be written, explained from its path.
pub use formation_proto::files::WriteError;

fn write_error(path: &Path) -> impl FnOnce(std::io::Error) -> RunLogError + '_ {
    move |source| RunLogError::Write(Box::new(WriteError::new(path, source)))
}

/// Paths of run `index`'s logs under `out`: `runs/run-NNNN.json` and `timing/run-NNNN.json`.
pub fn log_paths(out: &Path, index: usize) -> (PathBuf, PathBuf) {
    let name = format!("run-{index:04}.json");
    (out.join("runs").join(&name), out.join("timing").join(name))
}

/// Path of run `index`'s journal under `out`: `runs/run-NNNN.journal`.
pub fn journal_path(out: &Path, index: usize) -> PathBuf {
    out.join("runs").join(format!("run-{index:04}.journal"))
}

/// Writes `bytes` to `path` with [`formation_proto::files::write_atomic`]: the whole file or,
/// on failure, the old one and no temporary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RunLogError> {
    formation_proto::files::write_atomic(path, bytes).map_err(write_error(path))
}

/// Writes a file of one of [`formation_schema`]'s formats (a run or timing log) as JSON, with its
/// format name and schema version, with [`write_atomic`].
pub fn write_json_atomic<F: SchemaFile>(path: &Path, value: &F) -> Result<(), RunLogError> {
    let bytes = formation_schema::to_json(value)
        .map_err(|source| write_error(path)(std::io::Error::other(source)))?;
    write_atomic(path, &bytes)
}

// ---- the journal format ----------------------------------------------------------------------

fn all_pairs_rule() -> NeighbourRule {
    NeighbourRule::AllPairs
}

/// The first line of a run journal: what identifies the format and the run's static data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JournalHeader {
    /// Always [`JOURNAL_FORMAT`].
    pub format: String,
    /// The format version, [`JOURNAL_VERSION`] when written by this build.
    pub version: u32,
    /// Run index within the scenario.
    pub index: usize,
    /// `lockstep` or `realtime`.
    pub clock: String,
    /// Time step \[s\].
    pub dt: f64,
    /// Desired pairwise distance \[m\].
    pub d_star: f64,
    /// Desired speed \[m/s\].
    pub v_star: f64,
    /// Formation edges of the first sample (all pairs for the paper's formation).
    pub edges: Vec<(usize, usize)>,
    /// The neighbour rule (journals written before it existed were all pairs).
    #[serde(default = "all_pairs_rule")]
    pub neighbours: NeighbourRule,
    /// Team size.
    pub n_robots: usize,
    /// Ticks the run is to play.
    pub ticks: u64,
    /// The run's own seed.
    pub seed: u64,
    /// The model each robot's agent reported when the run began.
    pub models: Vec<String>,
}

impl JournalHeader {
    /// The header of run `spec` played with `clock` by agents running `models`.
    pub fn new(spec: &RunSpec, clock: &str, models: &[String]) -> JournalHeader {
        JournalHeader {
            format: JOURNAL_FORMAT.to_owned(),
            version: JOURNAL_VERSION,
            index: spec.index,
            clock: clock.to_owned(),
            dt: spec.world.dt,
            d_star: spec.d_star,
            v_star: spec.v_star,
            edges: crate::neighbours::first_sample_edges(spec.neighbours, &spec.initial),
            neighbours: spec.neighbours,
            n_robots: spec.n_robots,
            ticks: spec.ticks(),
            seed: spec.seed,
            models: models.to_vec(),
        }
    }
}

/// One journal line after the header: the state at sample `k` and how it was reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JournalSample {
    /// Sample index, `0, 1, ..` in order.
    pub k: u64,
    /// Sample time \[s\].
    pub time: f64,
    /// Desired heading \[rad\].
    pub phi_star: f64,
    /// Every robot's pose.
    pub poses: Vec<Pose>,
    /// The commands applied at tick `k - 1` (absent for `k = 0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands: Option<Vec<WheelCmd>>,
    /// Pairs `(i, j)` overlapping at this sample.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub collisions: Vec<(usize, usize)>,
}

/// The format and version keys alone, read before the rest of the header.
#[derive(Deserialize)]
struct FormatProbe {
    #[serde(default)]
    format: Option<String>,
    #[serde(default)]
    version: Option<u32>,
}

// ---- writing ---------------------------------------------------------------------------------

/// Where a [`RunJournal`] reads the time, so tests can drive its flush period.
pub trait JournalClock {
    /// The current instant.
    fn now(&mut self) -> Instant;
}

/// The monotonic system clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl JournalClock for SystemClock {
    fn now(&mut self) -> Instant {
        Instant::now()
    }
}

impl<F: FnMut() -> Instant> JournalClock for F {
    fn now(&mut self) -> Instant {
        self()
    }
}

/// Writes a run journal as the run goes: [`RunJournal::append`] after every step writes the
/// trajectory's new entries, buffered and flushed to the operating system at least every
/// [`FLUSH_PERIOD`] (and whenever 64 KiB are buffered), so a killed process loses at most the
/// last second. A write error is returned at once and truncates the file back to its last whole
/// line (or removes it when not even the header was written); the journal then refuses further
/// lines. While open, the file holds an exclusive advisory lock, so [`recover_journals`] leaves
/// the journal of a running world alone.
pub struct RunJournal<C: JournalClock = SystemClock> {
    path: PathBuf,
    file: Option<File>,
    buffer: Vec<u8>,
    /// Bytes of whole lines the operating system has accepted.
    committed: u64,
    /// Samples and collisions of the trajectory written so far.
    samples: usize,
    collisions: usize,
    last_flush: Instant,
    clock: C,
}

impl RunJournal<SystemClock> {
    /// Creates (or truncates) the journal at `path` and writes its header through to the file.
    pub fn create(path: &Path, header: &JournalHeader) -> Result<Self, RunLogError> {
        RunJournal::create_with_clock(path, header, SystemClock)
    }
}

impl<C: JournalClock> RunJournal<C> {
    /// [`RunJournal::create`] with the clock the flush period is measured on.
    pub fn create_with_clock(
        path: &Path,
        header: &JournalHeader,
        mut clock: C,
    ) -> Result<Self, RunLogError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            formation_proto::files::create_private_dir_all(dir)
                .map_err(|e| RunLogError::Write(Box::new(WriteError::creating_dir(dir, e))))?;
        }
        let file = formation_proto::files::create_private_file(path).map_err(write_error(path))?;
        // Advisory only: a file system without locks still journals.
        let _ = file.lock();
        let mut journal = RunJournal {
            path: path.to_path_buf(),
            file: Some(file),
            buffer: Vec::with_capacity(FLUSH_BYTES * 2),
            committed: 0,
            samples: 0,
            collisions: 0,
            last_flush: clock.now(),
            clock,
        };
        journal.push_line(header)?;
        journal.flush()?;
        Ok(journal)
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Samples written so far (buffered or flushed).
    pub fn samples_written(&self) -> usize {
        self.samples
    }

    /// Writes the entries `trajectory` gained since the last call (it must be the same growing
    /// trajectory), and flushes when the flush period has passed or the buffer is large.
    pub fn append(&mut self, trajectory: &Trajectory) -> Result<(), RunLogError> {
        if self.file.is_none() {
            return Err(RunLogError::Failed {
                path: self.path.clone(),
            });
        }
        let available = trajectory
            .times
            .len()
            .min(trajectory.phi_star.len())
            .min(trajectory.poses.len());
        while self.samples < available {
            let k = self.samples;
            let commands = if k == 0 {
                None
            } else {
                trajectory.commands.get(k - 1).cloned()
            };
            let mut collisions = Vec::new();
            while let Some(&(sample, i, j)) = trajectory.collisions.get(self.collisions) {
                if sample > k as u64 {
                    break;
                }
                collisions.push((i, j));
                self.collisions += 1;
            }
            let line = JournalSample {
                k: k as u64,
                time: trajectory.times[k],
                phi_star: trajectory.phi_star[k],
                poses: trajectory.poses[k].clone(),
                commands,
                collisions,
            };
            self.push_line(&line)?;
            self.samples += 1;
        }
        let now = self.clock.now();
        if self.buffer.len() >= FLUSH_BYTES || now.duration_since(self.last_flush) >= FLUSH_PERIOD {
            self.flush()?;
        }
        Ok(())
    }

    /// Hands everything buffered to the operating system.
    pub fn flush(&mut self) -> Result<(), RunLogError> {
        let now = self.clock.now();
        let Some(file) = self.file.as_mut() else {
            return Err(RunLogError::Failed {
                path: self.path.clone(),
            });
        };
        if !self.buffer.is_empty() {
            if let Err(source) = file.write_all(&self.buffer) {
                self.fail();
                return Err(write_error(&self.path)(source));
            }
            self.committed += self.buffer.len() as u64;
            self.buffer.clear();
        }
        self.last_flush = now;
        Ok(())
    }

    /// Flushes and closes the journal (releasing its lock); returns its path.
    pub fn close(mut self) -> Result<PathBuf, RunLogError> {
        self.flush()?;
        self.file = None;
        Ok(self.path.clone())
    }

    fn push_line<T: Serialize>(&mut self, value: &T) -> Result<(), RunLogError> {
        let before = self.buffer.len();
        if let Err(source) = serde_json::to_writer(&mut self.buffer, value) {
            self.buffer.truncate(before);
            return Err(write_error(&self.path)(std::io::Error::other(source)));
        }
        self.buffer.push(b'\n');
        Ok(())
    }

    /// After a failed write: drops what was buffered, cuts the file back to its whole lines (or
    /// removes it when the header is not among them) and refuses further lines. Only a regular
    /// file is cut or removed (never a device such as `/dev/full`).
    fn fail(&mut self) {
        self.buffer.clear();
        if let Some(file) = self.file.take() {
            let regular = file.metadata().is_ok_and(|m| m.is_file());
            if regular {
                let _ = file.set_len(self.committed);
            }
            drop(file);
            if regular && self.committed == 0 {
                let _ = fs::remove_file(&self.path);
            }
        }
    }
}

// ---- reading and recovering ------------------------------------------------------------------

/// Rebuilds the run a journal records as a [`RunLog`]: the trajectory up to the last whole line
/// (a torn last line, as a killed writer leaves, is dropped), the metrics over the ticks recorded
/// against the ticks the header planned, and so `complete = false` unless every tick was
/// journaled; the header's models. `stop_reason` is left
/// for the caller. Refuses files that are not journals, journals of another version, and damaged
/// lines before the last.
pub fn recover_journal(path: &Path) -> Result<RunLog, RunLogError> {
    let (header, trajectory) = read_journal(path)?;
    let metrics = run_metrics(&trajectory, header.ticks, &MetricsConfig::default());
    Ok(RunLog {
        index: header.index,
        complete: metrics.is_complete(),
        metrics,
        trajectory,
        clock: header.clock,
        models: header.models,
        stop_reason: None,
        planned_ticks: Some(header.ticks),
    })
}

/// The metrics of a run log, with an incomplete run never counted as a success: a log written
/// before the metrics recorded it says so only by `complete = false` (the ticks it was to play
/// taken as unknown, one more than it played, when the log lacks them).
pub fn log_metrics(log: &RunLog) -> crate::metrics::RunMetrics {
    let mut metrics = log.metrics.clone();
    if !log.complete && metrics.is_complete() {
        let ticks = log.ticks() as u64;
        crate::metrics::mark_incomplete(
            &mut metrics,
            crate::metrics::TicksPlayed {
                ticks,
                planned_ticks: log.planned_ticks.unwrap_or(ticks + 1),
            },
        );
    }
    metrics
}

/// Reads a journal's header and the trajectory its whole lines record.
pub fn read_journal(path: &Path) -> Result<(JournalHeader, Trajectory), RunLogError> {
    let read_error = |source| RunLogError::Read {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(read_error)?;
    let mut lines = JournalLines {
        reader: BufReader::new(file.take(MAX_FILE_BYTES + 1)),
        line: Vec::new(),
        path,
        total: 0,
    };
    let header = read_journal_header(&mut lines)?;
    let trajectory = read_journal_samples(&mut lines, &header)?;
    Ok((header, trajectory))
}

/// A journal read line by line: the reader, the line last read and the bytes read so far.
struct JournalLines<'a, R> {
    reader: R,
    line: Vec<u8>,
    path: &'a Path,
    total: u64,
}

impl<R: BufRead> JournalLines<'_, R> {
    /// Reads the next line into `self.line`, as [`next_line`] does.
    fn next(&mut self) -> Result<Option<bool>, RunLogError> {
        next_line(&mut self.reader, &mut self.line, self.path, &mut self.total)
    }
}

/// The error for line `line_no` of the journal at `path` that does not parse.
fn journal_parse_error(
    path: &Path,
    line_no: usize,
) -> impl FnOnce(serde_json::Error) -> RunLogError {
    move |source| RunLogError::Parse {
        path: path.to_path_buf(),
        line: Some(line_no),
        source,
    }
}

/// Reads and checks a journal's first line: a journal of this version, and its header.
fn read_journal_header<R: BufRead>(
    lines: &mut JournalLines<'_, R>,
) -> Result<JournalHeader, RunLogError> {
    let path = lines.path;
    let Some(whole) = lines.next()? else {
        return Err(RunLogError::NotAJournal {
            path: path.to_path_buf(),
        });
    };
    let probe: FormatProbe = serde_json::from_slice(&lines.line).map_err(|e| {
        if whole {
            RunLogError::NotAJournal {
                path: path.to_path_buf(),
            }
        } else {
            journal_parse_error(path, 1)(e)
        }
    })?;
    if probe.format.as_deref() != Some(JOURNAL_FORMAT) {
        return Err(RunLogError::NotAJournal {
            path: path.to_path_buf(),
        });
    }
    match probe.version {
        Some(JOURNAL_VERSION) => {}
        Some(found) => {
            return Err(RunLogError::Version {
                path: path.to_path_buf(),
                found,
            });
        }
        None => {
            return Err(RunLogError::NotAJournal {
                path: path.to_path_buf(),
            });
        }
    }
    serde_json::from_slice(&lines.line).map_err(journal_parse_error(path, 1))
}

/// Reads the samples after the header into a trajectory, up to the last whole line.
fn read_journal_samples<R: BufRead>(
    lines: &mut JournalLines<'_, R>,
    header: &JournalHeader,
) -> Result<Trajectory, RunLogError> {
    let mut trajectory = Trajectory {
        dt: header.dt,
        d_star: header.d_star,
        v_star: header.v_star,
        edges: header.edges.clone(),
        neighbours: header.neighbours,
        times: Vec::new(),
        phi_star: Vec::new(),
        poses: Vec::new(),
        commands: Vec::new(),
        collisions: Vec::new(),
    };
    let mut line_no = 1;
    while let Some(whole) = lines.next()? {
        line_no += 1;
        // A line that parses is whole even without its newline (a JSON object ends with `}`).
        let sample: JournalSample = match serde_json::from_slice(&lines.line) {
            Ok(sample) => sample,
            // A torn last line: the writer was stopped in the middle of it.
            Err(_) if !whole => break,
            Err(e) => {
                if lines.next()?.is_none() {
                    // The last line, ended but unparsable (e.g. zeros after a system crash).
                    break;
                }
                return Err(journal_parse_error(lines.path, line_no)(e));
            }
        };
        push_sample(
            &mut trajectory,
            sample,
            header.n_robots,
            lines.path,
            line_no,
        )?;
    }
    Ok(trajectory)
}

/// Checks that `sample` (journal line `line_no`) follows the trajectory so far with every
/// robot's pose and commands, and appends it.
fn push_sample(
    trajectory: &mut Trajectory,
    sample: JournalSample,
    n_robots: usize,
    path: &Path,
    line_no: usize,
) -> Result<(), RunLogError> {
    let inconsistent = |reason: String| RunLogError::Inconsistent {
        path: path.to_path_buf(),
        line: line_no,
        reason,
    };
    let k = trajectory.poses.len();
    if sample.k != k as u64 {
        return Err(inconsistent(format!(
            "expected sample {k}, found sample {}",
            sample.k
        )));
    }
    if sample.poses.len() != n_robots {
        return Err(inconsistent(format!(
            "{} poses for {} robots",
            sample.poses.len(),
            n_robots
        )));
    }
    match (&sample.commands, k) {
        (None, 0) => {}
        (Some(commands), k) if k > 0 && commands.len() == n_robots => {
            trajectory.commands.push(commands.clone());
        }
        (None, _) => return Err(inconsistent(format!("sample {k} lacks its commands"))),
        (Some(commands), _) => {
            return Err(inconsistent(format!(
                "{} commands at sample {k} for {} robots",
                commands.len(),
                n_robots
            )));
        }
    }
    trajectory.times.push(sample.time);
    trajectory.phi_star.push(sample.phi_star);
    trajectory.poses.push(sample.poses);
    trajectory
        .collisions
        .extend(sample.collisions.into_iter().map(|(i, j)| (sample.k, i, j)));
    Ok(())
}

/// Reads the next line into `line` (without its newline): `Some(true)` for a whole line,
/// `Some(false)` for a last line without a newline, `None` at the end.
fn next_line(
    reader: &mut impl BufRead,
    line: &mut Vec<u8>,
    path: &Path,
    total: &mut u64,
) -> Result<Option<bool>, RunLogError> {
    line.clear();
    let read = reader
        .take(MAX_LINE_BYTES as u64 + 1)
        .read_until(b'\n', line)
        .map_err(|source| RunLogError::Read {
            path: path.to_path_buf(),
            source,
        })?;
    *total += read as u64;
    if *total > MAX_FILE_BYTES {
        return Err(RunLogError::TooLarge {
            path: path.to_path_buf(),
            limit: MAX_FILE_BYTES,
        });
    }
    if read == 0 {
        return Ok(None);
    }
    if line.last() == Some(&b'\n') {
        line.pop();
        Ok(Some(true))
    } else if line.len() > MAX_LINE_BYTES {
        Err(RunLogError::TooLarge {
            path: path.to_path_buf(),
            limit: MAX_LINE_BYTES as u64,
        })
    } else {
        Ok(Some(false))
    }
}

/// What [`recover_journals`] did with one journal.
#[derive(Debug)]
pub struct JournalRecovery {
    /// The journal.
    pub journal: PathBuf,
    /// The run log written from it (the journal is then removed), or why none was.
    pub outcome: Result<RecoveredRun, RunLogError>,
}

/// A journal turned into a run log.
#[derive(Debug, Clone, PartialEq)]
pub struct RecoveredRun {
    /// The run log written.
    pub log: PathBuf,
    /// Its run index.
    pub index: usize,
    /// Ticks it records.
    pub ticks: usize,
}

/// Turns every journal in `out/runs/` that no running world holds into an incomplete
/// `runs/run-NNNN.json` (written atomically, `stop_reason` set to `stop_reason`) and removes the
/// journal. A journal whose run log cannot be written stays, to be recovered later; one that
/// records no state is removed ([`RunLogError::NoSamples`]); one a running world still holds is
/// left alone ([`RunLogError::InUse`]). A missing `runs/` directory recovers nothing.
pub fn recover_journals(out: &Path, stop_reason: &str) -> Vec<JournalRecovery> {
    journals_in(out)
        .into_iter()
        .map(|journal| {
            let outcome = if held_by_a_writer(&journal) {
                Err(RunLogError::InUse {
                    path: journal.clone(),
                })
            } else {
                recover_one(&journal, stop_reason)
            };
            JournalRecovery { journal, outcome }
        })
        .collect()
}

fn recover_one(journal: &Path, stop_reason: &str) -> Result<RecoveredRun, RunLogError> {
    let mut log = recover_journal(journal)?;
    if log.trajectory.poses.is_empty() {
        let _ = fs::remove_file(journal);
        return Err(RunLogError::NoSamples {
            path: journal.to_path_buf(),
        });
    }
    log.stop_reason = Some(stop_reason.to_owned());
    let dir = journal.parent().unwrap_or(Path::new("."));
    let path = dir.join(format!("run-{:04}.json", log.index));
    write_json_atomic(&path, &log)?;
    let _ = fs::remove_file(journal);
    Ok(RecoveredRun {
        log: path,
        index: log.index,
        ticks: log.ticks(),
    })
}

/// True for `run-*.journal`.
fn is_journal(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with("run-") && n.ends_with(".journal"))
        && path.is_file()
}

/// True when another open file holds the journal's lock (a world still writing it).
fn held_by_a_writer(journal: &Path) -> bool {
    match File::open(journal).map(|f| f.try_lock()) {
        Ok(Err(fs::TryLockError::WouldBlock)) => true,
        // Unlocked (the lock is dropped with the file), or no locking here: recover.
        _ => false,
    }
}

/// The directories under `root` (itself included) whose `runs/` holds a run journal
/// (`run-*.journal`) or a run log (`run-*.json`), sorted: the output directories of runs.
/// Hidden directories and `target` are not searched; symbolic links are not followed.
pub fn find_run_dirs(root: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    search_runs(root, 0, &mut found);
    found.sort();
    found.dedup();
    found
}

fn search_runs(dir: &Path, depth: usize, found: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let in_runs = dir.file_name().is_some_and(|n| n == "runs");
    for entry in entries.flatten() {
        let Ok(file_type) = entry.file_type() else {
            continue;
        };
        let name = entry.file_name().to_string_lossy().into_owned();
        if file_type.is_dir() {
            if depth < MAX_SEARCH_DEPTH && !name.starts_with('.') && name != "target" {
                search_runs(&entry.path(), depth + 1, found);
            }
        } else if file_type.is_file()
            && in_runs
            && name.starts_with("run-")
            && (name.ends_with(".journal") || name.ends_with(".json"))
            && let Some(out) = dir.parent()
        {
            found.push(out.to_path_buf());
        }
    }
}

/// The run journals in `out/runs/`, sorted.
pub fn journals_in(out: &Path) -> Vec<PathBuf> {
    let Ok(entries) = fs::read_dir(out.join("runs")) else {
        return Vec::new();
    };
    let mut journals: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| is_journal(p))
        .collect();
    journals.sort();
    journals
}

/// The run logs `out/runs/run-NNNN.json` with their index, sorted by index.
pub fn run_logs_in(out: &Path) -> Vec<(usize, PathBuf)> {
    let Ok(entries) = fs::read_dir(out.join("runs")) else {
        return Vec::new();
    };
    let mut logs: Vec<(usize, PathBuf)> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name();
            let index = name
                .to_str()?
                .strip_prefix("run-")?
                .strip_suffix(".json")?
                .parse()
                .ok()?;
            Some((index, e.path()))
        })
        .filter(|(_, p)| p.is_file())
        .collect();
    logs.sort();
    logs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{Controller, EpisodeError};
    use crate::run_episode_recorded;
    use crate::test_scratch::Scratch;
    use crate::test_support::RampTeam;
    use formation_proto::control::controller_fn;
    use std::cell::Cell;
    use std::rc::Rc;

    fn spec(duration_s: f64) -> RunSpec {
        let ramp = RampTeam {
            duration_s,
            v_star: 0.7,
            d_star: 0.6,
            beams: 36,
            noise_std: 0.01,
        };
        let mut spec = ramp.run_spec("journal-test", 5, 2);
        // Robots 0 and 1 start overlapping, so there are collisions to journal.
        spec.initial = vec![
            Pose::new(0.0, 0.0, 0.1),
            Pose::new(0.3, 0.05, 3.0),
            Pose::new(4.0, 4.0, 1.0),
        ];
        spec
    }

    /// Wheel speeds that vary per robot and tick (so the numbers are not round) and drive the
    /// robots into each other (so there are collisions to journal).
    fn wobble() -> impl Controller {
        controller_fn(|obs, out| {
            for (i, cmd) in out.iter_mut().enumerate() {
                let phase = obs.time * (1.0 + i as f64) + 0.1;
                *cmd = WheelCmd {
                    left: 0.4 * phase.sin() + 0.1 / 3.0,
                    right: 0.3 * phase.cos() + std::f64::consts::PI / 10.0,
                };
            }
            Ok(())
        })
    }

    /// A scratch folder of its own, and the path of run 2's journal in it.
    fn journal_in(tag: &str) -> (Scratch, PathBuf) {
        let scratch = Scratch::new(&format!("runlog-{tag}"));
        let path = scratch.path().join("run-0002.journal");
        (scratch, path)
    }

    fn bits(traj: &Trajectory) -> Vec<u64> {
        let mut out = vec![
            traj.dt.to_bits(),
            traj.d_star.to_bits(),
            traj.v_star.to_bits(),
        ];
        out.extend(traj.times.iter().map(|t| t.to_bits()));
        out.extend(traj.phi_star.iter().map(|t| t.to_bits()));
        for row in &traj.poses {
            out.extend(
                row.iter()
                    .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()]),
            );
        }
        for row in &traj.commands {
            out.extend(
                row.iter()
                    .flat_map(|c| [c.left.to_bits(), c.right.to_bits()]),
            );
        }
        out
    }

    /// The first `samples` samples of `traj` (and the commands and collisions leading there).
    fn prefix(traj: &Trajectory, samples: usize) -> Trajectory {
        Trajectory {
            times: traj.times[..samples].to_vec(),
            phi_star: traj.phi_star[..samples].to_vec(),
            poses: traj.poses[..samples].to_vec(),
            commands: traj.commands[..samples - 1].to_vec(),
            collisions: traj
                .collisions
                .iter()
                .copied()
                .filter(|&(k, _, _)| (k as usize) < samples)
                .collect(),
            ..traj.clone()
        }
    }

    fn header(spec: &RunSpec) -> JournalHeader {
        JournalHeader::new(
            spec,
            "lockstep",
            &["model-a".into(), "model-b".into(), "model-a".into()],
        )
    }

    #[test]
    fn a_journal_reads_back_bit_for_bit_and_stopped_early_as_a_prefix() {
        let spec = spec(6.0);
        let scratch = Scratch::new("runlog-roundtrip");
        let path = journal_path(scratch.path(), spec.index);
        let mut journal = RunJournal::create(&path, &header(&spec)).unwrap();
        let full = run_episode_recorded(&spec, &mut wobble(), &mut |_, _| {}, &mut |t| {
            journal.append(t)
        })
        .unwrap();
        journal.close().unwrap();
        assert!(
            !full.collisions.is_empty(),
            "the test should journal collisions"
        );

        let log = recover_journal(&path).unwrap();
        assert_eq!(log.trajectory, full);
        assert_eq!(bits(&log.trajectory), bits(&full));
        assert_eq!(log.trajectory.collisions, full.collisions);
        // Every tick was journaled: the run is complete, though its world saved no run log.
        assert!(log.complete && log.metrics.is_complete());
        assert_eq!(log.index, 2);
        assert_eq!(log.planned_ticks, Some(spec.ticks()));
        assert_eq!(log.models[1], "model-b");
        assert_eq!(
            log.metrics,
            run_metrics(&full, spec.ticks(), &MetricsConfig::default())
        );

        // Stopped after 40 steps (the recorder fails the episode): the journal holds the prefix.
        let mut journal = RunJournal::create(&path, &header(&spec)).unwrap();
        let error = run_episode_recorded(&spec, &mut wobble(), &mut |_, _| {}, &mut |t| {
            journal.append(t)?;
            if t.commands.len() == 40 {
                Err(RunLogError::Failed {
                    path: PathBuf::new(),
                })
            } else {
                Ok(())
            }
        })
        .unwrap_err();
        assert!(matches!(error, EpisodeError::Record(_)));
        journal.close().unwrap();
        let log = recover_journal(&path).unwrap();
        assert_eq!(log.trajectory, prefix(&full, 41));
        assert_eq!(bits(&log.trajectory), bits(&prefix(&full, 41)));
        assert_eq!(
            log.metrics,
            run_metrics(&prefix(&full, 41), spec.ticks(), &MetricsConfig::default())
        );
    }

    fn journal_of(spec: &RunSpec, path: &Path) -> Trajectory {
        let mut journal = RunJournal::create(path, &header(spec)).unwrap();
        let traj = run_episode_recorded(spec, &mut wobble(), &mut |_, _| {}, &mut |t| {
            journal.append(t)
        })
        .unwrap();
        journal.close().unwrap();
        traj
    }

    #[test]
    fn a_torn_last_line_is_dropped_and_damage_before_it_is_refused() {
        let spec = spec(1.0);
        let (_scratch, path) = journal_in("torn");
        let full = journal_of(&spec, &path);
        let text = fs::read(&path).unwrap();
        let lines: Vec<&[u8]> = text.split_inclusive(|&b| b == b'\n').collect();
        assert_eq!(lines.len(), 1 + 21, "header and 21 samples");

        // Cut in the middle of the last line.
        let cut = text.len() - lines[21].len() / 2;
        fs::write(&path, &text[..cut]).unwrap();
        assert_eq!(
            recover_journal(&path).unwrap().trajectory,
            prefix(&full, 20)
        );
        // Cut right before the last newline: the line is whole.
        fs::write(&path, &text[..text.len() - 1]).unwrap();
        assert_eq!(recover_journal(&path).unwrap().trajectory, full);
        // Only the header.
        fs::write(&path, lines[0]).unwrap();
        let log = recover_journal(&path).unwrap();
        assert!(log.trajectory.poses.is_empty() && log.ticks() == 0);

        // A damaged line in the middle is an error naming the line.
        let mut damaged = text.clone();
        let at = lines[0].len() + lines[1].len() + 3;
        damaged[at] = b'#';
        fs::write(&path, &damaged).unwrap();
        let err = recover_journal(&path).unwrap_err();
        assert!(
            matches!(err, RunLogError::Parse { line: Some(3), .. }),
            "{err}"
        );
        assert!(err.to_string().contains("line 3"), "{err}");

        // A missing sample is inconsistent.
        let skipped: Vec<u8> = [lines[0], lines[1], lines[3]].concat();
        fs::write(&path, skipped).unwrap();
        let err = recover_journal(&path).unwrap_err();
        assert!(matches!(err, RunLogError::Inconsistent { .. }), "{err}");
    }

    #[test]
    fn other_versions_and_other_files_are_refused() {
        let spec = spec(0.5);
        let (_scratch, path) = journal_in("version");
        journal_of(&spec, &path);
        let text = fs::read_to_string(&path).unwrap();
        let newer = text.replacen("\"version\":1", "\"version\":2", 1);
        assert_ne!(newer, text);
        fs::write(&path, newer).unwrap();
        let err = recover_journal(&path).unwrap_err();
        assert!(
            matches!(err, RunLogError::Version { found: 2, .. }),
            "{err}"
        );
        assert!(
            err.to_string().contains("version 2") && err.to_string().contains("reads version 1"),
            "{err}"
        );

        let other = text.replacen(JOURNAL_FORMAT, "something-else", 1);
        for not_a_journal in [
            other.as_str(),
            "{\"index\": 0}\n",
            "not json at all\n{}\n",
            "",
        ] {
            fs::write(&path, not_a_journal).unwrap();
            let read = recover_journal(&path);
            assert!(
                matches!(read, Err(RunLogError::NotAJournal { .. })),
                "{not_a_journal:?}: {read:?}"
            );
        }
    }

    #[test]
    fn the_journal_is_flushed_when_a_second_has_passed() {
        let spec = spec(1.0);
        let (_scratch, path) = journal_in("flush");
        let t0 = Instant::now();
        let elapsed = Rc::new(Cell::new(Duration::ZERO));
        let clock = {
            let elapsed = Rc::clone(&elapsed);
            move || t0 + elapsed.get()
        };
        let mut journal = RunJournal::create_with_clock(&path, &header(&spec), clock).unwrap();
        let header_len = fs::metadata(&path).unwrap().len();
        assert!(header_len > 0, "the header is written at once");
        let mut on_disk = Vec::new();
        let mut grew_at = Vec::new();
        run_episode_recorded(&spec, &mut wobble(), &mut |_, _| {}, &mut |t| {
            // 100 ms of wall time per tick.
            elapsed.set(elapsed.get() + Duration::from_millis(100));
            journal.append(t)?;
            let len = fs::metadata(&path).unwrap().len();
            if on_disk.last().is_some_and(|&last| len > last) {
                grew_at.push(t.commands.len());
            }
            on_disk.push(len);
            Ok::<(), RunLogError>(())
        })
        .unwrap();
        assert_eq!(
            on_disk[0], header_len,
            "nothing flushed before a second passed"
        );
        assert_eq!(
            grew_at,
            vec![9, 19],
            "flushed once per second of the fake clock"
        );
        let before_close = *on_disk.last().unwrap();
        journal.close().unwrap();
        assert!(
            fs::metadata(&path).unwrap().len() > before_close,
            "close flushes the rest"
        );
        assert_eq!(recover_journal(&path).unwrap().trajectory.poses.len(), 21);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_error_surfaces_at_once_and_names_the_file() {
        // /dev/full accepts the open and fails every write with ENOSPC.
        let spec = spec(0.5);
        let err = RunJournal::create(Path::new("/dev/full"), &header(&spec))
            .err()
            .expect("writing to /dev/full fails");
        let message = err.to_string();
        assert!(matches!(err, RunLogError::Write { .. }), "{message}");
        assert!(message.contains("/dev/full"), "{message}");
        assert!(
            message.contains("disk is full") && message.contains("another output directory"),
            "{message}"
        );

        // A directory that is a file: creating the journal fails naming it.
        let scratch = Scratch::new("runlog-notdir");
        let dir = scratch.path();
        let blocker = dir.join("runs");
        fs::write(&blocker, b"a file").unwrap();
        let err = RunJournal::create(&journal_path(dir, 0), &header(&spec))
            .err()
            .expect("runs/ is a file");
        assert!(
            err.to_string()
                .contains(&format!("{} is a file, not a directory", blocker.display())),
            "{err}"
        );

        // An atomic write that fails leaves no temporary file behind.
        let target = dir.join("sub").join("x.json");
        fs::create_dir_all(dir.join("sub")).unwrap();
        fs::create_dir_all(&target).unwrap(); // renaming a file over a directory fails
        assert!(write_atomic(&target, b"{}").is_err());
        let left: Vec<_> = fs::read_dir(dir.join("sub"))
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(
            left,
            vec![std::ffi::OsString::from("x.json")],
            "no temporary file left"
        );
    }

    #[test]
    fn a_failed_write_cuts_the_journal_to_whole_lines_and_refuses_more() {
        let spec = spec(0.5);
        let (_scratch, path) = journal_in("fail");
        let full = journal_of(&spec, &path);

        // A write that fails after part of a flush reached the file: cut back to what was
        // committed before it.
        let mut journal = RunJournal::create(&path, &header(&spec)).unwrap();
        let header_len = fs::metadata(&path).unwrap().len();
        for k in 1..=5 {
            journal.append(&prefix(&full, k)).unwrap();
        }
        journal.flush().unwrap();
        let five = fs::metadata(&path).unwrap().len();
        for k in 6..=full.poses.len() {
            journal.append(&prefix(&full, k)).unwrap();
        }
        journal.flush().unwrap();
        assert!(fs::metadata(&path).unwrap().len() > five);
        journal.committed = five;
        journal.fail();
        assert_eq!(fs::metadata(&path).unwrap().len(), five);
        assert_eq!(recover_journal(&path).unwrap().trajectory, prefix(&full, 5));
        assert!(matches!(
            journal.append(&full),
            Err(RunLogError::Failed { .. })
        ));
        assert!(matches!(journal.flush(), Err(RunLogError::Failed { .. })));

        // A file that refuses writes (opened read-only under the writer): the flush fails naming
        // the file, nothing past the header is kept, and no more lines are taken.
        let mut journal = RunJournal::create(&path, &header(&spec)).unwrap();
        journal.file = Some(File::open(&path).unwrap());
        for k in 1..=full.poses.len() {
            journal.append(&prefix(&full, k)).unwrap();
        }
        let err = journal.flush().unwrap_err();
        assert!(matches!(err, RunLogError::Write { .. }), "{err}");
        assert!(err.to_string().contains("run-0002.journal"), "{err}");
        assert!(matches!(
            journal.append(&full),
            Err(RunLogError::Failed { .. })
        ));
        assert_eq!(fs::metadata(&path).unwrap().len(), header_len);
        assert!(recover_journal(&path).unwrap().trajectory.poses.is_empty());
    }

    #[test]
    fn orphan_journals_are_recovered_into_incomplete_run_logs_and_live_ones_are_left() {
        let spec = spec(0.5);
        let scratch = Scratch::new("runlog-recover");
        let dir = scratch.path();
        let out = dir.join("a").join("out");
        let orphan = journal_path(&out, spec.index);
        // A world killed before the last of its 12 ticks (the spec plays 10 here).
        let mut planned = spec.clone();
        planned.duration_s = 0.6;
        let full = journal_of(&spec, &orphan);
        let mut rewritten = fs::read_to_string(&orphan).unwrap();
        let header_end = rewritten.find('\n').unwrap();
        let longer = serde_json::to_string(&header(&planned)).unwrap();
        rewritten.replace_range(..header_end, &longer);
        fs::write(&orphan, rewritten).unwrap();

        let mut live_spec = spec.clone();
        live_spec.index = 7;
        let live_path = journal_path(&out, 7);
        let live = RunJournal::create(&live_path, &header(&live_spec)).unwrap();

        assert_eq!(find_run_dirs(dir), vec![out.clone()]);
        assert_eq!(journals_in(&out), vec![orphan.clone(), live_path.clone()]);
        let recovered = recover_journals(&out, "the world was killed");
        assert_eq!(recovered.len(), 2, "{recovered:?}");
        assert!(
            matches!(recovered[1].outcome, Err(RunLogError::InUse { .. })),
            "{recovered:?}"
        );
        let run = recovered[0].outcome.as_ref().unwrap();
        assert_eq!(run.index, 2);
        assert_eq!(run.ticks, 10);
        assert!(!orphan.exists(), "the orphan journal is removed");
        assert!(live_path.exists(), "a journal a writer holds is left alone");
        let log = RunLog::read(&run.log).unwrap();
        assert!(!log.complete);
        assert_eq!(
            log.metrics.incomplete,
            Some(crate::metrics::TicksPlayed {
                ticks: 10,
                planned_ticks: 12
            })
        );
        assert!(!log.metrics.success_5 && !log.metrics.success_10);
        assert_eq!(log.stop_reason.as_deref(), Some("the world was killed"));
        assert_eq!(log.trajectory, full);

        // Closed with only its header: nothing to keep, removed.
        live.close().unwrap();
        let recovered = recover_journals(&out, "gone");
        assert_eq!(recovered.len(), 1);
        assert!(
            matches!(recovered[0].outcome, Err(RunLogError::NoSamples { .. })),
            "{recovered:?}"
        );
        assert!(!live_path.exists());
        assert!(journals_in(&out).is_empty());
        assert_eq!(run_logs_in(&out), vec![(2, out.join("runs/run-0002.json"))]);
        assert_eq!(find_run_dirs(dir), vec![out.clone()]);
    }

    #[test]
    fn run_logs_without_the_new_fields_read_as_complete() {
        let spec = spec(0.5);
        let traj = crate::run_episode(&spec, &mut wobble(), &mut |_, _| {}).unwrap();
        let log = RunLog {
            index: 1,
            metrics: run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default()),
            trajectory: traj,
            clock: "lockstep".into(),
            models: vec![],
            complete: true,
            stop_reason: None,
            planned_ticks: None,
        };
        let text = serde_json::to_string(&log).unwrap();
        assert!(!text.contains("stop_reason") && !text.contains("planned_ticks"));
        let old = text.replace(",\"complete\":true", "");
        assert_ne!(old, text);
        let read: RunLog = serde_json::from_str(&old).unwrap();
        assert!(read.complete);
        assert_eq!(read, log);
        let partial = RunLog {
            complete: false,
            stop_reason: Some("interrupted by Ctrl-C".into()),
            ..log
        };
        let read: RunLog = serde_json::from_slice(&serde_json::to_vec(&partial).unwrap()).unwrap();
        assert_eq!(read, partial);
    }
}
