//! Fixtures shared by the expert's unit tests.

use formation_proto::control::Observation;
use formation_proto::{Goal, Pose};

/// The goal of heading `phi_star` and distance `d_star` at the paper's speed, v* = 0.7 m/s.
pub(crate) fn goal(phi_star: f64, d_star: f64) -> Goal {
    Goal::new(phi_star, d_star, 0.7)
}

/// The observation of the first tick (tick 0 at time 0) of a team at `poses` with their `scans`
/// under `goal`, before any wheel has turned (no wheel speeds).
pub(crate) fn first_tick<'a>(
    goal: Goal,
    poses: &'a [Pose],
    scans: &'a [Vec<f32>],
) -> Observation<'a> {
    Observation {
        tick: 0,
        time: 0.0,
        goal,
        poses,
        wheel_speeds: &[],
        scans,
    }
}
