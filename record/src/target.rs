//! Where recordings go (`--record FILE.mcap` or `--record DIR`), the checks made before a run
//! starts, and the settings file through which a launcher hands its world process what to
//! record.
//!
//! Before a run: the folder must exist (a recording is not a reason to create folders, and a
//! typo should not record somewhere unexpected), an existing target must be a regular file (a
//! device or FIFO is refused: nothing is opened, so `/dev/full`'s mode is never touched), and the
//! folder must take a page of data (a probe file, written and removed), so that a full disk is
//! said before the run rather than found after it.

use std::path::{Path, PathBuf};

use formation_proto::files::{FileSystem, PathKind, PathProbe, WriteError};
use serde::{Deserialize, Serialize};

use crate::error::RecordError;
use crate::setup::LaunchInfo;

/// Where a launch's recordings go.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum RecordTarget {
    /// One file (`formation run --record FILE.mcap`): a launch of one run records into it; with
    /// several runs, run `N` records into `<stem>-run-NNNN.mcap` beside it.
    File(PathBuf),
    /// A folder (`formation eval --record DIR`): `run-NNNN.mcap` for each of the first
    /// `max_runs` runs played.
    Folder {
        /// The folder.
        dir: PathBuf,
        /// At most this many runs are recorded.
        max_runs: usize,
    },
}

impl RecordTarget {
    /// The file run `index` records into, when it is recorded: `nth` is its position among the
    /// launch's runs and `runs` their number.
    pub fn path_for(&self, index: usize, nth: usize, runs: usize) -> Option<PathBuf> {
        match self {
            RecordTarget::File(path) if runs == 1 => Some(path.clone()),
            RecordTarget::File(path) => {
                let stem = path.file_stem().map_or_else(
                    || "recording".to_owned(),
                    |s| s.to_string_lossy().into_owned(),
                );
                Some(path.with_file_name(format!("{stem}-run-{index:04}.mcap")))
            }
            RecordTarget::Folder { dir, max_runs } => {
                (nth < *max_runs).then(|| dir.join(format!("run-{index:04}.mcap")))
            }
        }
    }

    /// The folder the recordings go into.
    pub fn folder(&self) -> PathBuf {
        match self {
            RecordTarget::File(path) => match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            },
            RecordTarget::Folder { dir, .. } => dir.clone(),
        }
    }

    /// Checks, before a run starts, that recordings can be written here (see the module docs).
    /// Creates nothing that stays.
    pub fn check(&self) -> Result<(), RecordError> {
        let named = match self {
            RecordTarget::File(path) => path.clone(),
            RecordTarget::Folder { dir, .. } => dir.clone(),
        };
        // A component on the way that is a file, or a file target that is a folder.
        match self {
            RecordTarget::File(path) => {
                formation_proto::files::check_output_file_as(path, RECORDING_EXAMPLE)
            }
            RecordTarget::Folder { dir, .. } => formation_proto::files::check_output_dir(dir),
        }
        .map_err(RecordError::Write)?;
        let dir = self.folder();
        if FileSystem.kind(&dir) != PathKind::Directory {
            return Err(RecordError::MissingFolder { path: named, dir });
        }
        if let RecordTarget::File(path) = self {
            check_regular_or_absent(path)?;
        }
        probe(&dir, &named)
    }
}

/// The file name a fix suggests for a recording given a folder where a file was wanted.
pub const RECORDING_EXAMPLE: &str = "run.mcap";

/// Refuses a path that exists and is not a regular file (symbolic links followed).
fn check_regular_or_absent(path: &Path) -> Result<(), RecordError> {
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_dir() => Err(RecordError::Write(
            WriteError::new(path, std::io::Error::from(std::io::ErrorKind::IsADirectory))
                .with_example(RECORDING_EXAMPLE),
        )),
        Ok(meta) if !meta.is_file() => Err(RecordError::NotAFile {
            path: path.to_path_buf(),
            what: formation_proto::files::file_kind(&meta),
        }),
        _ => Ok(()),
    }
}

/// Writes a page into a probe file in `dir` and removes it: a full disk, a read-only file system
/// or a folder this user may not write in is said now, naming `named`.
fn probe(dir: &Path, named: &Path) -> Result<(), RecordError> {
    use std::io::Write as _;
    let probe = dir.join(format!(".formation-record-probe-{}", std::process::id()));
    let written = formation_proto::files::create_private_file(&probe)
        .and_then(|mut f| f.write_all(&[0u8; 4096]).and_then(|()| f.sync_data()));
    let _ = std::fs::remove_file(&probe);
    written.map_err(|e| {
        let shown = if named == dir {
            named.join("run-0000.mcap")
        } else {
            named.to_path_buf()
        };
        RecordError::Write(WriteError::new(&shown, e))
    })
}

/// Creates (or truncates) the recording at `path`, private to its user; refuses a path that is
/// not a regular file.
pub(crate) fn create_file(path: &Path) -> Result<std::fs::File, RecordError> {
    check_regular_or_absent(path)?;
    formation_proto::files::create_private_file(path)
        .map_err(|e| RecordError::Write(WriteError::new(path, e)))
}

/// What a launcher hands its world process to record (`formation-world --record-settings`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordSettings {
    /// Where the recordings go.
    pub target: RecordTarget,
    /// What the launch knows of its runs.
    pub launch: LaunchInfo,
}

/// The most bytes a settings file may have.
const MAX_SETTINGS_BYTES: u64 = 1 << 20;

impl RecordSettings {
    /// Writes the settings to `path` (atomically, private).
    pub fn write(&self, path: &Path) -> Result<(), RecordError> {
        write_settings_json(self, path)
    }

    /// Reads the settings at `path` (at most 1 MiB).
    pub fn read(path: &Path) -> Result<RecordSettings, RecordError> {
        read_settings_json(path)
    }
}

impl LaunchInfo {
    /// Writes what the launch knows to `path` (atomically, private), for a world that has no
    /// recording settings but may be recorded from outside (`formation-world --launch-info`).
    pub fn write(&self, path: &Path) -> Result<(), RecordError> {
        write_settings_json(self, path)
    }

    /// Reads it back from `path` (at most 1 MiB).
    pub fn read(path: &Path) -> Result<LaunchInfo, RecordError> {
        read_settings_json(path)
    }
}

/// Writes `value` as JSON to `path` (atomically, private).
fn write_settings_json<T: Serialize>(value: &T, path: &Path) -> Result<(), RecordError> {
    let json = serde_json::to_vec_pretty(value).map_err(|source| RecordError::SettingsFormat {
        path: path.to_path_buf(),
        source,
    })?;
    formation_proto::files::write_atomic(path, &json)
        .map_err(|e| RecordError::Write(WriteError::new(path, e)))
}

/// Reads the JSON at `path` (at most [`MAX_SETTINGS_BYTES`]).
fn read_settings_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, RecordError> {
    let bytes =
        formation_proto::files::read_bounded(path, MAX_SETTINGS_BYTES).map_err(|refusal| {
            use formation_proto::files::FileRefusal;
            let source = match refusal {
                FileRefusal::Io(e) => e,
                FileRefusal::NotAFile { kind } => {
                    std::io::Error::other(format!("it is {kind}, not a regular file"))
                }
                FileRefusal::TooLarge { .. } => {
                    std::io::Error::other(format!("it is larger than {MAX_SETTINGS_BYTES} bytes"))
                }
            };
            RecordError::Settings {
                path: path.to_path_buf(),
                source,
            }
        })?;
    serde_json::from_slice(&bytes).map_err(|source| RecordError::SettingsFormat {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_target_names_each_run_when_there_are_several() {
        let target = RecordTarget::File(PathBuf::from("out/team.mcap"));
        assert_eq!(
            target.path_for(7, 0, 1),
            Some(PathBuf::from("out/team.mcap"))
        );
        assert_eq!(
            target.path_for(7, 0, 3),
            Some(PathBuf::from("out/team-run-0007.mcap"))
        );
        assert_eq!(target.folder(), PathBuf::from("out"));
        assert_eq!(
            RecordTarget::File(PathBuf::from("x.mcap")).folder(),
            PathBuf::from(".")
        );
    }

    #[test]
    fn a_folder_target_keeps_the_first_runs_only() {
        let target = RecordTarget::Folder {
            dir: PathBuf::from("rec"),
            max_runs: 2,
        };
        assert_eq!(
            target.path_for(4, 1, 9),
            Some(PathBuf::from("rec/run-0004.mcap"))
        );
        assert_eq!(target.path_for(5, 2, 9), None);
    }

    #[test]
    fn a_missing_folder_a_device_and_a_folder_are_refused_with_the_fix() {
        let missing = RecordTarget::File(PathBuf::from("/nonexistent-formation/x/run.mcap"));
        let text = missing.check().unwrap_err().to_string();
        assert!(
            text.contains("/nonexistent-formation/x does not exist")
                && text.contains("mkdir -p /nonexistent-formation/x"),
            "{text}"
        );
        let device = RecordTarget::File(PathBuf::from("/dev/null"));
        let text = device.check().unwrap_err().to_string();
        assert!(text.contains("not a regular file"), "{text}");
        let dir = std::env::temp_dir();
        let text = RecordTarget::File(dir.clone())
            .check()
            .unwrap_err()
            .to_string();
        assert!(text.contains("is a directory"), "{text}");
    }

    #[test]
    fn settings_round_trip_through_their_file() {
        let dir =
            std::env::temp_dir().join(format!("formation-record-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let settings = RecordSettings {
            target: RecordTarget::Folder {
                dir: dir.clone(),
                max_runs: 3,
            },
            launch: LaunchInfo {
                scenario: "case1".into(),
                base_seed: Some(1),
                clock: "lockstep".into(),
                controller: "policy".into(),
                models: vec![PathBuf::from("m.onnx")],
                shipped_models: None,
            },
        };
        let path = dir.join("record-settings.json");
        settings.write(&path).unwrap();
        assert_eq!(RecordSettings::read(&path).unwrap(), settings);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
