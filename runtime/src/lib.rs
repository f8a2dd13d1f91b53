//! The multi-process runtime as a library, independent of the transport.
//!
//! * [`exchange`]: the world's side, [`exchange::AgentsController`], a
//!   [`Controller`](formation_proto::control::Controller) that trades each robot's scan for its
//!   command under the clock mode's rule, with the watchdog, admission by the launch secret,
//!   lagging and rejoining, the realtime schedule and swap forwarding.
//! * [`agent`]: an agent's side, [`agent::AgentLoop`]: control requests, swaps at a tick
//!   boundary, one command per scan through a [`agent::Pilot`], and injected [`faults`].
//! * [`link`]: the seams both talk through, [`link::WorldLink`] and [`link::AgentLink`].
//! * [`stamps`]: when each robot's recent scans were published, so a command is timed from the
//!   scan it answered.
//! * [`link_health`]: the degraded-link detector, whose reports the world sends while a run goes
//!   on.
//! * [`liveness`]: when the world asks its transport which agents died (only when one went
//!   quiet, or every 100 periods).
//! * [`reconnect`]: the peers of a network transport that are unreachable but may come back
//!   within a grace.
//! * [`auth`]: the launch secret, with which an agent proves that its own launch started it.
//! * [`memory`]: both links over channels in one process, for tests.
//! * [`clock`]: the injected [`clock::Clock`] (system, or fake for tests).
//! * [`settings`]: [`settings::ClockMode`] and [`settings::RuntimeSettings`], shared by the
//!   launcher and the world.
//! * [`transport`]: [`transport::Transport`], which link the processes use, and the parser of
//!   `--transport` ([`transport::TransportParser`]).
//! * [`plugin`]: [`plugin::TransportPlugin`], a transport registered by name: what a transport
//!   crate implements so that the binaries' generic code opens its links.
//! * [`process`]: what both processes do about the launcher going away.
//!
//! The transports are crates of their own that implement the link traits: `formation-transport-iceoryx2`
//! (shared memory, the default), `formation-transport-zenoh` (agents on other hosts) and
//! `formation-transport-ros2` (ROS 2 over rmw_zenoh); a further one registers a
//! [`plugin::TransportPlugin`] (`examples/transport-unix-datagram/` is one). Dependencies point one way: this crate
//! depends only on `formation-proto` and builds no transport; the transports, the world's binary,
//! the agent's binary and the launcher depend on it, and it knows neither physics nor ONNX.

pub mod agent;
pub mod auth;
pub mod clock;
pub mod exchange;
pub mod faults;
pub mod link;
pub mod link_health;
pub mod liveness;
pub mod memory;
pub mod plugin;
pub mod process;
pub mod reconnect;
pub mod settings;
pub mod stamps;
pub mod transport;

pub use settings::{ClockMode, RuntimeSettings};

#[cfg(test)]
mod tests;
