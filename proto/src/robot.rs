//! One robot's decision: what it is given ([`RobotInput`]: its own scan, its own heading and the
//! goal) and the one trait that decides from it ([`Pilot`]), with [`PilotMaker`], which loads
//! models and makes pilots of them.
//!
//! Decentralisation is a type here: a [`Pilot`] is handed one robot's [`RobotInput`] and nothing
//! else. The world's episode loop drives a [`Controller`], which sees every pose; the only
//! controllers that read them are the expert and the world side of the runtime (which forwards to
//! each robot its own). A learned team is [`Decentralised`]: a [`Controller`] that splits each
//! observation into one [`RobotInput`] per robot.
//!
//! The same [`Pilot`] runs in-process ([`Decentralised`]), in the agent process (the runtime's
//! agent loop), in a ROS 2 agent and in replay. A goal is checked where it enters a robot
//! ([`CheckedGoal`]), once, and held until the next.

use std::path::Path;

use crate::control::{Controller, ControllerError, Observation};
use crate::types::{Goal, LidarSpec, WheelCmd, WheelLimits};

/// Any error a pilot or a model loader gives; its chain of sources is kept and shown.
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a goal cannot be acted on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GoalError {
    /// d* is not a positive finite distance.
    #[error("d* must be > 0, got {d_star}")]
    DStar {
        /// The goal's d* \[m\].
        d_star: f64,
    },
    /// phi* or v* is NaN or infinite.
    #[error("non-finite goal (phi* {phi_star}, v* {v_star})")]
    NonFinite {
        /// The goal's phi* \[rad\].
        phi_star: f64,
        /// The goal's v* \[m/s\].
        v_star: f64,
    },
}

/// A goal checked where it entered a robot: d* a positive finite distance, phi* and v* finite.
/// Whoever holds one need not check it again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedGoal(Goal);

impl CheckedGoal {
    /// Checks `goal`.
    pub fn new(goal: Goal) -> Result<CheckedGoal, GoalError> {
        if !(goal.d_star.is_finite() && goal.d_star > 0.0) {
            return Err(GoalError::DStar {
                d_star: goal.d_star,
            });
        }
        if !(goal.phi_star.is_finite() && goal.v_star.is_finite()) {
            return Err(GoalError::NonFinite {
                phi_star: goal.phi_star,
                v_star: goal.v_star,
            });
        }
        Ok(CheckedGoal(goal))
    }

    /// The goal.
    pub fn goal(&self) -> &Goal {
        &self.0
    }
}

/// What one robot is given at one tick, and all it is given: its own LIDAR scan, its own compass
/// heading and the goal every robot shares.
#[derive(Debug, Clone, Copy)]
pub struct RobotInput<'a> {
    /// The robot's own ranges, one a beam.
    pub scan: &'a [f32],
    /// The robot's own compass heading \[rad\].
    pub heading: f64,
    /// The goal.
    pub goal: &'a Goal,
}

/// One robot's decision maker: from its own [`RobotInput`] to its wheel command.
pub trait Pilot {
    /// The model it runs (loaded off the hot path for a swap).
    type Model: Send + 'static;
    /// The id of the model now driving (logged with every command).
    fn model_id(&self) -> &str;
    /// Takes in this robot's own scan under the goal it holds (whose d* sizes the window of a
    /// model that scales with d*), checking the goal where it enters ([`CheckedGoal`]).
    fn perceive(&mut self, ranges: &[f32], goal: &Goal) -> Result<(), BoxError>;
    /// Decides the wheel command from the last perceived scan, the own heading and the goal.
    fn decide(&mut self, heading: f64, goal: &Goal) -> Result<WheelCmd, BoxError>;
    /// The whole decision on one robot's input: [`Pilot::perceive`] then [`Pilot::decide`].
    fn act(&mut self, input: &RobotInput<'_>) -> Result<WheelCmd, BoxError> {
        self.perceive(input.scan, input.goal)?;
        self.decide(input.heading, input.goal)
    }
    /// Puts another model in place after validating it; on error the old one keeps driving.
    fn swap(&mut self, model: Self::Model) -> Result<(), BoxError>;
    /// Sets the robot's wheel limits for the episode beginning, within which a policy's
    /// formation velocity is turned into wheel speeds (its acceleration limit shapes it).
    fn set_wheel_limits(&mut self, wheels: WheelLimits);
    /// Runs the last decision again, changing nothing and answering nothing, to warm the caches
    /// before the next scan is due. By default a no-op.
    fn rehearse(&mut self) -> Result<(), BoxError> {
        Ok(())
    }
}

/// Loads models and makes pilots of them for a robot's sensor.
pub trait PilotMaker: Send + Sync + 'static {
    /// The model type.
    type Model: Send + 'static;
    /// The pilot type.
    type Pilot: Pilot<Model = Self::Model>;
    /// Loads and validates the model at `path` (runs on a helper thread for swaps).
    fn load(&self, path: &Path) -> Result<Self::Model, BoxError>;
    /// The id of a loaded model.
    fn model_id<'m>(&self, model: &'m Self::Model) -> &'m str;
    /// A pilot running `model` on a robot with this LIDAR; refuses a model made for another
    /// sensor.
    fn pilot(&self, model: Self::Model, lidar: LidarSpec) -> Result<Self::Pilot, BoxError>;
}

/// A team of independent pilots in one process, one a robot: the [`Controller`] that hands robot
/// `i` its own [`RobotInput`] (`scans[i]`, `poses[i].theta`, the goal) and nothing else.
pub struct Decentralised<P> {
    pilots: Vec<P>,
}

impl<P: Pilot> Decentralised<P> {
    /// One pilot per robot, in robot order.
    pub fn new(pilots: Vec<P>) -> Decentralised<P> {
        Decentralised { pilots }
    }

    /// The pilots, in robot order.
    pub fn pilots_mut(&mut self) -> &mut [P] {
        &mut self.pilots
    }

    /// Robot `i`'s input in `obs`: all a decentralised robot is given.
    pub fn input<'a>(obs: &'a Observation<'_>, i: usize) -> RobotInput<'a> {
        RobotInput {
            scan: &obs.scans[i],
            heading: obs.poses[i].theta,
            goal: &obs.goal,
        }
    }
}

impl<P: Pilot> Controller for Decentralised<P> {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        if self.pilots.len() != out.len() {
            return Err(ControllerError::new(format!(
                "{} agents for {} robots: give one model per robot",
                self.pilots.len(),
                out.len()
            )));
        }
        for (i, (pilot, cmd)) in self.pilots.iter_mut().zip(out.iter_mut()).enumerate() {
            *cmd = pilot
                .act(&Self::input(obs, i))
                .map_err(|e| ControllerError::new(format!("robot {i}: {e}")))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Pose;

    #[test]
    fn a_goal_is_checked_once_where_it_enters() {
        let goal = |d_star, v_star| Goal {
            phi_star: 0.0,
            d_star,
            v_star,
        };
        assert_eq!(CheckedGoal::new(goal(1.5, 0.7)).unwrap().goal().d_star, 1.5);
        assert_eq!(
            CheckedGoal::new(goal(0.0, 0.7)).unwrap_err().to_string(),
            "d* must be > 0, got 0"
        );
        assert!(matches!(
            CheckedGoal::new(goal(1.0, f64::NAN)),
            Err(GoalError::NonFinite { .. })
        ));
    }

    /// Answers its own scan's first range and its heading: what it was handed.
    struct Echo;

    impl Pilot for Echo {
        type Model = ();
        fn model_id(&self) -> &str {
            "echo"
        }
        fn perceive(&mut self, _ranges: &[f32], _goal: &Goal) -> Result<(), BoxError> {
            Ok(())
        }
        fn decide(&mut self, _heading: f64, _goal: &Goal) -> Result<WheelCmd, BoxError> {
            Ok(WheelCmd::BRAKE)
        }
        fn act(&mut self, input: &RobotInput<'_>) -> Result<WheelCmd, BoxError> {
            Ok(WheelCmd {
                left: f64::from(input.scan[0]),
                right: input.heading,
            })
        }
        fn swap(&mut self, _model: ()) -> Result<(), BoxError> {
            Ok(())
        }
        fn set_wheel_limits(&mut self, _wheels: WheelLimits) {}
    }

    #[test]
    fn each_robot_of_a_decentralised_team_is_handed_its_own_input_only() {
        let poses = [Pose::new(5.0, 5.0, 0.25), Pose::new(-5.0, 1.0, -1.0)];
        let scans = [vec![1.0_f32], vec![2.0_f32]];
        let obs = Observation {
            tick: 0,
            time: 0.0,
            goal: Goal {
                phi_star: 0.0,
                d_star: 1.0,
                v_star: 0.5,
            },
            poses: &poses,
            wheel_speeds: &[],
            scans: &scans,
        };
        let mut team = Decentralised::new(vec![Echo, Echo]);
        let mut out = [WheelCmd::BRAKE; 2];
        team.commands(&obs, &mut out).unwrap();
        assert_eq!(
            out,
            [
                WheelCmd {
                    left: 1.0,
                    right: 0.25
                },
                WheelCmd {
                    left: 2.0,
                    right: -1.0
                }
            ]
        );
        let mut three = [WheelCmd::BRAKE; 3];
        assert_eq!(
            team.commands(&obs, &mut three).unwrap_err().to_string(),
            "2 agents for 3 robots: give one model per robot"
        );
    }
}
