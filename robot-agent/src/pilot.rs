//! The agent's decision as the runtime's agent loop drives it: [`OnnxPilots`] loads ONNX models
//! and makes an [`Agent`] of each, and [`Agent`] is the loop's
//! [`Pilot`].

use std::path::Path;

use formation_onnx::OnnxPolicy;
use formation_proto::{Goal, LidarSpec, WheelCmd};
use formation_runtime::agent::{BoxError, Pilot, PilotMaker};

use crate::decision::{Agent, PolicyBackend};

/// Loads ONNX policies (validating their contract) and wraps them in an [`Agent`] for a robot's
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

    fn perceive(&mut self, ranges: &[f32]) -> Result<(), BoxError> {
        Ok(Agent::perceive(self, ranges)?)
    }

    fn decide(&mut self, heading: f64, goal: &Goal) -> Result<WheelCmd, BoxError> {
        Ok(Agent::decide(self, heading, goal)?)
    }

    fn swap(&mut self, model: Box<dyn PolicyBackend>) -> Result<(), BoxError> {
        Ok(self.swap_policy(model)?)
    }

    fn rehearse(&mut self) -> Result<(), BoxError> {
        Ok(Agent::rehearse(self)?)
    }
}
