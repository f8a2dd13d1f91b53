//! Model files on disk: what may be loaded, checked by metadata before anything is read, and a
//! bounded read.
//!
//! A model must be a regular file of at most [`MAX_MODEL_BYTES`]. A missing path, a directory, a
//! FIFO, a device (`/dev/zero`) and an oversized file are each refused with their own
//! [`PolicyError`] naming the path and the fix, before a byte is read: a FIFO is never opened and a
//! 4 GB file never read. Tools that only pass a path on (`formation swap`, the launch planner) call
//! [`check_model_file`] for the same refusal without reading.

use std::path::Path;

use formation_proto::files::{FileRefusal, check_regular_file, read_bounded};

use crate::error::PolicyError;

/// Largest model file that is loaded \[bytes\]: 64 MiB. The paper's network exports to 87 KB; the
/// limit leaves room for much larger policies while refusing a wrong path before it is read whole.
pub const MAX_MODEL_BYTES: u64 = 64 << 20;

/// Checks by its metadata alone that `path` is a model file that may be loaded: it exists, is a
/// regular file (symbolic links followed) and holds at most [`MAX_MODEL_BYTES`]. Returns its size.
pub fn check_model_file(path: &Path) -> Result<u64, PolicyError> {
    check_regular_file(path, MAX_MODEL_BYTES).map_err(|refusal| model_error(path, refusal))
}

/// The bytes of the model file at `path`, read only after [`check_model_file`] passed, checked
/// again on the opened file (it may have been replaced in between), and stopping one byte past
/// [`MAX_MODEL_BYTES`] whatever the metadata said.
pub(crate) fn read_model_file(path: &Path) -> Result<Vec<u8>, PolicyError> {
    read_bounded(path, MAX_MODEL_BYTES).map_err(|refusal| model_error(path, refusal))
}

/// The model error for a refused file; a missing path is [`PolicyError::ModelNotFound`].
fn model_error(path: &Path, refusal: FileRefusal) -> PolicyError {
    let path = path.to_path_buf();
    match refusal {
        FileRefusal::NotAFile { kind } => PolicyError::ModelNotAFile { path, kind },
        FileRefusal::TooLarge { size } => PolicyError::ModelTooLarge {
            path,
            size,
            limit: MAX_MODEL_BYTES,
        },
        FileRefusal::Io(source) if source.kind() == std::io::ErrorKind::NotFound => {
            PolicyError::ModelNotFound { path }
        }
        FileRefusal::Io(source) => PolicyError::ModelRead { path, source },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_path_is_not_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("nothing.onnx");
        match read_model_file(&path) {
            Err(ref err @ PolicyError::ModelNotFound { path: ref p }) => {
                assert_eq!(*p, path);
                assert!(err.to_string().contains("not found"), "{err}");
            }
            other => panic!("expected ModelNotFound, got {other:?}"),
        }
    }

    #[test]
    fn directories_fifos_and_devices_are_not_regular_files() {
        let dir = tempfile::tempdir().expect("tempdir");
        let fifo = dir.path().join("pipe.onnx");
        formation_test_kit::make_fifo(&fifo);
        for (path, kind) in [
            (dir.path(), "a directory"),
            (fifo.as_path(), "a FIFO (named pipe)"),
            (Path::new("/dev/zero"), "a character device"),
        ] {
            // Opening the FIFO or reading /dev/zero would block or never end: refused first.
            for result in [
                check_model_file(path).map(|_| ()),
                read_model_file(path).map(|_| ()),
            ] {
                match result {
                    Err(ref err @ PolicyError::ModelNotAFile { kind: k, .. }) => {
                        assert_eq!(k, kind);
                        let message = err.to_string();
                        assert!(message.contains("not a regular file"), "{message}");
                        assert!(!message.contains("not found"), "{message}");
                        assert!(message.contains(&path.display().to_string()), "{message}");
                    }
                    other => panic!("{path:?}: expected ModelNotAFile, got {other:?}"),
                }
            }
        }
    }

    #[test]
    fn an_oversized_file_is_refused_by_its_size() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("huge.onnx");
        let file = std::fs::File::create(&path).expect("create");
        // Sparse: 4 GiB that take no disk space; reading them whole is what must not happen.
        file.set_len(4 << 30).expect("set_len");
        for result in [
            check_model_file(&path).map(|_| ()),
            read_model_file(&path).map(|_| ()),
        ] {
            match result {
                Err(ref err @ PolicyError::ModelTooLarge { size, .. }) => {
                    assert_eq!(size, Some(4 << 30));
                    let message = err.to_string();
                    assert!(message.contains("4294967296 bytes"), "{message}");
                    assert!(message.contains("64 MiB"), "{message}");
                    assert!(message.contains("huge.onnx"), "{message}");
                }
                other => panic!("expected ModelTooLarge, got {other:?}"),
            }
        }
        file.set_len(MAX_MODEL_BYTES + 1).expect("set_len");
        assert!(matches!(
            check_model_file(&path),
            Err(PolicyError::ModelTooLarge { .. })
        ));
        file.set_len(MAX_MODEL_BYTES).expect("set_len");
        assert_eq!(
            check_model_file(&path).expect("at the limit"),
            MAX_MODEL_BYTES
        );
    }

    #[test]
    fn a_small_regular_file_is_read_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("small.onnx");
        std::fs::write(&path, b"0123456789").expect("write");
        assert_eq!(check_model_file(&path).expect("a model file"), 10);
        assert_eq!(read_model_file(&path).expect("readable"), b"0123456789");
    }
}
