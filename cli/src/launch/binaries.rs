//! Finding the `formation-world` and `formation-agent` executables the launcher starts.
//!
//! They are looked up next to the running executable (`target/<profile>/` for a cargo build; the
//! parent directory too when the running executable is a test binary in `target/<profile>/deps/`).
//! `FORMATION_WORLD_BIN` / `FORMATION_AGENT_BIN` override the lookup (tests use this to start a
//! deliberately broken agent).

use std::path::{Path, PathBuf};

/// The two runtime executables.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RuntimeBinaries {
    /// The world process.
    pub world: PathBuf,
    /// The agent process.
    pub agent: PathBuf,
}

/// A runtime executable could not be found.
#[derive(Debug, thiserror::Error)]
pub enum BinaryError {
    /// Not next to the running executable.
    #[error(
        "{name} was not found in {searched}; build the runtime executables with \
         `cargo build --release` in the repository (the workspace's default members: `formation`, \
         `formation-world` and `formation-agent`; `cargo run -p formation-cli` builds only the \
         `formation` command), or point {env} at it"
    )]
    NotFound {
        /// Executable name.
        name: &'static str,
        /// Directories searched.
        searched: String,
        /// The override variable.
        env: &'static str,
    },
    /// The override names a missing file.
    #[error("{env} is set to {path}, which is not a file")]
    BadOverride {
        /// The override variable.
        env: &'static str,
        /// Its value.
        path: PathBuf,
    },
    /// The running executable's location is unknown.
    #[error("cannot locate the running executable: {0}")]
    CurrentExe(std::io::Error),
}

/// Candidate directories for `exe`: its own directory and, for `deps/`, the one above.
pub fn search_dirs(exe: &Path) -> Vec<PathBuf> {
    let mut dirs = Vec::new();
    if let Some(dir) = exe.parent() {
        dirs.push(dir.to_path_buf());
        if dir.file_name().is_some_and(|n| n == "deps")
            && let Some(up) = dir.parent()
        {
            dirs.push(up.to_path_buf());
        }
    }
    dirs
}

fn locate(
    name: &'static str,
    env: &'static str,
    dirs: &[PathBuf],
    override_value: Option<PathBuf>,
) -> Result<PathBuf, BinaryError> {
    if let Some(path) = override_value {
        return if path.is_file() {
            Ok(path)
        } else {
            Err(BinaryError::BadOverride { env, path })
        };
    }
    let file = format!("{name}{}", std::env::consts::EXE_SUFFIX);
    dirs.iter()
        .map(|d| d.join(&file))
        .find(|p| p.is_file())
        .ok_or_else(|| BinaryError::NotFound {
            name,
            searched: dirs
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            env,
        })
}

impl RuntimeBinaries {
    /// Finds both executables (overrides first, then next to the running executable).
    pub fn locate() -> Result<RuntimeBinaries, BinaryError> {
        let exe = std::env::current_exe().map_err(BinaryError::CurrentExe)?;
        let dirs = search_dirs(&exe);
        let var = |name| std::env::var_os(name).map(PathBuf::from);
        Ok(RuntimeBinaries {
            world: locate(
                "formation-world",
                "FORMATION_WORLD_BIN",
                &dirs,
                var("FORMATION_WORLD_BIN"),
            )?,
            agent: locate(
                "formation-agent",
                "FORMATION_AGENT_BIN",
                &dirs,
                var("FORMATION_AGENT_BIN"),
            )?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn test_binaries_in_deps_also_search_the_profile_directory() {
        let dirs = search_dirs(Path::new("/t/target/debug/deps/formation-abc"));
        assert_eq!(
            dirs,
            vec![
                PathBuf::from("/t/target/debug/deps"),
                PathBuf::from("/t/target/debug")
            ]
        );
        assert_eq!(
            search_dirs(Path::new("/t/target/release/formation")),
            vec![PathBuf::from("/t/target/release")]
        );
    }

    #[test]
    fn missing_binaries_name_the_build_command_and_bad_overrides_are_refused() {
        let dir = std::env::temp_dir().join(format!("formation-bin-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let err = locate(
            "formation-world",
            "FORMATION_WORLD_BIN",
            std::slice::from_ref(&dir),
            None,
        )
        .unwrap_err();
        assert!(err.to_string().contains("cargo build --release"), "{err}");
        let present = dir.join("formation-world");
        std::fs::write(&present, b"").unwrap();
        assert_eq!(
            locate("formation-world", "X", std::slice::from_ref(&dir), None).unwrap(),
            present
        );
        let missing = dir.join("nope");
        assert!(matches!(
            locate("formation-world", "X", &[], Some(missing)),
            Err(BinaryError::BadOverride { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
