//! The decoders under fuzzing, one [`Target`] each: how its case bytes reach the decoder's public
//! entry point, what counts as decoded, its seeds (made by the real encoders) and its dictionary.

use std::path::{Path, PathBuf};

use crate::FuzzError;
use crate::mutate::Shape;

pub mod dagger;
pub mod dataset;
pub mod live;
pub mod model_metadata;
pub mod recording;
pub mod ros2;
pub mod sample;
pub mod scenario;
pub mod wire;

/// Why a case was refused: a short label for the report (the error's variant), after its
/// message was formatted (formatting is part of the decoder: the message is what a user sees).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal(pub String);

impl Refusal {
    /// The refusal of `error`: its message is formatted (and dropped), its label is the name of
    /// its variant, followed by the variant of the error inside it when it wraps one.
    pub fn of<E: std::fmt::Debug + std::fmt::Display>(error: E) -> Refusal {
        let message = error.to_string();
        debug_assert!(!message.is_empty());
        let debug = format!("{error:?}");
        Refusal(label(&debug))
    }

    /// A refusal with a fixed label.
    pub fn named(label: &str) -> Refusal {
        Refusal(label.to_owned())
    }
}

/// The variant names in a `Debug` text: the first identifier, and the first one after
/// `source:` (the wrapped error), e.g. `Step/Cdr`.
fn label(debug: &str) -> String {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = ident(debug);
    if let Some(i) = debug.find("source: ") {
        let inner = ident(&debug[i + 8..]);
        if !inner.is_empty() {
            out.push('/');
            out.push_str(&inner);
        }
    }
    out
}

/// A place for decoders that read files: a private folder, removed when the campaign ends.
#[derive(Debug)]
pub struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    /// A fresh folder, in memory (`/dev/shm`) where there is one.
    pub fn new() -> Result<Scratch, FuzzError> {
        let shm = Path::new("/dev/shm");
        let builder = || {
            let mut b = tempfile::Builder::new();
            b.prefix("formation-fuzz-");
            b
        };
        let dir = if shm.is_dir() {
            builder().tempdir_in(shm)
        } else {
            builder().tempdir()
        }
        .map_err(|source| FuzzError::Scratch { source })?;
        Ok(Scratch { dir })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// `name` in the folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Writes `bytes` to `name` in the folder.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<PathBuf, Refusal> {
        let path = self.path(name);
        std::fs::write(&path, bytes).map_err(|_| Refusal::named("scratch write failed"))?;
        Ok(path)
    }
}

/// A seed of a corpus: a file name and its bytes.
pub type Seed = (String, Vec<u8>);

/// One decoder under fuzzing.
pub struct Target {
    /// Its name (`scripts/fuzz NAME`, the corpus folder).
    pub name: &'static str,
    /// What it decodes, through which entry point.
    pub about: &'static str,
    /// Runs one case: `Ok` when it decoded, the refusal otherwise. Panics are findings.
    pub run: fn(&Scratch, &[u8]) -> Result<(), Refusal>,
    /// Its seeds, made by the real encoders.
    pub seeds: fn() -> Result<Vec<Seed>, FuzzError>,
    /// Tokens the mutations insert (magic bytes, keys, separators).
    pub tokens: &'static [&'static [u8]],
    /// What its cases mostly look like.
    pub shape: Shape,
}

impl std::fmt::Debug for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Target").field("name", &self.name).finish()
    }
}

/// Every target, in the CI lane's order.
pub const ALL: &[Target] = &[
    wire::TARGET,
    ros2::TARGET,
    recording::TARGET,
    live::TARGET,
    dataset::TARGET,
    dagger::TARGET,
    scenario::TARGET,
    model_metadata::TARGET,
];

/// The target named `name`.
pub fn find(name: &str) -> Result<&'static Target, FuzzError> {
    ALL.iter()
        .find(|t| t.name == name)
        .ok_or_else(|| FuzzError::UnknownTarget {
            name: name.to_owned(),
            known: ALL.iter().map(|t| t.name).collect::<Vec<_>>().join(", "),
        })
}

/// A seed error of target `target`.
pub(crate) fn seed_error<E: std::error::Error + Send + Sync + 'static>(
    target: &'static str,
) -> impl FnOnce(E) -> FuzzError {
    move |source| FuzzError::Seed {
        target,
        source: Box::new(source),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_label_names_the_variant_and_the_one_it_wraps() {
        assert_eq!(
            super::label("Step { path: \"x\", source: Cdr(Truncated { .. }) }"),
            "Step/Cdr"
        );
        assert_eq!(super::label("Magic"), "Magic");
    }
}
