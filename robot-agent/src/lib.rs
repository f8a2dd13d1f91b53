//! One robot's side of formation: everything a robot does with its own sensor data only.
//!
//! * [`occupancy`]: renders the occupancy image from one raw LIDAR scan. The single function used
//!   both when collecting demonstrations and by the running agent, so both see the same pixels.
//! * [`decision`]: the agent's decision `act(own scan, own heading, goal) -> wheel command`, a pure
//!   function of one robot's own inputs and its policy, and an in-process [`formation_proto::control::Controller`]
//!   that runs it for every robot independently.

pub mod decision;
pub mod occupancy;
