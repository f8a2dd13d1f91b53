//! The Zenoh endpoint a transport needs from a flag (`--listen` or `--connect`): missing, it is
//! [`TransportError::MissingEndpoint`] naming the flag; given, it must parse as `tcp/HOST:PORT`.
//! One reading for the world's and the agent's binaries, over Zenoh and ROS 2.

use formation_runtime::transport::{Transport, TransportError};
use formation_runtime::zenoh::Endpoint;

/// The endpoint `given` with `flag`, which `transport` needs.
pub fn required_endpoint(
    given: Option<&str>,
    flag: &'static str,
    transport: Transport,
) -> anyhow::Result<Endpoint> {
    let text = given.ok_or(TransportError::MissingEndpoint { flag, transport })?;
    Ok(Endpoint::parse(text)?)
}
