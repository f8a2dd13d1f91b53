//! The simulated world of formation, as a pure library.
//!
//! * [`robot`]: P3-DX-like differential-drive kinematics and wheel limits.
//! * [`lidar`]: the planar LIDAR ring, ray-cast against the other robots' bodies with parry2d.
//! * [`lidar_noise`]: the noise models the world adds to the ranges it casts, which no agent sees.
//! * [`grid`]: uniform grid hashing of the robots' positions, so that scans and collision tests look
//!   only at nearby robots.
//! * [`world`]: [`World`], which owns the robots' state and advances it by [`World::step`], taking the
//!   wheel commands and no clock, and doing no I/O.
//! * [`scenario`]: scenarios read from TOML (unknown keys are errors), heading schedules, seeded
//!   initial conditions, and the fully resolved [`RunSpec`] of one run.
//! * [`episode`]: the in-process loop of one run over a [`Controller`], producing a [`Trajectory`].
//! * [`reality`]: what makes a real robot differ from the ideal world (motor lag, noise and gains,
//!   LIDAR timing and geometry, compass error, command latency, per-robot spread), all off by default.
//! * [`neighbours`]: the formation's neighbour rule (all pairs, or the Gabriel rule each robot can
//!   apply from its own LIDAR), recomputed sample after sample.
//! * [`metrics`]: the paper's Table I and Fig. 9 metrics, made exact, over formation edges that may
//!   change from sample to sample.
//! * [`runlog`]: the run logs the multi-process runtime writes, and the run journal that keeps a
//!   run that ends abnormally.

pub mod episode;
pub mod grid;
pub mod lidar;
pub mod lidar_noise;
pub mod metrics;
pub mod neighbours;
pub mod reality;
pub mod robot;
pub mod runlog;
pub mod scenario;
mod seed_mix;
#[cfg(test)]
mod test_layouts;
#[cfg(test)]
mod test_scratch;
#[cfg(test)]
mod test_support;
pub mod world;

pub use episode::{
    Controller, Episode, EpisodeError, Observation, StepError, Trajectory, run_episode,
    run_episode_recorded,
};
pub use robot::RobotParams;
pub use runlog::{RunJournal, RunLog, TimingLog, recover_journal, recover_journals};
pub use scenario::{HeadingSchedule, RunSpec, Scenario};
pub use world::{StepReport, World, WorldConfig};
