//! Zero-copy messages exchanged between the world process and the robot-agent processes, the
//! per-run service names, and the per-run iceoryx2 namespace (file prefix and root directory).
//!
//! Every message is a fixed-size `#[repr(C)]` value that iceoryx2 places in shared memory as it
//! is, so nothing is serialised. Wire structs are deliberately dumb (plain numbers and fixed byte
//! arrays); each has a typed Rust view ([`ControlRequest`], [`AgentStatus`], [`CmdStatus`]) and a
//! checked constructor, so a malformed message turns into a [`WireError`] instead of a panic.
//!
//! Per robot `i` of a run `<run>` there is a *lobby*, where an agent asks to drive the robot and
//! proves with the launch secret (see [`crate::auth`]) that its launch started it:
//!
//! | service | payload | publisher → subscriber |
//! |---|---|---|
//! | `formation/<run>/robot/<i>/hello` | [`HelloMsg`] | candidate agents (up to 8) → world |
//! | `formation/<run>/robot/<i>/welcome` | [`WelcomeMsg`] | world → candidate agents |
//!
//! and, per accepted agent (an *incarnation*, named by the agent's nonce `<n>` in 16 hex digits),
//! four publish-subscribe services, each paired with an event service of the same name
//! (publishing wakes nobody in iceoryx2; the paired event does):
//!
//! | service | payload | publisher → subscriber |
//! |---|---|---|
//! | `formation/<run>/robot/<i>/<n>/scan` | [`ScanMsg`] | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/cmd` | [`CmdMsg`] | agent `i` → world |
//! | `formation/<run>/robot/<i>/<n>/control` | [`ControlMsg`] | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/status` | [`StatusMsg`] | agent `i` → world |
//!
//! The world creates an incarnation's services only after it checked the agent's proof, and drops
//! them when the agent is gone, so a process that squats on a dead agent's ports blocks nothing:
//! the next agent of the launch gets services of its own.
//!
//! Per run there is also a swap channel, through which `formation swap` asks the world to change one
//! robot's model: `formation/<run>/swap/request` ([`SwapRequestMsg`], tools → world) and
//! `formation/<run>/swap/reply` ([`SwapReplyMsg`], world → tools).
//!
//! Each robot service admits at most one publisher and one subscriber ([`ServiceLimits::ROBOT`]), which
//! is how decentralisation is enforced by the transport itself: once agent `i` holds its scan
//! subscription no other process can read robot `i`'s scan, and once it holds its command
//! publisher no other process can command robot `i`.
//!
//! Transports that carry bytes rather than shared memory (Zenoh, between hosts) send each message's
//! own bytes: every wire struct is [`bytemuck::Pod`] (no padding, checked when it compiles), so
//! [`message_bytes`] views it and [`message_from_bytes`] takes it back, refusing a payload of the
//! wrong size. The bytes are in the host's byte order: every host of one run must share it (every
//! supported target is little-endian).
//!
//! Every file iceoryx2 creates for a run carries the run's own prefix (`fm_<run>_` in the
//! shared-memory folder) and lives under the run's own root directory (see [`RunNamespace`]), so
//! parallel runs and tests never collide and a run's leftovers can be listed and removed exactly.

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use iceoryx2::prelude::*;

use crate::types::{Goal, LidarSpec, WheelCmd};

/// Most LIDAR beams a [`ScanMsg`] can carry (the paper's sensor: 900 beams over 360 degrees).
pub const MAX_BEAMS: usize = 900;
/// Bytes of a model id on the wire (UTF-8, zero padded).
pub const MODEL_ID_LEN: usize = 64;
/// Bytes of a model path in a swap request (UTF-8, zero padded).
pub const MODEL_PATH_LEN: usize = 512;
/// Bytes of a refusal reason in a status message (UTF-8, zero padded; a longer reason is cut at a
/// word boundary and ends in `…`).
pub const REASON_LEN: usize = 1024;
/// Longest accepted run id.
pub const MAX_RUN_ID_LEN: usize = 24;

/// Why a message, a name or a namespace could not be built or read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// A run id with characters other than ASCII letters, digits, `-` and `_`, or of bad length.
    #[error(
        "run id {run:?} is not valid: use 1 to {MAX_RUN_ID_LEN} ASCII letters, digits, '-' or '_'"
    )]
    InvalidRunId {
        /// The rejected id.
        run: String,
    },
    /// A scan longer than a [`ScanMsg`] can carry.
    #[error("a scan of {beams} beams does not fit the wire message (at most {MAX_BEAMS} beams)")]
    TooManyBeams {
        /// Beams in the scan.
        beams: usize,
    },
    /// A text field (model id, model path) longer than its fixed wire field.
    #[error("{field} is {len} bytes long; the wire field holds at most {max} bytes")]
    TextTooLong {
        /// Which field.
        field: &'static str,
        /// Its length in bytes.
        len: usize,
        /// The field's capacity.
        max: usize,
    },
    /// A message whose kind code is not known to this version.
    #[error("unknown {message} kind {kind}: world and agent binaries are from different builds")]
    UnknownKind {
        /// Which message type.
        message: &'static str,
        /// The code received.
        kind: u32,
    },
    /// A message field that does not hold a valid value.
    #[error("malformed {message}: {reason}")]
    Malformed {
        /// Which message type.
        message: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// The bytes of a wire message, as a transport between hosts sends them.
pub fn message_bytes<T: bytemuck::Pod>(msg: &T) -> &[u8] {
    bytemuck::bytes_of(msg)
}

/// A wire message back from the bytes [`message_bytes`] gave; a payload of another size (a
/// different build, a stray publisher) is [`WireError::Malformed`].
pub fn message_from_bytes<T: bytemuck::Pod>(
    message: &'static str,
    bytes: &[u8],
) -> Result<T, WireError> {
    bytemuck::try_pod_read_unaligned(bytes).map_err(|_| WireError::Malformed {
        message,
        reason: format!(
            "{} bytes arrived, the message has {}: world and agent binaries are from different \
             builds, or another process publishes on this key",
            bytes.len(),
            std::mem::size_of::<T>()
        ),
    })
}

// ---------------------------------------------------------------------------------------------
// Run ids, service names, namespaces
// ---------------------------------------------------------------------------------------------

/// The id of one launch of the runtime. It namespaces service names and iceoryx2 files.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId(String);

impl RunId {
    /// Validates an id: 1 to [`MAX_RUN_ID_LEN`] ASCII letters, digits, `-` or `_`.
    pub fn new(id: &str) -> Result<RunId, WireError> {
        let ok = !id.is_empty()
            && id.len() <= MAX_RUN_ID_LEN
            && id
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if ok {
            Ok(RunId(id.to_owned()))
        } else {
            Err(WireError::InvalidRunId { run: id.to_owned() })
        }
    }

    /// A fresh id, unique on this machine: the process id and the wall-clock nanoseconds, in base 36.
    pub fn generate() -> RunId {
        let nanos = wall_clock_ns();
        RunId(format!(
            "{}{}",
            base36(u64::from(std::process::id())),
            base36(nanos % (36u64.pow(8)))
        ))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for RunId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

fn base36(mut n: u64) -> String {
    const DIGITS: &[u8; 36] = b"0123456789abcdefghijklmnopqrstuvwxyz";
    let mut out = Vec::new();
    loop {
        out.push(DIGITS[(n % 36) as usize]);
        n /= 36;
        if n == 0 {
            break;
        }
    }
    out.reverse();
    String::from_utf8(out).unwrap_or_default()
}

/// The channels of one robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotChannel {
    /// World → agent: the robot's own scan, heading and goal ([`ScanMsg`]).
    Scan,
    /// Agent → world: the robot's wheel command ([`CmdMsg`]).
    Cmd,
    /// World → agent: episode begin, shutdown, model swap ([`ControlMsg`]).
    Control,
    /// Agent → world: hello, ready, refusals, swap acknowledgements ([`StatusMsg`]).
    Status,
}

impl RobotChannel {
    /// Every channel.
    pub const ALL: [RobotChannel; 4] = [
        RobotChannel::Scan,
        RobotChannel::Cmd,
        RobotChannel::Control,
        RobotChannel::Status,
    ];

    /// The last segment of the service name.
    pub fn as_str(&self) -> &'static str {
        match self {
            RobotChannel::Scan => "scan",
            RobotChannel::Cmd => "cmd",
            RobotChannel::Control => "control",
            RobotChannel::Status => "status",
        }
    }
}

/// `formation/<run>/robot/<robot>/<incarnation>/<channel>`, the incarnation in 16 hex digits: the
/// name of both the publish-subscribe service and its paired event service of one accepted agent.
pub fn robot_service_name(
    run: &RunId,
    robot: usize,
    incarnation: u64,
    channel: RobotChannel,
) -> String {
    format!(
        "formation/{run}/robot/{robot}/{incarnation:016x}/{}",
        channel.as_str()
    )
}

/// The two services of a robot's lobby.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LobbyChannel {
    /// Candidate agents → world ([`HelloMsg`]); paired with an event service.
    Hello,
    /// World → candidate agents ([`WelcomeMsg`]); polled, no event.
    Welcome,
}

/// `formation/<run>/robot/<robot>/hello` or `.../welcome`.
pub fn lobby_service_name(run: &RunId, robot: usize, channel: LobbyChannel) -> String {
    match channel {
        LobbyChannel::Hello => format!("formation/{run}/robot/{robot}/hello"),
        LobbyChannel::Welcome => format!("formation/{run}/robot/{robot}/welcome"),
    }
}

/// The two services of a run's swap channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwapChannel {
    /// `formation swap` → world ([`SwapRequestMsg`]).
    Request,
    /// World → `formation swap` ([`SwapReplyMsg`]).
    Reply,
}

impl SwapChannel {
    /// The sizes of this service, shared by creator and openers.
    pub fn limits(&self) -> ServiceLimits {
        match self {
            SwapChannel::Request => ServiceLimits::SWAP_REQUEST,
            SwapChannel::Reply => ServiceLimits::SWAP_REPLY,
        }
    }
}

/// `formation/<run>/swap/request` or `formation/<run>/swap/reply`: the name of both the
/// publish-subscribe service and its paired event service.
pub fn swap_service_name(run: &RunId, channel: SwapChannel) -> String {
    match channel {
        SwapChannel::Request => format!("formation/{run}/swap/request"),
        SwapChannel::Reply => format!("formation/{run}/swap/reply"),
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

    /// A robot's hello service: up to 8 candidate agents at once write, only the world reads.
    pub const HELLO: ServiceLimits = ServiceLimits {
        max_publishers: 8,
        max_subscribers: 1,
        subscriber_buffer: 16,
        max_nodes: 16,
    };

    /// A robot's welcome service: only the world writes; every candidate reads and keeps the
    /// answer to its own nonce.
    pub const WELCOME: ServiceLimits = ServiceLimits {
        max_publishers: 1,
        max_subscribers: 8,
        subscriber_buffer: 16,
        max_nodes: 16,
    };

    /// Swap requests: any number of `formation swap` processes (up to 8 at once) write, only the
    /// world reads.
    pub const SWAP_REQUEST: ServiceLimits = ServiceLimits {
        max_publishers: 8,
        max_subscribers: 1,
        subscriber_buffer: 16,
        max_nodes: 16,
    };

    /// Swap replies: only the world writes; every waiting `formation swap` reads and keeps the
    /// reply with its own request id.
    pub const SWAP_REPLY: ServiceLimits = ServiceLimits {
        max_publishers: 1,
        max_subscribers: 8,
        subscriber_buffer: 16,
        max_nodes: 16,
    };
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
    #[error("{action} {path}: {source}")]
    Io {
        /// What was being done.
        action: &'static str,
        /// On what.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
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
        let io = |action, source| NamespaceError::Io {
            action,
            path: base.to_path_buf(),
            source,
        };
        match std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(base)
        {
            Ok(()) => {}
            Err(e) => return Err(io("creating", e)),
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
                .map_err(|source| NamespaceError::Io {
                    action: "opening the run lock",
                    path: path.clone(),
                    source,
                })?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(NamespaceError::InUse {
                        run: self.run.to_string(),
                        lock: path,
                    });
                }
                Err(std::fs::TryLockError::Error(source)) => {
                    return Err(NamespaceError::Io {
                        action: "locking",
                        path,
                        source,
                    });
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
            Err(source) => Err(NamespaceError::Io {
                action: "creating",
                path: self.root.clone(),
                source,
            }),
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
        Err(source) => {
            return Err(NamespaceError::Io {
                action: "inspecting",
                path: path.to_path_buf(),
                source,
            });
        }
    };
    if meta.file_type().is_symlink() || meta.permissions().mode() & 0o077 == 0 {
        return Ok(0);
    }
    match std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)) {
        Ok(()) => Ok(1),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
        Err(source) => Err(NamespaceError::Io {
            action: "making private",
            path: path.to_path_buf(),
            source,
        }),
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

/// Nanoseconds since the Unix epoch on the system clock: the one clock every process of a run
/// shares, used only to measure one-way latencies between processes.
pub fn wall_clock_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

// ---------------------------------------------------------------------------------------------
// Fixed text fields
// ---------------------------------------------------------------------------------------------

fn encode_text<const N: usize>(field: &'static str, text: &str) -> Result<[u8; N], WireError> {
    if text.len() > N {
        return Err(WireError::TextTooLong {
            field,
            len: text.len(),
            max: N,
        });
    }
    let mut out = [0u8; N];
    out[..text.len()].copy_from_slice(text.as_bytes());
    Ok(out)
}

/// Like [`encode_text`] but for human messages: an over-long text is cut at the last word
/// boundary that leaves room for a closing `…`, so a reader sees that something was cut and
/// never half a word.
fn encode_text_lossy<const N: usize>(text: &str) -> [u8; N] {
    const ELLIPSIS: &str = " …";
    let mut out = [0u8; N];
    if text.len() <= N {
        out[..text.len()].copy_from_slice(text.as_bytes());
        return out;
    }
    let mut end = N.saturating_sub(ELLIPSIS.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    let cut = text[..end]
        .rfind(char::is_whitespace)
        .filter(|&at| at > end / 2)
        .unwrap_or(end);
    let kept = text[..cut].trim_end();
    out[..kept.len()].copy_from_slice(kept.as_bytes());
    out[kept.len()..kept.len() + ELLIPSIS.len()].copy_from_slice(ELLIPSIS.as_bytes());
    out
}

fn decode_text<'a>(message: &'static str, bytes: &'a [u8]) -> Result<&'a str, WireError> {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    std::str::from_utf8(&bytes[..end]).map_err(|e| WireError::Malformed {
        message,
        reason: format!("text field is not UTF-8 ({e})"),
    })
}

// ---------------------------------------------------------------------------------------------
// Lobby: candidate agent -> world, and the world's answer
// ---------------------------------------------------------------------------------------------

/// An agent's request to drive one robot: its pid, a fresh nonce (which also names the
/// incarnation's services if the world accepts) and its proof of the launch secret.
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.HelloMsg.v1")]
pub struct HelloMsg {
    /// The candidate's process id.
    pub pid: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// A fresh random number, never used twice.
    pub nonce: u64,
    /// [`crate::auth::LaunchSecret::prove`] over the run, the robot, `pid` and `nonce`.
    pub proof: [u8; crate::auth::PROOF_LEN],
}

/// The world's answer to one [`HelloMsg`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Welcome {
    /// The incarnation's services exist now: open them and drive.
    Accepted,
    /// Refused; the reason is phrased for the user.
    Refused(String),
}

/// The wire form of a [`Welcome`], tagged with the nonce of the hello it answers.
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.WelcomeMsg.v1")]
pub struct WelcomeMsg {
    /// The nonce of the hello this answers.
    pub nonce: u64,
    /// 1 accepted, 2 refused.
    pub kind: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Why (refused), UTF-8, zero padded, possibly cut.
    pub reason: [u8; REASON_LEN],
}

const WELCOME_ACCEPTED: u32 = 1;
const WELCOME_REFUSED: u32 = 2;

impl WelcomeMsg {
    /// Encodes the answer to the hello with `nonce`.
    pub fn encode(nonce: u64, welcome: &Welcome) -> WelcomeMsg {
        let (kind, reason) = match welcome {
            Welcome::Accepted => (WELCOME_ACCEPTED, [0; REASON_LEN]),
            Welcome::Refused(reason) => (WELCOME_REFUSED, encode_text_lossy(reason)),
        };
        WelcomeMsg {
            nonce,
            kind,
            reserved: 0,
            reason,
        }
    }

    /// Decodes the answer.
    pub fn decode(&self) -> Result<Welcome, WireError> {
        match self.kind {
            WELCOME_ACCEPTED => Ok(Welcome::Accepted),
            WELCOME_REFUSED => Ok(Welcome::Refused(
                decode_text("welcome", &self.reason)?.to_owned(),
            )),
            kind => Err(WireError::UnknownKind {
                message: "welcome",
                kind,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Scan: world -> agent
// ---------------------------------------------------------------------------------------------

/// One robot's observation at one tick: its own scan, its own compass heading and the goal.
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.ScanMsg.v1")]
pub struct ScanMsg {
    /// Episode generation: increases with every episode the world begins; stale messages of an
    /// earlier episode are recognised by it.
    pub generation: u64,
    /// Tick index `k` within the episode.
    pub tick: u64,
    /// Simulated time `k dt` \[s\].
    pub sim_time: f64,
    /// The robot's own heading \[rad\] (its compass).
    pub heading: f64,
    /// Desired heading phi* at this tick \[rad\].
    pub phi_star: f64,
    /// Desired pairwise distance d* \[m\].
    pub d_star: f64,
    /// Desired speed v* \[m/s\].
    pub v_star: f64,
    /// [`wall_clock_ns`] when the world published this scan.
    pub published_wall_ns: u64,
    /// Valid entries of `ranges`.
    pub n_beams: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Ranges \[m\], beam `k` at body-frame bearing `2 pi k / n_beams`; entries past `n_beams` are 0.
    pub ranges: [f32; MAX_BEAMS],
}

impl ScanMsg {
    /// A scan message. Fails when `ranges` has more than [`MAX_BEAMS`] entries.
    pub fn new(
        generation: u64,
        tick: u64,
        sim_time: f64,
        heading: f64,
        goal: &Goal,
        ranges: &[f32],
    ) -> Result<ScanMsg, WireError> {
        if ranges.len() > MAX_BEAMS {
            return Err(WireError::TooManyBeams {
                beams: ranges.len(),
            });
        }
        let mut fixed = [0.0f32; MAX_BEAMS];
        fixed[..ranges.len()].copy_from_slice(ranges);
        Ok(ScanMsg {
            generation,
            tick,
            sim_time,
            heading,
            phi_star: goal.phi_star,
            d_star: goal.d_star,
            v_star: goal.v_star,
            published_wall_ns: wall_clock_ns(),
            n_beams: ranges.len() as u32,
            reserved: 0,
            ranges: fixed,
        })
    }

    /// The valid ranges. Fails on an `n_beams` beyond [`MAX_BEAMS`].
    pub fn ranges(&self) -> Result<&[f32], WireError> {
        let n = self.n_beams as usize;
        self.ranges.get(..n).ok_or_else(|| WireError::Malformed {
            message: "scan",
            reason: format!("n_beams {n} exceeds the {MAX_BEAMS} the message holds"),
        })
    }

    /// The goal carried by the scan.
    pub fn goal(&self) -> Goal {
        Goal {
            phi_star: self.phi_star,
            d_star: self.d_star,
            v_star: self.v_star,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Command: agent -> world
// ---------------------------------------------------------------------------------------------

/// Status bits an agent attaches to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CmdStatus(pub u32);

impl CmdStatus {
    /// A normal decision.
    pub const OK: CmdStatus = CmdStatus(0);
    /// The agent could not decide (bad scan or goal, policy failure) and asks for a brake.
    pub const DECISION_FAILED: CmdStatus = CmdStatus(1);
    /// A fault-injection mode altered this command (testing only).
    pub const FAULT_INJECTED: CmdStatus = CmdStatus(1 << 1);
    /// A new model took over at this tick.
    pub const MODEL_SWAPPED: CmdStatus = CmdStatus(1 << 2);

    /// True when every bit of `other` is set.
    pub fn contains(self, other: CmdStatus) -> bool {
        self.0 & other.0 == other.0
    }

    /// Both sets of bits.
    pub fn with(self, other: CmdStatus) -> CmdStatus {
        CmdStatus(self.0 | other.0)
    }
}

/// One robot's wheel command for one tick, with the agent's own timings.
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.CmdMsg.v1")]
pub struct CmdMsg {
    /// Episode generation of the scan this answers.
    pub generation: u64,
    /// Tick of the scan this answers.
    pub tick: u64,
    /// Left wheel rim speed \[m/s\].
    pub left: f64,
    /// Right wheel rim speed \[m/s\].
    pub right: f64,
    /// [`wall_clock_ns`] when the agent took the scan from its subscriber.
    pub received_wall_ns: u64,
    /// Time spent rendering the occupancy image \[ns\].
    pub occupancy_ns: u64,
    /// Time spent in the policy, including speed scaling \[ns\].
    pub inference_ns: u64,
    /// [`wall_clock_ns`] just before the agent published this command.
    pub published_wall_ns: u64,
    /// [`CmdStatus`] bits.
    pub status: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// Id of the model that decided (UTF-8, zero padded).
    pub model_id: [u8; MODEL_ID_LEN],
}

/// Timings an agent measured for one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AgentTimings {
    /// [`wall_clock_ns`] when the scan was taken from the subscriber.
    pub received_wall_ns: u64,
    /// Occupancy rendering \[ns\].
    pub occupancy_ns: u64,
    /// Policy inference \[ns\].
    pub inference_ns: u64,
}

impl CmdMsg {
    /// A command message; `published_wall_ns` is stamped now. Fails on a model id longer than
    /// [`MODEL_ID_LEN`] bytes.
    pub fn new(
        generation: u64,
        tick: u64,
        cmd: WheelCmd,
        model_id: &str,
        timings: AgentTimings,
        status: CmdStatus,
    ) -> Result<CmdMsg, WireError> {
        Ok(CmdMsg {
            generation,
            tick,
            left: cmd.left,
            right: cmd.right,
            received_wall_ns: timings.received_wall_ns,
            occupancy_ns: timings.occupancy_ns,
            inference_ns: timings.inference_ns,
            published_wall_ns: wall_clock_ns(),
            status: status.0,
            reserved: 0,
            model_id: encode_text("model id", model_id)?,
        })
    }

    /// The wheel command.
    pub fn wheels(&self) -> WheelCmd {
        WheelCmd {
            left: self.left,
            right: self.right,
        }
    }

    /// The status bits.
    pub fn status(&self) -> CmdStatus {
        CmdStatus(self.status)
    }

    /// The model id.
    pub fn model_id(&self) -> Result<&str, WireError> {
        decode_text("command", &self.model_id)
    }

    /// The agent's timings.
    pub fn timings(&self) -> AgentTimings {
        AgentTimings {
            received_wall_ns: self.received_wall_ns,
            occupancy_ns: self.occupancy_ns,
            inference_ns: self.inference_ns,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Control: world -> agent
// ---------------------------------------------------------------------------------------------

/// What the world asks of an agent, outside the per-tick exchange.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlRequest {
    /// A new episode starts: answer [`AgentStatus::Ready`] (or [`AgentStatus::Refused`] when the
    /// model does not fit this sensor) with the same generation, then expect its scans.
    BeginEpisode {
        /// The episode's generation.
        generation: u64,
        /// The robot's LIDAR settings this episode.
        lidar: LidarSpec,
    },
    /// Load another model off the hot path and let it drive from the first tick `>= at_tick`.
    SwapModel {
        /// Request id echoed in the acknowledgement.
        request_id: u64,
        /// First tick the new model may drive.
        at_tick: u64,
        /// The ONNX model file.
        path: PathBuf,
    },
    /// The run is over: exit cleanly.
    Shutdown,
}

/// The wire form of a [`ControlRequest`].
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.ControlMsg.v1")]
pub struct ControlMsg {
    /// 1 begin episode, 2 swap model, 3 shutdown.
    pub kind: u32,
    /// LIDAR beams (begin episode).
    pub beams: u32,
    /// Episode generation (begin episode).
    pub generation: u64,
    /// LIDAR maximum range \[m\] (begin episode).
    pub max_range: f64,
    /// LIDAR noise standard deviation \[m\] (begin episode).
    pub noise_std: f64,
    /// Request id (swap model).
    pub request_id: u64,
    /// First tick the new model may drive (swap model).
    pub at_tick: u64,
    /// Model path, UTF-8, zero padded (swap model).
    pub path: [u8; MODEL_PATH_LEN],
}

const CONTROL_BEGIN: u32 = 1;
const CONTROL_SWAP: u32 = 2;
const CONTROL_SHUTDOWN: u32 = 3;

impl ControlMsg {
    /// Encodes a request. Fails on a model path longer than [`MODEL_PATH_LEN`] bytes or not UTF-8.
    pub fn encode(request: &ControlRequest) -> Result<ControlMsg, WireError> {
        let mut msg = ControlMsg {
            kind: 0,
            beams: 0,
            generation: 0,
            max_range: 0.0,
            noise_std: 0.0,
            request_id: 0,
            at_tick: 0,
            path: [0; MODEL_PATH_LEN],
        };
        match request {
            ControlRequest::BeginEpisode { generation, lidar } => {
                msg.kind = CONTROL_BEGIN;
                msg.generation = *generation;
                msg.beams = u32::try_from(lidar.beams)
                    .map_err(|_| WireError::TooManyBeams { beams: lidar.beams })?;
                msg.max_range = lidar.max_range;
                msg.noise_std = lidar.noise_std;
            }
            ControlRequest::SwapModel {
                request_id,
                at_tick,
                path,
            } => {
                let text = path.to_str().ok_or_else(|| WireError::Malformed {
                    message: "control",
                    reason: format!("model path {} is not UTF-8", path.display()),
                })?;
                msg.kind = CONTROL_SWAP;
                msg.request_id = *request_id;
                msg.at_tick = *at_tick;
                msg.path = encode_text("model path", text)?;
            }
            ControlRequest::Shutdown => msg.kind = CONTROL_SHUTDOWN,
        }
        Ok(msg)
    }

    /// Decodes the request.
    pub fn decode(&self) -> Result<ControlRequest, WireError> {
        match self.kind {
            CONTROL_BEGIN => Ok(ControlRequest::BeginEpisode {
                generation: self.generation,
                lidar: LidarSpec {
                    beams: self.beams as usize,
                    max_range: self.max_range,
                    noise_std: self.noise_std,
                },
            }),
            CONTROL_SWAP => Ok(ControlRequest::SwapModel {
                request_id: self.request_id,
                at_tick: self.at_tick,
                path: PathBuf::from(decode_text("control", &self.path)?),
            }),
            CONTROL_SHUTDOWN => Ok(ControlRequest::Shutdown),
            kind => Err(WireError::UnknownKind {
                message: "control",
                kind,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Status: agent -> world
// ---------------------------------------------------------------------------------------------

/// What an agent tells the world, outside the per-tick exchange.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AgentStatus {
    /// The agent is up (its ports exist) with this model; sent once at start.
    Hello {
        /// The agent's process id.
        pid: u32,
        /// The model it loaded.
        model_id: String,
    },
    /// Ready for the episode of this generation.
    Ready {
        /// The episode's generation.
        generation: u64,
        /// The model that will drive.
        model_id: String,
    },
    /// Cannot take part in the episode of this generation (e.g. the model does not fit the sensor).
    Refused {
        /// The episode's generation.
        generation: u64,
        /// Why, phrased for the user.
        reason: String,
    },
    /// The model of swap request `request_id` drives from tick `tick` on.
    SwapDone {
        /// The request.
        request_id: u64,
        /// First tick decided by the new model.
        tick: u64,
        /// The new model's id.
        model_id: String,
    },
    /// Swap request `request_id` was refused; the old model keeps driving.
    SwapRefused {
        /// The request.
        request_id: u64,
        /// Why, phrased for the user.
        reason: String,
    },
}

/// The wire form of an [`AgentStatus`].
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.StatusMsg.v2")]
pub struct StatusMsg {
    /// 1 hello, 2 ready, 3 refused, 4 swap done, 5 swap refused.
    pub kind: u32,
    /// Process id (hello).
    pub pid: u32,
    /// Episode generation (ready, refused).
    pub generation: u64,
    /// Swap request id (swap done, swap refused).
    pub request_id: u64,
    /// First tick of the new model (swap done).
    pub tick: u64,
    /// Model id, UTF-8, zero padded (hello, ready, swap done).
    pub model_id: [u8; MODEL_ID_LEN],
    /// Reason, UTF-8, zero padded, possibly truncated (refused, swap refused).
    pub reason: [u8; REASON_LEN],
}

const STATUS_HELLO: u32 = 1;
const STATUS_READY: u32 = 2;
const STATUS_REFUSED: u32 = 3;
const STATUS_SWAP_DONE: u32 = 4;
const STATUS_SWAP_REFUSED: u32 = 5;

impl StatusMsg {
    /// Encodes a status. Fails on a model id longer than [`MODEL_ID_LEN`] bytes; reasons longer
    /// than [`REASON_LEN`] bytes are truncated.
    pub fn encode(status: &AgentStatus) -> Result<StatusMsg, WireError> {
        let mut msg = StatusMsg {
            kind: 0,
            pid: 0,
            generation: 0,
            request_id: 0,
            tick: 0,
            model_id: [0; MODEL_ID_LEN],
            reason: [0; REASON_LEN],
        };
        match status {
            AgentStatus::Hello { pid, model_id } => {
                msg.kind = STATUS_HELLO;
                msg.pid = *pid;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::Ready {
                generation,
                model_id,
            } => {
                msg.kind = STATUS_READY;
                msg.generation = *generation;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::Refused { generation, reason } => {
                msg.kind = STATUS_REFUSED;
                msg.generation = *generation;
                msg.reason = encode_text_lossy(reason);
            }
            AgentStatus::SwapDone {
                request_id,
                tick,
                model_id,
            } => {
                msg.kind = STATUS_SWAP_DONE;
                msg.request_id = *request_id;
                msg.tick = *tick;
                msg.model_id = encode_text("model id", model_id)?;
            }
            AgentStatus::SwapRefused { request_id, reason } => {
                msg.kind = STATUS_SWAP_REFUSED;
                msg.request_id = *request_id;
                msg.reason = encode_text_lossy(reason);
            }
        }
        Ok(msg)
    }

    /// Decodes the status.
    pub fn decode(&self) -> Result<AgentStatus, WireError> {
        let model_id = || decode_text("status", &self.model_id).map(str::to_owned);
        let reason = || decode_text("status", &self.reason).map(str::to_owned);
        Ok(match self.kind {
            STATUS_HELLO => AgentStatus::Hello {
                pid: self.pid,
                model_id: model_id()?,
            },
            STATUS_READY => AgentStatus::Ready {
                generation: self.generation,
                model_id: model_id()?,
            },
            STATUS_REFUSED => AgentStatus::Refused {
                generation: self.generation,
                reason: reason()?,
            },
            STATUS_SWAP_DONE => AgentStatus::SwapDone {
                request_id: self.request_id,
                tick: self.tick,
                model_id: model_id()?,
            },
            STATUS_SWAP_REFUSED => AgentStatus::SwapRefused {
                request_id: self.request_id,
                reason: reason()?,
            },
            kind => {
                return Err(WireError::UnknownKind {
                    message: "status",
                    kind,
                });
            }
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Swap: `formation swap` -> world -> agent, and the world's reply
// ---------------------------------------------------------------------------------------------

/// A user's request, sent by `formation swap` to the world of a run, to change the model of one
/// robot's agent. The world forwards it to that agent as a [`ControlRequest::SwapModel`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapRequest {
    /// Id chosen by the requester; the reply carries it back.
    pub request_id: u64,
    /// The robot whose agent should swap.
    pub robot: usize,
    /// First tick the new model may drive (0: as soon as it is loaded).
    pub at_tick: u64,
    /// The ONNX model file (absolute, so that the agent resolves it as the user meant).
    pub path: PathBuf,
}

/// The wire form of a [`SwapRequest`].
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.SwapRequestMsg.v1")]
pub struct SwapRequestMsg {
    /// Request id.
    pub request_id: u64,
    /// Robot index.
    pub robot: u64,
    /// First tick the new model may drive.
    pub at_tick: u64,
    /// Model path, UTF-8, zero padded.
    pub path: [u8; MODEL_PATH_LEN],
}

impl SwapRequestMsg {
    /// Encodes a request. Fails on a model path that is not UTF-8 or longer than
    /// [`MODEL_PATH_LEN`] bytes.
    pub fn encode(request: &SwapRequest) -> Result<SwapRequestMsg, WireError> {
        let text = request.path.to_str().ok_or_else(|| WireError::Malformed {
            message: "swap request",
            reason: format!("model path {} is not UTF-8", request.path.display()),
        })?;
        Ok(SwapRequestMsg {
            request_id: request.request_id,
            robot: request.robot as u64,
            at_tick: request.at_tick,
            path: encode_text("model path", text)?,
        })
    }

    /// Decodes the request.
    pub fn decode(&self) -> Result<SwapRequest, WireError> {
        Ok(SwapRequest {
            request_id: self.request_id,
            robot: usize::try_from(self.robot).unwrap_or(usize::MAX),
            at_tick: self.at_tick,
            path: PathBuf::from(decode_text("swap request", &self.path)?),
        })
    }
}

/// How a [`SwapRequest`] ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SwapOutcome {
    /// The new model drives robot `robot` from tick `tick` on.
    Done {
        /// First tick decided by the new model.
        tick: u64,
        /// The new model's id.
        model_id: String,
    },
    /// Refused by the world (unknown robot, no agent) or by the agent (the model failed to load
    /// or validate); the old model keeps driving.
    Refused {
        /// Why, phrased for the user.
        reason: String,
    },
}

/// The world's answer to a [`SwapRequest`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwapReply {
    /// The request this answers.
    pub request_id: u64,
    /// The robot of the request.
    pub robot: usize,
    /// What happened.
    pub outcome: SwapOutcome,
}

/// The wire form of a [`SwapReply`].
#[derive(Debug, Clone, Copy, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
#[type_name("formation.SwapReplyMsg.v2")]
pub struct SwapReplyMsg {
    /// Request id.
    pub request_id: u64,
    /// Robot index.
    pub robot: u64,
    /// 1 done, 2 refused.
    pub kind: u32,
    /// Keeps the layout explicit; always 0.
    pub reserved: u32,
    /// First tick of the new model (done).
    pub tick: u64,
    /// Model id, UTF-8, zero padded (done).
    pub model_id: [u8; MODEL_ID_LEN],
    /// Reason, UTF-8, zero padded, possibly truncated (refused).
    pub reason: [u8; REASON_LEN],
}

const SWAP_DONE: u32 = 1;
const SWAP_REFUSED: u32 = 2;

impl SwapReplyMsg {
    /// Encodes a reply. Fails on a model id longer than [`MODEL_ID_LEN`] bytes; reasons longer
    /// than [`REASON_LEN`] bytes are truncated.
    pub fn encode(reply: &SwapReply) -> Result<SwapReplyMsg, WireError> {
        let mut msg = SwapReplyMsg {
            request_id: reply.request_id,
            robot: reply.robot as u64,
            kind: 0,
            reserved: 0,
            tick: 0,
            model_id: [0; MODEL_ID_LEN],
            reason: [0; REASON_LEN],
        };
        match &reply.outcome {
            SwapOutcome::Done { tick, model_id } => {
                msg.kind = SWAP_DONE;
                msg.tick = *tick;
                msg.model_id = encode_text("model id", model_id)?;
            }
            SwapOutcome::Refused { reason } => {
                msg.kind = SWAP_REFUSED;
                msg.reason = encode_text_lossy(reason);
            }
        }
        Ok(msg)
    }

    /// Decodes the reply.
    pub fn decode(&self) -> Result<SwapReply, WireError> {
        let outcome = match self.kind {
            SWAP_DONE => SwapOutcome::Done {
                tick: self.tick,
                model_id: decode_text("swap reply", &self.model_id)?.to_owned(),
            },
            SWAP_REFUSED => SwapOutcome::Refused {
                reason: decode_text("swap reply", &self.reason)?.to_owned(),
            },
            kind => {
                return Err(WireError::UnknownKind {
                    message: "swap reply",
                    kind,
                });
            }
        };
        Ok(SwapReply {
            request_id: self.request_id,
            robot: usize::try_from(self.robot).unwrap_or(usize::MAX),
            outcome,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Progress events: world stdout -> launcher
// ---------------------------------------------------------------------------------------------

/// A progress event the world prints on its stdout, one JSON object per line
/// (`{"event":"run_done","index":3,"log":"..."}`), for the launcher to follow.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum WorldEvent {
    /// The world's services exist; agents may connect.
    Listening {
        /// Robots served.
        robots: usize,
    },
    /// Before the first run: robot `robot`'s agent said hello, `connected` of `robots` so far.
    AgentConnected {
        /// The robot.
        robot: usize,
        /// Agents connected so far.
        connected: usize,
        /// Robots in the team.
        robots: usize,
    },
    /// Every agent said hello.
    AgentsConnected,
    /// A run finished and its logs are written.
    RunDone {
        /// Run index.
        index: usize,
        /// The trajectory log.
        log: PathBuf,
    },
    /// Robot `robot`'s agent died; its robot brakes until an agent rejoins.
    AgentLost {
        /// The robot.
        robot: usize,
        /// The last tick the world published when it noticed.
        tick: u64,
        /// The last tick whose command from the dead agent the world applied, if any.
        last_fresh_tick: Option<u64>,
    },
    /// A process asked to drive robot `robot` and was refused; the robot keeps its agent, or keeps
    /// braking if it has none.
    AgentRefused {
        /// The robot.
        robot: usize,
        /// The process id it gave.
        pid: u32,
        /// Why, phrased for the user.
        reason: String,
    },
    /// A restarted agent (process `pid`) drives robot `robot` again from tick `tick` on.
    AgentRejoined {
        /// The robot.
        robot: usize,
        /// The new agent's process id.
        pid: u32,
        /// The first tick it drove.
        tick: u64,
    },
    /// Robot `robot`'s link is degraded: more than [`DEGRADED_SHARE_PERCENT`] % of its ticks in
    /// the last `window_ticks` ticks (`window_ms` of the run's time) were braked. Sent while the
    /// run goes on, at most once a second per robot.
    LinkDegraded {
        /// The robot.
        robot: usize,
        /// The tick at which the window ends.
        tick: u64,
        /// The window's length in the run's time \[ms\].
        window_ms: u64,
        /// The window's length in ticks.
        window_ticks: u64,
        /// Ticks of the window that were braked.
        braked: u64,
        /// Those braked ticks by reason ([`TickOutcome::name`]).
        reasons: std::collections::BTreeMap<String, u64>,
        /// The round trip of the newest command used in the window \[µs\], if one was used.
        round_trip_us: Option<u64>,
    },
    /// All runs finished.
    Finished,
    /// The world stops before its runs are done (an error such as a full disk, a signal, its
    /// input closed), said before it asks the agents to exit: the launcher then takes their
    /// exits for what they are and restarts none of them.
    Stopping {
        /// Why, phrased for the user (the world prints its error on stderr too).
        reason: String,
    },
}

/// The share of a robot's ticks, in percent, that may be braked within the degraded-link window
/// before [`WorldEvent::LinkDegraded`] is sent.
pub const DEGRADED_SHARE_PERCENT: u64 = 5;

impl WorldEvent {
    /// The event on one line of the world's stdout; `None` for any other line.
    pub fn parse(line: &str) -> Option<WorldEvent> {
        serde_json::from_str(line).ok()
    }

    /// The event as one line of JSON (without the newline).
    pub fn to_line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

// ---------------------------------------------------------------------------------------------
// Timing log: written by the world per run, read by `formation profile` and the report
// ---------------------------------------------------------------------------------------------

/// What the world's watchdog made of one robot's command at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TickOutcome {
    /// The agent's command for this tick arrived in time and was applied.
    Fresh,
    /// No command of this episode arrived: braked.
    Missing,
    /// Only an older command arrived (lockstep), or the newest is too old (realtime): braked.
    Stale,
    /// The command was not a finite number: braked.
    NonFinite,
    /// The agent flagged a failed decision: braked.
    AgentFailed,
    /// No agent was ready to drive the robot: its agent died (or was lost) and no successor was
    /// ready yet, so nothing could answer: braked. Distinct from [`TickOutcome::Stale`] (an agent
    /// answered too late) and [`TickOutcome::AgentFailed`] (an agent answered that it could not
    /// decide). Timing logs written before it existed never hold it.
    AgentDown,
}

impl TickOutcome {
    /// Every outcome, in declaration order.
    pub const ALL: [TickOutcome; 6] = [
        TickOutcome::Fresh,
        TickOutcome::Missing,
        TickOutcome::Stale,
        TickOutcome::NonFinite,
        TickOutcome::AgentFailed,
        TickOutcome::AgentDown,
    ];

    /// The outcome's name in the files (`fresh`, `missing`, `stale`, `non_finite`,
    /// `agent_failed`, `agent_down`), as serde writes it.
    pub fn name(self) -> &'static str {
        match self {
            TickOutcome::Fresh => "fresh",
            TickOutcome::Missing => "missing",
            TickOutcome::Stale => "stale",
            TickOutcome::NonFinite => "non_finite",
            TickOutcome::AgentFailed => "agent_failed",
            TickOutcome::AgentDown => "agent_down",
        }
    }

    /// Whether the watchdog braked the robot (everything but [`TickOutcome::Fresh`]).
    pub fn braked(self) -> bool {
        self != TickOutcome::Fresh
    }
}

/// One robot's per-tick record of a run, stored column-wise (one entry per tick in every column)
/// so a 1200-tick run stays small. Durations are nanoseconds; 0 where no command was used.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RobotTiming {
    /// Distinct model ids in order of first use.
    pub model_ids: Vec<String>,
    /// Per tick: index into `model_ids` of the model that decided, or -1 when no command was used.
    pub model: Vec<i16>,
    /// Per tick: what the watchdog made of the command.
    pub outcome: Vec<TickOutcome>,
    /// Per tick: the scan the used command answered published → that command received by the
    /// world (the world's own clock). Under lag (`lag_ticks` > 0) this is the older scan's
    /// publication, not the current tick's.
    pub round_trip_ns: Vec<u64>,
    /// Per tick: the scan the used command answered published by the world → taken by the agent
    /// (system clock of both).
    pub uplink_ns: Vec<u64>,
    /// Per tick: occupancy rendering in the agent.
    pub occupancy_ns: Vec<u64>,
    /// Per tick: policy inference in the agent.
    pub inference_ns: Vec<u64>,
    /// Per tick: command published by the agent → taken by the world (system clock of both).
    pub downlink_ns: Vec<u64>,
    /// Per tick: how many ticks older than this one the scan was that the used command answered
    /// (0 in lockstep; realtime uses a command while its scan is within the stale window).
    #[serde(default)]
    pub lag_ticks: Vec<u32>,
}

impl RobotTiming {
    /// Appends one tick: the outcome, the command used (if any), its round trip (from the
    /// publication of the scan that command answered, tick `used.tick`, to its arrival), when the
    /// world published that same scan and when it took the command (both [`wall_clock_ns`]).
    pub fn record(
        &mut self,
        outcome: TickOutcome,
        used: Option<&CmdMsg>,
        round_trip: Option<std::time::Duration>,
        scan_published_wall_ns: u64,
        cmd_taken_wall_ns: u64,
    ) {
        self.outcome.push(outcome);
        let tick = self.outcome.len() as u64 - 1;
        self.lag_ticks.push(used.map_or(0, |msg| {
            u32::try_from(tick.saturating_sub(msg.tick)).unwrap_or(u32::MAX)
        }));
        let Some(msg) = used else {
            self.model.push(-1);
            self.round_trip_ns.push(0);
            self.uplink_ns.push(0);
            self.occupancy_ns.push(0);
            self.inference_ns.push(0);
            self.downlink_ns.push(0);
            return;
        };
        let id = msg.model_id().unwrap_or("<malformed>");
        let index = match self.model_ids.iter().position(|m| m == id) {
            Some(i) => i,
            None => {
                self.model_ids.push(id.to_owned());
                self.model_ids.len() - 1
            }
        };
        self.model.push(i16::try_from(index).unwrap_or(i16::MAX));
        let ns = |d: std::time::Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.round_trip_ns.push(round_trip.map_or(0, ns));
        self.uplink_ns
            .push(msg.received_wall_ns.saturating_sub(scan_published_wall_ns));
        self.occupancy_ns.push(msg.occupancy_ns);
        self.inference_ns.push(msg.inference_ns);
        self.downlink_ns
            .push(cmd_taken_wall_ns.saturating_sub(msg.published_wall_ns));
    }

    /// Ticks recorded.
    pub fn ticks(&self) -> usize {
        self.outcome.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_ids_are_validated_and_generated_ids_are_valid() {
        assert!(RunId::new("abc-1_X").is_ok());
        for bad in ["", "a/b", "has space", "ü", &"x".repeat(MAX_RUN_ID_LEN + 1)] {
            assert!(
                matches!(RunId::new(bad), Err(WireError::InvalidRunId { .. })),
                "{bad:?}"
            );
        }
        let generated = RunId::generate();
        assert_eq!(RunId::new(generated.as_str()).as_ref(), Ok(&generated));
    }

    #[test]
    fn service_names_are_namespaced_by_run_robot_incarnation_and_channel() {
        let run = RunId::new("t1").unwrap();
        assert_eq!(
            robot_service_name(&run, 2, 0xab, RobotChannel::Scan),
            "formation/t1/robot/2/00000000000000ab/scan"
        );
        assert_eq!(
            lobby_service_name(&run, 0, LobbyChannel::Hello),
            "formation/t1/robot/0/hello"
        );
        let names: std::collections::HashSet<_> = RobotChannel::ALL
            .iter()
            .flat_map(|&c| {
                [
                    robot_service_name(&run, 0, 1, c),
                    robot_service_name(&run, 0, 2, c),
                ]
            })
            .chain([
                lobby_service_name(&run, 0, LobbyChannel::Hello),
                lobby_service_name(&run, 0, LobbyChannel::Welcome),
            ])
            .collect();
        assert_eq!(names.len(), 10, "every incarnation has services of its own");
    }

    #[test]
    fn messages_round_trip_through_their_bytes_and_a_wrong_size_is_refused() {
        let goal = Goal {
            phi_star: 1.0,
            d_star: 2.0,
            v_star: 0.3,
        };
        let scan = ScanMsg::new(3, 17, 0.85, -0.5, &goal, &[1.5, f32::INFINITY, 0.25]).unwrap();
        let bytes = message_bytes(&scan).to_vec();
        assert_eq!(bytes.len(), std::mem::size_of::<ScanMsg>());
        let back: ScanMsg = message_from_bytes("scan", &bytes).unwrap();
        assert_eq!(message_bytes(&back), &bytes[..], "bit for bit");
        assert_eq!(back.ranges().unwrap(), &[1.5, f32::INFINITY, 0.25]);
        let short = message_from_bytes::<ScanMsg>("scan", &bytes[1..]);
        assert!(
            matches!(&short, Err(WireError::Malformed { message: "scan", reason })
                if reason.contains("different builds")),
            "{short:?}"
        );
        let welcome = WelcomeMsg::encode(9, &Welcome::Refused("taken".into()));
        let back: WelcomeMsg = message_from_bytes("welcome", message_bytes(&welcome)).unwrap();
        assert_eq!(back.decode().unwrap(), Welcome::Refused("taken".into()));
    }

    #[test]
    fn welcome_round_trips() {
        for welcome in [
            Welcome::Accepted,
            Welcome::Refused("robot 1 is taken".into()),
        ] {
            let msg = WelcomeMsg::encode(7, &welcome);
            assert_eq!(msg.nonce, 7);
            assert_eq!(msg.decode().unwrap(), welcome);
        }
    }

    #[test]
    fn long_reasons_are_cut_at_a_word_and_say_so() {
        let reason = "word ".repeat(REASON_LEN);
        let bytes: [u8; REASON_LEN] = encode_text_lossy(&reason);
        let text = decode_text("test", &bytes).unwrap();
        assert!(text.ends_with("word …"), "{text:?}");
        assert!(text.len() <= REASON_LEN);
        let short: [u8; REASON_LEN] = encode_text_lossy("fits");
        assert_eq!(decode_text("test", &short).unwrap(), "fits");
    }

    #[test]
    fn scan_keeps_ranges_and_goal_and_rejects_oversized_scans() {
        let goal = Goal {
            phi_star: 1.0,
            d_star: 2.0,
            v_star: 0.7,
        };
        let ranges: Vec<f32> = (0..360).map(|k| k as f32 * 0.01).collect();
        let msg = ScanMsg::new(3, 7, 0.35, -0.5, &goal, &ranges).unwrap();
        assert_eq!(msg.ranges().unwrap(), &ranges[..]);
        assert_eq!(msg.goal(), goal);
        assert!(msg.ranges[360..].iter().all(|&r| r == 0.0));
        let too_many = vec![1.0; MAX_BEAMS + 1];
        assert_eq!(
            ScanMsg::new(0, 0, 0.0, 0.0, &goal, &too_many).unwrap_err(),
            WireError::TooManyBeams {
                beams: MAX_BEAMS + 1
            }
        );
        let mut corrupt = msg;
        corrupt.n_beams = MAX_BEAMS as u32 + 5;
        assert!(matches!(corrupt.ranges(), Err(WireError::Malformed { .. })));
    }

    #[test]
    fn world_events_round_trip_as_json_lines() {
        let event = WorldEvent::RunDone {
            index: 3,
            log: PathBuf::from("/o/runs/run-0003.json"),
        };
        let line = event.to_line();
        assert_eq!(
            line,
            r#"{"event":"run_done","index":3,"log":"/o/runs/run-0003.json"}"#
        );
        assert_eq!(WorldEvent::parse(&line), Some(event));
        assert_eq!(
            WorldEvent::parse(r#"{"event":"agent_rejoined","robot":1,"pid":42,"tick":57}"#),
            Some(WorldEvent::AgentRejoined {
                robot: 1,
                pid: 42,
                tick: 57
            })
        );
        assert_eq!(WorldEvent::parse("not json"), None);
        assert_eq!(WorldEvent::parse(r#"{"event":"unknown"}"#), None);
    }

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
    fn swap_request_and_reply_round_trip() {
        let request = SwapRequest {
            request_id: 77,
            robot: 2,
            at_tick: 40,
            path: PathBuf::from("/models/new.onnx"),
        };
        assert_eq!(
            SwapRequestMsg::encode(&request).unwrap().decode().unwrap(),
            request
        );
        let long = SwapRequest {
            path: PathBuf::from("m".repeat(MODEL_PATH_LEN + 1)),
            ..request
        };
        assert!(matches!(
            SwapRequestMsg::encode(&long),
            Err(WireError::TextTooLong { .. })
        ));
        for outcome in [
            SwapOutcome::Done {
                tick: 41,
                model_id: "policy-1234".into(),
            },
            SwapOutcome::Refused {
                reason: "wrong input shape".into(),
            },
        ] {
            let reply = SwapReply {
                request_id: 77,
                robot: 2,
                outcome,
            };
            assert_eq!(
                SwapReplyMsg::encode(&reply).unwrap().decode().unwrap(),
                reply
            );
        }
        let mut unknown = SwapReplyMsg::encode(&SwapReply {
            request_id: 1,
            robot: 0,
            outcome: SwapOutcome::Refused { reason: "x".into() },
        })
        .unwrap();
        unknown.kind = 9;
        assert!(matches!(
            unknown.decode(),
            Err(WireError::UnknownKind { .. })
        ));
    }

    #[test]
    fn command_round_trips_and_refuses_a_long_model_id() {
        let timings = AgentTimings {
            received_wall_ns: 5,
            occupancy_ns: 6,
            inference_ns: 7,
        };
        let cmd = WheelCmd {
            left: 0.25,
            right: -0.5,
        };
        let status = CmdStatus::OK.with(CmdStatus::MODEL_SWAPPED);
        let msg = CmdMsg::new(1, 2, cmd, "policy-abc123", timings, status).unwrap();
        assert_eq!(msg.wheels(), cmd);
        assert_eq!(msg.model_id().unwrap(), "policy-abc123");
        assert_eq!(msg.timings(), timings);
        assert!(msg.status().contains(CmdStatus::MODEL_SWAPPED));
        assert!(!msg.status().contains(CmdStatus::DECISION_FAILED));
        let long = "m".repeat(MODEL_ID_LEN + 1);
        assert!(matches!(
            CmdMsg::new(1, 2, cmd, &long, timings, status),
            Err(WireError::TextTooLong {
                field: "model id",
                ..
            })
        ));
    }

    #[test]
    fn control_requests_round_trip() {
        let requests = [
            ControlRequest::BeginEpisode {
                generation: 9,
                lidar: LidarSpec {
                    beams: 900,
                    max_range: 10.0,
                    noise_std: 0.03,
                },
            },
            ControlRequest::SwapModel {
                request_id: 4,
                at_tick: 100,
                path: "/m/policy.onnx".into(),
            },
            ControlRequest::Shutdown,
        ];
        for request in requests {
            assert_eq!(
                ControlMsg::encode(&request).unwrap().decode().unwrap(),
                request
            );
        }
        let mut unknown = ControlMsg::encode(&ControlRequest::Shutdown).unwrap();
        unknown.kind = 77;
        assert_eq!(
            unknown.decode().unwrap_err(),
            WireError::UnknownKind {
                message: "control",
                kind: 77
            }
        );
    }

    #[test]
    fn statuses_round_trip_and_long_reasons_are_cut_at_a_char_boundary() {
        let statuses = [
            AgentStatus::Hello {
                pid: 42,
                model_id: "a".into(),
            },
            AgentStatus::Ready {
                generation: 3,
                model_id: "b".into(),
            },
            AgentStatus::Refused {
                generation: 3,
                reason: "beams differ".into(),
            },
            AgentStatus::SwapDone {
                request_id: 1,
                tick: 50,
                model_id: "c".into(),
            },
            AgentStatus::SwapRefused {
                request_id: 2,
                reason: "no such file".into(),
            },
        ];
        for status in statuses {
            assert_eq!(
                StatusMsg::encode(&status).unwrap().decode().unwrap(),
                status
            );
        }
        let long = "é".repeat(REASON_LEN);
        let msg = StatusMsg::encode(&AgentStatus::Refused {
            generation: 0,
            reason: long,
        })
        .unwrap();
        match msg.decode().unwrap() {
            AgentStatus::Refused { reason, .. } => {
                assert!(reason.len() <= REASON_LEN, "{}", reason.len());
                assert!(reason.ends_with(" …"), "a cut reason says so");
                assert!(reason.trim_end_matches(" …").chars().all(|c| c == 'é'));
            }
            other => panic!("decoded {other:?}"),
        }
    }

    #[test]
    fn outcome_names_are_the_names_in_the_files_and_old_names_still_read() {
        for outcome in TickOutcome::ALL {
            assert_eq!(
                serde_json::to_string(&outcome).unwrap(),
                format!("\"{}\"", outcome.name())
            );
            assert_eq!(outcome.braked(), outcome != TickOutcome::Fresh);
        }
        let old: Vec<TickOutcome> =
            serde_json::from_str(r#"["fresh","missing","stale","non_finite","agent_failed"]"#)
                .unwrap();
        assert_eq!(old, TickOutcome::ALL[..5]);
    }

    #[test]
    fn a_degraded_link_event_is_one_json_line() {
        let event = WorldEvent::LinkDegraded {
            robot: 1,
            tick: 205,
            window_ms: 5000,
            window_ticks: 100,
            braked: 7,
            reasons: std::collections::BTreeMap::from([("stale".to_owned(), 7)]),
            round_trip_us: Some(101_000),
        };
        let line = event.to_line();
        assert!(
            line.starts_with(r#"{"event":"link_degraded","robot":1,"#),
            "{line}"
        );
        assert_eq!(WorldEvent::parse(&line), Some(event));
    }

    #[test]
    fn timing_log_records_used_commands_and_gaps() {
        let timings = AgentTimings {
            received_wall_ns: 1_500,
            occupancy_ns: 20,
            inference_ns: 30,
        };
        let mut a = CmdMsg::new(1, 0, WheelCmd::BRAKE, "a", timings, CmdStatus::OK).unwrap();
        let mut b = CmdMsg::new(1, 2, WheelCmd::BRAKE, "b", timings, CmdStatus::OK).unwrap();
        a.published_wall_ns = 1_600;
        b.published_wall_ns = 1_650;
        let mut log = RobotTiming::default();
        let ns = std::time::Duration::from_nanos;
        log.record(TickOutcome::Fresh, Some(&a), Some(ns(900)), 1_000, 1_900);
        log.record(TickOutcome::Missing, None, None, 2_000, 0);
        log.record(TickOutcome::Fresh, Some(&b), Some(ns(800)), 1_200, 2_000);
        log.record(TickOutcome::Fresh, Some(&a), Some(ns(700)), 1_000, 1_700);
        assert_eq!(log.ticks(), 4);
        assert_eq!(log.model_ids, vec!["a".to_owned(), "b".to_owned()]);
        assert_eq!(log.model, vec![0, -1, 1, 0]);
        assert_eq!(log.round_trip_ns, vec![900, 0, 800, 700]);
        assert_eq!(log.uplink_ns, vec![500, 0, 300, 500]);
        assert_eq!(log.downlink_ns, vec![300, 0, 350, 100]);
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
