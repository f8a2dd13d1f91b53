//! Where things are: the repository root, the shipped default model, and output files.

use std::path::{Path, PathBuf};

/// The shipped default model, relative to the repository root.
pub const DEFAULT_MODEL: &str = "onnx/models/policy.onnx";

/// The repository root: the nearest ancestor of the current directory whose `Cargo.toml` declares
/// the workspace, else the directory this crate was built from.
pub fn repo_root() -> PathBuf {
    let from_cwd = std::env::current_dir().ok().and_then(|cwd| {
        cwd.ancestors()
            .find(|dir| {
                std::fs::read_to_string(dir.join("Cargo.toml"))
                    .map(|text| text.contains("[workspace]"))
                    .unwrap_or(false)
            })
            .map(Path::to_path_buf)
    });
    from_cwd.unwrap_or_else(|| {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    })
}

/// The model to use: the one given, or the shipped default. A missing path, one that is not a
/// regular file and an oversized file are each an error that names the path and the fix
/// ([`formation_onnx::check_model_file`]); nothing is read.
pub fn resolve_model(given: Option<&Path>) -> anyhow::Result<PathBuf> {
    let path = match given {
        Some(p) => p.to_path_buf(),
        None => repo_root().join(DEFAULT_MODEL),
    };
    if let Err(err) = formation_onnx::check_model_file(&path) {
        let err = anyhow::Error::new(err);
        return Err(match given {
            Some(_) => err,
            None => err.context(format!(
                "the shipped default model {DEFAULT_MODEL} is unusable; pass --model PATH"
            )),
        });
    }
    Ok(path)
}

/// Writes `bytes` to `path` atomically ([`formation_proto::files::write_atomic`]), creating
/// parent directories. A failed write (e.g. a full disk) leaves the old file and no temporary one,
/// and its error says what stood in the way ([`WriteError`]: a file where a folder should be, a
/// full disk, ...).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    formation_proto::files::write_atomic(path, bytes).map_err(|e| WriteError::new(path, e))
}

/// A file the command line could not write, explained from its path.
pub use formation_proto::files::WriteError;
