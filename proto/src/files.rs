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

use std::io::Read as _;
use std::path::Path;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_small_regular_files_are_read() {
        let dir = std::env::temp_dir().join(format!("formation-files-{}", std::process::id()));
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
        let dir = std::env::temp_dir().join(format!("formation-write-{}", std::process::id()));
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
        let dir = std::env::temp_dir().join(format!("formation-private-{}", std::process::id()));
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
