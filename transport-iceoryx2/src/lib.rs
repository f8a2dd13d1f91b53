//! The iceoryx2 links: the world's ([`IceoryxWorldLink`]) and an agent's ([`IceoryxAgentLink`]),
//! over zero-copy shared memory in the run's namespace
//! ([`naming::RunNamespace`]).
//!
//! Service names and payloads are those of [`formation_proto::wire`]; limits, node names and
//! namespaces are [`naming`]'s. The one-publisher / one-subscriber limits on an incarnation's scan
//! and command services are how decentralisation is enforced. Waits run on iceoryx2 wait sets that handle termination requests (SIGINT,
//! SIGTERM); any other signal only interrupts a wait, which the callers resume. Which of the two
//! came is read from [`crate::signals`], whose watch both links start before they create their
//! node.

mod agent;
pub mod error;
pub mod naming;
mod services;
pub mod signals;
pub mod swap;
mod wakes;
mod world;

/// Starts recording which termination signal arrives ([`crate::signals`]); when that fails, a
/// SIGTERM reads as SIGINT (the process then exits 130 instead of 143), which is worth a warning
/// but not a failed start.
fn watch_termination_signals() {
    if let Err(e) = signals::watch_termination_signals() {
        tracing::warn!(
            "{}; a SIGTERM will be reported as SIGINT",
            formation_proto::errors::chain_text(&e)
        );
    }
}

pub use agent::IceoryxAgentLink;
pub use error::IceoryxError;
pub use swap::{SwapClientError, request_swap};
pub use world::IceoryxWorldLink;
