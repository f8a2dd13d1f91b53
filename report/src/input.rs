//! Finding and reading the report's inputs: eval output directories (`summary.json` plus
//! `runs/run-NNNN.json`), training loss curves (`*loss*.csv`) and latency profiles (`profile.json`).
//!
//! The JSON files are read with their one definition in [`formation_schema`] (the types their
//! writers serialise), which checks each file's format and schema version and reads `null` back
//! as NaN where the writer may have written one. What cannot be drawn (no samples, a pose row
//! of the wrong length) is an error naming the file.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use formation_schema::{EvalOutput, RunLog, SchemaFile};

use crate::error::ReportError;
use crate::loss::{LossCurve, parse_loss_csv};
use crate::profile::{LatencyProfile, profile_view};

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
    /// Scaling tables (`scaling*.json`, written by `formation eval --robots ... --json`).
    pub scalings: Vec<ScalingData>,
    /// Response curves (`response*.json`, written by `formation gauge --json`).
    pub responses: Vec<ResponseData>,
    /// Reality ladders (`ladder*.json`, written by `formation eval --ladder PROFILE --json`).
    pub ladders: Vec<LadderData>,
}

/// A file the report reads whole with its one definition in [`formation_schema`] (a scaling
/// table, a response curve, a reality ladder), and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct SourcedFile<T> {
    /// The file.
    pub source: PathBuf,
    /// What it holds.
    pub content: T,
}

/// One reality ladder and where it came from.
pub type LadderData = SourcedFile<formation_schema::LadderTable>;

/// One response curve and where it came from.
pub type ResponseData = SourcedFile<formation_schema::ResponseCurve>;

/// One scaling table and where it came from.
pub type ScalingData = SourcedFile<formation_schema::ScalingTable>;

/// True for a reality ladder's file name: `ladder*.json`.
pub fn is_ladder_json(file_name: &str) -> bool {
    file_name.starts_with("ladder") && file_name.ends_with(".json")
}

/// True for a response curve's file name: `response*.json`.
pub fn is_response_json(file_name: &str) -> bool {
    file_name.starts_with("response") && file_name.ends_with(".json")
}

/// True for a scaling table's file name: `scaling*.json`.
pub fn is_scaling_json(file_name: &str) -> bool {
    file_name.starts_with("scaling") && file_name.ends_with(".json")
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
    /// The input each distinct model declares (its occupancy window and LIDAR), when the summary
    /// records it (policy only; absent in summaries written before it existed).
    pub model_inputs: Vec<formation_schema::ModelInput>,
    /// Scenario name.
    pub scenario: String,
    /// Base seed, when recorded.
    pub seed: Option<u64>,
    /// The Table I figures and the Fig. 9 statistics (over the runs that succeed at 10 %), as
    /// the summary holds them.
    pub table: Summary,
    /// Per-run metrics, in run order.
    pub per_run: Vec<RunMetrics>,
    /// Run logs drawn (at most [`MAX_RUNS_PLOTTED_PER_EVAL`]), in run order.
    pub runs: Vec<RunData>,
    /// Run logs present but not drawn.
    pub runs_not_drawn: usize,
    /// Runs that stopped before their last tick (from the summary and the run logs), by index.
    pub incomplete: Vec<IncompleteRun>,
    /// The runs whose logs the summary says belong beside it (`run_logs`; empty for summaries
    /// that do not say).
    pub expected_run_logs: Vec<usize>,
    /// False when the summary says its writer could not write the whole output.
    pub output_complete: bool,
    /// The run logs the summary lists that are not there: a partial output.
    pub missing_run_logs: Vec<PathBuf>,
    /// The team size the summary records (its models' `team_size` notes, or the per-robot
    /// `braked_ticks` of a multi-process eval); `None` when it records none (the expert's).
    pub recorded_team_size: Option<usize>,
}

impl EvalData {
    /// The evaluation's team size: the robots in its first run log's trajectory, else what the
    /// summary records; `None` when neither says.
    pub fn team_size(&self) -> Option<usize> {
        self.runs
            .first()
            .map(|run| run.trajectory.n_robots())
            .or(self.recorded_team_size)
    }
}

/// A run that stopped before its last tick, the metrics of one run (NaN where the writer could
/// not compute a value), the order statistics of a Fig. 9 quantity, an evaluation's Table I
/// figures and Fig. 9 statistics, and a run's trajectory.
pub use formation_schema::{IncompleteRun, Quantiles, RunMetrics, Summary, Trajectory};

/// One run log.
#[derive(Debug, Clone)]
pub struct RunData {
    /// The file it was read from.
    pub source: PathBuf,
    /// Run index.
    pub index: usize,
    /// Its metrics.
    pub scores: RunMetrics,
    /// Its trajectory.
    pub trajectory: Trajectory,
    /// False when the run stopped before its last tick (older logs, without the key, are
    /// complete).
    pub complete: bool,
    /// Why an incomplete run stopped, when recorded.
    pub stop_reason: Option<String>,
    /// The ticks the run was to play, when recorded.
    pub planned_ticks: Option<u64>,
}

// ---- parsing (pure) ------------------------------------------------------------------------

/// Parses a `summary.json` (the `formation eval` output). `name` is how the report labels it.
pub fn parse_summary(text: &str, source: &Path, name: &str) -> Result<EvalData, ReportError> {
    eval_data(
        formation_schema::from_json(text.as_bytes(), source)?,
        source,
        name,
    )
}

/// Checks a summary read from `source` and makes it the report's [`EvalData`] (without its run
/// logs).
pub fn eval_data(summary: EvalOutput, source: &Path, name: &str) -> Result<EvalData, ReportError> {
    let EvalOutput {
        controller,
        models,
        scenario,
        seed,
        summary,
        per_run,
        incomplete_runs,
        run_logs,
        complete,
        model_inputs,
        team_size,
        braked_ticks,
        ..
    } = summary;
    for (key, rate) in [
        ("success_rate_5", summary.success_rate_5),
        ("success_rate_10", summary.success_rate_10),
    ] {
        if !(0.0..=1.0).contains(&rate) {
            return Err(invalid(
                source,
                format!("{key} is {rate}, expected a fraction in 0..1"),
            ));
        }
    }
    if !per_run.is_empty() && per_run.len() != summary.runs {
        return Err(invalid(
            source,
            format!(
                "`runs` is {} but `per_run` lists {} runs",
                summary.runs,
                per_run.len()
            ),
        ));
    }
    Ok(EvalData {
        name: name.to_owned(),
        source: source.to_path_buf(),
        controller,
        models,
        model_inputs,
        scenario,
        seed,
        table: summary,
        per_run,
        runs: Vec::new(),
        runs_not_drawn: 0,
        incomplete: incomplete_runs,
        expected_run_logs: run_logs,
        output_complete: complete,
        missing_run_logs: Vec::new(),
        recorded_team_size: team_size
            .first()
            .map(|t| t.robots)
            .or((!braked_ticks.is_empty()).then_some(braked_ticks.len())),
    })
}

/// Parses and validates one run log (`runs/run-NNNN.json`).
pub fn parse_run_log(text: &str, source: &Path) -> Result<RunData, ReportError> {
    run_data(
        formation_schema::from_json(text.as_bytes(), source)?,
        source,
    )
}

/// Validates a run log read from `source` and makes it the report's [`RunData`].
pub fn run_data(log: RunLog, source: &Path) -> Result<RunData, ReportError> {
    let trajectory =
        validate_trajectory(log.trajectory).map_err(|reason| invalid(source, reason))?;
    Ok(RunData {
        source: source.to_path_buf(),
        index: log.index,
        scores: log.metrics,
        trajectory,
        complete: log.complete,
        stop_reason: log.stop_reason,
        planned_ticks: log.planned_ticks,
    })
}

/// Checks that every sample has one pose per robot, every command row one command per robot and
/// every edge names existing robots; keeps the samples that have a time, a heading and poses.
fn validate_trajectory(mut traj: Trajectory) -> Result<Trajectory, String> {
    if !(traj.d_star.is_finite() && traj.d_star > 0.0) {
        return Err(format!(
            "trajectory.d_star is {}, expected a positive distance",
            traj.d_star
        ));
    }
    let samples = traj
        .times
        .len()
        .min(traj.poses.len())
        .min(traj.phi_star.len());
    if samples == 0 {
        return Err(
            "the trajectory has no samples (times, phi_star and poses must be non-empty)".into(),
        );
    }
    let n_robots = traj.poses[0].len();
    if n_robots == 0 {
        return Err("trajectory.poses[0] lists no robots".into());
    }
    if let Some((k, poses)) = ragged_row(&traj.poses[..samples], n_robots) {
        return Err(format!(
            "trajectory.poses[{k}] has {poses} poses, but poses[0] has {n_robots}"
        ));
    }
    if let Some(&(i, j)) = traj
        .edges
        .iter()
        .find(|&&(i, j)| i >= n_robots || j >= n_robots || i == j)
    {
        return Err(format!(
            "trajectory.edges has ({i}, {j}), but there are {n_robots} robots"
        ));
    }
    // `commands` normally has one entry fewer than the samples; more than `samples` cannot be timed.
    let ticks = traj.commands.len().min(samples);
    if let Some((k, commands)) = ragged_row(&traj.commands[..ticks], n_robots) {
        return Err(format!(
            "trajectory.commands[{k}] has {commands} commands, but there are {n_robots} robots"
        ));
    }
    traj.times.truncate(samples);
    traj.phi_star.truncate(samples);
    traj.poses.truncate(samples);
    traj.commands.truncate(ticks);
    Ok(traj)
}

/// The first of `rows` that does not hold one entry per robot: its index and its length.
fn ragged_row<T>(rows: &[Vec<T>], n_robots: usize) -> Option<(usize, usize)> {
    rows.iter()
        .position(|row| row.len() != n_robots)
        .map(|k| (k, rows[k].len()))
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
    scalings: Vec<PathBuf>,
    responses: Vec<PathBuf>,
    ladders: Vec<PathBuf>,
}

/// What input of the report a file at `path` would be, by its name (and, for a run log, its
/// folder's): `None` for a file the report does not read.
pub fn input_kind(path: &Path) -> Option<&'static str> {
    let name = path.file_name()?.to_string_lossy();
    let in_runs = path
        .parent()
        .and_then(Path::file_name)
        .is_some_and(|folder| folder == "runs");
    if name == "summary.json" {
        Some("an eval summary, summary.json")
    } else if name == "profile.json" {
        Some("a latency profile, profile.json")
    } else if is_scaling_json(&name) {
        Some("a scaling table, scaling*.json")
    } else if is_response_json(&name) {
        Some("a response curve, response*.json")
    } else if is_ladder_json(&name) {
        Some("a reality ladder, ladder*.json")
    } else if is_loss_csv(&name) {
        Some("a training loss curve, *loss*.csv")
    } else if in_runs && name.starts_with("run-") && name.ends_with(".json") {
        Some("a run log, runs/run-NNNN.json")
    } else {
        None
    }
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
    if found.summaries.is_empty()
        && found.scalings.is_empty()
        && found.responses.is_empty()
        && found.ladders.is_empty()
    {
        return Err(ReportError::NoEvalOutput {
            dir: root.to_path_buf(),
        });
    }
    for list in [
        &mut found.summaries,
        &mut found.loss_csvs,
        &mut found.profiles,
        &mut found.scalings,
        &mut found.responses,
        &mut found.ladders,
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
        .map(|path| profile_view(&formation_schema::read_profile(path)?, path))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Inputs {
        root: root.to_path_buf(),
        evals,
        loss_curves,
        profiles,
        scalings: read_sourced(&found.scalings)?,
        responses: read_sourced(&found.responses)?,
        ladders: read_sourced(&found.ladders)?,
    })
}

/// Reads each of `paths` as a file of format `F`, in order.
fn read_sourced<F: SchemaFile>(paths: &[PathBuf]) -> Result<Vec<SourcedFile<F>>, ReportError> {
    paths
        .iter()
        .map(|path| {
            Ok(SourcedFile {
                source: path.clone(),
                content: formation_schema::read(path)?,
            })
        })
        .collect()
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
        } else if is_scaling_json(&name) {
            found.scalings.push(path);
        } else if is_response_json(&name) {
            found.responses.push(path);
        } else if is_ladder_json(&name) {
            found.ladders.push(path);
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
    let mut eval = eval_data(formation_schema::read_summary(summary)?, summary, &name)?;
    eval.missing_run_logs = eval
        .expected_run_logs
        .iter()
        .map(|&index| run_log_path(dir, index))
        .filter(|path| !path.is_file())
        .collect();
    let logs = run_log_paths(&dir.join("runs"))?;
    eval.runs_not_drawn = logs.len().saturating_sub(MAX_RUNS_PLOTTED_PER_EVAL);
    eval.runs = logs
        .iter()
        .take(MAX_RUNS_PLOTTED_PER_EVAL)
        .map(|path| run_data(formation_schema::read_run_log(path)?, path))
        .collect::<Result<_, _>>()?;
    eval.runs.sort_by_key(|r| r.index);
    // A run log marked incomplete that the summary does not list (e.g. an older summary).
    for run in eval.runs.iter().filter(|r| !r.complete) {
        if !eval.incomplete.iter().any(|i| i.index == run.index) {
            eval.incomplete.push(IncompleteRun {
                index: run.index,
                ticks: run.trajectory.commands.len(),
                planned_ticks: run.planned_ticks,
                stop_reason: run.stop_reason.clone(),
            });
        }
    }
    eval.incomplete.sort_by_key(|i| i.index);
    Ok(eval)
}

/// Where run `index`'s log lies under an output directory: `runs/run-NNNN.json`.
fn run_log_path(dir: &Path, index: usize) -> PathBuf {
    dir.join("runs").join(format!("run-{index:04}.json"))
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
    use formation_proto::{Pose, WheelCmd};
    use formation_schema::{Summary, to_json};

    fn metrics(success_5: bool, convergence_s_10: f64, rel_formation_error: f64) -> RunMetrics {
        RunMetrics {
            success_5,
            success_10: true,
            convergence_s_5: success_5.then_some(convergence_s_10),
            convergence_s_10: Some(convergence_s_10),
            rel_formation_error,
            max_edge_window_error: 0.03,
            orientation_error_rad: 0.03,
            collisions: usize::from(!success_5),
            team: None,
            incomplete: None,
        }
    }

    fn summary() -> EvalOutput {
        EvalOutput::of_runs(
            "policy",
            vec!["m-1234".into()],
            "table1",
            Some(7),
            Summary {
                runs: 2,
                runs_incomplete: 0,
                success_rate_5: 0.5,
                success_rate_10: 1.0,
                median_convergence_s: Some(9.5),
                median_rel_formation_error: Some(0.025),
                median_orientation_error_rad: Some(0.03),
                medians_over: None,
                collisions: 1,
                // The two runs' convergence times, 9 and 10 s, as the eval writer summarizes them.
                convergence_s: formation_world::metrics::quantiles([9.0, 10.0]),
                rel_formation_error: None,
                orientation_error_rad: None,
                anchor_success_rate: None,
                connected_rate: None,
            },
            vec![metrics(true, 9.0, 0.02), metrics(false, 10.0, f64::NAN)],
        )
    }

    fn text<F: formation_schema::SchemaFile>(value: &F) -> String {
        String::from_utf8(to_json(value).expect("json")).expect("utf-8")
    }

    #[test]
    fn summary_keys_and_nulls_are_read() {
        let eval = parse_summary(&text(&summary()), Path::new("x/summary.json"), "x")
            .expect("valid summary");
        assert_eq!(eval.table.runs, 2);
        assert_eq!(eval.table.success_rate_5, 0.5);
        assert_eq!(eval.table.median_convergence_s, Some(9.5));
        assert_eq!(eval.table.convergence_s.map(|q| q.q3), Some(9.75));
        assert_eq!(eval.table.rel_formation_error, None);
        assert_eq!(eval.per_run.len(), 2);
        assert!(
            eval.per_run[1].rel_formation_error.is_nan(),
            "NaN, written as null, is read as NaN"
        );
        assert_eq!(eval.per_run[1].collisions, 1);
        assert_eq!(eval.seed, Some(7));
    }

    #[test]
    fn truncated_summary_is_an_error_naming_the_file() {
        let text = text(&summary());
        let err = parse_summary(
            &text[..text.len() / 2],
            Path::new("evals/a/summary.json"),
            "a",
        )
        .expect_err("truncated JSON");
        let message = err.to_string();
        assert!(
            matches!(
                err,
                ReportError::Schema(formation_schema::SchemaError::Parse { .. })
            ),
            "{message}"
        );
        assert!(message.contains("evals/a/summary.json"), "{message}");
    }

    #[test]
    fn inconsistent_run_count_is_rejected() {
        let mut three = summary();
        three.summary.runs = 3;
        let err = parse_summary(&text(&three), Path::new("s.json"), "s")
            .expect_err("runs != per_run.len()");
        assert!(err.to_string().contains("`per_run` lists 2 runs"), "{err}");
    }

    fn pose(x: f64, theta: f64) -> Pose {
        Pose { x, y: 0.0, theta }
    }

    fn run_log(poses: Vec<Vec<Pose>>, edges: Vec<(usize, usize)>) -> RunLog {
        RunLog {
            index: 4,
            metrics: metrics(true, 9.0, 0.01),
            trajectory: Trajectory {
                dt: 0.5,
                d_star: 1.0,
                v_star: 0.7,
                edges,
                neighbours: formation_proto::NeighbourRule::AllPairs,
                times: vec![0.0, 0.5],
                phi_star: vec![0.1, f64::NAN],
                poses,
                commands: vec![vec![
                    WheelCmd {
                        left: 0.1,
                        right: 0.2,
                    },
                    WheelCmd {
                        left: 0.3,
                        right: 0.4,
                    },
                ]],
                collisions: vec![(1, 0, 1)],
            },
            clock: "in-process".into(),
            models: Vec::new(),
            complete: true,
            stop_reason: None,
            planned_ticks: None,
        }
    }

    fn two_robots() -> Vec<Vec<Pose>> {
        vec![
            vec![pose(0.0, 0.0), pose(1.0, 0.0)],
            vec![pose(0.1, 0.0), pose(1.1, f64::NAN)],
        ]
    }

    #[test]
    fn run_log_is_read_and_validated() {
        let ok = text(&run_log(two_robots(), vec![(0, 1)]));
        let run = parse_run_log(&ok, Path::new("runs/run-0004.json")).expect("valid run log");
        assert_eq!(run.index, 4);
        assert_eq!(run.trajectory.n_robots(), 2);
        assert_eq!(run.trajectory.poses[1][0].x, 0.1);
        assert!(run.trajectory.poses[1][1].theta.is_nan());
        assert!(run.trajectory.phi_star[1].is_nan());
        assert_eq!(run.trajectory.commands[0][1].right, 0.4);
        assert_eq!(run.trajectory.collisions, vec![(1, 0, 1)]);

        let mut poses = two_robots();
        poses[1].pop();
        let ragged = text(&run_log(poses, vec![(0, 1)]));
        let err =
            parse_run_log(&ragged, Path::new("runs/run-0004.json")).expect_err("ragged poses");
        assert!(err.to_string().contains("poses[1] has 1 poses"), "{err}");
        assert!(err.to_string().contains("runs/run-0004.json"), "{err}");

        let bad_edge = text(&run_log(two_robots(), vec![(0, 2)]));
        let err =
            parse_run_log(&bad_edge, Path::new("r.json")).expect_err("edge to a missing robot");
        assert!(err.to_string().contains("(0, 2)"), "{err}");
    }

    #[test]
    fn incomplete_runs_are_read_and_older_files_are_complete() {
        // A run log from before `complete` and the schema version existed.
        let mut old: serde_json::Value =
            serde_json::to_value(run_log(two_robots(), vec![(0, 1)])).expect("json");
        old.as_object_mut().expect("object").remove("complete");
        let run = parse_run_log(&old.to_string(), Path::new("runs/run-0004.json"))
            .expect("older run log");
        assert!(run.complete, "a log without `complete` is complete");
        assert_eq!(run.stop_reason, None);

        let partial = RunLog {
            complete: false,
            stop_reason: Some("interrupted by Ctrl-C".into()),
            planned_ticks: Some(1200),
            ..run_log(two_robots(), vec![(0, 1)])
        };
        let run =
            parse_run_log(&text(&partial), Path::new("runs/run-0004.json")).expect("partial log");
        assert!(!run.complete);
        assert_eq!(run.stop_reason.as_deref(), Some("interrupted by Ctrl-C"));
        assert_eq!(run.planned_ticks, Some(1200));

        let eval = parse_summary(&text(&summary()), Path::new("s.json"), "s").expect("summary");
        assert!(eval.incomplete.is_empty());
        let stopped = IncompleteRun {
            index: 1,
            ticks: 80,
            planned_ticks: Some(1200),
            stop_reason: Some("interrupted by SIGTERM".into()),
        };
        let marked = EvalOutput {
            incomplete_runs: vec![stopped.clone()],
            team_size: Vec::new(),
            goal_speed: Vec::new(),
            ..summary()
        };
        let eval = parse_summary(&text(&marked), Path::new("s.json"), "s").expect("summary");
        assert_eq!(eval.incomplete, vec![stopped]);
    }

    #[test]
    fn loss_csv_names() {
        assert!(is_loss_csv("policy-loss.csv"));
        assert!(is_loss_csv("loss.csv"));
        assert!(!is_loss_csv("loss.json"));
        assert!(!is_loss_csv("metrics.csv"));
    }
}
