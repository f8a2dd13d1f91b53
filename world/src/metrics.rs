//! The paper's evaluation metrics (Table I and Fig. 9), made exact, over a set of formation edges.
//!
//! Definitions, for a [`Trajectory`] with samples `t_0 .. t_K` (the state at every tick) and edges `(i, j)`:
//!
//! * relative formation error of an edge: `e_ij(t) = |d_ij(t) - d*| / d*`, `d_ij` the distance between the
//!   two robots' positions;
//! * the evaluation window: the samples with `t >= t_K - window_s` (20 s in the paper), the bound taken with
//!   a tolerance of `1e-6 dt` so that the sample at exactly `t_K - window_s` is in whatever the rounding of
//!   `k dt`; a run shorter than the window is scored over all its samples;
//! * success at tolerance `tau`: for EVERY edge, the mean of `e_ij` over the window is `< tau`;
//! * convergence time at `tau`: the first sample time `t_k` such that `max_ij e_ij(t_m) < tau` for every
//!   `m >= k`; `None` when the last sample is not below `tau`;
//! * relative formation error of a run: the mean over edges of the window means; the largest window mean
//!   is reported too;
//! * orientation error: the mean over robots and window samples of `|wrap(theta_i(t) - phi*(t))|`;
//! * collisions: the number of collision events, an event being a pair that overlaps at a sample and did
//!   not at the previous sample (so a lasting contact counts once).
//!
//! A trajectory with no edges succeeds trivially (there is no pair to fail) with zero formation error.
//! Malformed trajectories (read back from a file) do not panic: a value that cannot be computed (an edge
//! naming a robot missing from a sample, no samples at all) is NaN, and NaN never passes a tolerance.
//!
//! [`summarize`] aggregates runs as Table I and Fig. 9 do.

use std::collections::HashSet;

use formation_proto::wrap_angle;
use serde::{Deserialize, Serialize};

use crate::episode::Trajectory;

/// Settings of [`run_metrics`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MetricsConfig {
    /// Length [s] of the final window the success test and the error means use (the paper's 20 s).
    pub window_s: f64,
    /// The two tolerances on the relative formation error (the paper's 5 % and 10 %), reported as
    /// `*_5` and `*_10`.
    pub tolerances: (f64, f64),
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig { window_s: 20.0, tolerances: (0.05, 0.10) }
    }
}

/// The metrics of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunMetrics {
    /// Success at the first tolerance (5 %).
    pub success_5: bool,
    /// Success at the second tolerance (10 %).
    pub success_10: bool,
    /// Convergence time [s] at the first tolerance.
    pub convergence_s_5: Option<f64>,
    /// Convergence time [s] at the second tolerance.
    pub convergence_s_10: Option<f64>,
    /// Mean over edges of each edge's mean relative error over the window.
    pub rel_formation_error: f64,
    /// The largest of the edges' window means.
    pub max_edge_window_error: f64,
    /// Mean over robots and window samples of the wrapped heading error [rad].
    pub orientation_error_rad: f64,
    /// Number of collision events.
    pub collisions: usize,
}

/// Scores one run.
pub fn run_metrics(traj: &Trajectory, cfg: &MetricsConfig) -> RunMetrics {
    let samples = traj.times.len().min(traj.poses.len());
    let window = window_start(&traj.times[..samples], traj.dt, cfg.window_s)..samples;

    // errors[k][e]: relative error of edge e at sample k.
    let errors: Vec<Vec<f64>> = traj.poses[..samples]
        .iter()
        .map(|poses| {
            traj.edges
                .iter()
                .map(|&(i, j)| match (poses.get(i), poses.get(j)) {
                    (Some(a), Some(b)) => ((a.x - b.x).hypot(a.y - b.y) - traj.d_star).abs() / traj.d_star,
                    _ => f64::NAN,
                })
                .collect()
        })
        .collect();

    let edge_window_means: Vec<f64> = (0..traj.edges.len())
        .map(|e| mean(errors[window.clone()].iter().map(|row| row[e])))
        .collect();
    let passes = |tolerance: f64| edge_window_means.iter().all(|&m| m < tolerance) && !window.is_empty();
    let (rel_formation_error, max_edge_window_error) = if traj.edges.is_empty() {
        (0.0, 0.0)
    } else {
        (mean(edge_window_means.iter().copied()), max_propagating_nan(edge_window_means.iter().copied()))
    };

    let max_error_per_sample: Vec<f64> =
        errors.iter().map(|row| max_propagating_nan(row.iter().copied())).collect();
    let convergence = |tolerance: f64| convergence_time(&traj.times[..samples], &max_error_per_sample, tolerance);

    let orientation_error_rad = mean(window.clone().flat_map(|k| {
        let phi_star = traj.phi_star.get(k).copied().unwrap_or(f64::NAN);
        traj.poses[k].iter().map(move |pose| wrap_angle(pose.theta - phi_star).abs())
    }));

    let (tol_5, tol_10) = cfg.tolerances;
    RunMetrics {
        success_5: passes(tol_5),
        success_10: passes(tol_10),
        convergence_s_5: convergence(tol_5),
        convergence_s_10: convergence(tol_10),
        rel_formation_error,
        max_edge_window_error,
        orientation_error_rad,
        collisions: collision_events(&traj.collisions),
    }
}

/// Index of the first sample inside the final window of `window_s` seconds.
fn window_start(times: &[f64], dt: f64, window_s: f64) -> usize {
    let Some(&end) = times.last() else { return 0 };
    let slack = if dt.is_finite() { dt.abs() * 1e-6 } else { 0.0 };
    let bound = end - window_s - slack;
    times.iter().position(|&t| t >= bound).unwrap_or(0)
}

/// First time after which every `max_error` stays below `tolerance`; `None` if the last one is not.
fn convergence_time(times: &[f64], max_error: &[f64], tolerance: f64) -> Option<f64> {
    let below = |e: f64| e < tolerance;
    match max_error.iter().rposition(|&e| !below(e)) {
        None => times.first().copied(),
        Some(last_bad) => times.get(last_bad + 1).copied(),
    }
}

/// Overlap onsets: a pair counts at sample `k` when it did not overlap at sample `k - 1`.
fn collision_events(collisions: &[(u64, usize, usize)]) -> usize {
    let overlapping: HashSet<(u64, usize, usize)> = collisions.iter().copied().collect();
    overlapping
        .iter()
        .filter(|&&(k, i, j)| k == 0 || !overlapping.contains(&(k - 1, i, j)))
        .count()
}

/// Arithmetic mean; NaN for no values.
fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0_usize), |(sum, count), v| (sum + v, count + 1));
    if count == 0 { f64::NAN } else { sum / count as f64 }
}

/// Maximum that returns NaN if any value is NaN (and for no values, `-inf`).
fn max_propagating_nan(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(f64::NEG_INFINITY, |acc, v| if acc.is_nan() || v.is_nan() { f64::NAN } else { acc.max(v) })
}

/// Order statistics of a sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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

impl Quantiles {
    /// Quartiles of the finite values in `values`, `None` if there are none.
    ///
    /// The `p`-quantile of the sorted values `x_0 <= .. <= x_{n-1}` interpolates linearly between order
    /// statistics at the fractional index `h = (n - 1) p`: `x_floor(h) + (h - floor(h)) (x_floor(h)+1 -
    /// x_floor(h))` (Hyndman & Fan type 7, the default of R and NumPy).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Quantiles> {
        let mut sorted: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
        if sorted.is_empty() {
            return None;
        }
        sorted.sort_by(f64::total_cmp);
        Some(Quantiles {
            min: sorted[0],
            q1: quantile_sorted(&sorted, 0.25),
            median: quantile_sorted(&sorted, 0.5),
            q3: quantile_sorted(&sorted, 0.75),
            max: sorted[sorted.len() - 1],
            count: sorted.len(),
        })
    }
}

/// Type-7 quantile of non-empty sorted values.
fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let lower = h.floor() as usize;
    let upper = (lower + 1).min(sorted.len() - 1);
    sorted[lower] + (h - lower as f64) * (sorted[upper] - sorted[lower])
}

/// Table I and Fig. 9 over a set of runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of runs.
    pub runs: usize,
    /// Fraction (0..1) of runs that succeed at the first tolerance (5 %); 0 for no runs.
    pub success_rate_5: f64,
    /// Fraction (0..1) of runs that succeed at the second tolerance (10 %); 0 for no runs.
    pub success_rate_10: f64,
    /// Median convergence time [s] at 10 % over the runs that succeed at 10 %.
    pub median_convergence_s: Option<f64>,
    /// Median relative formation error over the runs that succeed at 10 %.
    pub median_rel_formation_error: Option<f64>,
    /// Median orientation error [rad] over the runs that succeed at 10 %.
    pub median_orientation_error_rad: Option<f64>,
    /// Number of runs with at least one collision.
    pub collisions: usize,
    /// Convergence time [s] at 10 % over the runs that succeed at 10 % and converge (a run can succeed
    /// on the window mean without its maximum error staying below 10 % to the end).
    pub convergence_s: Option<Quantiles>,
    /// Relative formation error over the runs that succeed at 10 %.
    pub rel_formation_error: Option<Quantiles>,
    /// Orientation error [rad] over the runs that succeed at 10 %.
    pub orientation_error_rad: Option<Quantiles>,
}

/// Aggregates runs: success rates over all runs, Fig. 9 statistics over the runs that succeed at 10 %.
pub fn summarize(runs: &[RunMetrics]) -> Summary {
    let fraction = |count: usize| if runs.is_empty() { 0.0 } else { count as f64 / runs.len() as f64 };
    let successful: Vec<&RunMetrics> = runs.iter().filter(|r| r.success_10).collect();
    let convergence_s = Quantiles::of(successful.iter().filter_map(|r| r.convergence_s_10));
    let rel_formation_error = Quantiles::of(successful.iter().map(|r| r.rel_formation_error));
    let orientation_error_rad = Quantiles::of(successful.iter().map(|r| r.orientation_error_rad));
    Summary {
        runs: runs.len(),
        success_rate_5: fraction(runs.iter().filter(|r| r.success_5).count()),
        success_rate_10: fraction(successful.len()),
        median_convergence_s: convergence_s.as_ref().map(|q| q.median),
        median_rel_formation_error: rel_formation_error.as_ref().map(|q| q.median),
        median_orientation_error_rad: orientation_error_rad.as_ref().map(|q| q.median),
        collisions: runs.iter().filter(|r| r.collisions > 0).count(),
        convergence_s,
        rel_formation_error,
        orientation_error_rad,
    }
}
