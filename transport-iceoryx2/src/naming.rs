//! What a run's iceoryx2 services need beyond their names (which are the wire's, shared with
//! Zenoh): their limits, node names and the run's namespace, with the lock that claims a run.
//!
//! Per robot `i` of a run `<run>` there is a *lobby*, where an agent asks to drive the robot and
//! proves with the launch secret ([`formation_runtime::auth`]) that its launch started it:
//!
//! | service | payload | publisher → subscriber |
//! |---|---|---|
//! | `formation/<run>/robot/<i>/hello` | [`HelloMsg`](formation_proto::wire::HelloMsg) | candidate agents (up to 8) → world |
//! | `formation/<run>/robot/<i>/welcome` | [`WelcomeMsg`](formation_proto::wire::WelcomeMsg) | world → candidate agents |
//!
//! and, per accepted agent (an *incarnation*, named by the agent's nonce `<n>` in 16 hex digits),
//! four publish-subscribe services, each paired with an event service of the same name
//! (publishing wakes nobody in iceoryx2; the paired event does):
//!
//! | service | payload | publisher → subscriber |
//! |---|---|---|
//! | `formation/<run>/robot/<i>/<n>/scan` | `ScanMsg` | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/cmd` | `CmdMsg` | agent `i` → world |
//! | `formation/<run>/robot/<i>/<n>/control` | `ControlMsg` | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/status` | `StatusMsg` | agent `i` → world |
//!
//! The world creates an incarnation's services only after it checked the agent's proof, and drops
//! them when the agent is gone, so a process that squats on a dead agent's ports blocks nothing:
//! the next agent of the launch gets services of its own.
//!
//! Per run there is also a swap channel, through which `formation swap` asks the world to change one
//! robot's model: `formation/<run>/swap/request` (`SwapRequestMsg`, tools → world) and
//! `formation/<run>/swap/reply` (`SwapReplyMsg`, world → tools).
//!
//! Each robot service admits at most one publisher and one subscriber ([`ServiceLimits::ROBOT`]),
//! which is how decentralisation is enforced by the transport itself: once agent `i` holds its scan
//! subscription no other process can read robot `i`'s scan, and once it holds its command
//! publisher no other process can command robot `i`.
//!
//! Every file iceoryx2 creates for a run carries the run's own prefix (`fm_<run>_` in the
//! shared-memory folder) and lives under the run's own root directory (see [`RunNamespace`]), so
//! parallel runs and tests never collide and a run's leftovers can be listed and removed exactly.

use std::path::{Path, PathBuf};

use formation_proto::wire::{RunId, SwapChannel, WireError};
use formation_runtime::link::PathIoError;
use iceoryx2::prelude::*;

/// The sizes of a swap service, shared by creator and openers.
pub fn swap_limits(channel: SwapChannel) -> ServiceLimits {
    match channel {
        SwapChannel::Request => ServiceLimits::SWAP_REQUEST,
        SwapChannel::Reply => ServiceLimits::SWAP_REPLY,
    }
}

/// Node name of a `formation swap` process.
pub const SWAP_NODE_NAME: &str = "formation-swap";

/// Limits iceoryx2's own logging to errors unless `IOX2_LOG_LEVEL` asks for more. Its warnings
/// (e.g. that it cleaned up after a dead agent, which the runtime does on purpose) would otherwise
/// bury the runtime's messages. Every formation process that uses iceoryx2 calls this first.
pub fn quiet_iceoryx_logs() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// Node name of the world process of a run.
pub const WORLD_NODE_NAME: &str = "formation-world";

/// Node name of robot `robot`'s agent process `pid`. The pid makes a restarted agent's node
/// distinguishable from its dead predecessor's, so a late death report never hits the new agent.
pub fn agent_node_name(robot: usize, pid: u32) -> String {
    format!("formation-agent-{robot}-{pid}")
}

/// The robot and pid of an agent node name made by [`agent_node_name`]; `None` for other names.
pub fn parse_agent_node_name(name: &str) -> Option<(usize, u32)> {
    let (robot, pid) = name.strip_prefix("formation-agent-")?.split_once('-')?;
    Some((robot.parse().ok()?, pid.parse().ok()?))
}

/// Sizes of a robot service, shared by both sides so that opening never disagrees with creating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceLimits {
    /// Publishers allowed on the service.
    pub max_publishers: usize,
    /// Subscribers allowed on the service.
    pub max_subscribers: usize,
    /// Samples a subscriber can hold unread before the oldest is overwritten.
    pub subscriber_buffer: usize,
    /// Nodes that may open the service (the two ends and a dead predecessor awaiting cleanup).
    pub max_nodes: usize,
}

impl ServiceLimits {
    /// Every robot channel: one writer, one reader. A buffer of 8 samples: in lockstep at most one
    /// message per tick is in flight; in realtime the reader takes the newest of what arrived, and
    /// 8 x 50 ms of backlog is more than any stale-command limit, so overwriting the oldest is right.
    pub const ROBOT: ServiceLimits = ServiceLimits {
        max_publishers: 1,
        max_subscribers: 1,
        subscriber_buffer: 8,
        max_nodes: 4,
    };

    /// Many to one: up to 8 processes at once write, only the world reads.
    const FAN_IN: ServiceLimits = ServiceLimits {
        max_publishers: 8,
        max_subscribers: 1,
        subscriber_buffer: 16,
        max_nodes: 16,
    };

    /// One to many: only the world writes, up to 8 processes at once read.
    const FAN_OUT: ServiceLimits = ServiceLimits {
        max_publishers: 1,
        max_subscribers: 8,
        ..ServiceLimits::FAN_IN
    };

    /// A robot's hello service: up to 8 candidate agents at once write, only the world reads.
    pub const HELLO: ServiceLimits = ServiceLimits::FAN_IN;

    /// A robot's welcome service: only the world writes; every candidate reads and keeps the
    /// answer to its own nonce.
    pub const WELCOME: ServiceLimits = ServiceLimits::FAN_OUT;

    /// Swap requests: any number of `formation swap` processes (up to 8 at once) write, only the
    /// world reads.
    pub const SWAP_REQUEST: ServiceLimits = ServiceLimits::FAN_IN;

    /// Swap replies: only the world writes; every waiting `formation swap` reads and keeps the
    /// reply with its own request id.
    pub const SWAP_REPLY: ServiceLimits = ServiceLimits::FAN_OUT;
}

/// The iceoryx2 namespace of one run: a file prefix for the shared-memory folder and a root
/// directory for everything else iceoryx2 writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunNamespace {
    run: RunId,
    root: PathBuf,
}

/// Where POSIX shared-memory objects live on Linux.
pub const SHM_DIR: &str = "/dev/shm";

impl RunNamespace {
    /// The namespace of `run` under the system temp directory: `<tmp>/iceoryx2-formation/<run>/`.
    pub fn new(run: &RunId) -> RunNamespace {
        RunNamespace::with_base(run, &std::env::temp_dir().join("iceoryx2-formation"))
    }

    /// The namespace of `run` with its root directory under `base`.
    pub fn with_base(run: &RunId, base: &Path) -> RunNamespace {
        RunNamespace {
            run: run.clone(),
            root: base.join(run.as_str()),
        }
    }

    /// The run id.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// Prefix of every file iceoryx2 creates for this run.
    pub fn file_prefix(&self) -> String {
        format!("fm_{}_", self.run)
    }

    /// The root directory of iceoryx2's non-shared-memory files for this run.
    pub fn root_dir(&self) -> &Path {
        &self.root
    }

    /// An iceoryx2 configuration confined to this namespace. Building it reads no config file.
    pub fn iceoryx_config(&self) -> Result<iceoryx2::config::Config, WireError> {
        let mut config = iceoryx2::config::Config::default();
        let prefix = self.file_prefix();
        config.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(|e| WireError::Malformed {
                message: "namespace",
                reason: format!("file prefix {prefix:?} rejected by iceoryx2 ({e:?})"),
            })?;
        let mut root = self.root.display().to_string();
        if !root.ends_with('/') {
            root.push('/');
        }
        let root_path =
            iceoryx2::prelude::Path::new(root.as_bytes()).map_err(|e| WireError::Malformed {
                message: "namespace",
                reason: format!("root path {root:?} rejected by iceoryx2 ({e:?})"),
            })?;
        config.global.set_root_path(&root_path);
        Ok(config)
    }

    /// Every file and directory this run has left: shared-memory objects with the run's prefix and
    /// the root directory itself when it exists. Empty after a clean shutdown and
    /// [`RunNamespace::remove_all`].
    pub fn leftovers(&self) -> Vec<PathBuf> {
        let mut found = list_with_prefix(Path::new(SHM_DIR), &self.file_prefix());
        if self.root.exists() {
            found.push(self.root.clone());
        }
        found
    }

    /// The run's shared-memory objects but iceoryx2's management segment of the namespace, which
    /// stays after every node closed cleanly (by design, across nodes) until the launcher removes
    /// the namespace: empty after a clean shutdown.
    pub fn shared_memory_but_management(&self) -> Vec<PathBuf> {
        list_with_prefix(Path::new(SHM_DIR), &self.file_prefix())
            .into_iter()
            .filter(|p| !p.to_string_lossy().ends_with(".global_mgmt"))
            .collect()
    }

    /// Removes everything [`RunNamespace::leftovers`] lists. Returns how many entries were removed.
    /// Call it only when no process of the run is alive.
    pub fn remove_all(&self) -> std::io::Result<usize> {
        let mut removed = 0;
        for path in list_with_prefix(Path::new(SHM_DIR), &self.file_prefix()) {
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
        if self.root.exists() {
            std::fs::remove_dir_all(&self.root)?;
            removed += 1;
        }
        Ok(removed)
    }
}

/// Why a run's namespace could not be claimed or made private.
#[derive(Debug, thiserror::Error)]
pub enum NamespaceError {
    /// Another live launch holds the run id.
    #[error(
        "run id {run} is in use by another live launch (it holds {lock}); pick another --run-id, \
         or stop that launch first"
    )]
    InUse {
        /// The run id.
        run: String,
        /// The lock file.
        lock: PathBuf,
    },
    /// The folder holding every run's namespace belongs to another user.
    #[error(
        "{dir} belongs to user id {owner}, not to us ({us}); another user could tamper with our \
         runs there: remove it, or point TMPDIR at a directory of your own"
    )]
    ForeignBase {
        /// The folder.
        dir: PathBuf,
        /// Its owner.
        owner: u32,
        /// Our user id.
        us: u32,
    },
    /// A file system operation failed.
    #[error(transparent)]
    Io(#[from] PathIoError),
}

/// The claim of one launch on a run id: an exclusive lock on `<base>/<run>.lock`, held for as
/// long as this value lives (the OS drops it when the process dies, however it dies). Dropping it
/// removes the lock file.
#[derive(Debug)]
pub struct RunLock {
    file: std::fs::File,
    path: PathBuf,
}

impl RunLock {
    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        // Unlink while still holding the lock: a launch that opened the old file before the unlink
        // sees (after locking it) that the path no longer names its file, and tries again.
        let _ = std::fs::remove_file(&self.path);
        let _ = self.file.unlock();
    }
}

impl RunNamespace {
    /// The folder that holds every run's root directory (and their lock files).
    pub fn base_dir(&self) -> &Path {
        self.root.parent().unwrap_or(&self.root)
    }

    /// Makes sure the base folder exists, is ours and is private (0700).
    fn private_base(&self) -> Result<&Path, NamespaceError> {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        let base = self.base_dir();
        let io = |action, source| PathIoError::of(action, base)(source);
        match std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(base)
        {
            Ok(()) => {}
            Err(e) => return Err(io("creating", e).into()),
        }
        let meta = std::fs::metadata(base).map_err(|e| io("inspecting", e))?;
        let us = current_uid();
        if meta.uid() != us {
            return Err(NamespaceError::ForeignBase {
                dir: base.to_path_buf(),
                owner: meta.uid(),
                us,
            });
        }
        if meta.mode() & 0o077 != 0 {
            std::fs::set_permissions(base, std::fs::Permissions::from_mode(0o700))
                .map_err(|e| io("making private", e))?;
        }
        Ok(base)
    }

    /// The lock file a launch holds while it uses this run id.
    pub fn lock_path(&self) -> PathBuf {
        self.base_dir().join(format!("{}.lock", self.run))
    }

    /// Claims the run id for this process, atomically: of two launches that try at the same
    /// instant exactly one gets the lock, and the other gets [`NamespaceError::InUse`] without
    /// having touched anything of the winner's.
    pub fn lock(&self) -> Result<RunLock, NamespaceError> {
        use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
        self.private_base()?;
        let path = self.lock_path();
        for _ in 0..8 {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .mode(0o600)
                .open(&path)
                .map_err(PathIoError::of("opening the run lock", &path))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(NamespaceError::InUse {
                        run: self.run.to_string(),
                        lock: path,
                    });
                }
                Err(std::fs::TryLockError::Error(source)) => {
                    return Err(PathIoError::of("locking", path)(source).into());
                }
            }
            // The winner of a race may have unlinked the file we opened: then ours is stale.
            let ours = file.metadata().map(|m| (m.dev(), m.ino()));
            let named = std::fs::metadata(&path).map(|m| (m.dev(), m.ino()));
            if let (Ok(ours), Ok(named)) = (ours, named)
                && ours == named
            {
                return Ok(RunLock { file, path });
            }
        }
        Err(NamespaceError::InUse {
            run: self.run.to_string(),
            lock: path,
        })
    }

    /// Creates the base folder and the run's root folder owner-only (0700) if they do not exist
    /// yet, before iceoryx2 puts anything in them; a base folder of another user is refused.
    /// iceoryx2 creates some folders inside the root with group and other bits (0755), which is
    /// harmless behind the private root. Every process of a run calls this before it creates its
    /// iceoryx2 node.
    pub fn prepare(&self) -> Result<(), NamespaceError> {
        use std::os::unix::fs::DirBuilderExt;
        self.private_base()?;
        match std::fs::DirBuilder::new().mode(0o700).create(&self.root) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                restrict(&self.root, 0o700).map(|_| ())
            }
            Err(source) => Err(PathIoError::of("creating", &self.root)(source).into()),
        }
    }

    /// Makes what others could reach of the run private to its user: its shared-memory objects
    /// 0600 and its root folder 0700 (what lies inside the root is out of reach behind it).
    /// iceoryx2 0.10 creates its node-management segment readable and writable by everyone; every
    /// process of a run calls this right after creating its iceoryx2 node. Returns how many
    /// entries had their mode changed.
    pub fn restrict_permissions(&self) -> Result<usize, NamespaceError> {
        let mut changed = 0;
        for path in list_with_prefix(Path::new(SHM_DIR), &self.file_prefix()) {
            changed += restrict(&path, 0o600)?;
        }
        if self.root.exists() {
            changed += restrict(&self.root, 0o700)?;
        }
        Ok(changed)
    }

    /// Every entry of the run that another user could reach with permission bits for group or
    /// others: its shared-memory objects, the base folder and the root folder, and inside the
    /// root only what a reachable folder exposes. Empty for a private run.
    pub fn shared_entries(&self) -> Vec<(PathBuf, u32)> {
        use std::os::unix::fs::PermissionsExt;
        let mode_of = |path: &Path| {
            std::fs::symlink_metadata(path)
                .ok()
                .map(|m| (m.permissions().mode() & 0o777, m.is_dir()))
        };
        let mut found = Vec::new();
        let mut visit: Vec<PathBuf> = list_with_prefix(Path::new(SHM_DIR), &self.file_prefix());
        visit.push(self.base_dir().to_path_buf());
        if self.root.exists() {
            visit.push(self.root.clone());
        }
        while let Some(path) = visit.pop() {
            let Some((mode, is_dir)) = mode_of(&path) else {
                continue;
            };
            if mode & 0o077 != 0 {
                found.push((path.clone(), mode));
            }
            // A folder others cannot enter hides what it holds; the base folder's other entries
            // are other runs'.
            if is_dir
                && mode & 0o011 != 0
                && path != self.base_dir()
                && let Ok(entries) = std::fs::read_dir(&path)
            {
                visit.extend(entries.flatten().map(|e| e.path()));
            }
        }
        found.sort();
        found
    }
}

fn restrict(path: &Path, mode: u32) -> Result<usize, NamespaceError> {
    use std::os::unix::fs::PermissionsExt;
    let meta = match std::fs::symlink_metadata(path) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(source) => return Err(PathIoError::of("inspecting", path)(source).into()),
    };
    if meta.file_type().is_symlink() || meta.permissions().mode() & 0o077 == 0 {
        return Ok(0);
    }
    match std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)) {
        Ok(()) => Ok(1),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
        Err(source) => Err(PathIoError::of("making private", path)(source).into()),
    }
}

/// The real user id of this process, read from /proc (no unsafe call needed).
pub fn current_uid() -> u32 {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").map_or(u32::MAX, |m| m.uid())
}

fn list_with_prefix(dir: &Path, prefix: &str) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut found: Vec<PathBuf> = entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .map(|e| e.path())
        .collect();
    found.sort();
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agent_node_names_carry_robot_and_pid() {
        assert_eq!(
            parse_agent_node_name(&agent_node_name(2, 4711)),
            Some((2, 4711))
        );
        assert_eq!(parse_agent_node_name(WORLD_NODE_NAME), None);
        assert_eq!(parse_agent_node_name("formation-agent-x-1"), None);
    }

    #[test]
    fn namespace_confines_files_to_the_run() {
        let run = RunId::new("nsunit").unwrap();
        let base = std::env::temp_dir().join(format!("formation-wire-test-{}", std::process::id()));
        let ns = RunNamespace::with_base(&run, &base);
        assert_eq!(ns.file_prefix(), "fm_nsunit_");
        let config = ns.iceoryx_config().unwrap();
        assert_eq!(config.global.prefix.to_string(), "fm_nsunit_");
        assert!(
            config
                .global
                .root_path()
                .to_string()
                .starts_with(&base.display().to_string())
        );
        std::fs::create_dir_all(ns.root_dir()).unwrap();
        assert_eq!(ns.leftovers(), vec![ns.root_dir().to_path_buf()]);
        assert_eq!(ns.remove_all().unwrap(), 1);
        assert!(ns.leftovers().is_empty());
        let _ = std::fs::remove_dir_all(&base);
    }
}
