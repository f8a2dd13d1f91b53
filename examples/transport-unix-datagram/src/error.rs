//! The transport's own failures ([`DatagramError`]), each naming the folder or socket it concerns
//! and keeping the operating system's error; they reach the runtime as the source of
//! `WorldLinkError::Transport` and `AgentLinkError::Transport`.

use std::path::PathBuf;

use formation_proto::wire::WireError;
use formation_runtime::auth::SecretError;
use formation_runtime::link::{PathIoError, TransportCrateError};

/// A failure of the Unix datagram transport.
#[derive(Debug, thiserror::Error)]
pub enum DatagramError {
    /// A file system or socket operation failed.
    #[error(transparent)]
    Io(#[from] PathIoError),
    /// The folder of this user's runs belongs to another user, or others may enter it.
    #[error(
        "{dir} is not private to us (owner {owner}, mode {mode:o}; we are user {us}): another \
         user could reach our runs' sockets there; remove it, or pass another folder"
    )]
    NotPrivate {
        /// The folder.
        dir: PathBuf,
        /// Its owner.
        owner: u32,
        /// Its permission bits.
        mode: u32,
        /// Our user id.
        us: u32,
    },
    /// A socket's path is longer than a Unix socket address holds.
    #[error(
        "the socket path {path} is {len} bytes long, over the {max} a Unix socket takes: pass a \
         shorter folder (--listen/--connect) or TMPDIR"
    )]
    PathTooLong {
        /// The path.
        path: PathBuf,
        /// Its length in bytes.
        len: usize,
        /// The most a socket address holds.
        max: usize,
    },
    /// Another live world serves this run id.
    #[error("run {run} is in use: a world listens in {dir}; pick another --run-id")]
    RunInUse {
        /// The run id.
        run: String,
        /// The run's folder.
        dir: PathBuf,
    },
    /// No world of the run listened in time.
    #[error("no world of run {run} listened in {dir} within {waited_s:.1} s; is it running?")]
    WorldNotFound {
        /// The run id.
        run: String,
        /// The run's folder.
        dir: PathBuf,
        /// How long we waited.
        waited_s: f64,
    },
    /// The world did not answer a swap request in time.
    #[error("the world did not answer swap request {request_id} within {waited_s:.1} s")]
    NoSwapReply {
        /// The request.
        request_id: u64,
        /// How long we waited.
        waited_s: f64,
    },
    /// SIGINT and SIGTERM could not be watched.
    #[error("could not watch for SIGINT and SIGTERM: {0}")]
    Signals(std::sync::Arc<std::io::Error>),
    /// A message could not be encoded.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// No nonce could be drawn.
    #[error(transparent)]
    Secret(#[from] SecretError),
}

impl DatagramError {
    /// The error of `action` on `path` failing with `source`.
    pub(crate) fn io(
        action: &'static str,
        path: impl Into<PathBuf>,
    ) -> impl FnOnce(std::io::Error) -> DatagramError {
        let io = PathIoError::of(action, path);
        move |source| DatagramError::Io(io(source))
    }
}

impl TransportCrateError for DatagramError {}
