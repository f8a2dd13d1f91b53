//! A DAgger part: the expert-labelled samples of one share of one DAgger iteration's rollouts
//! (runs `first_run .. first_run + runs`), labelled by one worker of a sweep, to be appended to
//! the dataset with the other shares, in run order ([`append_parts`]).
//!
//! A part is one safetensors file holding the columns of a dataset shard ([`crate::dataset`]:
//! six, `ranges` where the dataset declares ranges and `neighbours` where it declares
//! neighbours), whose `__metadata__` extends the shard's with:
//!
//! - `format` = [`PART_FORMAT`], `version` = [`PART_VERSION`];
//! - `part`: the [`PartHeader`] as JSON: the dataset's settings ([`DatasetHeader`]), the
//!   iteration, the rollout settings ([`RolloutSettings`]) and the run range;
//! - `samples`: the sample count, and `columns_fnv1a64`: FNV-1a 64 over the columns.
//!
//! The dataset header in `part` holds the dataset's range input and neighbour input, if any
//! (each absent when none, so a part without them is byte for byte what builds before them
//! wrote); its samples carry ranges of that many sectors and neighbours of that many slots, and
//! [`append_parts`] appends them only to a dataset of the same inputs.
//!
//! Parts are written atomically (temporary name, sync, rename), so a worker killed mid-share
//! leaves no half file. [`append_parts`] checks that the parts are of one iteration with the same
//! settings, and that their runs are contiguous, do not overlap and cover the iteration, before
//! it writes anything; then it appends their samples as [`DatasetWriter::append`] does, so the
//! dataset is byte for byte the one a single labelling of all the runs writes.

use std::collections::HashMap;
use std::fs;
use std::ops::Range;
use std::path::{Path, PathBuf};

use safetensors::tensor::{SafeTensorError, SafeTensors};
use serde::{Deserialize, Serialize};

use crate::dataset::{
    DatasetError, DatasetHeader, DatasetWriter, Manifest, PendingShard, Sample, check_sample,
    decode_columns, io_error,
};
use crate::difference::{Difference, FirstDifference};
use crate::digest::Fnv1a64;

/// The `format` of every part's metadata.
pub const PART_FORMAT: &str = "formation-dagger-part";
/// The part layout version this build writes and reads.
pub const PART_VERSION: u32 = 1;
/// The largest part read (label a share of fewer runs to stay under it).
pub const MAX_PART_BYTES: u64 = 16 << 30;

/// What drove and labelled an iteration's rollouts: every part of one iteration has the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutSettings {
    /// Name of the rollout scenario.
    pub scenario: String,
    /// Team sizes of the runs, used in turn.
    pub team_sizes: Vec<usize>,
    /// Each team size's run length \[s\], in the same turn, where some differ from the
    /// scenario's (`formation dagger --rollout-durations`); empty: every run the scenario's.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub durations_s: Vec<f64>,
    /// Base seed of the DAgger rollouts.
    pub seed: u64,
    /// The expert's share of the runs in this iteration (`beta^k`).
    pub expert_share: f64,
    /// FNV-1a 64 of the policy model that drove ([`file_fnv1a64`]).
    pub model_fnv1a64: String,
}

/// What a part holds: its dataset, iteration, rollout settings and runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartHeader {
    /// The settings of the dataset the samples are for.
    pub dataset: DatasetHeader,
    /// DAgger iteration of every sample.
    pub iteration: u32,
    /// What drove and labelled the rollouts.
    pub rollouts: RolloutSettings,
    /// The first run held.
    pub first_run: usize,
    /// Runs held, `first_run .. first_run + runs`.
    pub runs: usize,
}

impl PartHeader {
    /// The runs the part holds.
    pub fn run_range(&self) -> Range<usize> {
        self.first_run..self.first_run + self.runs
    }

    /// The first field in which the two parts' iterations differ, with both values.
    fn first_difference(&self, other: &PartHeader) -> Option<Difference> {
        FirstDifference::of(self, other)
            .after(self.dataset.first_difference(&other.dataset))
            .display("iteration", |p| p.iteration)
            .display("rollout scenario", |p| &p.rollouts.scenario)
            .debug("team sizes", |p| &p.rollouts.team_sizes)
            .display("rollout seed", |p| p.rollouts.seed)
            .display("expert share", |p| p.rollouts.expert_share)
            .display("model", |p| &p.rollouts.model_fnv1a64)
            .found()
    }
}

/// A part read back: its header and samples, in run order.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// What it holds.
    pub header: PartHeader,
    /// Its samples.
    pub samples: Vec<Sample>,
}

/// Why a part could not be written, read or appended. Every message names the file and the fix.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// The file is larger than [`MAX_PART_BYTES`].
    #[error(
        "{path} is {bytes} bytes, more than a part may be ({MAX_PART_BYTES}); label the iteration in shares of fewer runs"
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// The file ends early.
    #[error("{path} is truncated ({reason}); label its runs again with `formation dagger-label`")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        reason: String,
    },
    /// The content is not a valid part.
    #[error(
        "{path} is not a valid DAgger part ({reason}); label its runs again with `formation dagger-label`"
    )]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Another kind of file.
    #[error(
        "{path} has format `{found}`, not `{PART_FORMAT}`: give the files `formation dagger-label --part` wrote"
    )]
    WrongFormat {
        /// The file.
        path: PathBuf,
        /// The format it declares.
        found: String,
    },
    /// A version this build does not read.
    #[error(
        "{path} is DAgger part version {found}, but this build reads version {PART_VERSION}; label it again with this build"
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version it declares.
        found: String,
    },
    /// A sample does not fit the part's dataset or iteration.
    #[error("{path}: {source}")]
    Sample {
        /// The part being written.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: DatasetError,
    },
    /// A sample of a run the part does not hold.
    #[error(
        "{path}: a sample of run {run} is outside the part's runs {runs:?}; label the share's runs only"
    )]
    SampleRun {
        /// The part being written.
        path: PathBuf,
        /// The sample's run.
        run: u32,
        /// The part's runs.
        runs: Range<usize>,
    },
    /// A file-system operation failed ([`DatasetError::Io`]), or encoding or appending failed in
    /// the dataset layer.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// No parts were given.
    #[error("no parts to append: give the files `formation dagger-label --part` wrote")]
    NoParts,
    /// A part of another iteration than the one being appended.
    #[error(
        "{path} holds DAgger iteration {found}, but iteration {expected} is being appended; give only that iteration's parts"
    )]
    WrongIteration {
        /// The part.
        path: PathBuf,
        /// The iteration asked for.
        expected: u32,
        /// The part's.
        found: u32,
    },
    /// Two parts of different settings.
    #[error(
        "{path} is of another DAgger iteration than {first}: its {field} is {found}, the other's is {expected}; append only the parts of one iteration's labelling"
    )]
    Mismatch {
        /// The part that differs.
        path: PathBuf,
        /// The part it was compared with.
        first: PathBuf,
        /// What differs.
        field: &'static str,
        /// The first part's value.
        expected: String,
        /// This part's value.
        found: String,
    },
    /// Runs held by two parts.
    #[error(
        "run {run} is in two parts, {first} (runs {first_runs:?}) and {second} (runs {second_runs:?}): a share was kept twice; keep one part per range of runs"
    )]
    Overlap {
        /// The first run held twice.
        run: usize,
        /// One part.
        first: PathBuf,
        /// Its runs.
        first_runs: Range<usize>,
        /// The other.
        second: PathBuf,
        /// Its runs.
        second_runs: Range<usize>,
    },
    /// Runs no part holds.
    #[error(
        "runs {missing:?} of iteration {iteration} are in no part (the iteration has {runs} runs): label them with `formation dagger-label --iteration {iteration} --first-run {} --runs {} --part FILE` and append again",
        missing.start,
        missing.len()
    )]
    Gap {
        /// The runs missing.
        missing: Range<usize>,
        /// The iteration.
        iteration: u32,
        /// Runs of the iteration.
        runs: usize,
    },
    /// Runs beyond the iteration's.
    #[error(
        "{path} holds runs {held:?}, beyond the iteration's {runs} runs; give the iteration's run count, or leave that part out"
    )]
    BeyondRuns {
        /// The part.
        path: PathBuf,
        /// Its runs.
        held: Range<usize>,
        /// Runs of the iteration.
        runs: usize,
    },
    /// The dataset already holds this iteration.
    #[error(
        "{dir} already holds samples of DAgger iteration {iteration}: appending them again would count them twice; append to a copy of the dataset from before that iteration"
    )]
    AlreadyAppended {
        /// The dataset.
        dir: PathBuf,
        /// The iteration.
        iteration: u32,
    },
}

/// FNV-1a 64 of a file's bytes, 16 hex digits (the model fingerprint of [`RolloutSettings`]).
pub fn file_fnv1a64(path: &Path) -> Result<String, PartError> {
    let bytes = fs::read(path).map_err(io_error("reading", path))?;
    let mut hash = Fnv1a64::new();
    hash.update(&bytes);
    Ok(hash.hex())
}

/// Writes `samples` (in run order) as the part `header` describes, atomically.
pub fn write_part(path: &Path, header: &PartHeader, samples: &[Sample]) -> Result<(), PartError> {
    let runs = header.run_range();
    header.dataset.check().map_err(|source| PartError::Sample {
        path: path.to_path_buf(),
        source,
    })?;
    let mut columns = PendingShard::new(&header.dataset);
    for sample in samples {
        check_sample(&header.dataset, header.iteration, sample).map_err(|source| {
            PartError::Sample {
                path: path.to_path_buf(),
                source,
            }
        })?;
        if !runs.contains(&(sample.run as usize)) {
            return Err(PartError::SampleRun {
                path: path.to_path_buf(),
                run: sample.run,
                runs,
            });
        }
        columns.push(sample);
    }
    let part = serde_json::to_string(header).map_err(|e| PartError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let metadata = HashMap::from([
        ("format".to_owned(), PART_FORMAT.to_owned()),
        ("version".to_owned(), PART_VERSION.to_string()),
        ("part".to_owned(), part),
        ("samples".to_owned(), columns.samples().to_string()),
        ("columns_fnv1a64".to_owned(), columns.columns_fnv1a64()),
    ]);
    let bytes = columns.encode_with(header.dataset.settings.occupancy.size_px, metadata, path)?;
    formation_proto::files::write_atomic(path, &bytes)
        .map_err(io_error("writing", path))
        .map_err(PartError::from)
}

/// Reads and checks a part: size, format, version, header, columns and checksum, and that every
/// sample is of the part's iteration and runs, in run order.
pub fn read_part(path: &Path) -> Result<Part, PartError> {
    let bytes = fs::metadata(path)
        .map_err(io_error("inspecting", path))?
        .len();
    if bytes > MAX_PART_BYTES {
        return Err(PartError::TooLarge {
            path: path.to_path_buf(),
            bytes,
        });
    }
    let data = fs::read(path).map_err(io_error("reading", path))?;
    let corrupt = |reason: String| PartError::Corrupt {
        path: path.to_path_buf(),
        reason,
    };
    let tensors = SafeTensors::deserialize(&data).map_err(|e| match e {
        SafeTensorError::HeaderTooSmall
        | SafeTensorError::InvalidHeaderLength
        | SafeTensorError::MetadataIncompleteBuffer => PartError::Truncated {
            path: path.to_path_buf(),
            reason: e.to_string(),
        },
        other => corrupt(other.to_string()),
    })?;
    let (_, metadata) = SafeTensors::read_metadata(&data).map_err(|e| corrupt(e.to_string()))?;
    let empty = HashMap::new();
    let meta = metadata.metadata().as_ref().unwrap_or(&empty);
    let field = |key: &str| meta.get(key).map(String::as_str);
    match field("format") {
        Some(PART_FORMAT) => {}
        found => {
            return Err(PartError::WrongFormat {
                path: path.to_path_buf(),
                found: found.unwrap_or("<missing>").to_owned(),
            });
        }
    }
    if field("version") != Some(PART_VERSION.to_string().as_str()) {
        return Err(PartError::UnsupportedVersion {
            path: path.to_path_buf(),
            found: field("version").unwrap_or("<missing>").to_owned(),
        });
    }
    let header: PartHeader = serde_json::from_str(field("part").unwrap_or_default())
        .map_err(|e| corrupt(format!("its `part` header: {e}")))?;
    let count: usize = field("samples")
        .and_then(|n| n.parse().ok())
        .ok_or_else(|| corrupt("no numeric `samples`".into()))?;
    header
        .dataset
        .check()
        .map_err(|e| corrupt(format!("its `part` header: {e}")))?;
    let samples = decode_columns(&tensors, count, &header.dataset).map_err(corrupt)?;
    check_read_samples(&header, &samples, field("columns_fnv1a64")).map_err(corrupt)?;
    Ok(Part { header, samples })
}

/// Checks decoded samples against the part's checksum, iteration and runs.
fn check_read_samples(
    header: &PartHeader,
    samples: &[Sample],
    checksum: Option<&str>,
) -> Result<(), String> {
    let mut columns = PendingShard::new(&header.dataset);
    let runs = header.run_range();
    let mut last_run = runs.start;
    for sample in samples {
        let run = sample.run as usize;
        if sample.iteration != header.iteration || !runs.contains(&run) || run < last_run {
            return Err(format!(
                "a sample of iteration {} run {run} in a part of iteration {} runs {runs:?}, in run order",
                sample.iteration, header.iteration
            ));
        }
        last_run = run;
        columns.push(sample);
    }
    let actual = columns.columns_fnv1a64();
    if checksum != Some(actual.as_str()) {
        return Err(format!(
            "checksum {actual} differs from the recorded {}",
            checksum.unwrap_or("<missing>")
        ));
    }
    Ok(())
}

/// Orders parts of iteration `iteration` of `runs` runs by their runs and checks that they are of
/// one labelling (same dataset and rollout settings), contiguous, non-overlapping and complete.
/// Returns the indices of `parts` in run order (empty parts, of no runs, are left out).
pub fn order_parts(
    parts: &[(PathBuf, PartHeader)],
    iteration: u32,
    runs: usize,
) -> Result<Vec<usize>, PartError> {
    let (first_path, first) = parts.first().ok_or(PartError::NoParts)?;
    for (path, header) in parts {
        if header.iteration != iteration {
            return Err(PartError::WrongIteration {
                path: path.clone(),
                expected: iteration,
                found: header.iteration,
            });
        }
        if let Some((field, expected, found)) = first.first_difference(header) {
            return Err(PartError::Mismatch {
                path: path.clone(),
                first: first_path.clone(),
                field,
                expected,
                found,
            });
        }
        if header.run_range().end > runs {
            return Err(PartError::BeyondRuns {
                path: path.clone(),
                held: header.run_range(),
                runs,
            });
        }
    }
    let mut order: Vec<usize> = (0..parts.len()).filter(|&i| parts[i].1.runs > 0).collect();
    order.sort_by_key(|&i| parts[i].1.first_run);
    let mut covered = 0;
    for pair in order.windows(2) {
        let (a, b) = (&parts[pair[0]], &parts[pair[1]]);
        if b.1.first_run < a.1.run_range().end {
            return Err(PartError::Overlap {
                run: b.1.first_run,
                first: a.0.clone(),
                first_runs: a.1.run_range(),
                second: b.0.clone(),
                second_runs: b.1.run_range(),
            });
        }
    }
    for &i in &order {
        let held = parts[i].1.run_range();
        if held.start > covered {
            return Err(PartError::Gap {
                missing: covered..held.start,
                iteration,
                runs,
            });
        }
        covered = held.end;
    }
    if covered < runs {
        return Err(PartError::Gap {
            missing: covered..runs,
            iteration,
            runs,
        });
    }
    Ok(order)
}

/// Appends the parts (files `formation dagger-label --part` wrote) of iteration `iteration` of
/// `runs` runs to the dataset `dir`, in run order, after checking them all ([`order_parts`], the
/// dataset's settings, and that the dataset does not hold the iteration yet). Returns the
/// dataset's manifest after the append and the samples appended.
pub fn append_parts(
    dir: &Path,
    iteration: u32,
    runs: usize,
    paths: &[PathBuf],
) -> Result<(Manifest, usize), PartError> {
    let parts = paths
        .iter()
        .map(|path| read_part(path).map(|part| (path.clone(), part)))
        .collect::<Result<Vec<_>, _>>()?;
    let headers: Vec<(PathBuf, PartHeader)> = parts
        .iter()
        .map(|(path, part)| (path.clone(), part.header.clone()))
        .collect();
    let order = order_parts(&headers, iteration, runs)?;
    let dataset = headers
        .first()
        .map(|(_, h)| h.dataset.clone())
        .ok_or(PartError::NoParts)?;
    let mut writer = DatasetWriter::append_matching(dir, &dataset, iteration)?;
    if writer
        .manifest()
        .shards
        .iter()
        .any(|shard| shard.iteration == iteration)
    {
        return Err(PartError::AlreadyAppended {
            dir: dir.to_path_buf(),
            iteration,
        });
    }
    let mut added = 0;
    let mut parts: Vec<Option<Part>> = parts.into_iter().map(|(_, part)| Some(part)).collect();
    for i in order {
        for sample in parts[i].take().map(|p| p.samples).unwrap_or_default() {
            writer.push(sample)?;
            added += 1;
        }
    }
    Ok((writer.finish()?, added))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::DatasetReader;
    use crate::dataset::tests::{
        header, header_with_neighbours, header_with_ranges, sample, sample_with_neighbours,
        sample_with_ranges,
    };

    const ITERATION: u32 = 1;

    fn part_header(first_run: usize, runs: usize) -> PartHeader {
        PartHeader {
            dataset: header(7),
            iteration: ITERATION,
            rollouts: RolloutSettings {
                scenario: "unit".into(),
                team_sizes: vec![3, 5],
                durations_s: Vec::new(),
                seed: 9,
                expert_share: 0.5,
                model_fnv1a64: "0123456789abcdef".into(),
            },
            first_run,
            runs,
        }
    }

    /// Two samples per run (`sample`'s run is `k / 4`: k = 4 run, 4 run + 1).
    fn samples_of(runs: Range<usize>) -> Vec<Sample> {
        runs.flat_map(|run| [4 * run as u32, 4 * run as u32 + 1])
            .map(|k| sample(k, ITERATION))
            .collect()
    }

    /// Writes the part of `runs` into `dir` as `name`.
    fn part(dir: &Path, name: &str, runs: Range<usize>) -> PathBuf {
        let path = dir.join(name);
        write_part(
            &path,
            &part_header(runs.start, runs.len()),
            &samples_of(runs),
        )
        .unwrap();
        path
    }

    /// Creates the dataset `dir/name` of `header` holding the one sample `first`.
    fn dataset_of(dir: &Path, name: &str, header: DatasetHeader, first: Sample) -> PathBuf {
        let data = dir.join(name);
        let mut writer = DatasetWriter::create(&data, header).unwrap();
        writer.push(first).unwrap();
        writer.finish().unwrap();
        data
    }

    /// The plain test dataset `dir/data`, holding one sample of iteration 0.
    fn dataset(dir: &Path) -> PathBuf {
        dataset_of(dir, "data", header(7), sample(100, 0))
    }

    /// Asserts that `data` ([`dataset`]) still holds its one sample: a refused append wrote nothing.
    fn assert_nothing_appended(data: &Path) {
        assert_eq!(
            DatasetReader::open(data).unwrap().samples(),
            1,
            "nothing was appended"
        );
    }

    #[test]
    fn a_part_round_trips_with_its_header_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = part(dir.path(), "p", 2..5);
        let read = read_part(&path).unwrap();
        assert_eq!(read.header, part_header(2, 3));
        assert_eq!(read.samples, samples_of(2..5));
        let files: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(files, ["p"]);
    }

    #[test]
    fn parts_given_in_any_order_append_in_run_order_as_one_writer_would() {
        let dir = tempfile::tempdir().unwrap();
        let parts = [part(dir.path(), "b", 2..4), part(dir.path(), "a", 0..2)];
        let data = dataset(&dir.path().join("x"));
        let (manifest, added) = append_parts(&data, ITERATION, 4, &parts).unwrap();
        assert_eq!(added, 8);
        assert_eq!(manifest.last_iteration(), ITERATION);
        let direct = dataset(&dir.path().join("y"));
        let mut writer = DatasetWriter::append(&direct, ITERATION).unwrap();
        for s in samples_of(0..4) {
            writer.push(s).unwrap();
        }
        writer.finish().unwrap();
        for file in [
            "manifest.json",
            "shard-000000.safetensors",
            "shard-000001.safetensors",
        ] {
            assert_eq!(
                fs::read(data.join(file)).unwrap(),
                fs::read(direct.join(file)).unwrap(),
                "{file}"
            );
        }
        let all = DatasetReader::open(&data).unwrap().load_all().unwrap();
        assert_eq!(all[1..], samples_of(0..4)[..]);
    }

    #[test]
    fn a_gap_names_the_missing_runs_and_the_command_that_labels_them() {
        let dir = tempfile::tempdir().unwrap();
        let parts = [part(dir.path(), "a", 0..2), part(dir.path(), "c", 3..5)];
        let data = dataset(dir.path());
        let err = append_parts(&data, ITERATION, 6, &parts).unwrap_err();
        assert!(
            matches!(err, PartError::Gap { ref missing, runs: 6, .. } if *missing == (2..3)),
            "{err:?}"
        );
        assert!(
            err.to_string()
                .contains("--iteration 1 --first-run 2 --runs 1"),
            "{err}"
        );
        let err = append_parts(&data, ITERATION, 6, &parts[..1]).unwrap_err();
        assert!(
            matches!(err, PartError::Gap { ref missing, .. } if *missing == (2..6)),
            "{err:?}"
        );
        let err = append_parts(&data, ITERATION, 6, &parts[1..]).unwrap_err();
        assert!(
            matches!(err, PartError::Gap { ref missing, .. } if *missing == (0..3)),
            "{err:?}"
        );
        assert_nothing_appended(&data);
    }

    #[test]
    fn an_overlap_or_a_part_kept_twice_names_both_files() {
        let dir = tempfile::tempdir().unwrap();
        let a = part(dir.path(), "a", 0..3);
        let b = part(dir.path(), "b", 2..4);
        let data = dataset(dir.path());
        let err = append_parts(&data, ITERATION, 4, &[a.clone(), b]).unwrap_err();
        assert!(matches!(err, PartError::Overlap { run: 2, .. }), "{err:?}");
        let message = err.to_string();
        assert!(
            message.contains("/a") && message.contains("/b"),
            "{message}"
        );
        let err = append_parts(&data, ITERATION, 3, &[a.clone(), a]).unwrap_err();
        assert!(matches!(err, PartError::Overlap { run: 0, .. }), "{err:?}");
        assert_nothing_appended(&data);
    }

    #[test]
    fn a_part_of_another_iteration_or_labelling_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = part(dir.path(), "a", 0..2);
        let data = dataset(dir.path());
        let err = append_parts(&data, 2, 2, std::slice::from_ref(&a)).unwrap_err();
        assert!(
            matches!(
                err,
                PartError::WrongIteration {
                    expected: 2,
                    found: 1,
                    ..
                }
            ),
            "{err:?}"
        );
        let other = dir.path().join("other");
        let mut header = part_header(2, 1);
        header.rollouts.seed = 10;
        write_part(&other, &header, &samples_of(2..3)).unwrap();
        let err = append_parts(&data, ITERATION, 3, &[a.clone(), other]).unwrap_err();
        assert!(
            matches!(
                err,
                PartError::Mismatch {
                    field: "rollout seed",
                    ..
                }
            ),
            "{err:?}"
        );
        let err = append_parts(&data, ITERATION, 1, &[a]).unwrap_err();
        assert!(
            matches!(err, PartError::BeyondRuns { runs: 1, .. }),
            "{err:?}"
        );
    }

    #[test]
    fn a_truncated_or_corrupted_part_is_named_with_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let a = part(dir.path(), "a", 0..2);
        let bytes = fs::read(&a).unwrap();
        fs::write(&a, &bytes[..bytes.len() - 7]).unwrap();
        let data = dataset(dir.path());
        let err = append_parts(&data, ITERATION, 2, std::slice::from_ref(&a)).unwrap_err();
        assert!(matches!(err, PartError::Truncated { .. }), "{err:?}");
        assert!(
            err.to_string()
                .contains("label its runs again with `formation dagger-label`"),
            "{err}"
        );
        fs::write(&a, &bytes[..5]).unwrap();
        assert!(matches!(read_part(&a), Err(PartError::Truncated { .. })));
        let mut flipped = bytes.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 1;
        fs::write(&a, &flipped).unwrap();
        let err = read_part(&a).unwrap_err();
        assert!(
            matches!(err, PartError::Corrupt { ref reason, .. } if reason.contains("checksum")),
            "{err:?}"
        );
        let shard = dataset(&dir.path().join("d")).join("shard-000000.safetensors");
        assert!(
            matches!(read_part(&shard), Err(PartError::WrongFormat { ref found, .. }) if found == "formation-dataset")
        );
    }

    #[test]
    fn an_iteration_already_in_the_dataset_is_not_appended_twice() {
        let dir = tempfile::tempdir().unwrap();
        let a = part(dir.path(), "a", 0..2);
        let data = dataset(dir.path());
        append_parts(&data, ITERATION, 2, std::slice::from_ref(&a)).unwrap();
        let err = append_parts(&data, ITERATION, 2, &[a]).unwrap_err();
        assert!(
            matches!(err, PartError::AlreadyAppended { iteration: 1, .. }),
            "{err:?}"
        );
        assert_eq!(DatasetReader::open(&data).unwrap().samples(), 5);
    }

    /// One kind of input a sample may carry beside its image (ranges, neighbours): how the test
    /// datasets declare it, how their samples carry it, and how its absence is refused.
    struct ExtraInputCase {
        name: &'static str,
        /// The test datasets' settings with this input, with a seed.
        header: fn(u64) -> DatasetHeader,
        /// A test sample carrying this input.
        sample: fn(u32, u32) -> Sample,
        /// Whether a dataset error refuses a sample that lacks this input.
        refuses_a_sample_without_it: fn(&DatasetError) -> bool,
        /// The header field a mismatch is named by.
        field: &'static str,
        /// The input's metadata key and text in a serialized header, where the case checks it.
        declared: Option<(&'static str, &'static str)>,
    }

    const EXTRA_INPUTS: [ExtraInputCase; 2] = [
        ExtraInputCase {
            name: "ranges",
            header: header_with_ranges,
            sample: sample_with_ranges,
            refuses_a_sample_without_it: |err| {
                matches!(err, DatasetError::SampleRanges { actual: 0, .. })
            },
            field: "range input",
            declared: None,
        },
        ExtraInputCase {
            name: "neighbours",
            header: header_with_neighbours,
            sample: sample_with_neighbours,
            refuses_a_sample_without_it: |err| {
                matches!(err, DatasetError::SampleNeighbours { actual: 0, .. })
            },
            field: "neighbour input",
            declared: Some(("neighbours", "slots=3,threshold=1.3,nearest=2")),
        },
    ];

    #[test]
    fn a_part_with_an_extra_input_round_trips_and_appends_only_to_a_dataset_of_the_same_input() {
        for case in &EXTRA_INPUTS {
            let name = case.name;
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("p");
            let mut header = part_header(0, 2);
            header.dataset = (case.header)(7);
            let samples: Vec<Sample> = [0, 1, 4, 5]
                .into_iter()
                .map(|k| (case.sample)(k, ITERATION))
                .collect();
            write_part(&path, &header, &samples).unwrap();
            let read = read_part(&path).unwrap();
            assert_eq!(read.header, header, "{name}");
            assert_eq!(read.samples, samples, "{name}");
            if let Some((key, text)) = case.declared {
                let json = serde_json::to_value(&read.header.dataset).unwrap();
                assert_eq!(json[key], text, "{name}");
            }

            // A part without the input for the dataset with it is refused when written.
            let err = write_part(&dir.path().join("q"), &header, &samples_of(0..2)).unwrap_err();
            assert!(
                matches!(err, PartError::Sample { ref source, .. } if (case.refuses_a_sample_without_it)(source)),
                "{name}: {err:?}"
            );

            // Appended to a dataset without the input: refused, naming it, nothing written.
            let plain = dataset(dir.path());
            let err = append_parts(&plain, ITERATION, 2, std::slice::from_ref(&path)).unwrap_err();
            assert!(
                matches!(err, PartError::Dataset(DatasetError::HeaderMismatch { field, .. }) if field == case.field),
                "{name}: {err:?}"
            );
            assert_nothing_appended(&plain);

            // Appended to a dataset with the same input: the samples keep it.
            let data = dataset_of(dir.path(), "with", (case.header)(7), (case.sample)(100, 0));
            let (_, added) = append_parts(&data, ITERATION, 2, &[path]).unwrap();
            assert_eq!(added, 4, "{name}");
            let all = DatasetReader::open(&data).unwrap().load_all().unwrap();
            assert_eq!(all[1..], samples[..], "{name}");
        }
    }

    #[test]
    fn a_part_whose_header_version_disagrees_with_its_ranges_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut header = part_header(0, 1);
        header.dataset.format_version = 2;
        let err = write_part(&dir.path().join("p"), &header, &[]).unwrap_err();
        assert!(
            matches!(
                err,
                PartError::Sample {
                    source: DatasetError::InconsistentHeader { version: 2, .. },
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn a_sample_outside_the_parts_runs_is_refused_when_writing() {
        let dir = tempfile::tempdir().unwrap();
        let err =
            write_part(&dir.path().join("p"), &part_header(0, 1), &samples_of(0..2)).unwrap_err();
        assert!(
            matches!(err, PartError::SampleRun { run: 1, .. }),
            "{err:?}"
        );
        assert!(!dir.path().join("p").exists());
    }
}
