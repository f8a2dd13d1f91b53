//! The model-based distance formation controller (the expert) and demonstration collection.
//!
//! * [`controller`]: [`expert_commands`], the paper's distance-based formation controller as a pure
//!   function of all robots' poses and the goal, with its [`ExpertGains`], and [`ExpertController`],
//!   the same as a [`formation_world::Controller`].
//! * [`pair_weights`]: the neighbour rule's pairs weighed smoothly by their witness ratio, for
//!   labels that are continuous across the rule's threshold ([`ExpertGains::pair_weight_band`]).
//! * [`collect`]: demonstration collection into the training data set, and the expert labelling of
//!   any observation that DAgger uses while the learned policy drives.
//! * [`own_scan`]: the same law on what one robot sees: its command from the neighbours it
//!   detects in its own scan ([`own_scan::OwnScanPilot`], a [`formation_proto::robot::Pilot`];
//!   [`own_scan::own_scan_team`], the decentralised team of them).
//! * [`response`]: the response gauge, a controller's formation velocity against the expert's
//!   label on the controller's own states (`formation gauge`).
//!
//! The expert reads ground truth that no agent has; it exists to teach and to compare with, never to
//! run inside a robot.

pub mod collect;
pub mod controller;
pub mod own_scan;
pub mod pair_weights;
pub mod response;
#[cfg(test)]
mod test_support;

pub use controller::{
    ExpertController, ExpertGains, InvalidGains, PairPoints, expert_commands,
    expert_commands_among, expert_commands_weighted,
};
