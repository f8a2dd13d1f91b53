//! What the Zenoh transport could not do ([`ZenohError`]). The runtime's link errors carry it as
//! their transport failure ([`formation_runtime::link::WorldLinkError::Transport`]).
//!
//! Zenoh's own errors are boxed strings with the source file and line of the Zenoh code that
//! raised them; they are kept as their text without those locations ([`crate::without_source_locations`]),
//! since a user can do nothing with them.

use formation_runtime::link::TransportCrateError;

/// A failure of the Zenoh transport.
#[derive(Debug, thiserror::Error)]
pub enum ZenohError {
    /// Zenoh refused an operation.
    #[error("zenoh could not {action} ({detail})")]
    Refused {
        /// What the process was doing.
        action: String,
        /// Zenoh's error, without its source locations.
        detail: String,
    },
    /// The world's endpoint could not be reached, or its router refused the login.
    #[error(
        "cannot reach the world at {endpoint}: {detail}; is `formation-world --transport zenoh \
         --listen {endpoint}` (or `formation run --transport zenoh --listen {endpoint}`) running, \
         is that address reachable from this host, and is --credentials this run's \
         robot-{robot}.json? (the world's router refuses a connection without a login it knows)"
    )]
    Unreachable {
        /// The endpoint given with `--connect`.
        endpoint: String,
        /// The robot the agent would drive.
        robot: usize,
        /// Zenoh's error.
        detail: String,
    },
    /// A world answers at the endpoint, but not for this run.
    #[error(
        "no world of run {run} at {endpoint} after {waited_s:.1} s: the endpoint answers, but the \
         world there plays another run, or the credentials do not allow this robot's keys; check \
         --run-id and the credentials file"
    )]
    NoWorldAt {
        /// The endpoint given with `--connect`.
        endpoint: String,
        /// The run id.
        run: String,
        /// How long the agent waited.
        waited_s: f64,
    },
    /// The TLS certificate is not usable, or the other end refused it (feature `tls`).
    #[cfg(feature = "tls")]
    #[error(transparent)]
    Tls(#[from] crate::tls::TlsError),
}

impl TransportCrateError for ZenohError {}

#[cfg(feature = "tls")]
impl From<crate::tls::TlsError> for formation_runtime::link::AgentLinkError {
    fn from(e: crate::tls::TlsError) -> Self {
        ZenohError::from(e).into()
    }
}
