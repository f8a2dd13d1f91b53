//! Where a run's sockets live ([`RunFolder`]): `<base>/formation-udg-<uid>/<run>/`, the base
//! being the endpoint (`--listen`/`--connect` FOLDER) or the temporary folder. The per-user
//! folder is created owner-only (0700) and refused when another user owns it or may enter it;
//! the run's folder, made by its world (0700), holds the world's socket `w`, each agent's
//! `a<robot>-<nonce>` and each swap client's `s<nonce>`, and goes with the world.

use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

use formation_proto::wire::RunId;
use formation_runtime::plugin::RunSite;

use crate::error::DatagramError;
use crate::socket::listening;

/// The folder of one run's sockets.
#[derive(Debug, Clone)]
pub struct RunFolder {
    run: RunId,
    dir: PathBuf,
}

impl RunFolder {
    /// The run's folder for `site` (not created), after making sure this user's folder above it
    /// exists and is private.
    pub fn locate(site: &RunSite<'_>) -> Result<RunFolder, DatagramError> {
        let base = site.endpoint.map_or_else(std::env::temp_dir, PathBuf::from);
        let user = private_folder(&base.join(format!("formation-udg-{}", current_uid())))?;
        Ok(RunFolder {
            run: site.run.clone(),
            dir: user.join(site.run.as_str()),
        })
    }

    /// The run id.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// The run's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The world's socket, where every agent and swap client sends.
    pub fn world_socket(&self) -> PathBuf {
        self.dir.join("w")
    }

    /// The socket of robot `robot`'s agent that greeted with `nonce`.
    pub fn agent_socket(&self, robot: usize, nonce: u64) -> PathBuf {
        self.dir.join(format!("a{robot}-{nonce:016x}"))
    }

    /// The socket of the swap client that sent its request with `nonce`.
    pub fn swap_socket(&self, nonce: u64) -> PathBuf {
        self.dir.join(format!("s{nonce:016x}"))
    }

    /// Creates the run's folder (0700) for its world. A folder a dead world left is removed
    /// first; one whose world still listens is [`DatagramError::RunInUse`].
    pub fn create(&self) -> Result<(), DatagramError> {
        let create = || std::fs::DirBuilder::new().mode(0o700).create(&self.dir);
        match create() {
            Ok(()) => return Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(DatagramError::io("creating", &self.dir)(e)),
        }
        if listening(&self.world_socket()) {
            return Err(DatagramError::RunInUse {
                run: self.run.to_string(),
                dir: self.dir.clone(),
            });
        }
        tracing::info!("removing {}, which a dead world left", self.dir.display());
        self.remove()?;
        create().map_err(DatagramError::io("creating", &self.dir))
    }

    /// Removes the run's folder and every socket in it, if it exists; returns how many entries
    /// went (the folder included).
    pub fn remove(&self) -> Result<usize, DatagramError> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries.count(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(DatagramError::io("listing", &self.dir)(e)),
        };
        match std::fs::remove_dir_all(&self.dir) {
            Ok(()) => Ok(entries + 1),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
            Err(e) => Err(DatagramError::io("removing", &self.dir)(e)),
        }
    }
}

/// `dir`, created owner-only if it is missing (with its parents), and checked to be a folder of
/// ours that nobody else may enter.
fn private_folder(dir: &Path) -> Result<PathBuf, DatagramError> {
    match std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
    {
        Ok(()) => {}
        Err(e) => return Err(DatagramError::io("creating", dir)(e)),
    }
    let meta = std::fs::symlink_metadata(dir).map_err(DatagramError::io("inspecting", dir))?;
    let us = current_uid();
    if !meta.is_dir() || meta.uid() != us || meta.mode() & 0o077 != 0 {
        return Err(DatagramError::NotPrivate {
            dir: dir.to_path_buf(),
            owner: meta.uid(),
            mode: meta.mode() & 0o7777,
            us,
        });
    }
    Ok(dir.to_path_buf())
}

/// The real user id of this process, read from /proc (no unsafe call needed).
fn current_uid() -> u32 {
    std::fs::metadata("/proc/self").map_or(u32::MAX, |m| m.uid())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn a_users_folder_is_private_and_an_open_one_is_refused() {
        let base = formation_test_kit::TempDir::new("udgdir");
        let run = RunId::new("r1").unwrap();
        let base_text = base.path().display().to_string();
        let site = RunSite {
            run: &run,
            endpoint: Some(&base_text),
        };
        let folder = RunFolder::locate(&site).unwrap();
        let user = folder.dir().parent().unwrap().to_path_buf();
        let mode = std::fs::metadata(&user).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o700);
        folder.create().unwrap();
        assert!(folder.dir().is_dir());
        // A folder left behind by a dead world is taken over.
        folder.create().unwrap();
        assert_eq!(folder.remove().unwrap(), 1);
        assert_eq!(folder.remove().unwrap(), 0);
        std::fs::set_permissions(&user, std::fs::Permissions::from_mode(0o755)).unwrap();
        let refused = RunFolder::locate(&site).unwrap_err().to_string();
        assert!(refused.contains("is not private to us"), "{refused}");
    }
}
