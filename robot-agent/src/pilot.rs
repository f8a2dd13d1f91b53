//! The robot's decision behind the one decision seam, [`formation_proto::robot::Pilot`]:
//! [`Agent`] is a pilot, [`OnnxPilots`] loads ONNX models and makes an agent of each, and
//! [`PolicyTeam`] is a team of agents in one process.
//!
//! The runtime's agent loop, the ROS 2 agent, replay and `formation eval` all drive an [`Agent`]
//! through these traits; none of them knows ONNX, and this crate knows no transport.

use std::path::Path;

use formation_onnx::OnnxPolicy;
use formation_proto::robot::{BoxError, Decentralised, Pilot, PilotMaker};
use formation_proto::{Goal, LidarSpec, WheelCmd, WheelLimits};

use crate::decision::{Agent, PolicyBackend};

/// One robot's [`Agent`] as the agent loop drives it: its pilot.
pub type OnnxPilot = Agent;

/// A team of [`Agent`]s in one process, each handed only its own robot's input.
pub type PolicyTeam = Decentralised<Agent>;

/// Loads ONNX policies (validating their contract) and makes an [`Agent`] of each for a robot's
/// LIDAR.
#[derive(Debug, Clone, Copy, Default)]
pub struct OnnxPilots;

impl PilotMaker for OnnxPilots {
    type Model = Box<dyn PolicyBackend>;
    type Pilot = Agent;

    fn load(&self, path: &Path) -> Result<Box<dyn PolicyBackend>, BoxError> {
        Ok(Box::new(OnnxPolicy::load(path)?))
    }

    fn model_id<'m>(&self, model: &'m Box<dyn PolicyBackend>) -> &'m str {
        model.model_id()
    }

    fn pilot(&self, model: Box<dyn PolicyBackend>, lidar: LidarSpec) -> Result<Agent, BoxError> {
        Ok(Agent::new(model, lidar)?)
    }
}

impl Pilot for Agent {
    type Model = Box<dyn PolicyBackend>;

    fn model_id(&self) -> &str {
        Agent::model_id(self)
    }

    fn perceive(&mut self, ranges: &[f32], goal: &Goal) -> Result<(), BoxError> {
        Ok(Agent::perceive(self, ranges, goal)?)
    }

    /// Decides under the goal [`Pilot::perceive`] just checked and held (every caller hands both
    /// the same goal), which is not checked again.
    fn decide(&mut self, heading: f64, _goal: &Goal) -> Result<WheelCmd, BoxError> {
        Ok(Agent::decide(self, heading)?)
    }

    fn swap(&mut self, model: Box<dyn PolicyBackend>) -> Result<(), BoxError> {
        Ok(self.swap_policy(model)?)
    }

    fn rehearse(&mut self) -> Result<(), BoxError> {
        Ok(Agent::rehearse(self)?)
    }

    fn set_wheel_limits(&mut self, wheels: WheelLimits) {
        Agent::set_wheel_limits(self, wheels);
    }
}
