//! A share of an evaluation's runs (`formation eval --first-run A --runs N --shard FILE`), to be
//! merged with the other shares into the evaluation's summary (`formation merge`).
//!
//! A sweep that spreads an evaluation over several workers (a Ray cluster, say) has each worker
//! play a contiguous range of runs and write their per-run metrics here, with what the summary
//! names (controller, models, scenario, seed, team-size and v* notes, the models' declared inputs). Every run is a pure function of
//! (scenario, base seed, run index, driver), so the merged summary is the one a single
//! `formation eval` writes, byte for byte.

use serde::{Deserialize, Serialize};

use crate::{ModelGoalSpeed, ModelInput, ModelTeamSize, RunMetrics};

/// What `formation eval --shard` writes: runs `first_run .. first_run + per_run.len()` of an
/// evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalShard {
    /// `expert` or `policy`.
    pub controller: String,
    /// Model ids per robot (policy only).
    pub models: Vec<String>,
    /// Scenario name.
    pub scenario: String,
    /// Base seed.
    pub seed: u64,
    /// Policy only: the models' trained team sizes against this team's size, as the summary
    /// holds them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub team_size: Vec<ModelTeamSize>,
    /// Policy only: the models' trained v* against the runs' v*, as the summary holds them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub goal_speed: Vec<ModelGoalSpeed>,
    /// Policy only: the input each distinct model declares, as the summary holds it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_inputs: Vec<ModelInput>,
    /// Index of the first run this share played.
    pub first_run: usize,
    /// Per-run metrics of runs `first_run ..`, in run order.
    pub per_run: Vec<RunMetrics>,
}
