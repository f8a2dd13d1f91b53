//! The evaluation summary (`summary.json`, and what `formation eval --json` writes): Table I and
//! the Fig. 9 statistics over a set of runs, and the runs' metrics.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::RunMetrics;

/// Order statistics of a sample (computed by `formation_world::metrics::quantiles`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quantiles {
    /// Smallest value.
    pub min: f64,
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Largest value.
    pub max: f64,
    /// Number of values.
    pub count: usize,
}

/// Table I and Fig. 9 over a set of runs (computed by `formation_world::metrics::summarize`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of runs.
    pub runs: usize,
    /// How many of them stopped before their last tick: they count as runs, never as
    /// successes ([`RunMetrics::incomplete`]). Absent when every run finished.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub runs_incomplete: usize,
    /// Fraction (0..1) of runs that succeed at the first tolerance (5 %); 0 for no runs.
    pub success_rate_5: f64,
    /// Fraction (0..1) of runs that succeed at the second tolerance (10 %); 0 for no runs.
    pub success_rate_10: f64,
    /// Median convergence time \[s\] at 10 % over the runs that succeed at 10 % and converge
    /// ([`Summary::medians_over`] says how many that is).
    pub median_convergence_s: Option<f64>,
    /// Median relative formation error over the runs that succeed at 10 %.
    pub median_rel_formation_error: Option<f64>,
    /// Median orientation error \[rad\] over the runs that succeed at 10 %.
    pub median_orientation_error_rad: Option<f64>,
    /// Which runs each median above (and each set of quantiles below) covers, with the rule
    /// in words. Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medians_over: Option<MediansOver>,
    /// Number of runs with at least one collision.
    pub collisions: usize,
    /// Convergence time \[s\] at 10 % over the runs that succeed at 10 % and converge (a run can succeed
    /// on the window mean without its maximum error staying below 10 % to the end).
    pub convergence_s: Option<Quantiles>,
    /// Relative formation error over the runs that succeed at 10 %.
    pub rel_formation_error: Option<Quantiles>,
    /// Orientation error \[rad\] over the runs that succeed at 10 %.
    pub orientation_error_rad: Option<Quantiles>,
    /// Fraction (0..1) of runs that pass the anchor-compatible check ([`crate::TeamMetrics`]);
    /// present when every run has team figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchor_success_rate: Option<f64>,
    /// Fraction (0..1) of runs whose neighbour graph stayed connected over the window; present
    /// when every run has team figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connected_rate: Option<f64>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The runs each Fig. 9 median covers (computed by `formation_world::metrics::summarize`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MediansOver {
    /// The convergence time's: the runs successful at 10 % that converged.
    pub convergence_s: Coverage,
    /// The relative formation error's: the runs successful at 10 %.
    pub rel_formation_error: Coverage,
    /// The orientation error's: the runs successful at 10 %.
    pub orientation_error_rad: Coverage,
}

/// Which runs one median covers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// The rule, in words (`"runs successful at 10 % that converged"`).
    pub rule: String,
    /// How many runs it covers.
    pub runs: usize,
    /// Of how many runs successful at 10 % (those it leaves out are `of - runs`).
    pub of: usize,
}

/// What `formation eval` writes as JSON (`--json`, and `summary.json` under `--out`), and what
/// `formation run` writes as `summary.json`: the Table I keys at the top level, Fig. 9 quantiles
/// and the per-run metrics. Nothing in it depends on wall-clock time or on the execution mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalOutput {
    /// `expert` or `policy`.
    pub controller: String,
    /// Model ids per robot (policy only).
    pub models: Vec<String>,
    /// Scenario name (empty when unknown: runs recovered after their launcher was killed).
    pub scenario: String,
    /// Base seed; absent when unknown (runs recovered after their launcher was killed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Table I and Fig. 9 figures.
    #[serde(flatten)]
    pub summary: Summary,
    /// Per-run metrics, in run order.
    pub per_run: Vec<RunMetrics>,
    /// Multi-process runs only: per robot, the ticks its watchdog braked, by reason (`missing`,
    /// `stale`, `non_finite`, `agent_failed`, `agent_down`: no agent was ready to drive it, as
    /// `TickOutcome::name` spells them); an empty map for a robot never braked.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub braked_ticks: Vec<BTreeMap<String, usize>>,
    /// Runs that stopped before their last tick (a `formation run` that ended abnormally), in
    /// run order; their metrics above are over the ticks they played. Absent when every run
    /// finished.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub incomplete_runs: Vec<IncompleteRun>,
    /// Policy only: each distinct model that records its trained team sizes, against this
    /// team's size; `zero_shot` marks a size it never saw. Absent when no model records them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub team_size: Vec<crate::ModelTeamSize>,
    /// Policy only: each distinct model whose trained v* (`formation.v_train`) differs from the
    /// runs' v*, against it. Absent when every model was trained at this v*, and in files
    /// written before it existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub goal_speed: Vec<crate::ModelGoalSpeed>,
    /// Policy only: the input each distinct model declares in its metadata (its occupancy
    /// window and the LIDAR it was trained for), in first-use order. Absent for the expert and
    /// in files written before it existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub model_inputs: Vec<crate::ModelInput>,
    /// `formation eval --out`: the runs whose run logs (`runs/run-NNNN.json`) belong beside this
    /// summary, in run order. A reader that misses one of them has a partial output (the eval
    /// failed while writing it, say on a full disk) and says so. Absent when no run log was
    /// written, and in files written before it existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub run_logs: Vec<usize>,
    /// `formation eval --out`: false when the eval could not write every file of its output;
    /// `run_logs` then says which run logs belong here. Absent (true) for a whole output.
    #[serde(default = "whole", skip_serializing_if = "is_whole")]
    pub complete: bool,
}

impl EvalOutput {
    /// A whole output over `per_run` with nothing beside the runs: no braked ticks, no
    /// incomplete runs, no model notes and no run logs. The writers that know more fill the
    /// optional fields in afterwards.
    pub fn of_runs(
        controller: impl Into<String>,
        models: Vec<String>,
        scenario: impl Into<String>,
        seed: Option<u64>,
        summary: Summary,
        per_run: Vec<RunMetrics>,
    ) -> Self {
        Self {
            controller: controller.into(),
            models,
            scenario: scenario.into(),
            seed,
            summary,
            per_run,
            braked_ticks: Vec::new(),
            incomplete_runs: Vec::new(),
            team_size: Vec::new(),
            goal_speed: Vec::new(),
            model_inputs: Vec::new(),
            run_logs: Vec::new(),
            complete: true,
        }
    }
}

fn whole() -> bool {
    true
}

fn is_whole(complete: &bool) -> bool {
    *complete
}

/// A run that stopped before its last tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IncompleteRun {
    /// Run index.
    pub index: usize,
    /// Ticks it played.
    pub ticks: usize,
    /// Ticks it was to play, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub planned_ticks: Option<u64>,
    /// Why it stopped, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
}
