//! An example transport registered by name ([`UnixDatagram`], `--transport unix-datagram`): the
//! world's and the agents' links over Unix datagram sockets in a folder private to the user and
//! the run, every process on one host. It shows what a transport is now: one crate that
//! implements the runtime's link traits (`formation_runtime::link`) and its registration trait
//! (`formation_runtime::plugin::TransportPlugin`), and one line in each binary package's
//! `TRANSPORT_PLUGINS`.
//!
//! * [`folder`]: where a run's sockets live, and who may reach them.
//! * [`frame`]: one datagram: a header and one wire message's bytes.
//! * [`socket`]: bound sockets, receiving with or without waiting, the liveness probe.
//! * [`world`]: the world's link, [`DatagramWorldLink`].
//! * [`agent`]: an agent's link, [`DatagramAgentLink`].
//! * [`swap`]: `formation swap`'s client.
//! * [`signals`]: SIGINT and SIGTERM as the waits report them.
//! * [`error`]: the transport's own failures, [`DatagramError`].
//!
//! The conformance suite (`formation-transport-conformance`) holds it to the same behaviours as
//! the first-party transports (`tests/conformance.rs`).

pub mod agent;
pub mod error;
pub mod folder;
pub mod frame;
pub mod signals;
pub mod socket;
pub mod swap;
pub mod world;

use std::time::Duration;

use formation_proto::wire::{SwapReply, SwapRequest};
use formation_runtime::link::{
    AgentLink, AgentLinkError, TransportFailure, WorldLink, WorldLinkError,
};
use formation_runtime::plugin::{AgentSite, RunSite, TransportPlugin, WorldSite};

pub use agent::DatagramAgentLink;
pub use error::DatagramError;
pub use world::DatagramWorldLink;

/// The transport as the binaries register it: `&formation_example_transport_unix_datagram::UnixDatagram`.
#[derive(Debug, Clone, Copy)]
pub struct UnixDatagram;

impl TransportPlugin for UnixDatagram {
    fn name(&self) -> &'static str {
        "unix-datagram"
    }

    fn description(&self) -> &'static str {
        "An example: Unix datagram sockets in a folder private to you and the run, every process \
         on this host (--listen/--connect FOLDER: where that folder goes, default the temporary \
         folder)"
    }

    fn endpoint(&self) -> Option<&'static str> {
        Some("FOLDER")
    }

    fn open_world(&self, site: &WorldSite<'_>) -> Result<Box<dyn WorldLink>, WorldLinkError> {
        Ok(Box::new(DatagramWorldLink::create(site)?))
    }

    fn connect_agent(&self, site: &AgentSite<'_>) -> Result<Box<dyn AgentLink>, AgentLinkError> {
        Ok(Box::new(DatagramAgentLink::connect(site)?))
    }

    fn request_swap(
        &self,
        site: &RunSite<'_>,
        request: &SwapRequest,
        timeout: Duration,
    ) -> Result<SwapReply, TransportFailure> {
        Ok(swap::request_swap(site, request, timeout)?)
    }

    fn remove_leftovers(&self, site: &RunSite<'_>) -> Result<usize, TransportFailure> {
        let folder = folder::RunFolder::locate(site)?;
        if socket::listening(&folder.world_socket()) {
            return Ok(0);
        }
        Ok(folder.remove()?)
    }
}
