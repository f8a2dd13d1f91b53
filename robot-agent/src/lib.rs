//! One robot's side of formation: everything a robot does with its own sensor data only.
//!
//! * [`occupancy`]: renders the occupancy image from one raw LIDAR scan. The single function used
//!   both when collecting demonstrations and by the running agent, so both see the same pixels.
//! * [`decision`]: the agent's decision `act(own scan, own heading, goal) -> wheel command`, a pure
//!   function of one robot's own inputs and its policy, and an in-process [`formation_proto::control::Controller`]
//!   that runs it for every robot independently.
//! * [`pilot`]: the decision as the runtime's agent loop drives it (ONNX models, one
//!   [`decision::Agent`] per robot).

pub mod decision;
pub mod occupancy;
pub mod pilot;
