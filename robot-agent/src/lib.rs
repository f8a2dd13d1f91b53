//! One robot's side of formation: everything a robot decides with its own sensor data only.
//!
//! * [`decision`]: the agent's decision `act(own scan, own heading, goal) -> wheel command`, a pure
//!   function of one robot's own inputs and its policy (the scan rendered by
//!   [`formation_perception::occupancy`], the network run by `formation-onnx`), and an in-process
//!   [`formation_proto::control::Controller`] that runs it for every robot independently.
//!
//! The agent process that drives this decision over a transport is the `formation-agent` binary
//! of `formation-cli`; this crate builds no transport.

pub mod decision;
