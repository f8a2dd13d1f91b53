//! The seed corpora on disk: `tests/fuzz/corpus/NAME/` per target, read with bounded reads and
//! written from the targets' real encoders.

use std::io::Read as _;
use std::path::{Path, PathBuf};

use crate::FuzzError;
use crate::mutate::MAX_CASE_BYTES;
use crate::targets::{Seed, Target};

/// Most seed files read from one corpus folder.
pub const MAX_SEEDS: usize = 256;

/// The repository's corpus root, `tests/fuzz/corpus` beside this crate.
pub fn default_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fuzz/corpus")
}

/// The folder of `target`'s seeds under `root`.
pub fn dir(root: &Path, target: &Target) -> PathBuf {
    root.join(target.name)
}

/// Maps an I/O error of `action` on `path` to [`FuzzError::Corpus`] naming both.
fn corpus(action: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> FuzzError {
    let path = path.to_path_buf();
    move |source| FuzzError::Corpus {
        action,
        path,
        source,
    }
}

/// Reads `target`'s seeds (at most [`MAX_SEEDS`] files, in name order, each at most
/// [`MAX_CASE_BYTES`]).
pub fn load(root: &Path, target: &Target) -> Result<Vec<Seed>, FuzzError> {
    let dir = dir(root, target);
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).map_err(corpus("reading the corpus folder", &dir))? {
        let entry = entry.map_err(corpus("reading the corpus folder", &dir))?;
        if entry.file_type().is_ok_and(|t| t.is_file()) {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    names.sort();
    names.truncate(MAX_SEEDS);
    let mut seeds = Vec::with_capacity(names.len());
    for name in names {
        let path = dir.join(&name);
        let file = std::fs::File::open(&path).map_err(corpus("opening the seed", &path))?;
        let mut bytes = Vec::new();
        file.take(MAX_CASE_BYTES as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(corpus("reading the seed", &path))?;
        if bytes.len() > MAX_CASE_BYTES {
            return Err(FuzzError::SeedTooLarge {
                path,
                max: MAX_CASE_BYTES,
            });
        }
        seeds.push((name, bytes));
    }
    if seeds.is_empty() {
        return Err(FuzzError::EmptyCorpus {
            target: target.name,
            dir,
        });
    }
    Ok(seeds)
}

/// Writes `target`'s seeds under `root`, replacing the files its folder held.
pub fn write(root: &Path, target: &Target) -> Result<Vec<PathBuf>, FuzzError> {
    let seeds = (target.seeds)()?;
    let dir = dir(root, target);
    if dir.is_dir() {
        for entry in std::fs::read_dir(&dir).map_err(corpus("reading the corpus folder", &dir))? {
            let path = entry
                .map_err(corpus("reading the corpus folder", &dir))?
                .path();
            if path.is_file() {
                std::fs::remove_file(&path).map_err(corpus("removing the old seed", &path))?;
            }
        }
    }
    std::fs::create_dir_all(&dir).map_err(corpus("creating the corpus folder", &dir))?;
    let mut written = Vec::with_capacity(seeds.len());
    for (name, bytes) in seeds {
        let path = dir.join(name);
        std::fs::write(&path, bytes).map_err(corpus("writing the seed", &path))?;
        written.push(path);
    }
    Ok(written)
}
