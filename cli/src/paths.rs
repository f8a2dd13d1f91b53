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

/// The model to use: the one given (a relative path missing here is tried from the repository
/// root), or the shipped default. A missing path, one that is not a
/// regular file and an oversized file are each an error that names the path and the fix
/// ([`formation_onnx::check_model_file`]); nothing is read.
pub fn resolve_model(given: Option<&Path>) -> anyhow::Result<PathBuf> {
    let path = match given {
        // A relative path not found here, but found from the repository root (the shipped
        // models' `onnx/models/...`, typed from another folder), is taken from the root.
        Some(p) if p.is_relative() && !p.exists() && repo_root().join(p).exists() => {
            repo_root().join(p)
        }
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

/// The model a command runs on `scenario` when `given` (`--model`) is absent: the scenario's own
/// (its `model` key), else the shipped default; checked as [`resolve_model`] checks it, and a
/// scenario's unusable model is named with its key.
pub fn resolve_model_for(
    given: Option<&Path>,
    scenario: &formation_world::Scenario,
) -> anyhow::Result<PathBuf> {
    match (given, scenario.model()) {
        (None, Some(named)) => resolve_model(Some(named)).map_err(|err| {
            err.context(format!(
                "the scenario's model (its `model` key, {}) is unusable; fix the key or pass --model PATH",
                named.display()
            ))
        }),
        _ => resolve_model(given),
    }
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

/// An output that would overwrite one of the command's own inputs.
#[derive(Debug, thiserror::Error)]
#[error(
    "{flag} {}: {} is the file {input_flag} reads, and writing there would destroy it: {fix}",
    output.display(), input.display()
)]
pub struct OutputIsInput {
    /// The output's flag (`--json`, `--record`, `--out`).
    pub flag: &'static str,
    /// The output as given.
    pub output: PathBuf,
    /// The input's flag (`--scenario`, `--model`, ...).
    pub input_flag: &'static str,
    /// The input it would overwrite.
    pub input: PathBuf,
    /// What to do instead.
    pub fix: String,
}

/// The files an output folder (`--out DIR` of `eval` and `run`) gets: its summary, run specs,
/// latency profile and the logs under `runs/`, `timing/` and `credentials/`.
fn written_in_out_folder(relative: &Path) -> bool {
    let mut parts = relative.components();
    let first = parts
        .next()
        .map(|c| c.as_os_str().to_string_lossy().into_owned());
    let nested = parts.next().is_some();
    match first.as_deref() {
        Some("runs" | "timing" | "credentials") => nested,
        Some("summary.json" | "run-specs.json" | "profile.json" | "profile.svg") => !nested,
        _ => false,
    }
}

/// Refuses, before anything is written, an output that is one of `inputs` (each with its flag):
/// a file output (`files`: flag, path, an example name for the fix) that is the same file as an
/// input, or an output folder (`folders`) an input lies in where the command writes (its
/// `summary.json`, `runs/...`). Nothing is created.
pub fn refuse_overwriting_inputs(
    files: &[(&'static str, &Path, &str)],
    folders: &[(&'static str, &Path)],
    inputs: &[(&'static str, &Path)],
) -> Result<(), OutputIsInput> {
    let canonical = |p: &Path| std::fs::canonicalize(p).ok();
    let inputs: Vec<(&'static str, &Path, PathBuf)> = inputs
        .iter()
        .filter_map(|&(flag, path)| Some((flag, path, canonical(path)?)))
        .collect();
    for &(flag, output, example) in files {
        let Some(out) = canonical(output) else {
            continue; // not there yet: no input is
        };
        if let Some((input_flag, input, _)) = inputs.iter().find(|(_, _, c)| *c == out) {
            return Err(OutputIsInput {
                flag,
                output: output.to_path_buf(),
                input_flag,
                input: input.to_path_buf(),
                fix: format!(
                    "name another file (for example {})",
                    output.with_file_name(example).display()
                ),
            });
        }
    }
    for &(flag, dir) in folders {
        let Some(out) = canonical(dir) else {
            continue;
        };
        let clash = inputs
            .iter()
            .find(|(_, _, c)| c.strip_prefix(&out).is_ok_and(written_in_out_folder));
        if let Some((input_flag, input, _)) = clash {
            return Err(OutputIsInput {
                flag,
                output: dir.to_path_buf(),
                input_flag,
                input: input.to_path_buf(),
                fix: format!(
                    "{flag} writes its summary and logs there; name another folder, or move \
                     the input out of it"
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_that_is_an_input_is_refused_by_its_identity() {
        let dir = tempfile::tempdir().unwrap();
        let scenario = dir.path().join("case1.toml");
        std::fs::write(&scenario, "x").unwrap();
        // The same file under another spelling.
        let spelled = dir.path().join(".").join("case1.toml");
        let err = refuse_overwriting_inputs(
            &[("--json", &spelled, "out.json")],
            &[],
            &[("--scenario", &scenario)],
        )
        .unwrap_err();
        let message = err.to_string();
        assert!(
            message.contains("--json") && message.contains("--scenario"),
            "{message}"
        );
        assert!(message.contains("out.json"), "{message}");
        // A new file, or another one, is no input.
        let other = dir.path().join("other.json");
        refuse_overwriting_inputs(
            &[("--json", &other, "out.json")],
            &[],
            &[("--scenario", &scenario)],
        )
        .unwrap();
        // An input where an output folder gets its summary or run logs.
        std::fs::create_dir_all(dir.path().join("runs")).unwrap();
        let log = dir.path().join("runs/run-0000.json");
        std::fs::write(&log, "x").unwrap();
        let err = refuse_overwriting_inputs(&[], &[("--out", dir.path())], &[("--model", &log)])
            .unwrap_err();
        assert!(err.to_string().contains("--out"), "{err}");
        // ... but not one beside them that the command does not write.
        refuse_overwriting_inputs(&[], &[("--out", dir.path())], &[("--scenario", &scenario)])
            .unwrap();
    }
}
