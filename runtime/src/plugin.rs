//! Transports registered by name: a [`TransportPlugin`] is a transport crate's one value that the
//! world's, the agent's and the launcher's binaries list (each package's `TRANSPORT_PLUGINS`), so
//! that `--transport NAME` picks it without any code of theirs knowing it.
//!
//! A plugin opens the world's side of a run ([`TransportPlugin::open_world`]) and one agent's
//! side ([`TransportPlugin::connect_agent`]) from a small backend-neutral description of where the
//! run is ([`RunSite`], [`WorldSite`], [`AgentSite`]): the run id, the team size or the robot, the
//! launch secret an agent proves, how long it may wait, and an optional endpoint, the string the
//! generic flags carry (`--listen` for the world and the launcher, `--connect` for an agent)
//! when the transport takes one ([`TransportPlugin::endpoint`]). It may answer `formation swap`
//! ([`TransportPlugin::request_swap`]) and clean up after a run whose processes died
//! ([`TransportPlugin::remove_leftovers`]). Its failures are its crate's typed errors, kept as the
//! source of the link errors or of [`TransportFailure`]; the binaries wrap them in
//! [`crate::transport::TransportError`], which names the transport.
//!
//! The first-party transports (iceoryx2, Zenoh, ROS 2) keep their own flags and code paths; a
//! plugin is one more [`crate::transport::Transport`], `Transport::Plugin`.

use std::time::Duration;

use formation_proto::wire::{RunId, SwapReply, SwapRequest};

use crate::auth::LaunchSecret;
use crate::link::{AgentLink, AgentLinkError, TransportFailure, WorldLink, WorldLinkError};

/// Where a run of a plugin transport is: what every process of the run knows alike.
#[derive(Debug, Clone, Copy)]
pub struct RunSite<'a> {
    /// The run id (letters, digits, `-`, `_`): the transport's namespace for the run.
    pub run: &'a RunId,
    /// The endpoint the generic flag gave (`--listen`, `--connect`), if any; only a transport
    /// whose [`TransportPlugin::endpoint`] says what it means is handed one.
    pub endpoint: Option<&'a str>,
}

/// What the world's side of a run needs.
#[derive(Debug, Clone, Copy)]
pub struct WorldSite<'a> {
    /// The run.
    pub run: RunSite<'a>,
    /// How many robots the team has.
    pub robots: usize,
}

/// What one agent's side needs: it greets the world proving the launch secret, and its link is
/// the incarnation the world then opens for it.
#[derive(Clone, Copy)]
pub struct AgentSite<'a> {
    /// The run.
    pub run: RunSite<'a>,
    /// The robot this agent drives.
    pub robot: usize,
    /// The process id the agent proves and is known by (this process's, but in tests that run
    /// agents on threads).
    pub pid: u32,
    /// The launch secret the agent proves.
    pub secret: &'a LaunchSecret,
    /// How long to wait for the world to be there and to answer the greeting.
    pub connect_timeout: Duration,
}

impl std::fmt::Debug for AgentSite<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AgentSite")
            .field("run", &self.run)
            .field("robot", &self.robot)
            .field("pid", &self.pid)
            .field("connect_timeout", &self.connect_timeout)
            .finish_non_exhaustive()
    }
}

/// A transport that the binaries list by name. Implementations are unit structs in their own
/// crate, registered as `&MyTransport` in each binary package's `TRANSPORT_PLUGINS`.
pub trait TransportPlugin: Sync {
    /// The name `--transport` takes: lowercase ASCII letters, digits and `-`, unlike any other
    /// transport's.
    fn name(&self) -> &'static str;

    /// One line for `--help`: what the transport is and where its processes may run.
    fn description(&self) -> &'static str;

    /// What the endpoint means to this transport (for the help and the errors), if it takes
    /// one; `None` (the default) refuses `--listen` and `--connect`.
    fn endpoint(&self) -> Option<&'static str> {
        None
    }

    /// Opens the world's side of the run: every robot's lobby, and whatever else the run needs.
    fn open_world(&self, site: &WorldSite<'_>) -> Result<Box<dyn WorldLink>, WorldLinkError>;

    /// Connects one agent: greets the world proving the launch secret and returns its end of
    /// the incarnation the world opened. A refusal is [`AgentLinkError::Refused`], no answer in
    /// time [`AgentLinkError::NoWelcome`] (or the transport's own error), a signal while waiting
    /// [`AgentLinkError::Terminated`].
    fn connect_agent(&self, site: &AgentSite<'_>) -> Result<Box<dyn AgentLink>, AgentLinkError>;

    /// Sends `request` to the world of the run (`formation swap`) and waits up to `timeout` for
    /// its reply. By default the transport carries no swaps.
    fn request_swap(
        &self,
        site: &RunSite<'_>,
        request: &SwapRequest,
        timeout: Duration,
    ) -> Result<SwapReply, TransportFailure> {
        let _ = (site, request, timeout);
        Err(Box::new(NoSwaps {
            transport: self.name(),
        }))
    }

    /// Removes what a run left behind once none of its processes lives (the launcher calls it
    /// after its children exited, however they exited); returns how many entries it removed. By
    /// default there is nothing to remove.
    fn remove_leftovers(&self, site: &RunSite<'_>) -> Result<usize, TransportFailure> {
        let _ = site;
        Ok(0)
    }
}

/// The transport carries no swap requests.
#[derive(Debug, thiserror::Error)]
#[error(
    "the {transport} transport carries no swap requests: restart the robot's agent with the \
     other model instead"
)]
pub struct NoSwaps {
    /// The transport.
    pub transport: &'static str,
}

/// The plugin of `plugins` named `name`, if there is one.
pub fn find_plugin(
    plugins: &[&'static dyn TransportPlugin],
    name: &str,
) -> Option<&'static dyn TransportPlugin> {
    plugins.iter().copied().find(|plugin| plugin.name() == name)
}
