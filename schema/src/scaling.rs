//! The scaling table (`formation eval --robots 3,5,8 --json`): Table I figures per team size and
//! controller.

use serde::{Deserialize, Serialize};

use crate::Quantiles;

/// One controller on one team size.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScalingRow {
    /// `expert` or `policy`.
    pub controller: String,
    /// The model id (policy only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Team size.
    pub robots: usize,
    /// The neighbour rule's name (`all_pairs`, `gabriel`).
    pub neighbours: String,
    /// Number of runs.
    pub runs: usize,
    /// Fraction (0..1) of runs that succeed at 5 % (the strict check: every edge, a connected
    /// graph, no collision; the paper's check for all pairs).
    pub success_rate_5: f64,
    /// The same at 10 %.
    pub success_rate_10: f64,
    /// Fraction (0..1) of runs that pass the anchor-compatible check.
    pub anchor_success_rate: f64,
    /// Convergence time \[s\] at 10 % over the runs that succeed at 10 % and converge.
    pub convergence_s: Option<Quantiles>,
    /// Relative formation error (mean over edges) over the runs that succeed at 10 %.
    pub rel_formation_error: Option<Quantiles>,
    /// The largest edge's window error, over all runs.
    pub max_edge_window_error: Option<Quantiles>,
    /// Number of runs with at least one collision.
    pub collisions: usize,
    /// Policy only: this team size against the model's trained team sizes (absent when the
    /// model records none); `zero_shot` marks a size it never saw.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub team_size: Option<crate::ModelTeamSize>,
    /// Policy only: the runs' v* against the model's trained v*, when they differ. Absent at
    /// the trained v*, and in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_speed: Option<crate::ModelGoalSpeed>,
    /// Policy only: the input the model declares (its occupancy window and LIDAR). Absent for
    /// the expert and in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_input: Option<crate::ModelInput>,
}

/// What `formation eval --robots` writes as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScalingTable {
    /// The scenario every team size was derived from.
    pub scenario: String,
    /// Base seed of every team size's runs.
    pub seed: u64,
    /// Simulated seconds per run.
    pub duration_s: f64,
    /// One row per controller and team size, in the order asked.
    pub rows: Vec<ScalingRow>,
}
