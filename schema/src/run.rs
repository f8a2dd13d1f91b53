//! The run log (`runs/run-NNNN.json`) and what it embeds: a run's trajectory and its metrics.

use formation_proto::{NeighbourRule, Pose, WheelCmd};
use serde::{Deserialize, Serialize};

use crate::nan;

/// The record of one run.
///
/// `times`, `phi_star` and `poses` have `ticks + 1` entries: the state at `t = k dt`, `k = 0..=ticks`.
/// `commands` has `ticks` entries: the commands the world applied at tick `k` (after braking non-finite
/// commands, wheel saturation and any acceleration limit), which take the state from `k` to `k + 1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// Time step \[s\].
    pub dt: f64,
    /// Desired pairwise distance \[m\].
    pub d_star: f64,
    /// Desired speed \[m/s\].
    #[serde(deserialize_with = "nan::float")]
    pub v_star: f64,
    /// Formation edges: under [`NeighbourRule::AllPairs`] every pair, the edges the metrics
    /// score; under a rule whose edges change, the edges at the last sample (for drawing), the
    /// metrics recomputing them at every sample from `neighbours` and the poses.
    pub edges: Vec<(usize, usize)>,
    /// The neighbour rule of the run (schema version 2; files of version 1 read as all pairs).
    #[serde(default = "all_pairs")]
    pub neighbours: NeighbourRule,
    /// Sample times \[s\].
    #[serde(deserialize_with = "nan::floats")]
    pub times: Vec<f64>,
    /// Desired heading at each sample time \[rad\], not wrapped.
    #[serde(deserialize_with = "nan::floats")]
    pub phi_star: Vec<f64>,
    /// Poses of all robots at each sample time.
    #[serde(deserialize_with = "nan::pose_rows")]
    pub poses: Vec<Vec<Pose>>,
    /// Applied wheel commands of all robots at each tick.
    #[serde(deserialize_with = "nan::command_rows")]
    pub commands: Vec<Vec<WheelCmd>>,
    /// Robot-robot overlaps `(k, i, j)`, `i < j`, found in the state at sample `k` (so `k >= 1`), as the
    /// world reported them after each step.
    pub collisions: Vec<(u64, usize, usize)>,
}

fn all_pairs() -> NeighbourRule {
    NeighbourRule::AllPairs
}

impl Trajectory {
    /// Number of robots (of the first sample; 0 for none).
    pub fn n_robots(&self) -> usize {
        self.poses.first().map_or(0, Vec::len)
    }
}

/// The metrics of one run (computed by `formation_world::metrics::run_metrics`). A value that
/// could not be computed is NaN (`null` in the file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunMetrics {
    /// Success at the first tolerance (5 %).
    pub success_5: bool,
    /// Success at the second tolerance (10 %).
    pub success_10: bool,
    /// Convergence time \[s\] at the first tolerance.
    pub convergence_s_5: Option<f64>,
    /// Convergence time \[s\] at the second tolerance.
    pub convergence_s_10: Option<f64>,
    /// Mean over edges of each edge's mean relative error over the window.
    #[serde(deserialize_with = "nan::float")]
    pub rel_formation_error: f64,
    /// The largest of the edges' window means.
    #[serde(deserialize_with = "nan::float")]
    pub max_edge_window_error: f64,
    /// Mean over robots and window samples of the wrapped heading error \[rad\].
    #[serde(deserialize_with = "nan::float")]
    pub orientation_error_rad: f64,
    /// Number of collision events.
    pub collisions: usize,
    /// The team figures: present for runs whose edges follow a changing neighbour graph, and
    /// whenever the writer was asked for them; absent for the paper's all-pairs runs, whose
    /// metrics keep their original form.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub team: Option<TeamMetrics>,
    /// Set for a run that stopped before its last tick: how many ticks it played of how many it
    /// was to play. Such a run has no final window to judge, so it succeeds at no tolerance
    /// (neither the strict check nor the anchor-compatible one); its other figures are over the
    /// ticks it played. Absent for a complete run (files written before it existed read as
    /// complete; their run log's `complete` says otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub incomplete: Option<TicksPlayed>,
}

impl RunMetrics {
    /// Whether the run played every tick it was to play.
    pub fn is_complete(&self) -> bool {
        self.incomplete.is_none()
    }
}

/// How far a run that stopped early got.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TicksPlayed {
    /// Ticks it played.
    pub ticks: u64,
    /// Ticks it was to play.
    pub planned_ticks: u64,
}

/// What a team's run adds to the paper's metrics (computed by
/// `formation_world::metrics::run_metrics`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TeamMetrics {
    /// Whether the neighbour graph connected the whole team at every sample of the window.
    pub connected: bool,
    /// The pairs scored: those that were edges at some sample of the window.
    pub edges_scored: usize,
    /// Median over the scored edges of each edge's mean relative error over the samples of the
    /// window at which it was an edge.
    #[serde(deserialize_with = "nan::float")]
    pub median_edge_window_error: f64,
    /// Mean relative error over the edges of the last sample.
    #[serde(deserialize_with = "nan::float")]
    pub final_mean_edge_error: f64,
    /// Smallest distance \[m\] between two robots at the last sample.
    #[serde(deserialize_with = "nan::float")]
    pub final_min_distance: f64,
    /// The anchor-compatible check (Huang, Yang and Guo, ICRA 2026): the mean edge error at the
    /// last sample is at most 10 % and no two robots are closer than 0.2 m there.
    pub anchor_success: bool,
}

/// One run's log (`runs/run-NNNN.json`), written by the world process for `formation run` and
/// `formation eval --processes`, and by `formation eval --out` for in-process runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunLog {
    /// Run index within the scenario.
    pub index: usize,
    /// The paper's metrics of the run (over the ticks played, for an incomplete run).
    pub metrics: RunMetrics,
    /// The trajectory, exactly as the world recorded it.
    pub trajectory: Trajectory,
    /// How the run was clocked: `lockstep` or `realtime` (the multi-process runtime) or
    /// `in-process` (`formation eval` without `--processes`). Empty in logs `formation eval`
    /// wrote before run logs had one format.
    #[serde(default)]
    pub clock: String,
    /// The model each robot ran (the id its agent last reported); empty for the expert.
    #[serde(default)]
    pub models: Vec<String>,
    /// False when the run stopped before its last tick. Files written before this field existed
    /// read as complete.
    #[serde(default = "complete_by_default")]
    pub complete: bool,
    /// Why an incomplete run stopped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
    /// The ticks the run was to play, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub planned_ticks: Option<u64>,
}

fn complete_by_default() -> bool {
    true
}

impl RunLog {
    /// Reads a run log ([`read_run_log`](crate::read_run_log)).
    pub fn read(path: &std::path::Path) -> Result<RunLog, crate::SchemaError> {
        crate::read_run_log(path)
    }

    /// Ticks played (command rows recorded).
    pub fn ticks(&self) -> usize {
        self.trajectory.commands.len()
    }
}
