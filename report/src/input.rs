//! Finding and reading the report's inputs: eval output directories (`summary.json` plus
//! `runs/run-NNNN.json`), training loss curves (`*loss*.csv`) and latency profiles (`profile.json`).
//!
//! The JSON is read with the report's own structs, which mirror what `formation eval` writes
//! (`EvalOutput` and `RunLog` in the CLI, `Trajectory`/`RunMetrics`/`Summary` in `formation-world`)
//! but are lenient where the writer can legitimately emit `null` (serde_json writes NaN as `null`)
//! and ignore keys they do not use, so that a report can still be drawn from older or newer
//! outputs. What cannot be drawn (no samples, a pose row of the wrong length) is an error naming
//! the file.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use formation_proto::{Pose, WheelCmd};
use serde::Deserialize;

use crate::error::ReportError;
use crate::loss::{LossCurve, parse_loss_csv};
use crate::profile::{LatencyProfile, parse_profile};

/// At most this many run logs per eval directory are drawn (the rest are counted and mentioned).
pub const MAX_RUNS_PLOTTED_PER_EVAL: usize = 3;

/// Directory levels searched below the input directory.
const MAX_SEARCH_DEPTH: usize = 12;

/// Everything found under the input directory.
#[derive(Debug, Clone)]
pub struct Inputs {
    /// The input directory as given.
    pub root: PathBuf,
    /// Eval outputs, sorted by their path relative to `root`.
    pub evals: Vec<EvalData>,
    /// Training loss curves.
    pub loss_curves: Vec<LossCurve>,
    /// Latency profiles.
    pub profiles: Vec<LatencyProfile>,
}

/// One eval output directory.
#[derive(Debug, Clone)]
pub struct EvalData {
    /// Its path relative to the input directory (the directory's own name for the input directory
    /// itself).
    pub name: String,
    /// Its `summary.json`.
    pub source: PathBuf,
    /// `expert` or `policy`.
    pub controller: String,
    /// Model ids (policy only).
    pub models: Vec<String>,
    /// Scenario name.
    pub scenario: String,
    /// Base seed, when recorded.
    pub seed: Option<u64>,
    /// The Table I figures.
    pub table: TableRow,
    /// Fig. 9 statistics over the runs that succeed at 10 %.
    pub fig9: Fig9Stats,
    /// Per-run metrics, in run order.
    pub per_run: Vec<RunScores>,
    /// Run logs drawn (at most [`MAX_RUNS_PLOTTED_PER_EVAL`]), in run order.
    pub runs: Vec<RunData>,
    /// Run logs present but not drawn.
    pub runs_not_drawn: usize,
    /// Runs that stopped before their last tick (from the summary and the run logs), by index.
    pub incomplete: Vec<IncompleteRun>,
}

/// A run that stopped before its last tick.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct IncompleteRun {
    /// Run index.
    pub index: usize,
    /// Ticks it played, when recorded.
    #[serde(default)]
    pub ticks: Option<usize>,
    /// Ticks it was to play, when recorded.
    #[serde(default)]
    pub planned_ticks: Option<u64>,
    /// Why it stopped, when recorded.
    #[serde(default)]
    pub stop_reason: Option<String>,
}

/// The Table I keys of one evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct TableRow {
    /// Number of runs.
    pub runs: usize,
    /// Fraction (0..1) of runs successful at 5 %.
    pub success_rate_5: f64,
    /// Fraction (0..1) of runs successful at 10 %.
    pub success_rate_10: f64,
    /// Median convergence time \[s\] over runs successful at 10 %.
    pub median_convergence_s: Option<f64>,
    /// Median relative formation error (fraction) over runs successful at 10 %.
    pub median_rel_formation_error: Option<f64>,
    /// Median orientation error \[rad\] over runs successful at 10 %.
    pub median_orientation_error_rad: Option<f64>,
    /// Runs with at least one collision.
    pub collisions: usize,
}

/// Order statistics of one Fig. 9 quantity.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct Quartiles {
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

/// The three Fig. 9 quantities.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Fig9Stats {
    /// Convergence time \[s\].
    pub convergence_s: Option<Quartiles>,
    /// Relative formation error (fraction).
    pub rel_formation_error: Option<Quartiles>,
    /// Orientation error \[rad\].
    pub orientation_error_rad: Option<Quartiles>,
}

/// The metrics of one run; NaN where the writer could not compute a value.
#[derive(Debug, Clone, PartialEq)]
pub struct RunScores {
    /// Success at 5 %.
    pub success_5: bool,
    /// Success at 10 %.
    pub success_10: bool,
    /// Convergence time \[s\] at 10 %.
    pub convergence_s_10: Option<f64>,
    /// Relative formation error over the final window (fraction).
    pub rel_formation_error: f64,
    /// Orientation error over the final window \[rad\].
    pub orientation_error_rad: f64,
    /// Collision events.
    pub collisions: usize,
}

/// One run log.
#[derive(Debug, Clone)]
pub struct RunData {
    /// The file it was read from.
    pub source: PathBuf,
    /// Run index.
    pub index: usize,
    /// Its metrics.
    pub scores: RunScores,
    /// Its trajectory.
    pub trajectory: RunTrajectory,
    /// False when the run stopped before its last tick (older logs, without the key, are
    /// complete).
    pub complete: bool,
    /// Why an incomplete run stopped, when recorded.
    pub stop_reason: Option<String>,
    /// The ticks the run was to play, when recorded.
    pub planned_ticks: Option<u64>,
}

/// A run's recorded trajectory, validated: every sample has one pose per robot, every command row
/// one command per robot, every edge names existing robots.
#[derive(Debug, Clone, PartialEq)]
pub struct RunTrajectory {
    /// Time step \[s\].
    pub dt: f64,
    /// Desired pairwise distance \[m\] (finite, positive).
    pub d_star: f64,
    /// Desired speed \[m/s\] (NaN when not recorded).
    pub v_star: f64,
    /// Formation edges `(i, j)`, 0-based robot indices.
    pub edges: Vec<(usize, usize)>,
    /// Sample times \[s\].
    pub times: Vec<f64>,
    /// Desired heading at each sample \[rad\].
    pub phi_star: Vec<f64>,
    /// Poses of every robot at each sample.
    pub poses: Vec<Vec<Pose>>,
    /// Applied wheel commands of every robot at each tick (at most one fewer than samples).
    pub commands: Vec<Vec<WheelCmd>>,
    /// Collision records `(sample, i, j)`.
    pub collisions: Vec<(u64, usize, usize)>,
}

impl RunTrajectory {
    /// Number of robots.
    pub fn n_robots(&self) -> usize {
        self.poses.first().map_or(0, Vec::len)
    }
}

// ---- raw JSON shapes -------------------------------------------------------------------------

#[derive(Deserialize)]
struct RawSummary {
    #[serde(default)]
    controller: String,
    #[serde(default)]
    models: Vec<String>,
    #[serde(default)]
    scenario: String,
    #[serde(default)]
    seed: Option<u64>,
    runs: usize,
    success_rate_5: f64,
    success_rate_10: f64,
    #[serde(default)]
    median_convergence_s: Option<f64>,
    #[serde(default)]
    median_rel_formation_error: Option<f64>,
    #[serde(default)]
    median_orientation_error_rad: Option<f64>,
    #[serde(default)]
    collisions: usize,
    #[serde(default)]
    convergence_s: Option<Quartiles>,
    #[serde(default)]
    rel_formation_error: Option<Quartiles>,
    #[serde(default)]
    orientation_error_rad: Option<Quartiles>,
    #[serde(default)]
    per_run: Vec<RawRunMetrics>,
    #[serde(default)]
    incomplete_runs: Vec<IncompleteRun>,
}

#[derive(Deserialize)]
struct RawRunMetrics {
    success_5: bool,
    success_10: bool,
    #[serde(default)]
    convergence_s_10: Option<f64>,
    #[serde(default)]
    rel_formation_error: Option<f64>,
    #[serde(default)]
    orientation_error_rad: Option<f64>,
    #[serde(default)]
    collisions: usize,
}

#[derive(Deserialize)]
struct RawRunLog {
    index: usize,
    metrics: RawRunMetrics,
    trajectory: RawTrajectory,
    #[serde(default = "complete_by_default")]
    complete: bool,
    #[serde(default)]
    stop_reason: Option<String>,
    #[serde(default)]
    planned_ticks: Option<u64>,
}

fn complete_by_default() -> bool {
    true
}

#[derive(Deserialize)]
struct RawTrajectory {
    dt: f64,
    d_star: f64,
    #[serde(default)]
    v_star: Option<f64>,
    edges: Vec<(usize, usize)>,
    times: Vec<Option<f64>>,
    phi_star: Vec<Option<f64>>,
    poses: Vec<Vec<RawPose>>,
    #[serde(default)]
    commands: Vec<Vec<RawWheelCmd>>,
    #[serde(default)]
    collisions: Vec<(u64, usize, usize)>,
}

#[derive(Deserialize)]
struct RawPose {
    x: Option<f64>,
    y: Option<f64>,
    theta: Option<f64>,
}

#[derive(Deserialize)]
struct RawWheelCmd {
    left: Option<f64>,
    right: Option<f64>,
}

fn or_nan(value: Option<f64>) -> f64 {
    value.unwrap_or(f64::NAN)
}

impl From<RawRunMetrics> for RunScores {
    fn from(raw: RawRunMetrics) -> RunScores {
        RunScores {
            success_5: raw.success_5,
            success_10: raw.success_10,
            convergence_s_10: raw.convergence_s_10,
            rel_formation_error: or_nan(raw.rel_formation_error),
            orientation_error_rad: or_nan(raw.orientation_error_rad),
            collisions: raw.collisions,
        }
    }
}

// ---- parsing (pure) ------------------------------------------------------------------------

/// Parses a `summary.json` (the `formation eval` output). `name` is how the report labels it.
pub fn parse_summary(text: &str, source: &Path, name: &str) -> Result<EvalData, ReportError> {
    let raw: RawSummary = parse_json(text, source)?;
    for (key, rate) in [
        ("success_rate_5", raw.success_rate_5),
        ("success_rate_10", raw.success_rate_10),
    ] {
        if !(0.0..=1.0).contains(&rate) {
            return Err(invalid(
                source,
                format!("{key} is {rate}, expected a fraction in 0..1"),
            ));
        }
    }
    if !raw.per_run.is_empty() && raw.per_run.len() != raw.runs {
        return Err(invalid(
            source,
            format!(
                "`runs` is {} but `per_run` lists {} runs",
                raw.runs,
                raw.per_run.len()
            ),
        ));
    }
    Ok(EvalData {
        name: name.to_owned(),
        source: source.to_path_buf(),
        controller: raw.controller,
        models: raw.models,
        scenario: raw.scenario,
        seed: raw.seed,
        table: TableRow {
            runs: raw.runs,
            success_rate_5: raw.success_rate_5,
            success_rate_10: raw.success_rate_10,
            median_convergence_s: raw.median_convergence_s,
            median_rel_formation_error: raw.median_rel_formation_error,
            median_orientation_error_rad: raw.median_orientation_error_rad,
            collisions: raw.collisions,
        },
        fig9: Fig9Stats {
            convergence_s: raw.convergence_s,
            rel_formation_error: raw.rel_formation_error,
            orientation_error_rad: raw.orientation_error_rad,
        },
        per_run: raw.per_run.into_iter().map(RunScores::from).collect(),
        runs: Vec::new(),
        runs_not_drawn: 0,
        incomplete: raw.incomplete_runs,
    })
}

/// Parses and validates one run log (`runs/run-NNNN.json`).
pub fn parse_run_log(text: &str, source: &Path) -> Result<RunData, ReportError> {
    let raw: RawRunLog = parse_json(text, source)?;
    let trajectory =
        validate_trajectory(raw.trajectory).map_err(|reason| invalid(source, reason))?;
    Ok(RunData {
        source: source.to_path_buf(),
        index: raw.index,
        scores: raw.metrics.into(),
        trajectory,
        complete: raw.complete,
        stop_reason: raw.stop_reason,
        planned_ticks: raw.planned_ticks,
    })
}

fn validate_trajectory(raw: RawTrajectory) -> Result<RunTrajectory, String> {
    if !(raw.d_star.is_finite() && raw.d_star > 0.0) {
        return Err(format!(
            "trajectory.d_star is {}, expected a positive distance",
            raw.d_star
        ));
    }
    let samples = raw.times.len().min(raw.poses.len()).min(raw.phi_star.len());
    if samples == 0 {
        return Err(
            "the trajectory has no samples (times, phi_star and poses must be non-empty)".into(),
        );
    }
    let n_robots = raw.poses[0].len();
    if n_robots == 0 {
        return Err("trajectory.poses[0] lists no robots".into());
    }
    if let Some(k) = raw.poses[..samples]
        .iter()
        .position(|row| row.len() != n_robots)
    {
        return Err(format!(
            "trajectory.poses[{k}] has {} poses, but poses[0] has {n_robots}",
            raw.poses[k].len()
        ));
    }
    if let Some(&(i, j)) = raw
        .edges
        .iter()
        .find(|&&(i, j)| i >= n_robots || j >= n_robots || i == j)
    {
        return Err(format!(
            "trajectory.edges has ({i}, {j}), but there are {n_robots} robots"
        ));
    }
    // `commands` normally has one entry fewer than the samples; more than `samples` cannot be timed.
    let ticks = raw.commands.len().min(samples);
    if let Some(k) = raw.commands[..ticks]
        .iter()
        .position(|row| row.len() != n_robots)
    {
        return Err(format!(
            "trajectory.commands[{k}] has {} commands, but there are {n_robots} robots",
            raw.commands[k].len()
        ));
    }
    Ok(RunTrajectory {
        dt: raw.dt,
        d_star: raw.d_star,
        v_star: or_nan(raw.v_star),
        edges: raw.edges,
        times: raw.times[..samples].iter().map(|&t| or_nan(t)).collect(),
        phi_star: raw.phi_star[..samples].iter().map(|&p| or_nan(p)).collect(),
        poses: raw
            .poses
            .into_iter()
            .take(samples)
            .map(|row| {
                row.into_iter()
                    .map(|p| Pose {
                        x: or_nan(p.x),
                        y: or_nan(p.y),
                        theta: or_nan(p.theta),
                    })
                    .collect()
            })
            .collect(),
        commands: raw
            .commands
            .into_iter()
            .take(ticks)
            .map(|row| {
                row.into_iter()
                    .map(|c| WheelCmd {
                        left: or_nan(c.left),
                        right: or_nan(c.right),
                    })
                    .collect()
            })
            .collect(),
        collisions: raw.collisions,
    })
}

fn parse_json<T: serde::de::DeserializeOwned>(text: &str, source: &Path) -> Result<T, ReportError> {
    serde_json::from_str(text).map_err(|e| ReportError::Json {
        path: source.to_path_buf(),
        source: e,
    })
}

fn invalid(source: &Path, reason: String) -> ReportError {
    ReportError::InvalidData {
        path: source.to_path_buf(),
        reason,
    }
}

// ---- discovery (I/O) -----------------------------------------------------------------------

/// Files of interest found under the input directory, before reading them.
#[derive(Debug, Default, PartialEq)]
struct Found {
    summaries: Vec<PathBuf>,
    loss_csvs: Vec<PathBuf>,
    profiles: Vec<PathBuf>,
}

/// True for a training loss curve file name: `*loss*.csv`.
pub fn is_loss_csv(file_name: &str) -> bool {
    file_name.ends_with(".csv") && file_name.contains("loss")
}

/// Reads every input under `root`. Hidden directories and `target` are not searched.
pub fn load_inputs(root: &Path) -> Result<Inputs, ReportError> {
    let meta = fs::metadata(root).map_err(|source| {
        if source.kind() == std::io::ErrorKind::NotFound {
            ReportError::MissingInputDir {
                dir: root.to_path_buf(),
            }
        } else {
            ReportError::Read {
                path: root.to_path_buf(),
                source,
            }
        }
    })?;
    if !meta.is_dir() {
        return Err(ReportError::NotADirectory {
            path: root.to_path_buf(),
        });
    }
    let mut found = Found::default();
    search(root, 0, &mut found)?;
    if found.summaries.is_empty() {
        return Err(ReportError::NoEvalOutput {
            dir: root.to_path_buf(),
        });
    }
    for list in [
        &mut found.summaries,
        &mut found.loss_csvs,
        &mut found.profiles,
    ] {
        list.sort();
    }
    let evals = found
        .summaries
        .iter()
        .map(|path| load_eval(root, path))
        .collect::<Result<Vec<_>, _>>()?;
    let loss_curves = found
        .loss_csvs
        .iter()
        .map(|path| parse_loss_csv(&read_text(path)?, path))
        .collect::<Result<Vec<_>, _>>()?;
    let profiles = found
        .profiles
        .iter()
        .map(|path| parse_profile(&read_text(path)?, path))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Inputs {
        root: root.to_path_buf(),
        evals,
        loss_curves,
        profiles,
    })
}

fn search(dir: &Path, depth: usize, found: &mut Found) -> Result<(), ReportError> {
    let read_error = |source| ReportError::Read {
        path: dir.to_path_buf(),
        source,
    };
    let mut entries: Vec<fs::DirEntry> = fs::read_dir(dir)
        .map_err(read_error)?
        .collect::<Result<_, _>>()
        .map_err(read_error)?;
    entries.sort_by_key(fs::DirEntry::file_name);
    for entry in entries {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        // `file_type` does not follow symbolic links, so a link cycle cannot recurse forever.
        let file_type = entry.file_type().map_err(|source| ReportError::Read {
            path: path.clone(),
            source,
        })?;
        if file_type.is_dir() {
            if depth < MAX_SEARCH_DEPTH && !name.starts_with('.') && name != "target" {
                search(&path, depth + 1, found)?;
            }
        } else if name == "summary.json" {
            found.summaries.push(path);
        } else if name == "profile.json" {
            found.profiles.push(path);
        } else if is_loss_csv(&name) {
            found.loss_csvs.push(path);
        }
    }
    Ok(())
}

fn load_eval(root: &Path, summary: &Path) -> Result<EvalData, ReportError> {
    let dir = summary.parent().unwrap_or(root);
    let name = match dir.strip_prefix(root) {
        // The input directory itself: its own name (`.` when it has none, like `/`).
        Ok(rel) if rel.as_os_str().is_empty() => root
            .canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| ".".to_owned()),
        Ok(rel) => rel.to_string_lossy().into_owned(),
        Err(_) => dir.to_string_lossy().into_owned(),
    };
    let mut eval = parse_summary(&read_text(summary)?, summary, &name)?;
    let logs = run_log_paths(&dir.join("runs"))?;
    eval.runs_not_drawn = logs.len().saturating_sub(MAX_RUNS_PLOTTED_PER_EVAL);
    eval.runs = logs
        .iter()
        .take(MAX_RUNS_PLOTTED_PER_EVAL)
        .map(|path| parse_run_log(&read_text(path)?, path))
        .collect::<Result<_, _>>()?;
    eval.runs.sort_by_key(|r| r.index);
    // A run log marked incomplete that the summary does not list (e.g. an older summary).
    for run in eval.runs.iter().filter(|r| !r.complete) {
        if !eval.incomplete.iter().any(|i| i.index == run.index) {
            eval.incomplete.push(IncompleteRun {
                index: run.index,
                ticks: Some(run.trajectory.commands.len()),
                planned_ticks: run.planned_ticks,
                stop_reason: run.stop_reason.clone(),
            });
        }
    }
    eval.incomplete.sort_by_key(|i| i.index);
    Ok(eval)
}

/// `run-*.json` files in `runs_dir`, sorted; none when the directory does not exist.
fn run_log_paths(runs_dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let entries = match fs::read_dir(runs_dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => {
            return Err(ReportError::Read {
                path: runs_dir.to_path_buf(),
                source,
            });
        }
    };
    let mut paths: BTreeMap<String, PathBuf> = BTreeMap::new();
    for entry in entries {
        let entry = entry.map_err(|source| ReportError::Read {
            path: runs_dir.to_path_buf(),
            source,
        })?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("run-") && name.ends_with(".json") {
            paths.insert(name, entry.path());
        }
    }
    Ok(paths.into_values().collect())
}

fn read_text(path: &Path) -> Result<String, ReportError> {
    fs::read_to_string(path).map_err(|source| ReportError::Read {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SUMMARY: &str = r#"{
      "controller": "policy", "models": ["m-1234"], "scenario": "table1", "seed": 7,
      "runs": 2, "success_rate_5": 0.5, "success_rate_10": 1.0,
      "median_convergence_s": 9.5, "median_rel_formation_error": 0.025, "median_orientation_error_rad": 0.03,
      "collisions": 0,
      "convergence_s": {"min": 9.0, "q1": 9.25, "median": 9.5, "q3": 9.75, "max": 10.0, "count": 2},
      "rel_formation_error": null, "orientation_error_rad": null,
      "per_run": [
        {"success_5": true, "success_10": true, "convergence_s_5": 9.0, "convergence_s_10": 9.0,
         "rel_formation_error": 0.02, "max_edge_window_error": 0.03, "orientation_error_rad": 0.03, "collisions": 0},
        {"success_5": false, "success_10": true, "convergence_s_5": null, "convergence_s_10": 10.0,
         "rel_formation_error": null, "max_edge_window_error": null, "orientation_error_rad": 0.04, "collisions": 1}
      ],
      "some_future_key": 1
    }"#;

    #[test]
    fn summary_keys_and_nulls_are_read() {
        let eval = parse_summary(SUMMARY, Path::new("x/summary.json"), "x").expect("valid summary");
        assert_eq!(eval.table.runs, 2);
        assert_eq!(eval.table.success_rate_5, 0.5);
        assert_eq!(eval.table.median_convergence_s, Some(9.5));
        assert_eq!(eval.fig9.convergence_s.map(|q| q.q3), Some(9.75));
        assert_eq!(eval.fig9.rel_formation_error, None);
        assert_eq!(eval.per_run.len(), 2);
        assert!(
            eval.per_run[1].rel_formation_error.is_nan(),
            "null is read as NaN"
        );
        assert_eq!(eval.per_run[1].collisions, 1);
        assert_eq!(eval.seed, Some(7));
    }

    #[test]
    fn truncated_summary_is_an_error_naming_the_file() {
        let err = parse_summary(
            &SUMMARY[..SUMMARY.len() / 2],
            Path::new("evals/a/summary.json"),
            "a",
        )
        .expect_err("truncated JSON");
        let message = err.to_string();
        assert!(matches!(err, ReportError::Json { .. }), "{message}");
        assert!(message.contains("evals/a/summary.json"), "{message}");
    }

    #[test]
    fn inconsistent_run_count_is_rejected() {
        let text = SUMMARY.replace("\"runs\": 2", "\"runs\": 3");
        let err =
            parse_summary(&text, Path::new("s.json"), "s").expect_err("runs != per_run.len()");
        assert!(err.to_string().contains("`per_run` lists 2 runs"), "{err}");
    }

    fn run_log(poses: &str, edges: &str) -> String {
        format!(
            r#"{{"index": 4, "metrics": {{"success_5": true, "success_10": true, "rel_formation_error": 0.01,
               "orientation_error_rad": 0.02, "collisions": 0}},
               "trajectory": {{"dt": 0.5, "d_star": 1.0, "v_star": 0.7, "edges": {edges},
                 "times": [0.0, 0.5], "phi_star": [0.1, null],
                 "poses": {poses},
                 "commands": [[{{"left": 0.1, "right": 0.2}}, {{"left": 0.3, "right": 0.4}}]],
                 "collisions": [[1, 0, 1]]}}}}"#
        )
    }

    #[test]
    fn run_log_is_read_and_validated() {
        let ok = run_log(
            r#"[[{"x":0,"y":0,"theta":0},{"x":1,"y":0,"theta":0}],[{"x":0.1,"y":0,"theta":0},{"x":1.1,"y":0,"theta":null}]]"#,
            "[[0, 1]]",
        );
        let run = parse_run_log(&ok, Path::new("runs/run-0004.json")).expect("valid run log");
        assert_eq!(run.index, 4);
        assert_eq!(run.trajectory.n_robots(), 2);
        assert_eq!(run.trajectory.poses[1][0].x, 0.1);
        assert!(run.trajectory.poses[1][1].theta.is_nan());
        assert!(run.trajectory.phi_star[1].is_nan());
        assert_eq!(run.trajectory.commands[0][1].right, 0.4);
        assert_eq!(run.trajectory.collisions, vec![(1, 0, 1)]);

        let ragged = run_log(
            r#"[[{"x":0,"y":0,"theta":0},{"x":1,"y":0,"theta":0}],[{"x":0.1,"y":0,"theta":0}]]"#,
            "[[0, 1]]",
        );
        let err =
            parse_run_log(&ragged, Path::new("runs/run-0004.json")).expect_err("ragged poses");
        assert!(err.to_string().contains("poses[1] has 1 poses"), "{err}");
        assert!(err.to_string().contains("runs/run-0004.json"), "{err}");

        let bad_edge = run_log(
            r#"[[{"x":0,"y":0,"theta":0},{"x":1,"y":0,"theta":0}],[{"x":0.1,"y":0,"theta":0},{"x":1,"y":0,"theta":0}]]"#,
            "[[0, 2]]",
        );
        let err =
            parse_run_log(&bad_edge, Path::new("r.json")).expect_err("edge to a missing robot");
        assert!(err.to_string().contains("(0, 2)"), "{err}");
    }

    #[test]
    fn incomplete_runs_are_read_and_older_files_are_complete() {
        let poses = r#"[[{"x":0,"y":0,"theta":0},{"x":1,"y":0,"theta":0}],[{"x":0.1,"y":0,"theta":0},{"x":1.1,"y":0,"theta":0}]]"#;
        let old = run_log(poses, "[[0, 1]]");
        let run = parse_run_log(&old, Path::new("runs/run-0004.json")).expect("older run log");
        assert!(run.complete, "a log without `complete` is complete");
        assert_eq!(run.stop_reason, None);

        let partial = old.replacen(
            "\"index\": 4,",
            "\"index\": 4, \"complete\": false, \"stop_reason\": \"interrupted by Ctrl-C\", \"planned_ticks\": 1200,",
            1,
        );
        assert_ne!(partial, old);
        let run = parse_run_log(&partial, Path::new("runs/run-0004.json")).expect("partial log");
        assert!(!run.complete);
        assert_eq!(run.stop_reason.as_deref(), Some("interrupted by Ctrl-C"));
        assert_eq!(run.planned_ticks, Some(1200));

        let eval = parse_summary(SUMMARY, Path::new("s.json"), "s").expect("summary");
        assert!(eval.incomplete.is_empty(), "an older summary lists none");
        let marked = SUMMARY.replacen(
            "\"some_future_key\": 1",
            r#""incomplete_runs": [{"index": 1, "ticks": 80, "planned_ticks": 1200, "stop_reason": "interrupted by SIGTERM"}]"#,
            1,
        );
        let eval = parse_summary(&marked, Path::new("s.json"), "s").expect("summary");
        assert_eq!(
            eval.incomplete,
            vec![IncompleteRun {
                index: 1,
                ticks: Some(80),
                planned_ticks: Some(1200),
                stop_reason: Some("interrupted by SIGTERM".into()),
            }]
        );
    }

    #[test]
    fn loss_csv_names() {
        assert!(is_loss_csv("policy-loss.csv"));
        assert!(is_loss_csv("loss.csv"));
        assert!(!is_loss_csv("loss.json"));
        assert!(!is_loss_csv("metrics.csv"));
    }
}
