//! Types shared by every part of formation.
//!
//! * [`types`]: plain values that cross crate boundaries (poses, wheel commands, the goal a robot
//!   is given, LIDAR and occupancy settings). They carry no behaviour beyond validation.
//! * [`lidar_noise`]: what a simulated LIDAR adds beyond the sensor contract ([`LidarSpec`]):
//!   [`LidarNoise`], and [`SimulatedLidar`], the two as files record them.
//! * [`neighbours`]: the formation's neighbour rule as a value (its computation is the world's).
//! * [`policy_output`]: what a policy's output means ([`PolicyOutput`]), as its model declares it.
//! * [`policy_io`]: a policy's whole input and output contract ([`PolicyIo`]).
//! * [`files`]: reading a user's file only if it is a regular file within a size limit.
//! * [`mod@model_id`]: the id an agent reports for its model (file stem and content hash).
//! * [`errors`]: an error and its sources as one line, each cause printed once.
//! * [`exit`]: the exit codes of the three binaries and the termination signals behind two of
//!   them.
//! * [`control`]: the [`control::Controller`] seam between an episode loop and what decides the
//!   wheel commands, with its [`control::Observation`] and [`control::ControllerError`].
//! * [`robot`]: one robot's decision: its [`robot::RobotInput`] (own scan, own heading, goal),
//!   the [`robot::Pilot`] that decides from it, [`robot::CheckedGoal`] and
//!   [`robot::Decentralised`], a team of pilots as a [`control::Controller`].
//! * [`wire`]: the fixed-size `#[repr(C)]` messages between the world process and the
//!   robot-agent processes, whatever carries them, and the names of their channels.
//!
//! Nothing here knows about physics, policies or ONNX; both the world and the agents depend on
//! this crate so that neither depends on the other.

pub mod control;
pub mod errors;
pub mod exit;
pub mod files;
pub mod goal_speed;
pub mod lidar_noise;
pub mod model_id;
pub mod neighbours;
pub mod policy_io;
pub mod policy_output;
pub mod robot;
pub mod swap_done;
pub mod team_size;
pub mod types;
pub mod wire;

pub use goal_speed::GoalSpeedFit;
pub use lidar_noise::{LidarNoise, SimulatedLidar};
pub use neighbours::{GabrielRule, NeighbourRule};
pub use policy_io::{
    AuxInput, AuxLayout, AuxValues, NeighbourInput, NeighbourInputError, PolicyInput, PolicyIo,
    RangeInput, RangeInputError,
};
pub use policy_output::{MAX_REFERENCE_SPEED, PolicyOutput};
pub use swap_done::SwapDone;
pub use team_size::TeamSizeFit;
pub use types::*;
