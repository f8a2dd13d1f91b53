//! `formation eval`: runs a controller over a scenario's runs and reports the paper's Table I and
//! Fig. 9 figures.
//!
//! In-process evaluation is `formation_learning::evaluate_runs` (rayon); every run is a pure
//! function of (scenario, base seed, run index, model), so the result does not depend on the
//! thread count and the same seed gives byte-identical JSON. `--processes` runs every robot's
//! policy in its own OS process, over iceoryx2 or (`--transport zenoh --listen E`) Zenoh, and
//! must give the same JSON. `--robots 3,5,8`
//! evaluates the expert (and the policy, when `--model` is given) over team sizes and writes the
//! scaling table (`formation_learning::scaling`).

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use formation_expert::ExpertGains;
use formation_learning::rollout::with_threads;
use formation_learning::scaling::{ScalingDriver, evaluate_scaling, scaling_text};
use formation_learning::{Driver, LearningError};
use formation_runtime::transport::Transport;
use formation_schema::SchemaFile;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics};
use formation_world::{RunLog, Scenario, Trajectory};

use crate::args::{ControllerKind, EvalArgs, MergeArgs};
use crate::paths;
use crate::table::table_text;
use crate::team_models::{
    checked_models, goal_speeds_of, model_inputs_of, policy_driver, print_goal_speed_notes,
    print_team_size_notes, resolved_models_per_robot, team_sizes_of,
};

/// What `formation eval` writes as JSON, and a run that stopped early: defined in
/// [`formation_schema`].
pub use formation_schema::{EvalOutput, IncompleteRun};

/// The output of runs with these per-run metrics: the Table I and Fig. 9 summary over them.
pub use formation_learning::eval_output;

/// One evaluated run.
pub struct RunResult {
    /// Run index.
    pub index: usize,
    /// Its metrics.
    pub metrics: RunMetrics,
    /// Its trajectory, when it was asked to be kept.
    pub trajectory: Option<Trajectory>,
    /// How it was clocked: `in-process`, or `lockstep` over processes.
    pub clock: &'static str,
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(len: usize, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{msg} [{elapsed_precise}] {bar:40} {pos}/{len} ({eta} left)",
    ) {
        bar.set_style(style);
    }
    bar.set_message(what.to_owned());
    bar
}

/// A sweep of `rows` rows (a team size and driver each) of `runs` runs, behind a progress bar.
pub struct RowSweep {
    /// The progress bar's label (`scaling`, `gauge`).
    pub what: &'static str,
    /// What was done to every run, for the closing line (`evaluated`, `gauged`).
    pub did: &'static str,
    /// Rows in the sweep.
    pub rows: usize,
    /// Runs per row.
    pub runs: usize,
}

impl RowSweep {
    /// A sweep of `rows` rows of `runs` runs, `what` on its bar, said to be `did` when done.
    pub fn new(what: &'static str, did: &'static str, rows: usize, runs: usize) -> RowSweep {
        RowSweep {
            what,
            did,
            rows,
            runs,
        }
    }

    /// Runs `sweep` on `threads` threads (`None`: one per core), handing it the callback that
    /// moves the bar (the row, and the runs done in it); then says on stderr how many runs it
    /// did and how long that took.
    pub fn run<T: Send>(
        &self,
        threads: Option<usize>,
        sweep: impl FnOnce(&(dyn Fn(usize, usize) + Sync)) -> Result<T, LearningError> + Send,
    ) -> anyhow::Result<T> {
        let bar = progress_bar(self.runs * self.rows, self.what);
        let started = Instant::now();
        let runs = self.runs;
        let done = with_threads(threads, || {
            sweep(&|row, done| bar.set_position((row * runs + done) as u64))
        })??;
        bar.finish_and_clear();
        eprintln!(
            "{} {} runs in {:.1} s",
            self.did,
            self.runs * self.rows,
            started.elapsed().as_secs_f64()
        );
        Ok(done)
    }
}

/// The runs `first..end` of `scenario` that `--first-run first` and `--runs runs` (default:
/// every run from `first` on) select; none is an error that says what they were to be used for
/// (`to`: `play`, `label`) and names `--runs` with its value (`runs_value`: `N`, `R`).
pub fn run_share(
    scenario: &Scenario,
    first: usize,
    runs: Option<usize>,
    to: &str,
    runs_value: &str,
) -> anyhow::Result<Range<usize>> {
    let runs = runs.unwrap_or_else(|| scenario.runs().saturating_sub(first));
    let Some(end) = first.checked_add(runs).filter(|_| runs > 0) else {
        anyhow::bail!(
            "--first-run {first} leaves no runs to {to}: give --runs {runs_value} (the scenario has {} runs)",
            scenario.runs()
        );
    };
    Ok(first..end)
}

/// Prints `text` and, when `json` names a file, writes `value` there as JSON and says so.
pub fn print_and_write_json<F: SchemaFile>(
    text: &str,
    value: &F,
    json: Option<&Path>,
) -> anyhow::Result<()> {
    print!("{text}");
    if let Some(json) = json {
        paths::write_atomic(json, &formation_schema::to_json_pretty(value)?)?;
        println!("wrote {}", json.display());
    }
    Ok(())
}

/// Writes the eval output directory the report reads: for the runs whose trajectory was kept,
/// `runs/run-NNNN.json` in the run-log format the world writes, then `summary.json`, which lists
/// them (`run_logs`). A summary already there is removed first and the new one comes last, so a
/// summary never stands beside run logs it does not describe. When a run log cannot be written
/// (a full disk), the summary is still written if it can be, marked `complete: false`, and the
/// error says what failed and that the output is partial ([`PartialOutput`]).
pub fn write_eval_dir(dir: &Path, out: &EvalOutput, results: &[RunResult]) -> anyhow::Result<()> {
    let summary_path = dir.join("summary.json");
    match std::fs::remove_file(&summary_path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(paths::WriteError::new(&summary_path, e).into());
        }
        _ => {}
    }
    let mut summary = out.clone();
    summary.run_logs = results
        .iter()
        .filter(|r| r.trajectory.is_some())
        .map(|r| r.index)
        .collect();
    let mut failed = None;
    for r in results {
        if let Some(traj) = &r.trajectory {
            let log = RunLog {
                index: r.index,
                metrics: r.metrics.clone(),
                trajectory: traj.clone(),
                clock: r.clock.to_owned(),
                models: out.models.clone(),
                complete: r.metrics.is_complete(),
                stop_reason: None,
                planned_ticks: Some(
                    r.metrics
                        .incomplete
                        .map_or(traj.commands.len() as u64, |p| p.planned_ticks),
                ),
            };
            let written = paths::write_atomic(
                &formation_world::runlog::log_paths(dir, r.index).0,
                &formation_schema::to_json(&log)?,
            );
            if let Err(e) = written {
                failed = Some(e);
                break;
            }
        }
    }
    let Some(cause) = failed else {
        paths::write_atomic(&summary_path, &formation_schema::to_json_pretty(&summary)?)?;
        return Ok(());
    };
    summary.complete = false;
    let summary_written =
        paths::write_atomic(&summary_path, &formation_schema::to_json_pretty(&summary)?).is_ok();
    Err(PartialOutput {
        dir: dir.to_path_buf(),
        cause,
        summary_written,
    }
    .into())
}

/// An `eval --out` whose files could not all be written.
#[derive(Debug, thiserror::Error)]
#[error(
    "{cause}; the output in {} is partial: {}",
    dir.display(),
    if *summary_written {
        "its summary.json is marked incomplete (`complete: false`), and `formation report` names the run logs it lacks"
    } else {
        "no summary.json could be written either, so `formation report` does not read it"
    }
)]
pub struct PartialOutput {
    /// The output directory.
    pub dir: PathBuf,
    /// The write that failed.
    pub cause: paths::WriteError,
    /// Whether the summary, marked incomplete, was written after all.
    pub summary_written: bool,
}

/// The transport flags of `eval`: Zenoh's flags need `--transport zenoh`, and a transport is
/// something only processes have, so `--transport zenoh` needs `--processes`.
pub fn network_flags(args: &EvalArgs) -> anyhow::Result<crate::launch::NetworkFlags> {
    let flags = crate::launch::NetworkFlags {
        transport: args.transport,
        listen: args.listen.clone(),
        ..Default::default()
    };
    flags.refuse_misplaced()?;
    if args.transport != Transport::Iceoryx2 && !args.processes {
        anyhow::bail!(
            "--transport {} joins the world and agent processes, and an evaluation without \
             --processes runs every robot in this process: add --processes (e.g. `formation \
             eval --processes --transport zenoh --listen tcp/127.0.0.1:7447`)",
            args.transport
        );
    }
    Ok(flags)
}

/// Evaluates and returns the output and the per-run results (shared by `eval` and `demo`).
pub fn evaluate(args: &EvalArgs) -> anyhow::Result<(EvalOutput, Vec<RunResult>)> {
    let network = network_flags(args)?;
    let scenario = Scenario::from_path(&args.scenario)?;
    // `--robots N` with --out and the like: the scenario's team resized as the scaling table does.
    let scenario = match args.robots.as_deref() {
        Some(&[robots]) => scenario.with_robots(robots)?,
        _ => scenario,
    };
    let runs = args.runs.unwrap_or_else(|| scenario.runs());
    if runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let seed = args.seed.unwrap_or_else(|| scenario.seed());
    let keep_n = args
        .save_trajectories
        .unwrap_or(if runs <= 5 { runs } else { 0 });
    let team = eval_team(args, &scenario)?;
    let plan = EvalRuns {
        scenario: &scenario,
        seed,
        runs,
        keep_n,
        record: record_settings(args, &scenario, seed, runs, &team)?,
    };
    let bar = progress_bar(runs, "eval");
    let started = Instant::now();
    let results: Vec<RunResult> = if args.processes {
        results_over_processes(args, &plan, &team.models, &network, &bar)?
    } else {
        results_in_process(args, &plan, &team, &bar)?
    };
    bar.finish_and_clear();
    let elapsed = started.elapsed().as_secs_f64();
    let per_run: Vec<RunMetrics> = results.iter().map(|r| r.metrics.clone()).collect();
    let mut out = eval_output(
        controller_name(args),
        team.model_ids,
        scenario.name(),
        Some(seed),
        per_run,
    );
    out.team_size = team.team_size;
    out.goal_speed = team.goal_speed;
    out.model_inputs = team.model_inputs;
    eprintln!(
        "evaluated {runs} runs in {elapsed:.1} s ({:.2} s per run)",
        elapsed / runs as f64
    );
    Ok((out, results))
}

/// The runs an evaluation plays.
struct EvalRuns<'a> {
    /// The scenario.
    scenario: &'a Scenario,
    /// The base seed.
    seed: u64,
    /// How many runs.
    runs: usize,
    /// The first `keep_n` runs keep their trajectories.
    keep_n: usize,
    /// What to record (`--record`), checked.
    record: Option<formation_record::RecordSettings>,
}

impl EvalRuns<'_> {
    /// Whether run `i` keeps its trajectory.
    fn keep(&self, i: usize) -> bool {
        i < self.keep_n
    }
}

/// What `--record DIR` (at most `--record-runs` runs) or the demo's recording of run 0 asks
/// for, checked before any run.
fn record_settings(
    args: &EvalArgs,
    scenario: &Scenario,
    seed: u64,
    runs: usize,
    team: &EvalTeam,
) -> anyhow::Result<Option<formation_record::RecordSettings>> {
    use formation_record::RecordTarget;
    let target = match (&args.record, &args.record_file) {
        (Some(dir), _) => RecordTarget::Folder {
            dir: dir.clone(),
            max_runs: args.record_runs.unwrap_or(if runs <= 5 { runs } else { 5 }),
        },
        (None, Some(file)) => RecordTarget::File(file.clone()),
        (None, None) => return Ok(None),
    };
    let clock = if args.processes {
        crate::launch::ClockMode::Lockstep.as_str()
    } else {
        "in-process"
    };
    let launch =
        crate::record::launch_info(scenario, seed, clock, controller_name(args), &team.models);
    crate::record::checked_settings(target, launch).map(Some)
}

/// The team an evaluation drives: no models for the expert, else each robot's model.
struct EvalTeam {
    /// Each robot's model file (empty for the expert).
    models: Vec<PathBuf>,
    /// Each robot's model id, for the output.
    model_ids: Vec<String>,
    /// The team-size notes of the models, for the output.
    team_size: Vec<formation_schema::ModelTeamSize>,
    /// The models trained at another v* than the runs', for the output.
    goal_speed: Vec<formation_schema::ModelGoalSpeed>,
    /// The input each distinct model declares, for the output.
    model_inputs: Vec<formation_schema::ModelInput>,
}

/// Resolves and checks the team's models (printing their team-size and v* notes); refuses
/// `--processes` with the expert.
fn eval_team(args: &EvalArgs, scenario: &Scenario) -> anyhow::Result<EvalTeam> {
    let mut team_size = Vec::new();
    let mut goal_speed = Vec::new();
    let mut model_inputs = Vec::new();
    let (models, model_ids) = match args.controller {
        ControllerKind::Expert => {
            if args.processes {
                anyhow::bail!(
                    "--processes runs learned agents; the expert sees every robot and runs in-process only"
                );
            }
            (Vec::new(), Vec::new())
        }
        ControllerKind::ExpertOwnScan => {
            if args.processes {
                anyhow::bail!(
                    "--processes runs learned agents; --controller expert-own-scan runs every \
                     robot's own-scan pilot in-process only: drop --processes"
                );
            }
            (Vec::new(), Vec::new())
        }
        ControllerKind::Policy => {
            let default = paths::resolve_model_for(args.model.as_deref(), scenario)?;
            let models = resolved_models_per_robot(scenario, &default)?;
            let checked = checked_models(&models, scenario)?;
            team_size = team_sizes_of(&checked, scenario.n_robots());
            model_inputs = model_inputs_of(&checked);
            goal_speed = goal_speeds_of(&checked, scenario.v_star());
            print_team_size_notes(&team_size);
            print_goal_speed_notes(&goal_speed);
            (models, checked.into_iter().map(|(id, _)| id).collect())
        }
    };
    Ok(EvalTeam {
        models,
        model_ids,
        team_size,
        goal_speed,
        model_inputs,
    })
}

/// `--processes`: plays the runs with every robot's agent in its own process (lockstep), writing
/// the latency profile to `--out`.
fn results_over_processes(
    args: &EvalArgs,
    plan: &EvalRuns<'_>,
    models: &[PathBuf],
    network: &crate::launch::NetworkFlags,
    bar: &indicatif::ProgressBar,
) -> anyhow::Result<Vec<RunResult>> {
    let default = models.first().cloned().context("no robots")?;
    let evaluation = crate::launch::ProcessEvalRuns {
        scenario: plan.scenario,
        base_seed: plan.seed,
        runs: plan.runs,
        default_model: &default,
        clock: crate::launch::ClockMode::Lockstep,
        network,
    };
    let evaluated = crate::launch::eval_over_processes_recorded(
        &evaluation,
        plan.record.clone(),
        args.foxglove,
        &mut |n| bar.set_position(n as u64),
    )?;
    if let Some(dir) = &args.out {
        // The report shows it as the latency profile.
        paths::write_atomic(
            &dir.join("profile.json"),
            &formation_schema::to_json_pretty(&evaluated.latency)?,
        )?;
    }
    let cfg = MetricsConfig::default();
    Ok(evaluated
        .trajectories
        .into_iter()
        .enumerate()
        .map(|(index, traj)| RunResult {
            index,
            metrics: run_metrics(
                &traj,
                plan.scenario.run_spec(plan.seed, index).ticks(),
                &cfg,
            ),
            trajectory: plan.keep(index).then_some(traj),
            clock: crate::launch::ClockMode::Lockstep.as_str(),
        })
        .collect())
}

/// Plays the runs in this process (on `--threads` threads) with the expert or the models, then
/// records the runs `--record` asks for.
fn results_in_process(
    args: &EvalArgs,
    plan: &EvalRuns<'_>,
    team: &EvalTeam,
    bar: &indicatif::ProgressBar,
) -> anyhow::Result<Vec<RunResult>> {
    let driver = driver_of(args, team);
    let recorded = |i: usize| {
        plan.record
            .as_ref()
            .is_some_and(|r| r.target.path_for(i, i, plan.runs).is_some())
    };
    // A recorded run keeps its trajectory until the recording is compared with it.
    let keep = |i: usize| plan.keep(i) || recorded(i);
    let mut results: Vec<RunResult> = with_threads(args.threads, || {
        formation_learning::evaluate_runs(
            plan.scenario,
            plan.seed,
            plan.runs,
            &driver,
            &MetricsConfig::default(),
            &keep,
            &|n| bar.set_position(n as u64),
        )
    })??
    .into_iter()
    .map(|r| RunResult {
        index: r.index,
        metrics: r.metrics,
        trajectory: r.trajectory,
        clock: "in-process",
    })
    .collect();
    if let Some(settings) = &plan.record {
        bar.finish_and_clear();
        crate::record::record_in_process(
            plan.scenario,
            plan.seed,
            plan.runs,
            settings,
            &team.model_ids,
            &|| Ok(driver.controller(plan.scenario)?),
            &|i| results.get(i).and_then(|r| r.trajectory.clone()),
        )?;
    }
    for r in &mut results {
        if !plan.keep(r.index) {
            r.trajectory = None;
        }
    }
    Ok(results)
}

/// `Ok` unless `--gains` was given to a controller other than the expert's own-scan law (the
/// scored expert is the baseline and keeps its gains; a policy has none).
pub fn refuse_gains_without_own_scan(args: &EvalArgs) -> anyhow::Result<()> {
    if args.gains.is_some() && args.controller != ControllerKind::ExpertOwnScan {
        anyhow::bail!(
            "--gains sets the gains of --controller expert-own-scan, not of --controller {}: the \
             scored expert keeps its own (try them with `formation gauge --expert JSON`); add \
             --controller expert-own-scan or drop --gains",
            controller_name(args)
        );
    }
    Ok(())
}

/// What drives the robots of an in-process evaluation.
fn driver_of(args: &EvalArgs, team: &EvalTeam) -> Driver {
    match args.controller {
        ControllerKind::Expert => Driver::Expert(ExpertGains::default()),
        ControllerKind::ExpertOwnScan => Driver::ExpertOwnScan(args.gains.unwrap_or_default()),
        ControllerKind::Policy => Driver::Policy {
            models: team.models.clone(),
        },
    }
}

/// `expert`, `expert-own-scan` or `policy`, as the outputs name the controller.
fn controller_name(args: &EvalArgs) -> &'static str {
    match args.controller {
        ControllerKind::Expert => "expert",
        ControllerKind::ExpertOwnScan => formation_expert::own_scan::OWN_SCAN_ID,
        ControllerKind::Policy => "policy",
    }
}

/// `formation eval --shard FILE [--first-run A] [--runs N] [--robots R]`: plays runs `A .. A + N`
/// of the evaluation in this process (N: the scenario's runs after A), the scenario resized to
/// `R` robots when given (one size: a sweep cell), and writes their metrics as a shard, for
/// `formation merge`.
pub fn shard_command(args: &EvalArgs, shard: &Path) -> anyhow::Result<()> {
    if args.processes
        || args.out.is_some()
        || args.json.is_some()
        || args.save_trajectories.is_some()
        || args.record.is_some()
        || args.robots.as_ref().is_some_and(|sizes| sizes.len() != 1)
    {
        anyhow::bail!(
            "--shard plays a share of the runs in this process and writes only the shard: drop \
             --processes, --out, --json, --save-trajectories and --record, and give --robots one \
             team size at most (`formation merge SHARDS --json FILE` writes the summary)"
        );
    }
    formation_proto::files::check_output_file(shard)?;
    let mut scenario = Scenario::from_path(&args.scenario)?;
    if let Some(&[robots]) = args.robots.as_deref() {
        scenario = scenario.with_robots(robots)?;
    }
    let first = args.first_run.unwrap_or(0);
    let share = run_share(&scenario, first, args.runs, "play", "N")?;
    let seed = args.seed.unwrap_or_else(|| scenario.seed());
    let team = eval_team(args, &scenario)?;
    let driver = driver_of(args, &team);
    let bar = progress_bar(share.len(), "eval shard");
    let results = with_threads(args.threads, || {
        formation_learning::evaluate_run_range(
            &scenario,
            seed,
            share.clone(),
            &driver,
            &MetricsConfig::default(),
            &|_| false,
            &|n| bar.set_position(n as u64),
        )
    })??;
    bar.finish_and_clear();
    let out = formation_schema::EvalShard {
        controller: controller_name(args).to_owned(),
        models: team.model_ids,
        scenario: scenario.name().to_owned(),
        seed,
        team_size: team.team_size,
        goal_speed: team.goal_speed,
        model_inputs: team.model_inputs,
        first_run: first,
        per_run: results.into_iter().map(|r| r.metrics).collect(),
    };
    paths::write_atomic(shard, &formation_schema::to_json(&out)?)?;
    println!(
        "wrote {} (runs {}..{})",
        shard.display(),
        share.start,
        share.end
    );
    Ok(())
}

/// `formation merge SHARDS [--runs N] [--json FILE]`: the summary of an evaluation from its
/// shards, byte for byte what one `formation eval --json` of all the runs writes.
pub fn merge_command(args: &MergeArgs) -> anyhow::Result<()> {
    if let Some(json) = &args.json {
        formation_proto::files::check_output_file(json)?;
    }
    let shards = args
        .shards
        .iter()
        .map(|path| formation_schema::read::<formation_schema::EvalShard>(path))
        .collect::<Result<Vec<_>, _>>()?;
    let out = formation_learning::shards::merge_shards(&shards, args.runs)?;
    print_and_write_json(&table_text(&out), &out, args.json.as_deref())?;
    Ok(())
}

/// `formation eval --robots ...`: the scaling table over team sizes.
pub fn scaling_command(args: &EvalArgs, sizes: &[usize]) -> anyhow::Result<()> {
    if single_team_outputs(args) {
        anyhow::bail!(
            "--robots {} evaluates several team sizes in-process and writes a table (print and \
             --json); --processes, --out, --save-trajectories and --record are for one team: \
             drop them, or evaluate one team size at a time (--robots N)",
            sizes
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(",")
        );
    }
    let base = Scenario::from_path(&args.scenario)?;
    let runs = args.runs.unwrap_or_else(|| base.runs());
    let seed = args.seed.unwrap_or_else(|| base.seed());
    let mut drivers = vec![ScalingDriver::Expert(ExpertGains::default())];
    // The expert is the baseline of every size; the policy (`--model`, else the shipped one)
    // unless `--controller expert` asks for the expert alone, or the expert's law on each
    // robot's own scan (`--controller expert-own-scan`).
    match args.controller {
        ControllerKind::Policy => drivers.push(policy_driver(args.model.as_deref(), &base, sizes)?),
        ControllerKind::ExpertOwnScan => {
            drivers.push(ScalingDriver::ExpertOwnScan(args.gains.unwrap_or_default()));
        }
        ControllerKind::Expert => {}
    }
    let table = RowSweep::new("scaling", "evaluated", sizes.len() * drivers.len(), runs)
        .run(args.threads, |progress| {
            evaluate_scaling(&base, sizes, seed, runs, &drivers, progress)
        })?;
    print_and_write_json(&scaling_text(&table), &table, args.json.as_deref())
}

/// Whether `args` asks for what only an evaluation of one team gives (`--processes`, `--out`,
/// `--save-trajectories`, `--record`), rather than the scaling table.
fn single_team_outputs(args: &EvalArgs) -> bool {
    args.processes
        || args.out.is_some()
        || args.save_trajectories.is_some()
        || args.record.is_some()
}

/// Refuses `--json` or `--out` where they would overwrite the scenario or a model.
fn refuse_overwriting_inputs(args: &EvalArgs) -> anyhow::Result<()> {
    let mut inputs: Vec<(&'static str, &Path)> = vec![("--scenario", &args.scenario)];
    if let Some(model) = &args.model {
        inputs.push(("--model", model));
    }
    if let Some(shard) = &args.shard {
        inputs.push(("--shard", shard));
    }
    let json = args.json.as_deref().map(|j| ("--json", j, "out.json"));
    let out = args.out.as_deref().map(|o| ("--out", o));
    let record = args.record.as_deref().map(|r| ("--record", r));
    let folders: Vec<(&'static str, &Path)> = out.into_iter().chain(record).collect();
    paths::refuse_overwriting_inputs(json.as_slice(), &folders, &inputs)?;
    Ok(())
}

/// `formation eval`.
pub fn eval_command(args: &EvalArgs) -> anyhow::Result<()> {
    network_flags(args)?;
    refuse_gains_without_own_scan(args)?;
    // A path that cannot be written is refused before hours of runs, not after.
    if let Some(json) = &args.json {
        formation_proto::files::check_output_file(json)?;
    }
    if let Some(dir) = &args.out {
        formation_proto::files::check_output_dir(dir)?;
    }
    refuse_overwriting_inputs(args)?;
    if let Some(shard) = &args.shard {
        return shard_command(args, shard);
    }
    match args.robots.as_deref() {
        // One team size with what only an evaluation of one team writes: that evaluation.
        Some([_]) if single_team_outputs(args) => {}
        Some(sizes) => return scaling_command(args, sizes),
        None => {}
    }
    let (out, results) = evaluate(args)?;
    print_and_write_json(&table_text(&out), &out, args.json.as_deref())?;
    if let Some(dir) = &args.out {
        write_eval_dir(dir, &out, &results)?;
        println!("wrote {}", dir.display());
    }
    Ok(())
}
