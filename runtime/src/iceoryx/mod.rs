//! The iceoryx2 links: the world's ([`IceoryxWorldLink`]) and an agent's ([`IceoryxAgentLink`]),
//! over zero-copy shared memory in the run's namespace
//! ([`formation_proto::wire::RunNamespace`]).
//!
//! Service names, payloads and limits are those of [`formation_proto::wire`]: the one-publisher /
//! one-subscriber limits on an incarnation's scan and command services are how decentralisation
//! is enforced. Waits run on iceoryx2 wait sets that handle termination requests (SIGINT,
//! SIGTERM); any other signal only interrupts a wait, which the callers resume.

mod agent;
mod world;

pub use agent::IceoryxAgentLink;
pub use world::IceoryxWorldLink;
