//! What the iceoryx2 transport could not do ([`IceoryxError`]), with iceoryx2's own error kept
//! as the source. The runtime's link errors carry it as their transport failure
//! ([`formation_runtime::link::WorldLinkError::Transport`]).

use std::error::Error;

use formation_runtime::link::{AgentLinkError, TransportCrateError, WorldLinkError};

use crate::naming::NamespaceError;

/// An error of iceoryx2 or of the run's namespace, boxed as the source it came as.
pub type IceoryxCause = Box<dyn Error + Send + Sync + 'static>;

/// A failure of the iceoryx2 transport.
#[derive(Debug, thiserror::Error)]
pub enum IceoryxError {
    /// iceoryx2 refused an operation.
    #[error("iceoryx2 could not {action}: {source}")]
    Refused {
        /// What the process was doing.
        action: String,
        /// iceoryx2's error.
        source: IceoryxCause,
    },
    /// The world could not create one of the run's services.
    #[error("iceoryx2 could not {action}: {source}; is another world running with this run id?")]
    Create {
        /// `create service NAME` or `name service NAME`.
        action: String,
        /// iceoryx2's error.
        source: IceoryxCause,
    },
    /// The run's files could not be made private.
    #[error(transparent)]
    Namespace(#[from] NamespaceError),
    /// The run's services did not appear in time.
    #[error(
        "robot {robot}'s services do not exist in run {run} after {waited_s:.1} s: is the world \
         running with this run id, and does the scenario have more than {robot} robots?"
    )]
    WorldNotFound {
        /// The robot.
        robot: usize,
        /// The run id.
        run: String,
        /// How long the agent waited.
        waited_s: f64,
    },
    /// Another live process holds this robot's port.
    #[error(
        "robot {robot}'s {port} port is held by another process (only one agent may drive a robot)"
    )]
    PortTaken {
        /// The robot.
        robot: usize,
        /// Which port.
        port: &'static str,
        /// iceoryx2's error, when it gave one.
        source: Option<IceoryxCause>,
    },
}

/// `Err` mapper: iceoryx2's error `e` while doing `action`, as an [`IceoryxError::Refused`]
/// (which `?` turns into the caller's link error).
pub(crate) fn iox<E>(action: impl Into<String>) -> impl FnOnce(E) -> IceoryxError
where
    E: Error + Send + Sync + 'static,
{
    // Converted only on failure: a `&'static str` costs no allocation on the paths taken every
    // tick.
    move |e| IceoryxError::Refused {
        action: action.into(),
        source: Box::new(e),
    }
}

/// [`iox`] for the paths taken every tick: the action is written only when the call failed.
pub(crate) fn iox_lazy<E>(action: impl FnOnce() -> String) -> impl FnOnce(E) -> IceoryxError
where
    E: Error + Send + Sync + 'static,
{
    move |e| IceoryxError::Refused {
        action: action(),
        source: Box::new(e),
    }
}

impl TransportCrateError for IceoryxError {}

impl From<NamespaceError> for WorldLinkError {
    fn from(e: NamespaceError) -> Self {
        IceoryxError::from(e).into()
    }
}

impl From<NamespaceError> for AgentLinkError {
    fn from(e: NamespaceError) -> Self {
        IceoryxError::from(e).into()
    }
}
