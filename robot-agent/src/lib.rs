//! One robot's side of formation: everything a robot decides with its own sensor data only.
//!
//! * [`decision`]: the agent's decision `act(own scan, own heading, goal) -> wheel command`, a pure
//!   function of one robot's own inputs and its policy (the scan rendered by
//!   [`formation_perception::occupancy`], the network run by `formation-onnx`), and an in-process
//!   [`formation_proto::control::Controller`] that runs it for every robot independently.
//! * [`pilot`]: the agent behind the one decision seam, [`formation_proto::robot::Pilot`], which
//!   the runtime's agent loop, the ROS 2 agent, replay and `formation eval` drive; and
//!   [`pilot::OnnxPilots`], which loads ONNX models and makes agents of them.
//!
//! The agent process that drives this decision over a transport is `formation-agent`
//! (`agent-node/`); this crate builds no transport.

pub mod decision;
pub mod pilot;

/// Keeps ONNX Runtime from writing outside the run's folders; call it first in `main`
/// ([`formation_onnx::disable_telemetry_before_threads`]).
pub use formation_onnx::disable_telemetry_before_threads;
