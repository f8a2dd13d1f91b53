//! Reading a user's file safely: only a regular file, only up to a size limit, checked by its
//! metadata before anything is read (so a FIFO is never opened and `/dev/zero` never read), checked
//! again on the opened file (it may have been replaced in between), and read with a bound whatever
//! the metadata said. Scenarios and models both go through here; each caller turns a
//! [`FileRefusal`] into its own typed error that names the path and the fix.
//!
//! Writing one: [`write_atomic`] writes through a synced temporary file renamed into place, so a
//! reader (or a crash) sees the old file or the new one, never half of one. Every file formation
//! writes whole (logs, summaries, datasets' manifests, curves, reports) goes through it.
//!
//! Every file and folder formation creates is private to its user, whatever the umask: files
//! are created 0600 ([`create_private_file`]) and folders 0700 ([`create_private_dir_all`]). A
//! run's logs hold its trajectories and timings, and a machine shared with other users is the
//! common case in a lab; a user who wants to share a report copies or `chmod`s it. Folders that
//! already exist keep their mode: they are the user's.
//!
//! Explaining a failed write: the operating system's error names neither the path component in
//! the way nor the real cause (`--json /etc/passwd/x.json` fails with "File exists", since
//! `/etc/passwd` exists, as a file). [`WriteError`] looks at the path after the failure and
//! says what stands in the way ([`diagnose_write`], pure over a [`PathProbe`]): a component that
//! is a file, a target that is a directory, a full disk or quota (only for `ENOSPC` / `EDQUOT`), a
//! folder that is not writable or on a read-only file system. Every writer of the command line
//! builds its message with it.

use std::fmt;
use std::io::Read as _;
use std::path::{Path, PathBuf};

/// Why a file was not read.
#[derive(Debug)]
pub enum FileRefusal {
    /// Not a regular file: what it is instead, for messages (`"a directory"`, `"a FIFO (named
    /// pipe)"`, ...).
    NotAFile {
        /// What the path is.
        kind: &'static str,
    },
    /// Larger than the limit; `None` when the size grew past the limit during the read.
    TooLarge {
        /// Its size in bytes, when known.
        size: Option<u64>,
    },
    /// The operating system refused (missing path, permissions, ...).
    Io(std::io::Error),
}

/// Checks by its metadata alone (symbolic links followed) that `path` is a regular file of at most
/// `limit` bytes. Returns its size.
pub fn check_regular_file(path: &Path, limit: u64) -> Result<u64, FileRefusal> {
    check(&std::fs::metadata(path).map_err(FileRefusal::Io)?, limit)
}

/// The bytes of the regular file at `path`, at most `limit` of them (see the module docs).
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>, FileRefusal> {
    check_regular_file(path, limit)?;
    let file = std::fs::File::open(path).map_err(FileRefusal::Io)?;
    let size = check(&file.metadata().map_err(FileRefusal::Io)?, limit)?;
    // The size was checked, so the capacity is bounded; the read is bounded regardless.
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(FileRefusal::Io)?;
    if bytes.len() as u64 > limit {
        return Err(FileRefusal::TooLarge { size: None });
    }
    Ok(bytes)
}

fn check(meta: &std::fs::Metadata, limit: u64) -> Result<u64, FileRefusal> {
    if !meta.is_file() {
        return Err(FileRefusal::NotAFile {
            kind: file_kind(meta),
        });
    }
    if meta.len() > limit {
        return Err(FileRefusal::TooLarge {
            size: Some(meta.len()),
        });
    }
    Ok(meta.len())
}

/// What a non-regular file is, for messages.
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt as _;
    let kind = meta.file_type();
    if kind.is_dir() {
        "a directory"
    } else if kind.is_fifo() {
        "a FIFO (named pipe)"
    } else if kind.is_char_device() {
        "a character device"
    } else if kind.is_block_device() {
        "a block device"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Mode of every file formation creates: read and write for its user only.
pub const PRIVATE_FILE_MODE: u32 = 0o600;

/// Mode of every folder formation creates: its user only.
pub const PRIVATE_DIR_MODE: u32 = 0o700;

/// Creates `dir` and any missing parents, each new one [`PRIVATE_DIR_MODE`] whatever the umask
/// (the umask only clears bits, and 0700 has none it may clear but the user's own). Folders that
/// exist keep their mode.
pub fn create_private_dir_all(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::DirBuilderExt as _;
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(PRIVATE_DIR_MODE)
        .create(dir)
}

/// Creates (or truncates) the file at `path` for writing, [`PRIVATE_FILE_MODE`] whatever the
/// umask; a file that existed with a wider mode is narrowed to it.
pub fn create_private_file(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::{OpenOptionsExt as _, PermissionsExt as _};
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(PRIVATE_FILE_MODE)
        .open(path)?;
    if file.metadata()?.permissions().mode() & 0o777 != PRIVATE_FILE_MODE {
        file.set_permissions(std::fs::Permissions::from_mode(PRIVATE_FILE_MODE))?;
    }
    Ok(file)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory (created if
/// needed, private), synced, then renamed over `path`. On failure the temporary file is removed
/// and `path` keeps what it held. The file is private ([`PRIVATE_FILE_MODE`]). The error is the
/// operating system's; callers name `path` in their own.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write as _;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    create_private_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let written = (|| {
        let mut file = create_private_file(&tmp)?;
        file.write_all(bytes)?;
        file.sync_data()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// What a path is, as [`diagnose_write`] needs to know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathKind {
    /// Nothing there (or it cannot be looked at).
    Missing,
    /// A directory.
    Directory,
    /// Something else: what it is, for messages (`"a file"`, `"a FIFO (named pipe)"`, ...).
    Other(&'static str),
}

/// Looks at a path (symbolic links followed): the file system, or a table in tests.
pub trait PathProbe {
    /// What `path` is.
    fn kind(&self, path: &Path) -> PathKind;
}

/// The file system.
#[derive(Debug, Clone, Copy, Default)]
pub struct FileSystem;

impl PathProbe for FileSystem {
    fn kind(&self, path: &Path) -> PathKind {
        match std::fs::metadata(path) {
            Err(_) => PathKind::Missing,
            Ok(meta) if meta.is_dir() => PathKind::Directory,
            Ok(meta) if meta.is_file() => PathKind::Other("a file"),
            Ok(meta) => PathKind::Other(file_kind(&meta)),
        }
    }
}

/// What stands in the way of writing a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WriteObstacle {
    /// A folder on the way to the file is something else (a file, a device, ...).
    NotADirectory {
        /// That component of the path.
        component: PathBuf,
        /// What it is instead.
        what: &'static str,
    },
    /// The file to write is a directory.
    IsADirectory,
    /// No space is left on the disk (`ENOSPC`).
    DiskFull {
        /// The deepest existing folder of the path.
        dir: PathBuf,
    },
    /// The user's disk quota is spent (`EDQUOT`).
    QuotaExceeded {
        /// The deepest existing folder of the path.
        dir: PathBuf,
    },
    /// A folder this user may not write in (`EACCES`, `EPERM`).
    NotWritable {
        /// The deepest existing folder of the path.
        dir: PathBuf,
    },
    /// A read-only file system (`EROFS`).
    ReadOnly {
        /// The deepest existing folder of the path.
        dir: PathBuf,
    },
    /// None of the above: the operating system's own words say it.
    Other,
}

/// Why writing `path` failed with `error`, found by looking at the path with `probe`. The
/// error's kind decides a full disk, a quota, permissions and a read-only file system; any other
/// error is laid on the first component of the path that is not a folder, or on the path itself
/// when it is a folder.
pub fn diagnose_write(path: &Path, error: &std::io::Error, probe: &dyn PathProbe) -> WriteObstacle {
    use std::io::ErrorKind;
    let folders: Vec<&Path> = path
        .ancestors()
        .skip(1)
        .filter(|p| !p.as_os_str().is_empty())
        .collect();
    let deepest_existing = || {
        folders
            .iter()
            .find(|p| probe.kind(p) == PathKind::Directory)
            .map_or_else(|| PathBuf::from("."), |p| p.to_path_buf())
    };
    match error.kind() {
        ErrorKind::StorageFull => {
            return WriteObstacle::DiskFull {
                dir: deepest_existing(),
            };
        }
        ErrorKind::QuotaExceeded => {
            return WriteObstacle::QuotaExceeded {
                dir: deepest_existing(),
            };
        }
        ErrorKind::ReadOnlyFilesystem => {
            return WriteObstacle::ReadOnly {
                dir: deepest_existing(),
            };
        }
        _ => {}
    }
    // From the root down: the first folder on the way that is something else.
    for folder in folders.iter().rev() {
        if let PathKind::Other(what) = probe.kind(folder) {
            return WriteObstacle::NotADirectory {
                component: folder.to_path_buf(),
                what,
            };
        }
    }
    if probe.kind(path) == PathKind::Directory {
        return WriteObstacle::IsADirectory;
    }
    if error.kind() == ErrorKind::PermissionDenied {
        return WriteObstacle::NotWritable {
            dir: deepest_existing(),
        };
    }
    WriteObstacle::Other
}

/// Checks, before anything is computed, that `path` could be written as a file: no component on
/// the way is something other than a folder, and the path is not a folder. Nothing is created.
pub fn check_output_file(path: &Path) -> Result<(), WriteError> {
    check_output(path, false)
}

/// [`check_output_file`] for a file of a kind the fix's example names: a folder given as the
/// file says "name a file (for example DIR/`example`)", `report.html` for a report,
/// `run.mcap` for a recording.
pub fn check_output_file_as(path: &Path, example: &str) -> Result<(), WriteError> {
    check_output(path, false).map_err(|e| e.with_example(example))
}

/// Checks, before anything is computed, that `dir` could be created or used as an output
/// folder: no component of it is something other than a folder. Nothing is created.
pub fn check_output_dir(dir: &Path) -> Result<(), WriteError> {
    check_output(&dir.join("file"), true)
}

fn check_output(path: &Path, dir_wanted: bool) -> Result<(), WriteError> {
    let probe = FileSystem;
    let refused = std::io::Error::from(std::io::ErrorKind::NotADirectory);
    match diagnose_write(path, &refused, &probe) {
        WriteObstacle::Other => Ok(()),
        WriteObstacle::IsADirectory if dir_wanted => Ok(()),
        obstacle => Err(WriteError {
            path: if dir_wanted {
                path.parent().unwrap_or(path).to_path_buf()
            } else {
                path.to_path_buf()
            },
            obstacle,
            error: refused,
            example: None,
        }),
    }
}

/// A file or folder that could not be written, with what stood in the way.
///
/// Its message replaces the operating system's words when they describe another path (the OS
/// says "File exists" when a folder on the way is a file); the OS error is kept
/// ([`WriteError::io_error`]) but not given as the error's source, so it is not printed after the
/// explanation that replaces it.
#[derive(Debug)]
pub struct WriteError {
    path: PathBuf,
    obstacle: WriteObstacle,
    error: std::io::Error,
    /// The file name the fix gives as an example when the path is a folder (`out.json` if none).
    example: Option<String>,
}

impl WriteError {
    /// Explains `error`, the failure to write `path`, by looking at the file system now.
    pub fn new(path: &Path, error: std::io::Error) -> WriteError {
        WriteError {
            obstacle: diagnose_write(path, &error, &FileSystem),
            path: path.to_path_buf(),
            error,
            example: None,
        }
    }

    /// The same error, whose fix names `example` (`report.html`, `run.mcap`) as the file to
    /// write into a folder given as the file.
    #[must_use]
    pub fn with_example(mut self, example: &str) -> WriteError {
        self.example = Some(example.to_owned());
        self
    }

    /// Explains `error`, the failure to create the folder `dir` (and its parents): the folder
    /// itself being a file is in the way too.
    pub fn creating_dir(dir: &Path, error: std::io::Error) -> WriteError {
        let obstacle = match diagnose_write(&dir.join("file"), &error, &FileSystem) {
            WriteObstacle::IsADirectory => WriteObstacle::Other,
            obstacle => obstacle,
        };
        WriteError {
            obstacle,
            path: dir.to_path_buf(),
            error,
            example: None,
        }
    }

    /// The path that could not be written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What stood in the way.
    pub fn obstacle(&self) -> &WriteObstacle {
        &self.obstacle
    }

    /// The operating system's error.
    pub fn io_error(&self) -> &std::io::Error {
        &self.error
    }

    /// True for a full disk or a spent quota.
    pub fn is_out_of_space(&self) -> bool {
        matches!(
            self.obstacle,
            WriteObstacle::DiskFull { .. } | WriteObstacle::QuotaExceeded { .. }
        )
    }
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "could not write {}: {}",
            self.path.display(),
            explain_as(
                &self.path,
                &self.obstacle,
                &self.error,
                self.example.as_deref().unwrap_or(DEFAULT_EXAMPLE)
            )
        )
    }
}

impl std::error::Error for WriteError {}

/// The example file name of a fix that asks for a file where a folder was given.
const DEFAULT_EXAMPLE: &str = "out.json";

/// The reason and the fix, in words, for writing `path` against `obstacle`.
pub fn explain(path: &Path, obstacle: &WriteObstacle, error: &std::io::Error) -> String {
    explain_as(path, obstacle, error, DEFAULT_EXAMPLE)
}

/// [`explain`], with `example` as the file name the fix suggests for a folder given as the file.
pub fn explain_as(
    path: &Path,
    obstacle: &WriteObstacle,
    error: &std::io::Error,
    example: &str,
) -> String {
    match obstacle {
        WriteObstacle::NotADirectory { component, what } => format!(
            "{} is {what}, not a directory, so nothing can be written under it: choose a path under a directory",
            component.display()
        ),
        WriteObstacle::IsADirectory => format!(
            "{} is a directory: name a file (for example {})",
            path.display(),
            path.join(example).display()
        ),
        WriteObstacle::DiskFull { dir } => format!(
            "the disk is full (no space left on the file system of {}): free some space or choose another output directory",
            dir.display()
        ),
        WriteObstacle::QuotaExceeded { dir } => format!(
            "the disk quota is spent (on the file system of {}): free some space or choose another output directory",
            dir.display()
        ),
        WriteObstacle::NotWritable { dir } => format!(
            "{} is not writable by this user: choose another output directory or change its permissions",
            dir.display()
        ),
        WriteObstacle::ReadOnly { dir } => format!(
            "{} is on a read-only file system: choose another output directory",
            dir.display()
        ),
        WriteObstacle::Other => error.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder of this test process in the temporary folder, named after `tag`; not made here.
    pub(super) fn scratch(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("formation-{tag}-{}", std::process::id()))
    }

    #[test]
    fn only_small_regular_files_are_read() {
        let dir = scratch("files");
        std::fs::create_dir_all(&dir).unwrap();
        let small = dir.join("small");
        std::fs::write(&small, b"hello").unwrap();
        assert_eq!(read_bounded(&small, 5).unwrap(), b"hello");
        assert!(matches!(
            read_bounded(&small, 4),
            Err(FileRefusal::TooLarge { size: Some(5) })
        ));
        assert!(matches!(
            read_bounded(&dir, 1 << 20),
            Err(FileRefusal::NotAFile {
                kind: "a directory"
            })
        ));
        assert!(matches!(
            read_bounded(Path::new("/dev/zero"), 1 << 20),
            Err(FileRefusal::NotAFile {
                kind: "a character device"
            })
        ));
        assert!(matches!(
            read_bounded(&dir.join("missing"), 1),
            Err(FileRefusal::Io(e)) if e.kind() == std::io::ErrorKind::NotFound
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_atomic_write_replaces_the_whole_file_or_leaves_it_and_no_temporary_behind() {
        let dir = scratch("write");
        let path = dir.join("nested").join("out.json");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        // A directory where the file should go: the rename fails, the directory stays, and the
        // temporary file is gone.
        let blocked = dir.join("blocked");
        std::fs::create_dir_all(blocked.join("inside")).unwrap();
        assert!(write_atomic(&blocked, b"x").is_err());
        assert!(blocked.join("inside").is_dir());
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-"))
            .collect();
        assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn created_files_and_folders_are_private_whatever_was_there() {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        let dir = scratch("private");
        let nested = dir.join("a").join("b");
        let path = nested.join("out.json");
        write_atomic(&path, b"x").unwrap();
        assert_eq!(mode(&path), PRIVATE_FILE_MODE);
        assert_eq!(mode(&dir), PRIVATE_DIR_MODE);
        assert_eq!(mode(&dir.join("a")), PRIVATE_DIR_MODE);
        assert_eq!(mode(&nested), PRIVATE_DIR_MODE);
        // A file that was world-readable is narrowed when it is created again.
        let wide = dir.join("wide.log");
        std::fs::write(&wide, b"old").unwrap();
        std::fs::set_permissions(&wide, std::fs::Permissions::from_mode(0o644)).unwrap();
        drop(create_private_file(&wide).unwrap());
        assert_eq!(mode(&wide), PRIVATE_FILE_MODE);
        // A folder that exists keeps its mode: it is the user's.
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        create_private_dir_all(&dir.join("c")).unwrap();
        assert_eq!(mode(&dir), 0o755);
        assert_eq!(mode(&dir.join("c")), PRIVATE_DIR_MODE);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[cfg(test)]
mod write_error_tests {
    use std::collections::HashMap;
    use std::io::{Error, ErrorKind};

    use super::*;

    /// A file system described by a table: every path not in it is missing.
    struct Table(HashMap<PathBuf, PathKind>);

    impl Table {
        fn new(entries: &[(&str, PathKind)]) -> Table {
            Table(
                entries
                    .iter()
                    .map(|(p, k)| (PathBuf::from(p), *k))
                    .collect(),
            )
        }
    }

    impl PathProbe for Table {
        fn kind(&self, path: &Path) -> PathKind {
            self.0.get(path).copied().unwrap_or(PathKind::Missing)
        }
    }

    fn etc() -> Table {
        Table::new(&[
            ("/", PathKind::Directory),
            ("/etc", PathKind::Directory),
            ("/etc/passwd", PathKind::Other("a file")),
            ("/tmp", PathKind::Directory),
            ("/tmp/out", PathKind::Directory),
        ])
    }

    fn diagnose(path: &str, error: Error) -> (WriteObstacle, String) {
        let path = Path::new(path);
        let obstacle = diagnose_write(path, &error, &etc());
        let text = explain(path, &obstacle, &error);
        (obstacle, text)
    }

    #[test]
    fn a_file_on_the_way_is_named_whatever_the_os_said() {
        // `create_dir_all("/etc/passwd")` says "File exists"; creating under it, "Not a directory".
        for (path, error) in [
            ("/etc/passwd/x.json", Error::from(ErrorKind::AlreadyExists)),
            (
                "/etc/passwd/x/summary.json",
                Error::from(ErrorKind::NotADirectory),
            ),
        ] {
            let (obstacle, text) = diagnose(path, error);
            assert_eq!(
                obstacle,
                WriteObstacle::NotADirectory {
                    component: PathBuf::from("/etc/passwd"),
                    what: "a file"
                }
            );
            assert!(
                text.starts_with("/etc/passwd is a file, not a directory"),
                "{text}"
            );
            assert!(!text.contains("disk") && !text.contains("exists"), "{text}");
        }
    }

    #[test]
    fn only_a_full_disk_or_quota_says_so() {
        let (obstacle, text) = diagnose(
            "/tmp/out/runs/run-0000.json",
            Error::from(ErrorKind::StorageFull),
        );
        assert_eq!(
            obstacle,
            WriteObstacle::DiskFull {
                dir: PathBuf::from("/tmp/out")
            }
        );
        assert!(text.starts_with("the disk is full"), "{text}");
        let (obstacle, _) = diagnose("/tmp/x", Error::from(ErrorKind::QuotaExceeded));
        assert!(matches!(obstacle, WriteObstacle::QuotaExceeded { .. }));
        for kind in [
            ErrorKind::AlreadyExists,
            ErrorKind::NotADirectory,
            ErrorKind::PermissionDenied,
            ErrorKind::Other,
        ] {
            let (_, text) = diagnose("/tmp/out/x.json", Error::from(kind));
            assert!(!text.contains("disk"), "{kind:?}: {text}");
        }
    }

    #[test]
    fn a_directory_target_permissions_and_read_only_name_their_folder() {
        let (obstacle, text) = diagnose("/tmp/out", Error::from(ErrorKind::IsADirectory));
        assert_eq!(obstacle, WriteObstacle::IsADirectory);
        assert!(text.starts_with("/tmp/out is a directory"), "{text}");
        let (obstacle, text) =
            diagnose("/etc/new/x.json", Error::from(ErrorKind::PermissionDenied));
        assert_eq!(
            obstacle,
            WriteObstacle::NotWritable {
                dir: PathBuf::from("/etc")
            }
        );
        assert!(text.starts_with("/etc is not writable"), "{text}");
        let (obstacle, _) = diagnose("/tmp/x", Error::from(ErrorKind::ReadOnlyFilesystem));
        assert_eq!(
            obstacle,
            WriteObstacle::ReadOnly {
                dir: PathBuf::from("/tmp")
            }
        );
        // Anything else keeps the operating system's words.
        let (obstacle, text) = diagnose("/tmp/x", Error::other("something odd"));
        assert_eq!(
            (obstacle, text.as_str()),
            (WriteObstacle::Other, "something odd")
        );
    }

    #[test]
    fn output_paths_are_checked_before_anything_is_written() {
        let dir = super::tests::scratch("check");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a-file");
        std::fs::write(&file, b"x").unwrap();
        assert!(check_output_file(&dir.join("new/x.json")).is_ok());
        assert!(check_output_dir(&dir.join("new/out")).is_ok());
        assert!(check_output_dir(&dir).is_ok());
        let err = check_output_file(&file.join("x.json")).unwrap_err();
        assert!(
            err.to_string()
                .contains(&format!("{} is a file, not a directory", file.display())),
            "{err}"
        );
        let err = check_output_dir(&file.join("out")).unwrap_err();
        assert!(
            err.to_string().contains("is a file, not a directory"),
            "{err}"
        );
        let err = check_output_dir(&file).unwrap_err();
        assert!(
            err.to_string().contains("is a file, not a directory"),
            "{err}"
        );
        let err = check_output_file(&dir).unwrap_err();
        assert!(err.to_string().contains("is a directory"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
