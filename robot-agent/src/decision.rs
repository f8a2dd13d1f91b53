//! The agent's decision: `act(own scan, own heading, goal) -> wheel command`.
//!
//! An [`Agent`] holds one robot's policy and its reusable image buffers. Its decision reads nothing
//! but that robot's own LIDAR scan, its own compass heading and the goal every robot is given:
//!
//! 1. render the occupancy image from the scan ([`crate::occupancy::render`], the same function the
//!    demonstration collector uses);
//! 2. `delta_phi = wrap(phi* - theta)`, and `aux = (delta_phi, d*)`;
//! 3. `u_hat = policy(image, aux)`, the wheel speeds at the training speed `v_train`;
//! 4. `u = K u_hat` with `K = v* / v_train` (the paper's speed scaling).
//!
//! The steps are exposed separately ([`Agent::perceive`], [`Agent::decide`]) so the agent process
//! can time them, and together as [`Agent::act`]. [`PolicyController`] runs one independent `Agent`
//! per robot inside one process: the in-process twin of the multi-process runtime.

use std::path::Path;

use formation_onnx::{OnnxPolicy, PolicyError};
use formation_proto::{Goal, LidarSpec, OccupancySpec, WheelCmd, wrap_angle};
use formation_world::episode::{Controller, ControllerError, Observation};

use crate::occupancy;

/// Why an agent could not decide, or could not take a policy.
#[derive(Debug, thiserror::Error)]
pub enum DecisionError {
    /// The ONNX policy failed to load, validate or run.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// The model was trained for another sensor than this robot's.
    #[error(
        "model {model} expects {expected} LIDAR beams but this robot's scan has {actual}; \
         use a model trained with the scenario's sensor settings (formation collect/train)"
    )]
    SensorMismatch {
        /// Model id.
        model: String,
        /// Beams in the model's metadata.
        expected: usize,
        /// Beams of this robot's LIDAR.
        actual: usize,
    },
    /// A scan of the wrong length reached the agent.
    #[error("scan has {actual} ranges, the LIDAR is configured for {expected}")]
    ScanLength {
        /// Configured beams.
        expected: usize,
        /// Ranges received.
        actual: usize,
    },
    /// The policy returned a non-finite wheel speed.
    #[error("policy {model} returned a non-finite command ({left}, {right})")]
    NonFinite {
        /// Model id.
        model: String,
        /// Left wheel output.
        left: f32,
        /// Right wheel output.
        right: f32,
    },
    /// The goal cannot be acted on.
    #[error("invalid goal: {reason}")]
    Goal {
        /// What is wrong.
        reason: String,
    },
}

/// A policy an [`Agent`] can run: maps one occupancy image and `(delta_phi, d*)` to wheel speeds.
pub trait PolicyBackend: Send {
    /// One forward pass. `occupancy` has `size_px * size_px` cells (0.0 or 1.0), row-major.
    fn infer(&mut self, occupancy: &[f32], aux: [f32; 2]) -> Result<[f32; 2], DecisionError>;
    /// The occupancy rendering the policy was trained on.
    fn occupancy_spec(&self) -> OccupancySpec;
    /// LIDAR beams the policy was trained with, if it records them.
    fn beams(&self) -> Option<usize>;
    /// Training speed `v_train` \[m/s\]; deployed commands are scaled by `v* / v_train`.
    fn v_train(&self) -> f64;
    /// A short id naming the model (logged with every command).
    fn model_id(&self) -> &str;
}

impl PolicyBackend for OnnxPolicy {
    fn infer(&mut self, occupancy: &[f32], aux: [f32; 2]) -> Result<[f32; 2], DecisionError> {
        Ok(OnnxPolicy::infer(self, occupancy, aux)?)
    }
    fn occupancy_spec(&self) -> OccupancySpec {
        self.metadata().occupancy
    }
    fn beams(&self) -> Option<usize> {
        Some(self.metadata().beams)
    }
    fn v_train(&self) -> f64 {
        self.metadata().v_train
    }
    fn model_id(&self) -> &str {
        OnnxPolicy::model_id(self)
    }
}

/// One robot's decision maker: its policy, its sensor settings and reusable image buffers.
pub struct Agent {
    policy: Box<dyn PolicyBackend>,
    lidar: LidarSpec,
    image: Vec<u8>,
    image_f32: Vec<f32>,
}

impl Agent {
    /// Wraps a policy after checking that it was trained for this robot's LIDAR.
    pub fn new(policy: Box<dyn PolicyBackend>, lidar: LidarSpec) -> Result<Agent, DecisionError> {
        check_policy(policy.as_ref(), &lidar)?;
        let cells = cells(&policy.occupancy_spec());
        Ok(Agent {
            policy,
            lidar,
            image: vec![0; cells],
            image_f32: vec![0.0; cells],
        })
    }

    /// Loads an ONNX model (validating its contract) and wraps it.
    pub fn from_model_path(path: &Path, lidar: LidarSpec) -> Result<Agent, DecisionError> {
        let policy = OnnxPolicy::load(path)?;
        Agent::new(Box::new(policy), lidar)
    }

    /// Renders this robot's occupancy image from its own scan.
    pub fn perceive(&mut self, scan: &[f32]) -> Result<(), DecisionError> {
        if scan.len() != self.lidar.beams {
            return Err(DecisionError::ScanLength {
                expected: self.lidar.beams,
                actual: scan.len(),
            });
        }
        let spec = self.policy.occupancy_spec();
        occupancy::render(scan, &self.lidar, &spec, &mut self.image);
        for (dst, &src) in self.image_f32.iter_mut().zip(&self.image) {
            *dst = f32::from(src);
        }
        Ok(())
    }

    /// Runs the policy on the last perceived image and scales its output to the goal's speed.
    pub fn decide(&mut self, heading: f64, goal: &Goal) -> Result<WheelCmd, DecisionError> {
        let aux = policy_aux(heading, goal)?;
        let [left, right] = self.policy.infer(&self.image_f32, aux)?;
        if !(left.is_finite() && right.is_finite()) {
            return Err(DecisionError::NonFinite {
                model: self.policy.model_id().to_owned(),
                left,
                right,
            });
        }
        let k = goal.v_star / self.policy.v_train();
        Ok(WheelCmd {
            left: k * f64::from(left),
            right: k * f64::from(right),
        })
    }

    /// The whole decision: [`Agent::perceive`] then [`Agent::decide`].
    pub fn act(
        &mut self,
        scan: &[f32],
        heading: f64,
        goal: &Goal,
    ) -> Result<WheelCmd, DecisionError> {
        self.perceive(scan)?;
        self.decide(heading, goal)
    }

    /// The occupancy image of the last [`Agent::perceive`] (u8 cells, row-major).
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    /// The id of the model now driving.
    pub fn model_id(&self) -> &str {
        self.policy.model_id()
    }

    /// Replaces the policy after validating the new one; on error the old policy keeps driving.
    pub fn swap_policy(&mut self, policy: Box<dyn PolicyBackend>) -> Result<(), DecisionError> {
        check_policy(policy.as_ref(), &self.lidar)?;
        let n = cells(&policy.occupancy_spec());
        self.image.resize(n, 0);
        self.image_f32.resize(n, 0.0);
        self.policy = policy;
        Ok(())
    }
}

/// The policy's auxiliary input `(delta_phi, d*)` for a robot with this heading and goal.
pub fn policy_aux(heading: f64, goal: &Goal) -> Result<[f32; 2], DecisionError> {
    if !(goal.d_star.is_finite() && goal.d_star > 0.0) {
        return Err(DecisionError::Goal {
            reason: format!("d* must be > 0, got {}", goal.d_star),
        });
    }
    if !(goal.phi_star.is_finite() && heading.is_finite() && goal.v_star.is_finite()) {
        return Err(DecisionError::Goal {
            reason: format!(
                "non-finite input (phi* {}, heading {}, v* {})",
                goal.phi_star, heading, goal.v_star
            ),
        });
    }
    Ok([
        wrap_angle(goal.phi_star - heading) as f32,
        goal.d_star as f32,
    ])
}

fn cells(spec: &OccupancySpec) -> usize {
    spec.size_px * spec.size_px
}

fn check_policy(policy: &dyn PolicyBackend, lidar: &LidarSpec) -> Result<(), DecisionError> {
    match policy.beams() {
        Some(beams) if beams != lidar.beams => Err(DecisionError::SensorMismatch {
            model: policy.model_id().to_owned(),
            expected: beams,
            actual: lidar.beams,
        }),
        _ => Ok(()),
    }
}

/// Runs one independent [`Agent`] per robot in-process. Robot `i`'s agent reads only
/// `obs.scans[i]`, `obs.poses[i].theta` and the goal.
pub struct PolicyController {
    agents: Vec<Agent>,
}

impl PolicyController {
    /// One agent per robot, in robot order.
    pub fn new(agents: Vec<Agent>) -> PolicyController {
        PolicyController { agents }
    }

    /// Loads `models[i]` for robot `i`.
    pub fn from_model_paths(
        models: &[&Path],
        lidar: LidarSpec,
    ) -> Result<PolicyController, DecisionError> {
        let agents = models
            .iter()
            .map(|m| Agent::from_model_path(m, lidar))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(PolicyController::new(agents))
    }

    /// The agents, in robot order.
    pub fn agents_mut(&mut self) -> &mut [Agent] {
        &mut self.agents
    }
}

impl Controller for PolicyController {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        if self.agents.len() != out.len() {
            return Err(ControllerError {
                message: format!(
                    "{} agents for {} robots: give one model per robot",
                    self.agents.len(),
                    out.len()
                ),
            });
        }
        for (i, (agent, cmd)) in self.agents.iter_mut().zip(out.iter_mut()).enumerate() {
            *cmd = agent
                .act(&obs.scans[i], obs.poses[i].theta, &obs.goal)
                .map_err(|e| ControllerError {
                    message: format!("robot {i}: {e}"),
                })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::BeyondWindow;

    /// A transparent policy for testing the decision's plumbing: returns the aux input and the
    /// number of occupied cells, so the test can see exactly what reached the policy.
    struct Probe {
        spec: OccupancySpec,
        seen: Option<([f32; 2], f32)>,
    }

    impl PolicyBackend for Probe {
        fn infer(&mut self, occupancy: &[f32], aux: [f32; 2]) -> Result<[f32; 2], DecisionError> {
            let occupied: f32 = occupancy.iter().sum();
            self.seen = Some((aux, occupied));
            Ok([aux[0], occupied])
        }
        fn occupancy_spec(&self) -> OccupancySpec {
            self.spec
        }
        fn beams(&self) -> Option<usize> {
            Some(900)
        }
        fn v_train(&self) -> f64 {
            0.5
        }
        fn model_id(&self) -> &str {
            "probe"
        }
    }

    fn probe() -> Box<Probe> {
        Box::new(Probe {
            spec: OccupancySpec {
                size_px: 50,
                resolution_m: 0.1,
                beyond: BeyondWindow::Drop,
            },
            seen: None,
        })
    }

    #[test]
    fn act_scales_by_v_star_over_v_train_and_feeds_wrapped_delta_phi() {
        let lidar = LidarSpec::default();
        let mut agent = Agent::new(probe(), lidar).expect("probe matches the sensor");
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[0] = 1.0; // one hit straight ahead
        let goal = Goal {
            phi_star: 3.0,
            d_star: 1.5,
            v_star: 0.7,
        };
        let cmd = agent.act(&scan, -3.0, &goal).expect("decides");
        let delta = wrap_angle(6.0);
        let k = 0.7 / 0.5;
        assert!((cmd.left - k * f64::from(delta as f32)).abs() < 1e-12);
        assert!(
            (cmd.right - k * 1.0).abs() < 1e-12,
            "exactly one occupied cell reached the policy"
        );
    }

    #[test]
    fn sensor_mismatch_and_bad_goal_are_refused() {
        let lidar = LidarSpec {
            beams: 360,
            ..LidarSpec::default()
        };
        assert!(matches!(
            Agent::new(probe(), lidar),
            Err(DecisionError::SensorMismatch { .. })
        ));
        let mut agent = Agent::new(probe(), LidarSpec::default()).expect("matches");
        let scan = vec![10.0; 900];
        let bad = Goal {
            phi_star: 0.0,
            d_star: 0.0,
            v_star: 0.7,
        };
        assert!(matches!(
            agent.act(&scan, 0.0, &bad),
            Err(DecisionError::Goal { .. })
        ));
        assert!(matches!(
            agent.act(&scan[..10], 0.0, &Goal { d_star: 1.0, ..bad }),
            Err(DecisionError::ScanLength {
                expected: 900,
                actual: 10
            })
        ));
    }
}
