//! The agent's decision as the runtime's agent loop drives it: [`OnnxPilots`] loads ONNX models
//! and makes an [`OnnxPilot`] of each, the loop's [`Pilot`] around one robot's
//! [`Agent`].
//!
//! It lives here, with the `formation-agent` binary, because it joins two crates that must not
//! know each other: the runtime (transports) and the robot's decision (ONNX).

use std::path::Path;

use formation_onnx::OnnxPolicy;
use formation_proto::{Goal, LidarSpec, WheelCmd};
use formation_robot_agent::decision::{Agent, PolicyBackend};
use formation_runtime::agent::{BoxError, Pilot, PilotMaker};

/// Loads ONNX policies (validating their contract) and wraps them in an [`OnnxPilot`] for a
/// robot's LIDAR.
#[derive(Debug, Clone, Copy, Default)]
pub struct OnnxPilots;

impl PilotMaker for OnnxPilots {
    type Model = Box<dyn PolicyBackend>;
    type Pilot = OnnxPilot;

    fn load(&self, path: &Path) -> Result<Box<dyn PolicyBackend>, BoxError> {
        Ok(Box::new(OnnxPolicy::load(path)?))
    }

    fn model_id<'m>(&self, model: &'m Box<dyn PolicyBackend>) -> &'m str {
        model.model_id()
    }

    fn pilot(
        &self,
        model: Box<dyn PolicyBackend>,
        lidar: LidarSpec,
    ) -> Result<OnnxPilot, BoxError> {
        Ok(OnnxPilot {
            agent: Agent::new(model, lidar)?,
        })
    }
}

/// One robot's [`Agent`] as the agent loop's [`Pilot`].
pub struct OnnxPilot {
    agent: Agent,
}

impl OnnxPilot {
    /// The decision this pilot runs.
    pub fn agent(&self) -> &Agent {
        &self.agent
    }
}

impl Pilot for OnnxPilot {
    type Model = Box<dyn PolicyBackend>;

    fn model_id(&self) -> &str {
        self.agent.model_id()
    }

    fn perceive(&mut self, ranges: &[f32], goal: &Goal) -> Result<(), BoxError> {
        Ok(self.agent.perceive(ranges, goal)?)
    }

    /// Decides under the goal [`Pilot::perceive`] just checked and held (the agent loop hands
    /// both the same goal), which is not checked again.
    fn decide(&mut self, heading: f64, _goal: &Goal) -> Result<WheelCmd, BoxError> {
        Ok(self.agent.decide(heading)?)
    }

    fn swap(&mut self, model: Box<dyn PolicyBackend>) -> Result<(), BoxError> {
        Ok(self.agent.swap_policy(model)?)
    }

    fn rehearse(&mut self) -> Result<(), BoxError> {
        Ok(self.agent.rehearse()?)
    }

    fn set_max_wheel_accel(&mut self, max_wheel_accel: Option<f64>) {
        self.agent.set_max_wheel_accel(max_wheel_accel);
    }
}
