//! The in-process loop of one run: sense, decide, step, record.
//!
//! [`run_episode`] drives a [`World`](crate::World) built from a [`RunSpec`] with any [`Controller`]
//! (the expert, the learned policy run per robot, a test double) and records a [`Trajectory`] that the
//! [`metrics`](crate::metrics) score. Every robot's scan is taken at every tick whatever the controller,
//! so the world's noise generator is consumed in the same order by every controller and a run with the
//! expert and one with a policy see the same noise for the same states. The multi-process lockstep runtime
//! calls the same world methods in the same order, which is what makes it bit-identical to this loop.

use formation_proto::{Goal, Pose, WheelCmd};
use serde::{Deserialize, Serialize};

use crate::scenario::RunSpec;

/// What a controller sees at one tick.
#[derive(Debug, Clone, Copy)]
pub struct Observation<'a> {
    /// Tick index `k`, starting at 0.
    pub tick: u64,
    /// Simulated time `k * dt` [s].
    pub time: f64,
    /// The goal at this instant.
    pub goal: Goal,
    /// Ground-truth poses of all robots. Decentralised controllers may read only `poses[i].theta`
    /// (the compass) for robot `i`.
    pub poses: &'a [Pose],
    /// Each robot's LIDAR ranges this tick; `scans[i]` is robot `i`'s own scan.
    pub scans: &'a [Vec<f32>],
}

/// Chooses every robot's wheel command from an observation.
pub trait Controller {
    /// Writes one command per robot into `out` (len n_robots, pre-filled with [`WheelCmd::BRAKE`]).
    /// Decentralised controllers must read only `scans[i]` and `poses[i].theta` for robot i.
    fn commands(&mut self, obs: &Observation<'_>, out: &mut [WheelCmd]) -> Result<(), ControllerError>;
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
        ControllerError { message: message.into() }
    }
}

/// The record of one run.
///
/// `times`, `phi_star` and `poses` have `ticks + 1` entries: the state at `t = k dt`, `k = 0..=ticks`.
/// `commands` has `ticks` entries: the commands the world applied at tick `k` (after braking non-finite
/// commands, wheel saturation and any acceleration limit), which take the state from `k` to `k + 1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// Time step [s].
    pub dt: f64,
    /// Desired pairwise distance [m].
    pub d_star: f64,
    /// Desired speed [m/s].
    pub v_star: f64,
    /// Formation edges the metrics score.
    pub edges: Vec<(usize, usize)>,
    /// Sample times [s].
    pub times: Vec<f64>,
    /// Desired heading at each sample time [rad], not wrapped.
    pub phi_star: Vec<f64>,
    /// Poses of all robots at each sample time.
    pub poses: Vec<Vec<Pose>>,
    /// Applied wheel commands of all robots at each tick.
    pub commands: Vec<Vec<WheelCmd>>,
    /// Robot-robot overlaps `(k, i, j)`, `i < j`, found in the state at sample `k` (so `k >= 1`), as the
    /// world reported them after each step.
    pub collisions: Vec<(u64, usize, usize)>,
}

/// Runs `spec` to the end with `controller`.
///
/// Per tick `k` in `0..ticks`: goal = `spec.goal_at(t_k)`; every robot's scan; `controller.commands`;
/// `on_tick(observation, commands)` (used by DAgger and data collection to record samples); `World::step`;
/// record. Stops at the first controller error.
pub fn run_episode(
    spec: &RunSpec,
    controller: &mut dyn Controller,
    on_tick: &mut dyn FnMut(&Observation<'_>, &[WheelCmd]),
) -> Result<Trajectory, ControllerError> {
    let mut world = spec.make_world();
    let n_robots = world.n_robots();
    let ticks = spec.ticks();
    let samples = usize::try_from(ticks).map_or(usize::MAX, |t| t.saturating_add(1));
    let capacity = samples.min(1 << 20);

    let mut trajectory = Trajectory {
        dt: spec.world.dt,
        d_star: spec.d_star,
        v_star: spec.v_star,
        edges: spec.edges.clone(),
        times: Vec::with_capacity(capacity),
        phi_star: Vec::with_capacity(capacity),
        poses: Vec::with_capacity(capacity),
        commands: Vec::with_capacity(capacity),
        collisions: Vec::new(),
    };
    let mut record_state = |trajectory: &mut Trajectory, time: f64, poses: &[Pose]| {
        trajectory.times.push(time);
        trajectory.phi_star.push(spec.heading.phi_star(time));
        trajectory.poses.push(poses.to_vec());
    };
    record_state(&mut trajectory, world.time(), world.poses());

    let mut scans = vec![vec![0.0_f32; spec.world.lidar.beams]; n_robots];
    let mut commands = vec![WheelCmd::BRAKE; n_robots];
    for _ in 0..ticks {
        let tick = world.tick();
        let time = world.time();
        world.scan_all(&mut scans);
        commands.fill(WheelCmd::BRAKE);
        let observation =
            Observation { tick, time, goal: spec.goal_at(time), poses: world.poses(), scans: &scans };
        controller.commands(&observation, &mut commands)?;
        on_tick(&observation, &commands);

        let report = world.step(&commands);
        trajectory.commands.push(report.applied);
        let sample = world.tick();
        trajectory.collisions.extend(report.collisions.into_iter().map(|(i, j)| (sample, i, j)));
        record_state(&mut trajectory, world.time(), world.poses());
    }
    Ok(trajectory)
}
