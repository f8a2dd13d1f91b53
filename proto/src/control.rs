//! What a controller is: the seam between the episode loop and whatever decides the wheel
//! commands.
//!
//! [`Controller`] is implemented by the expert, by the in-process policy (one agent per robot), by
//! the multi-process runtime's world-side exchange, and by test doubles (a closure is one through
//! [`controller_fn`]); the world's episode loop (`formation_world::run_episode`) drives any of
//! them. It lives here, with the plain shared values, so that an agent or the runtime can name it
//! without depending on the world's physics.

use crate::{Goal, Pose, WheelCmd};

/// What a controller sees at one tick.
#[derive(Debug, Clone, Copy)]
pub struct Observation<'a> {
    /// Tick index `k`, starting at 0.
    pub tick: u64,
    /// Simulated time `k * dt` \[s\].
    pub time: f64,
    /// The goal at this instant.
    pub goal: Goal,
    /// Ground-truth poses of all robots. Decentralised controllers may read only `poses[i].theta`
    /// (the compass) for robot `i`.
    pub poses: &'a [Pose],
    /// Each robot's wheel speeds over the last step, as its wheel encoders measure them (a real
    /// robot's odometry; all zero before the first step, empty where the caller has none).
    /// Decentralised controllers may read only their own.
    pub wheel_speeds: &'a [WheelCmd],
    /// Each robot's LIDAR ranges this tick; `scans[i]` is robot `i`'s own scan.
    pub scans: &'a [Vec<f32>],
}

/// Chooses every robot's wheel command from an observation.
pub trait Controller {
    /// Writes one command per robot into `out` (len n_robots, pre-filled with [`WheelCmd::BRAKE`]).
    /// Decentralised controllers must read only `scans[i]` and `poses[i].theta` for robot i.
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError>;
}

/// A [`Controller`] that is a closure writing every robot's command, made by [`controller_fn`]:
/// a test double or a small tool without a type of its own.
pub struct ControllerFn<F>(F);

/// The [`Controller`] that hands each observation and the commands to write to `decide`.
pub fn controller_fn<F>(decide: F) -> ControllerFn<F>
where
    F: FnMut(&Observation<'_>, &mut [WheelCmd]) -> Result<(), ControllerError>,
{
    ControllerFn(decide)
}

impl<F> Controller for ControllerFn<F>
where
    F: FnMut(&Observation<'_>, &mut [WheelCmd]) -> Result<(), ControllerError>,
{
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        (self.0)(obs, out)
    }
}

/// A controller could not produce commands; the episode stops with this error.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct ControllerError {
    /// What went wrong, phrased for the user.
    pub message: String,
}

impl ControllerError {
    /// An error with this message.
    pub fn new(message: impl Into<String>) -> ControllerError {
        ControllerError {
            message: message.into(),
        }
    }
}
