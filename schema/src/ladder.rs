//! The reality ladder (`formation eval --ladder PROFILE --json`): the Table I figures of each
//! controller and team size as a robot profile's effects are added one at a time.

use serde::{Deserialize, Serialize};

use crate::ScalingRow;

/// One rung: the scenario with the profile's effects up to this one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LadderRung {
    /// The effect this rung adds (`ideal` for the base scenario).
    pub rung: String,
    /// The scenario keys this rung adds to the previous one's (dotted, e.g. `robot.motor_tau`).
    pub added: Vec<String>,
    /// One row per team size and controller (the expert first), as in the scaling table.
    pub rows: Vec<ScalingRow>,
    /// Why the policy has no rows on this rung (it cannot drive the rung's robot, e.g. a LIDAR
    /// it was not trained on); absent when it has them or was not asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy_refused: Option<String>,
}

/// What `formation eval --ladder PROFILE --json` writes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LadderTable {
    /// The robot profile whose effects the rungs add (`turtlebot3-burger`).
    pub profile: String,
    /// The base scenario every rung was derived from.
    pub scenario: String,
    /// Base seed of every rung's runs.
    pub seed: u64,
    /// Simulated seconds per run.
    pub duration_s: f64,
    /// The rungs, in the order their effects were added.
    pub rungs: Vec<LadderRung>,
}
