//! The paper's evaluation metrics (Table I and Fig. 9), made exact, over formation edges that may
//! change from sample to sample.
//!
//! Definitions, for a [`Trajectory`] with samples `t_0 .. t_K` (the state at every tick) and edges `(i, j)`.
//! Under [`NeighbourRule::AllPairs`] the edges are the trajectory's `edges` at every sample (the paper's
//! three robots: every pair); under a rule whose edges change ([`NeighbourRule::Gabriel`]) they are
//! recomputed at every sample from the true positions by a
//! [`NeighbourTracker`], `E_k` being the edges at sample `k`:
//!
//! * relative formation error of an edge: `e_ij(t) = |d_ij(t) - d*| / d*`, `d_ij` the distance between the
//!   two robots' positions;
//! * the evaluation window: the samples with `t >= t_K - window_s` (20 s in the paper), the bound taken with
//!   a tolerance of `1e-6 dt` so that the sample at exactly `t_K - window_s` is in whatever the rounding of
//!   `k dt`; a run shorter than the window is scored over all its samples;
//! * an edge's window mean: the mean of `e_ij` over the samples of the window at which `(i, j)` is an edge;
//!   the *scored* edges are those that are edges at some sample of the window (all pairs: every pair);
//! * success at tolerance `tau` (all pairs, the paper's): for EVERY edge, the window mean is `< tau`;
//! * success at tolerance `tau` (a changing graph, the strict check): every scored edge's window mean is
//!   `< tau`, the graph `E_k` connects the whole team at every sample of the window, and the run has no
//!   collision;
//! * convergence time at `tau`: the first sample time `t_k` such that `max_{ij in E_m} e_ij(t_m) < tau` for
//!   every `m >= k`; `None` when the last sample is not below `tau`;
//! * relative formation error of a run: the mean over scored edges of the window means; the largest
//!   window mean is reported too;
//! * orientation error: the mean over robots and window samples of `|wrap(theta_i(t) - phi*(t))|`;
//! * collisions: the number of collision events, an event being a pair that overlaps at a sample and did
//!   not at the previous sample (so a lasting contact counts once).
//!
//! * team figures ([`TeamMetrics`], always under a changing graph, and under all pairs when
//!   [`MetricsConfig::team_figures`] asks): whether the graph stayed connected over the window, the
//!   number of scored edges, the median of their window means, and the anchor-compatible check of
//!   Huang, Yang and Guo (ICRA 2026) beside ours: at the last sample, the mean of `e_ij` over `E_K` is
//!   `<= 10 %` ([`ANCHOR_TOLERANCE`]) and no two robots are closer than 0.2 m ([`ANCHOR_MIN_DISTANCE`]).
//!
//! * an incomplete run: one that played fewer ticks than it was to play (a run stopped early by a
//!   signal, a failure or a full disk). It has no final window to judge, so it succeeds at no
//!   tolerance and fails the anchor-compatible check, whatever its last samples look like; its
//!   other figures are over the ticks it played, and [`RunMetrics::incomplete`] says how many of
//!   how many that was.
//!
//! A trajectory with no edges succeeds trivially (there is no pair to fail) with zero formation error.
//! Malformed trajectories (read back from a file) do not panic: a value that cannot be computed (an edge
//! naming a robot missing from a sample, no samples at all) is NaN, and NaN never passes a tolerance.
//!
//! [`summarize`] aggregates runs as Table I and Fig. 9 do: success rates over all runs (an
//! incomplete run counts as a run that did not succeed, and the number of incomplete runs is
//! stated), the relative formation and orientation errors' statistics over the runs successful
//! at 10 %, the convergence time's over those of them that converged ([`CONVERGED_RULE`]), each
//! with the rule and the count it covers ([`MediansOver`]).

use std::collections::{BTreeMap, HashSet};

use formation_proto::{NeighbourRule, wrap_angle};
use serde::{Deserialize, Serialize};

use crate::episode::Trajectory;
use crate::neighbours::{NeighbourTracker, is_connected};

/// The anchor-compatible check's tolerance on the mean edge error at the last sample.
pub const ANCHOR_TOLERANCE: f64 = 0.10;
/// The anchor-compatible check's smallest allowed distance \[m\] between two robots at the last
/// sample.
pub const ANCHOR_MIN_DISTANCE: f64 = 0.2;

/// Settings of [`run_metrics`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MetricsConfig {
    /// Length \[s\] of the final window the success test and the error means use (the paper's 20 s).
    pub window_s: f64,
    /// The two tolerances on the relative formation error (the paper's 5 % and 10 %), reported as
    /// `*_5` and `*_10`.
    pub tolerances: (f64, f64),
    /// Compute [`TeamMetrics`] for all-pairs runs too (they are always computed for a changing
    /// graph). Off by default, so the paper's runs keep their metrics' original form.
    #[serde(default)]
    pub team_figures: bool,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig {
            window_s: 20.0,
            tolerances: (0.05, 0.10),
            team_figures: false,
        }
    }
}

/// What a team's run adds to the paper's metrics.
pub use formation_schema::TeamMetrics;

/// The metrics of one run, as the run log and `summary.json` hold them, and how far an
/// incomplete run got.
pub use formation_schema::{RunMetrics, TicksPlayed};

/// Scores one run that was to play `planned_ticks` ticks (its scenario's duration over `dt`,
/// [`crate::RunSpec::ticks`]): a trajectory with fewer ticks is an incomplete run, which never
/// succeeds (see the module docs).
pub fn run_metrics(traj: &Trajectory, planned_ticks: u64, cfg: &MetricsConfig) -> RunMetrics {
    let mut metrics = match traj.neighbours {
        NeighbourRule::AllPairs => fixed_edge_metrics(traj, cfg),
        rule => changing_edge_metrics(traj, cfg, rule),
    };
    let played = traj.commands.len() as u64;
    if played < planned_ticks {
        mark_incomplete(
            &mut metrics,
            TicksPlayed {
                ticks: played,
                planned_ticks,
            },
        );
    }
    metrics
}

/// Marks `metrics` as those of a run that stopped early, after `played`: it succeeds at no
/// tolerance, strict or anchor-compatible.
pub fn mark_incomplete(metrics: &mut RunMetrics, played: TicksPlayed) {
    metrics.success_5 = false;
    metrics.success_10 = false;
    if let Some(team) = metrics.team.as_mut() {
        team.anchor_success = false;
    }
    metrics.incomplete = Some(played);
}

/// The per-edge errors of one run, whichever way its edges were chosen: what [`RunMetrics`] is
/// assembled from.
struct EdgeErrors {
    /// Samples scored (the shorter of the times and the poses).
    samples: usize,
    /// The final window's samples.
    window: std::ops::Range<usize>,
    /// Each scored edge's mean error over the window samples where it is an edge.
    edge_window_means: Vec<f64>,
    /// The largest edge error at each sample (what convergence is judged by).
    max_error_per_sample: Vec<f64>,
    /// The mean edge error at the last sample.
    final_mean_edge_error: f64,
    /// Whether the edges connected the team at every window sample.
    connected: bool,
}

/// The metrics over the trajectory's fixed `edges`: the paper's definition.
fn fixed_edge_metrics(traj: &Trajectory, cfg: &MetricsConfig) -> RunMetrics {
    let samples = traj.times.len().min(traj.poses.len());
    let window = window_start(&traj.times[..samples], traj.dt, cfg.window_s)..samples;

    // errors[k][e]: relative error of edge e at sample k.
    let errors: Vec<Vec<f64>> = traj.poses[..samples]
        .iter()
        .map(|poses| {
            traj.edges
                .iter()
                .map(|&(i, j)| match (poses.get(i), poses.get(j)) {
                    (Some(a), Some(b)) => {
                        ((a.x - b.x).hypot(a.y - b.y) - traj.d_star).abs() / traj.d_star
                    }
                    _ => f64::NAN,
                })
                .collect()
        })
        .collect();
    let edges = EdgeErrors {
        samples,
        edge_window_means: (0..traj.edges.len())
            .map(|e| mean(errors[window.clone()].iter().map(|row| row[e])))
            .collect(),
        max_error_per_sample: errors
            .iter()
            .map(|row| max_propagating_nan(row.iter().copied()))
            .collect(),
        final_mean_edge_error: errors
            .last()
            .map_or(f64::NAN, |row| mean(row.iter().copied())),
        connected: is_connected(traj.n_robots(), &traj.edges),
        window,
    };
    // The paper's success looks at the edges alone.
    assemble(traj, cfg, edges, Check::EdgesOnly, cfg.team_figures)
}

/// The metrics over edges recomputed at every sample by `rule`: the strict check.
fn changing_edge_metrics(
    traj: &Trajectory,
    cfg: &MetricsConfig,
    rule: NeighbourRule,
) -> RunMetrics {
    let samples = traj.times.len().min(traj.poses.len());
    let window = window_start(&traj.times[..samples], traj.dt, cfg.window_s)..samples;
    let n = traj.n_robots();
    let mut tracker = NeighbourTracker::new(rule, n);
    let mut positions = Vec::with_capacity(n);
    // Per scored edge: (sum, count) of its errors over the window samples where it is an edge.
    let mut window_sums: BTreeMap<(usize, usize), (f64, usize)> = BTreeMap::new();
    let mut max_error_per_sample = Vec::with_capacity(samples);
    let mut connected = true;
    let mut final_mean_edge_error = f64::NAN;
    for (k, poses) in traj.poses[..samples].iter().enumerate() {
        positions.clear();
        positions.extend(poses.iter().map(|p| (p.x, p.y)));
        tracker.update(&positions);
        let edges = tracker.edges();
        let error = |&(i, j): &(usize, usize)| {
            let (a, b) = (&poses[i], &poses[j]);
            ((a.x - b.x).hypot(a.y - b.y) - traj.d_star).abs() / traj.d_star
        };
        max_error_per_sample.push(max_propagating_nan(edges.iter().map(error)));
        if window.contains(&k) {
            connected &= is_connected(n, edges);
            for edge in edges {
                let entry = window_sums.entry(*edge).or_insert((0.0, 0));
                entry.0 += error(edge);
                entry.1 += 1;
            }
        }
        if k + 1 == samples {
            final_mean_edge_error = mean(edges.iter().map(error));
        }
    }
    let edges = EdgeErrors {
        samples,
        window,
        edge_window_means: window_sums
            .values()
            .map(|&(sum, count)| sum / count as f64)
            .collect(),
        max_error_per_sample,
        final_mean_edge_error,
        connected,
    };
    assemble(traj, cfg, edges, Check::Strict, true)
}

/// What success at a tolerance requires besides every scored edge's window mean below it.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Check {
    /// Nothing more: the paper's definition.
    EdgesOnly,
    /// A graph connected over the window and no collision.
    Strict,
}

/// The one place a [`RunMetrics`] is built, from a run's edge errors.
fn assemble(
    traj: &Trajectory,
    cfg: &MetricsConfig,
    edges: EdgeErrors,
    check: Check,
    with_team_figures: bool,
) -> RunMetrics {
    let collisions = collision_events(&traj.collisions);
    let means = &edges.edge_window_means;
    let passes = |tolerance: f64| {
        !edges.window.is_empty()
            && means.iter().all(|&m| m < tolerance)
            && (check == Check::EdgesOnly || (edges.connected && collisions == 0))
    };
    let (rel_formation_error, max_edge_window_error) = if means.is_empty() {
        (0.0, 0.0)
    } else {
        (
            mean(means.iter().copied()),
            max_propagating_nan(means.iter().copied()),
        )
    };
    let times = &traj.times[..edges.samples];
    let convergence =
        |tolerance: f64| convergence_time(times, &edges.max_error_per_sample, tolerance);
    let (tol_5, tol_10) = cfg.tolerances;
    RunMetrics {
        success_5: passes(tol_5),
        success_10: passes(tol_10),
        convergence_s_5: convergence(tol_5),
        convergence_s_10: convergence(tol_10),
        rel_formation_error,
        max_edge_window_error,
        orientation_error_rad: orientation_error(traj, edges.window.clone()),
        collisions,
        team: with_team_figures.then(|| {
            team_figures(
                traj,
                edges.samples,
                edges.connected,
                means,
                edges.final_mean_edge_error,
            )
        }),
        incomplete: None,
    }
}

/// Mean over robots and window samples of the wrapped heading error.
fn orientation_error(traj: &Trajectory, window: std::ops::Range<usize>) -> f64 {
    mean(window.flat_map(|k| {
        let phi_star = traj.phi_star.get(k).copied().unwrap_or(f64::NAN);
        traj.poses[k]
            .iter()
            .map(move |pose| wrap_angle(pose.theta - phi_star).abs())
    }))
}

/// The team figures, from the window means and the last sample's mean edge error.
fn team_figures(
    traj: &Trajectory,
    samples: usize,
    connected: bool,
    edge_window_means: &[f64],
    final_mean_edge_error: f64,
) -> TeamMetrics {
    let final_min_distance = samples
        .checked_sub(1)
        .map(|k| {
            let poses = &traj.poses[k];
            let mut smallest = f64::NAN;
            for (i, a) in poses.iter().enumerate() {
                for b in &poses[i + 1..] {
                    let d = (a.x - b.x).hypot(a.y - b.y);
                    if smallest.is_nan() || d < smallest || d.is_nan() {
                        smallest = d;
                    }
                }
            }
            smallest
        })
        .unwrap_or(f64::NAN);
    TeamMetrics {
        connected,
        edges_scored: edge_window_means.len(),
        median_edge_window_error: quantiles(edge_window_means.iter().copied())
            .map_or(f64::NAN, |q| q.median),
        final_mean_edge_error,
        final_min_distance,
        anchor_success: final_mean_edge_error <= ANCHOR_TOLERANCE
            && final_min_distance >= ANCHOR_MIN_DISTANCE,
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
    if count == 0 {
        f64::NAN
    } else {
        sum / count as f64
    }
}

/// Maximum that returns NaN if any value is NaN (and for no values, `-inf`).
fn max_propagating_nan(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(f64::NEG_INFINITY, |acc, v| {
        if acc.is_nan() || v.is_nan() {
            f64::NAN
        } else {
            acc.max(v)
        }
    })
}

/// Order statistics of a sample and the Table I summary, as `summary.json` holds them.
pub use formation_schema::{Quantiles, Summary};

/// Quartiles of the finite values in `values`, `None` if there are none.
///
/// The `p`-quantile of the sorted values `x_0 <= .. <= x_{n-1}` interpolates linearly between order
/// statistics at the fractional index `h = (n - 1) p`: `x_floor(h) + (h - floor(h)) (x_floor(h)+1 -
/// x_floor(h))` (Hyndman & Fan type 7, the default of R and NumPy).
pub fn quantiles(values: impl IntoIterator<Item = f64>) -> Option<Quantiles> {
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

/// Type-7 quantile of non-empty sorted values.
fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let lower = h.floor() as usize;
    let upper = (lower + 1).min(sorted.len() - 1);
    sorted[lower] + (h - lower as f64) * (sorted[upper] - sorted[lower])
}

/// The rule of the error medians: the runs successful at 10 %.
pub const SUCCESSFUL_RULE: &str = "runs successful at 10 %";
/// The rule of the convergence-time median: the runs successful at 10 % whose largest edge error
/// stayed below 10 % from some sample to the end (a run can succeed on its window mean without
/// that).
pub const CONVERGED_RULE: &str =
    "runs successful at 10 % that converged (largest edge error below 10 % to the end)";

/// The statistics, rates and counts of a set of runs, and which runs each median covers.
pub use formation_schema::{Coverage, MediansOver};

/// Aggregates runs: success rates over all runs (an incomplete run never succeeds), the error
/// statistics over the runs that succeed at 10 %, the convergence time's over those of them that
/// converged; [`Summary::medians_over`] states each rule and count, [`Summary::runs_incomplete`]
/// the runs that stopped early.
pub fn summarize(runs: &[RunMetrics]) -> Summary {
    let fraction = |count: usize| {
        if runs.is_empty() {
            0.0
        } else {
            count as f64 / runs.len() as f64
        }
    };
    // `run_metrics` never lets an incomplete run succeed; a file from elsewhere might.
    let successful: Vec<&RunMetrics> = runs
        .iter()
        .filter(|r| r.success_10 && r.is_complete())
        .collect();
    let convergence_s = quantiles(successful.iter().filter_map(|r| r.convergence_s_10));
    let rel_formation_error = quantiles(successful.iter().map(|r| r.rel_formation_error));
    let orientation_error_rad = quantiles(successful.iter().map(|r| r.orientation_error_rad));
    let covered = |rule: &str, q: &Option<Quantiles>| Coverage {
        rule: rule.to_owned(),
        runs: q.as_ref().map_or(0, |q| q.count),
        of: successful.len(),
    };
    let medians_over = MediansOver {
        convergence_s: covered(CONVERGED_RULE, &convergence_s),
        rel_formation_error: covered(SUCCESSFUL_RULE, &rel_formation_error),
        orientation_error_rad: covered(SUCCESSFUL_RULE, &orientation_error_rad),
    };
    let team: Option<Vec<&TeamMetrics>> = runs.iter().map(|r| r.team.as_ref()).collect();
    let team = team.filter(|t| !t.is_empty());
    let anchor_passes = runs
        .iter()
        .filter(|r| r.is_complete() && r.team.as_ref().is_some_and(|t| t.anchor_success))
        .count();
    Summary {
        anchor_success_rate: team.as_ref().map(|_| fraction(anchor_passes)),
        connected_rate: team
            .as_ref()
            .map(|t| fraction(t.iter().filter(|m| m.connected).count())),
        runs: runs.len(),
        runs_incomplete: runs.iter().filter(|r| !r.is_complete()).count(),
        success_rate_5: fraction(
            runs.iter()
                .filter(|r| r.success_5 && r.is_complete())
                .count(),
        ),
        success_rate_10: fraction(successful.len()),
        median_convergence_s: convergence_s.as_ref().map(|q| q.median),
        median_rel_formation_error: rel_formation_error.as_ref().map(|q| q.median),
        median_orientation_error_rad: orientation_error_rad.as_ref().map(|q| q.median),
        medians_over: Some(medians_over),
        collisions: runs.iter().filter(|r| r.collisions > 0).count(),
        convergence_s,
        rel_formation_error,
        orientation_error_rad,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::Pose;

    const DT: f64 = 0.05;
    const D_STAR: f64 = 2.0;
    const PHI_STAR: f64 = 3.76;

    /// Three robots on an equilateral triangle of side `side(t)`, headings `PHI_STAR + offsets`, sampled
    /// every `DT` for `duration_s`.
    fn triangle_run(
        duration_s: f64,
        side: impl Fn(usize, f64) -> f64,
        offsets: [f64; 3],
    ) -> Trajectory {
        let ticks = (duration_s / DT).round() as usize;
        let times: Vec<f64> = (0..=ticks).map(|k| k as f64 * DT).collect();
        let poses = times
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                let s = side(k, t);
                let corners = [(0.0, 0.0), (s, 0.0), (s / 2.0, s * 3f64.sqrt() / 2.0)];
                corners
                    .iter()
                    .zip(offsets)
                    .map(|(&(x, y), offset)| Pose {
                        x: x + 5.0,
                        y: y - 1.0,
                        theta: wrap_angle(PHI_STAR + offset),
                    })
                    .collect()
            })
            .collect();
        Trajectory {
            dt: DT,
            d_star: D_STAR,
            v_star: 0.7,
            edges: vec![(0, 1), (0, 2), (1, 2)],
            neighbours: NeighbourRule::AllPairs,
            phi_star: vec![PHI_STAR; times.len()],
            times,
            poses,
            commands: vec![vec![formation_proto::WheelCmd::BRAKE; 3]; ticks],
            collisions: Vec::new(),
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn a_step_onto_the_formation_converges_at_the_step() {
        let traj = triangle_run(
            60.0,
            |_, t| if t < 4.0 - 1e-9 { 1.5 } else { D_STAR },
            [0.0; 3],
        );
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert!(m.success_5 && m.success_10);
        assert_eq!(m.convergence_s_5, Some(traj.times[80]));
        assert!(close(m.convergence_s_10.unwrap(), 4.0));
        assert!(m.rel_formation_error.abs() < 1e-12 && m.max_edge_window_error.abs() < 1e-12);
        assert!(m.orientation_error_rad < 1e-12);
        assert_eq!(m.collisions, 0);
    }

    #[test]
    fn a_linear_approach_converges_where_it_crosses_each_tolerance() {
        // e(t) = 0.3 (1 - t/4) until t = 4: below 10 % after t = 8/3 s, below 5 % after t = 10/3 s.
        let traj = triangle_run(
            30.0,
            |_, t| if t < 4.0 { 1.4 + 0.15 * t } else { D_STAR },
            [0.0; 3],
        );
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert!(close(m.convergence_s_10.unwrap(), 2.7), "{m:?}");
        assert!(close(m.convergence_s_5.unwrap(), 3.35), "{m:?}");
    }

    #[test]
    fn a_steady_seven_percent_error_fails_five_and_passes_ten() {
        let traj = triangle_run(
            60.0,
            |k, _| {
                if k % 2 == 0 {
                    1.07 * D_STAR
                } else {
                    0.93 * D_STAR
                }
            },
            [0.0; 3],
        );
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert!(!m.success_5 && m.success_10, "{m:?}");
        assert!(close(m.rel_formation_error, 0.07) && close(m.max_edge_window_error, 0.07));
        assert_eq!(m.convergence_s_5, None);
        assert_eq!(m.convergence_s_10, Some(0.0));
    }

    #[test]
    fn only_the_final_window_decides_success() {
        // 50 % error until t = 40 s, exact afterwards: the last 20 s are perfect.
        let late = triangle_run(
            60.0,
            |k, _| if k < 800 { 1.5 * D_STAR } else { D_STAR },
            [0.0; 3],
        );
        let m = run_metrics(&late, late.commands.len() as u64, &MetricsConfig::default());
        assert!(m.success_5 && close(m.convergence_s_5.unwrap(), 40.0));
        // The same with the error lasting one more sample: that sample (t = 40 s) is inside the window.
        let one_more = triangle_run(
            60.0,
            |k, _| if k <= 800 { 1.5 * D_STAR } else { D_STAR },
            [0.0; 3],
        );
        let m = run_metrics(
            &one_more,
            one_more.commands.len() as u64,
            &MetricsConfig::default(),
        );
        assert!(close(m.rel_formation_error, 0.5 / 401.0), "{m:?}");
        // A 30 s window reaches back into the bad part.
        let m = run_metrics(
            &late,
            late.commands.len() as u64,
            &MetricsConfig {
                window_s: 30.0,
                ..MetricsConfig::default()
            },
        );
        assert!(!m.success_10 && close(m.rel_formation_error, 0.5 * 200.0 / 601.0));
    }

    /// Four robots: two equilateral triangles sharing the edge (1, 2), scaled by `scale(k)`,
    /// under the default Gabriel rule, for `duration_s`.
    fn lattice_run(duration_s: f64, scale: impl Fn(usize) -> f64) -> Trajectory {
        use crate::neighbours::GabrielRule;
        let mut traj = triangle_run(duration_s, |_, _| D_STAR, [0.0; 3]);
        let h = 3f64.sqrt() / 2.0;
        for (k, poses) in traj.poses.iter_mut().enumerate() {
            let s = D_STAR * scale(k);
            *poses = [(0.0, 0.0), (s, 0.0), (s / 2.0, s * h), (1.5 * s, s * h)]
                .iter()
                .map(|&(x, y)| Pose {
                    x,
                    y,
                    theta: PHI_STAR,
                })
                .collect();
        }
        traj.neighbours = NeighbourRule::Gabriel(GabrielRule::with_range(10.0));
        traj.edges = Vec::new();
        traj
    }

    #[test]
    fn a_formed_lattice_succeeds_on_its_changing_edges_with_team_figures() {
        let traj = lattice_run(60.0, |k| if k < 100 { 1.2 } else { 1.0 });
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert!(m.success_5 && m.success_10, "{m:?}");
        assert!(close(m.convergence_s_10.unwrap(), 5.0));
        let team = m.team.expect("team figures under a changing graph");
        // 5 unit edges; the long diagonal (0, 3) is no edge.
        assert_eq!(team.edges_scored, 5);
        assert!(team.connected && team.anchor_success);
        assert!(team.final_mean_edge_error < 1e-12 && close(team.final_min_distance, D_STAR));
    }

    #[test]
    fn the_strict_check_fails_a_collision_or_one_bad_edge_that_the_anchor_check_passes() {
        let mut collided = lattice_run(30.0, |_| 1.0);
        collided.collisions = vec![(3, 0, 1)];
        let m = run_metrics(
            &collided,
            collided.commands.len() as u64,
            &MetricsConfig::default(),
        );
        assert!(!m.success_5 && !m.success_10 && m.team.unwrap().anchor_success);

        // A 7 % error on the whole lattice in the window, then exact for the last sample only:
        // strict fails at 5 %, the anchor check (last sample) passes.
        let samples = collided.times.len();
        let late = lattice_run(30.0, |k| if k + 1 < samples { 1.07 } else { 1.0 });
        let m = run_metrics(&late, late.commands.len() as u64, &MetricsConfig::default());
        assert!(!m.success_5 && m.success_10, "{m:?}");
        assert!(m.team.unwrap().anchor_success);
    }

    #[test]
    fn a_team_split_in_two_fails_the_strict_check_however_well_each_part_is_formed() {
        let mut traj = lattice_run(30.0, |_| 1.0);
        for poses in &mut traj.poses {
            // Move robot 3 and a new robot 4 far away: a pair of its own, 2 m apart.
            poses[3].x += 50.0;
            poses.push(Pose {
                x: poses[3].x + D_STAR,
                ..poses[3]
            });
        }
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        let team = m.team.clone().unwrap();
        assert!(!team.connected && !m.success_10, "{m:?}");
        assert!(m.max_edge_window_error < 1e-12);
    }

    #[test]
    fn all_pairs_runs_keep_the_papers_form_unless_team_figures_are_asked() {
        let traj = triangle_run(30.0, |_, _| D_STAR, [0.0; 3]);
        let plain = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert_eq!(plain.team, None);
        let with_team = run_metrics(
            &traj,
            traj.commands.len() as u64,
            &MetricsConfig {
                team_figures: true,
                ..MetricsConfig::default()
            },
        );
        assert_eq!(
            RunMetrics {
                team: None,
                ..with_team.clone()
            },
            plain
        );
        let team = with_team.team.clone().unwrap();
        assert!(team.connected && team.anchor_success && team.edges_scored == 3);
        let summary = summarize(&[with_team]);
        assert_eq!(summary.anchor_success_rate, Some(1.0));
        assert_eq!(summarize(&[plain]).anchor_success_rate, None);
    }

    #[test]
    fn window_start_includes_the_boundary_sample_and_clamps_to_the_run() {
        let times: Vec<f64> = (0..=1200).map(|k| k as f64 * DT).collect();
        assert_eq!(window_start(&times, DT, 20.0), 800);
        assert_eq!(window_start(&times, DT, 100.0), 0);
        assert_eq!(window_start(&times, DT, 0.0), 1200);
        assert_eq!(window_start(&[], DT, 20.0), 0);
    }

    #[test]
    fn orientation_error_is_the_wrapped_mean_absolute_heading_error() {
        let traj = triangle_run(60.0, |_, _| D_STAR, [0.1, -0.2, 2.0 * std::f64::consts::PI]);
        let m = run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default());
        assert!(
            close(m.orientation_error_rad, 0.1),
            "{}",
            m.orientation_error_rad
        );
    }

    #[test]
    fn collision_events_count_onsets_not_overlapping_samples() {
        let overlaps = [(5, 0, 1), (6, 0, 1), (7, 0, 1), (10, 0, 1), (6, 1, 2)];
        assert_eq!(collision_events(&overlaps), 3);
        let mut traj = triangle_run(10.0, |_, _| D_STAR, [0.0; 3]);
        traj.collisions = overlaps.to_vec();
        assert_eq!(
            run_metrics(&traj, traj.commands.len() as u64, &MetricsConfig::default()).collisions,
            3
        );
    }

    #[test]
    fn malformed_or_edgeless_trajectories_do_not_panic() {
        let mut bad_edge = triangle_run(10.0, |_, _| D_STAR, [0.0; 3]);
        bad_edge.edges.push((0, 5));
        let m = run_metrics(
            &bad_edge,
            bad_edge.commands.len() as u64,
            &MetricsConfig::default(),
        );
        assert!(!m.success_10 && m.convergence_s_10.is_none() && m.rel_formation_error.is_nan());

        let mut no_edges = triangle_run(10.0, |_, _| 1.0, [0.0; 3]);
        no_edges.edges.clear();
        let m = run_metrics(
            &no_edges,
            no_edges.commands.len() as u64,
            &MetricsConfig::default(),
        );
        assert!(m.success_5 && m.rel_formation_error == 0.0 && m.convergence_s_5 == Some(0.0));

        let mut empty = triangle_run(10.0, |_, _| D_STAR, [0.0; 3]);
        empty.times.clear();
        empty.poses.clear();
        let m = run_metrics(
            &empty,
            empty.commands.len() as u64,
            &MetricsConfig::default(),
        );
        assert!(!m.success_10 && m.convergence_s_10.is_none());
    }

    #[test]
    fn quantiles_interpolate_linearly_between_order_statistics() {
        let q = quantiles([4.0, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!(
            (q.min, q.q1, q.median, q.q3, q.max, q.count),
            (1.0, 1.75, 2.5, 3.25, 4.0, 4)
        );
        let q = quantiles([50.0, 10.0, 40.0, 20.0, 30.0, f64::NAN]).unwrap();
        assert_eq!((q.q1, q.median, q.q3, q.count), (20.0, 30.0, 40.0, 5));
        let q = quantiles([7.0]).unwrap();
        assert_eq!(
            (q.min, q.q1, q.median, q.q3, q.max),
            (7.0, 7.0, 7.0, 7.0, 7.0)
        );
        assert!(quantiles([]).is_none());
    }

    fn run(
        success_5: bool,
        success_10: bool,
        convergence: Option<f64>,
        error: f64,
        collisions: usize,
    ) -> RunMetrics {
        RunMetrics {
            success_5,
            success_10,
            convergence_s_5: None,
            convergence_s_10: convergence,
            rel_formation_error: error,
            max_edge_window_error: error,
            orientation_error_rad: error / 10.0,
            collisions,
            team: None,
            incomplete: None,
        }
    }

    #[test]
    fn summarize_rates_over_all_runs_and_statistics_over_runs_successful_at_ten_percent() {
        let runs = [
            run(true, true, Some(4.0), 0.01, 0),
            run(false, true, Some(1.0), 0.04, 2),
            run(true, true, Some(3.0), 0.02, 0),
            run(false, true, Some(2.0), 0.03, 0),
            run(false, true, None, 0.09, 0),
            run(false, false, Some(0.5), 0.50, 1),
        ];
        let s = summarize(&runs);
        assert_eq!(s.runs, 6);
        assert!(close(s.success_rate_5, 2.0 / 6.0) && close(s.success_rate_10, 5.0 / 6.0));
        assert_eq!(s.collisions, 2);
        let convergence = s.convergence_s.unwrap();
        assert_eq!(
            (
                convergence.count,
                convergence.q1,
                convergence.median,
                convergence.q3
            ),
            (4, 1.75, 2.5, 3.25)
        );
        assert_eq!(s.median_convergence_s, Some(2.5));
        let error = s.rel_formation_error.unwrap();
        assert_eq!((error.count, error.median, error.max), (5, 0.03, 0.09));
        assert_eq!(s.median_rel_formation_error, Some(0.03));
        assert!(close(s.median_orientation_error_rad.unwrap(), 0.003));

        let empty = summarize(&[]);
        assert_eq!(
            (
                empty.runs,
                empty.success_rate_10,
                empty.median_convergence_s
            ),
            (0, 0.0, None)
        );
    }

    #[test]
    fn an_incomplete_run_never_succeeds_however_good_its_last_samples() {
        // 30 s of a perfect formation, of the 60 s (1200 ticks) the run was to play.
        let traj = triangle_run(30.0, |_, _| D_STAR, [0.0; 3]);
        let with_team = MetricsConfig {
            team_figures: true,
            ..MetricsConfig::default()
        };
        let whole = run_metrics(&traj, 600, &with_team);
        assert!(whole.success_5 && whole.success_10 && whole.is_complete());
        assert!(whole.team.as_ref().unwrap().anchor_success);
        let cut = run_metrics(&traj, 1200, &with_team);
        assert!(!cut.success_5 && !cut.success_10, "{cut:?}");
        assert!(!cut.team.as_ref().unwrap().anchor_success);
        assert_eq!(
            cut.incomplete,
            Some(TicksPlayed {
                ticks: 600,
                planned_ticks: 1200
            })
        );
        // Its other figures are over the ticks it played.
        assert_eq!(cut.rel_formation_error, whole.rel_formation_error);
        assert_eq!(cut.convergence_s_10, whole.convergence_s_10);
        // More ticks than planned is no shortfall.
        assert!(run_metrics(&traj, 100, &with_team).is_complete());

        let summary = summarize(&[whole.clone(), cut.clone()]);
        assert_eq!((summary.runs, summary.runs_incomplete), (2, 1));
        assert_eq!(summary.success_rate_10, 0.5);
        assert_eq!(summary.anchor_success_rate, Some(0.5));
        assert_eq!(summary.rel_formation_error.unwrap().count, 1);

        // A complete run's metrics and summary carry no trace of the new key.
        let json = serde_json::to_string(&whole).unwrap();
        assert!(!json.contains("incomplete"), "{json}");
        let json = serde_json::to_string(&summarize(&[whole])).unwrap();
        assert!(!json.contains("runs_incomplete"), "{json}");
        // An incomplete run that a file says succeeded still does not count.
        let forged = RunMetrics {
            success_5: true,
            success_10: true,
            ..cut
        };
        assert_eq!(summarize(&[forged]).success_rate_10, 0.0);
    }

    #[test]
    fn each_median_states_the_runs_it_covers() {
        // Seven runs succeed at 10 %, four of them without converging; one run fails.
        let mut runs: Vec<RunMetrics> = (0..7)
            .map(|k| {
                let converged = (k < 3).then_some(2.0 + k as f64);
                run(false, true, converged, 0.01 * (k + 1) as f64, 0)
            })
            .collect();
        runs.push(run(false, false, Some(1.0), 0.5, 0));
        let s = summarize(&runs);
        let over = s.medians_over.clone().expect("stated");
        assert_eq!(
            (over.convergence_s.runs, over.convergence_s.of),
            (3, 7),
            "{over:?}"
        );
        assert_eq!(over.convergence_s.rule, CONVERGED_RULE);
        assert_eq!(s.median_convergence_s, Some(3.0));
        assert_eq!(s.convergence_s.unwrap().count, 3);
        for coverage in [&over.rel_formation_error, &over.orientation_error_rad] {
            assert_eq!((coverage.runs, coverage.of), (7, 7));
            assert_eq!(coverage.rule, SUCCESSFUL_RULE);
        }
        assert!(close(s.median_rel_formation_error.unwrap(), 0.04));
        // No successful run: every median covers 0 of 0.
        let none = summarize(&runs[7..]);
        let over = none.medians_over.unwrap();
        assert_eq!((over.convergence_s.runs, over.convergence_s.of), (0, 0));
        assert_eq!(none.median_convergence_s, None);
    }
}
