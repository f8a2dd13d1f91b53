//! `formation eval`: runs a controller over a scenario's runs and reports the paper's Table I and
//! Fig. 9 figures.
//!
//! In-process evaluation runs independent runs on worker threads; every run is a pure function of
//! (scenario, base seed, run index, model), so the result does not depend on the thread count and
//! the same seed gives byte-identical JSON. `--processes` runs every robot's policy in its own OS
//! process over iceoryx2 and must give the same JSON.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use formation_expert::{ExpertController, ExpertGains};
use formation_proto::LidarSpec;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics, summarize};
use formation_world::{Controller, RunLog, Scenario, Trajectory, run_episode};
use robot_agent::decision::PolicyController;

use crate::args::{ControllerKind, EvalArgs};
use crate::paths;

/// What `formation eval` writes as JSON, and a run that stopped early: defined in
/// [`formation_schema`].
pub use formation_schema::{EvalOutput, IncompleteRun};

/// The output of runs with these per-run metrics: the Table I and Fig. 9 summary over them.
pub fn eval_output(
    controller: &str,
    models: Vec<String>,
    scenario: &str,
    seed: Option<u64>,
    per_run: Vec<RunMetrics>,
) -> EvalOutput {
    EvalOutput {
        controller: controller.to_owned(),
        models,
        scenario: scenario.to_owned(),
        seed,
        summary: summarize(&per_run),
        per_run,
        braked_ticks: Vec::new(),
        incomplete_runs: Vec::new(),
    }
}

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

/// Builds a fresh controller for one worker thread.
pub type ControllerFactory<'a> = dyn Fn() -> anyhow::Result<Box<dyn Controller>> + Sync + 'a;

/// Runs `runs` runs of `scenario` in-process on `threads` workers. `keep(i)` says whether run i's
/// trajectory is returned. `progress` is called after each finished run with the count so far.
pub fn evaluate_in_process(
    scenario: &Scenario,
    base_seed: u64,
    runs: usize,
    make_controller: &ControllerFactory<'_>,
    threads: usize,
    keep: &(dyn Fn(usize) -> bool + Sync),
    progress: &(dyn Fn(usize) + Sync),
) -> anyhow::Result<Vec<RunResult>> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<RunResult>> = Mutex::new(Vec::with_capacity(runs));
    let cfg = MetricsConfig::default();
    std::thread::scope(|s| -> anyhow::Result<()> {
        let workers: Vec<_> = (0..threads.clamp(1, runs.max(1)))
            .map(|_| {
                s.spawn(|| -> anyhow::Result<()> {
                    let mut controller = make_controller()?;
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= runs {
                            return Ok(());
                        }
                        let spec = scenario.run_spec(base_seed, i);
                        let traj = run_episode(&spec, controller.as_mut(), &mut |_, _| {})
                            .with_context(|| format!("run {i}"))?;
                        let metrics = run_metrics(&traj, &cfg);
                        let trajectory = keep(i).then_some(traj);
                        results
                            .lock()
                            .map_err(|_| anyhow::anyhow!("a worker panicked"))?
                            .push(RunResult {
                                index: i,
                                metrics,
                                trajectory,
                                clock: "in-process",
                            });
                        progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                    }
                })
            })
            .collect();
        for w in workers {
            w.join()
                .map_err(|_| anyhow::anyhow!("an evaluation worker panicked"))??;
        }
        Ok(())
    })?;
    let mut results = results
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a worker panicked"))?;
    results.sort_by_key(|r| r.index);
    Ok(results)
}

/// The model path for each robot: the scenario's per-robot overrides, else `default`.
pub fn models_per_robot(scenario: &Scenario, default: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut models = vec![default.to_path_buf(); scenario.n_robots()];
    for m in scenario.agent_models() {
        let slot = models.get_mut(m.robot).with_context(|| {
            format!(
                "scenario assigns a model to robot {}, but it has {} robots",
                m.robot,
                scenario.n_robots()
            )
        })?;
        *slot = paths::resolve_model(Some(&m.model))?;
    }
    Ok(models)
}

/// A controller factory for the chosen controller kind.
pub fn controller_factory<'a>(
    kind: ControllerKind,
    scenario: &'a Scenario,
    models: &'a [PathBuf],
) -> Box<ControllerFactory<'a>> {
    match kind {
        ControllerKind::Expert => Box::new(move || {
            let robot = scenario.world_config().robot;
            Ok(
                Box::new(ExpertController::new(ExpertGains::default(), robot))
                    as Box<dyn Controller>,
            )
        }),
        ControllerKind::Policy => Box::new(move || {
            let lidar = scenario.world_config().lidar;
            let refs: Vec<&Path> = models.iter().map(PathBuf::as_path).collect();
            Ok(Box::new(PolicyController::from_model_paths(&refs, lidar)?) as Box<dyn Controller>)
        }),
    }
}

/// Model ids of the given files, as the agents would report them, after checking each model
/// against the contract and this LIDAR (beams, range, window) before anything runs.
pub fn model_ids(models: &[PathBuf], lidar: &LidarSpec) -> anyhow::Result<Vec<String>> {
    Ok(robot_agent::decision::check_team_models(models, lidar)?)
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

/// Formats Table I and the Fig. 9 medians as text (and the incomplete runs, if any).
pub fn table_text(out: &EvalOutput) -> String {
    let mut text = table_i_text(out);
    if !out.incomplete_runs.is_empty() {
        text.push_str(&format!(
            "incomplete runs: {} of {} (stopped early{})\n",
            out.incomplete_runs.len(),
            out.summary.runs,
            out.incomplete_runs
                .first()
                .and_then(|r| r.stop_reason.as_deref())
                .map(|reason| format!(": {reason}"))
                .unwrap_or_default()
        ));
    }
    text
}

fn table_i_text(out: &EvalOutput) -> String {
    let s = &out.summary;
    let pct = |x: f64| format!("{:.1} %", 100.0 * x);
    let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map(f).unwrap_or_else(|| "-".into());
    format!(
        "Table I ({} controller, {} runs of {}, seed {})\n\
         \x20 success at 5 %:   {:>8}   (paper: 90 %)\n\
         \x20 success at 10 %:  {:>8}   (paper: 96 %)\n\
         Fig. 9 medians over runs successful at 10 %\n\
         \x20 convergence time: {:>8}   (paper: ~10 s)\n\
         \x20 formation error:  {:>8}   (paper: 2.5 %)\n\
         \x20 orientation err.: {:>8}   (paper: 0.031 rad)\n\
         runs with collisions: {}\n",
        out.controller,
        s.runs,
        out.scenario,
        out.seed
            .map_or_else(|| "unknown".to_owned(), |seed| seed.to_string()),
        pct(s.success_rate_5),
        pct(s.success_rate_10),
        opt(s.median_convergence_s, &|x| format!("{x:.2} s")),
        opt(s.median_rel_formation_error, &|x| format!(
            "{:.2} %",
            100.0 * x
        )),
        opt(s.median_orientation_error_rad, &|x| format!("{x:.3} rad")),
        s.collisions,
    )
}

/// Writes the eval output directory the report reads: `summary.json` and, for the runs whose
/// trajectory was kept, `runs/run-NNNN.json` in the run-log format the world writes.
pub fn write_eval_dir(dir: &Path, out: &EvalOutput, results: &[RunResult]) -> anyhow::Result<()> {
    paths::write_atomic(
        &dir.join("summary.json"),
        &formation_schema::to_json_pretty(out)?,
    )?;
    for r in results {
        if let Some(traj) = &r.trajectory {
            let log = RunLog {
                index: r.index,
                metrics: r.metrics.clone(),
                trajectory: traj.clone(),
                clock: r.clock.to_owned(),
                models: out.models.clone(),
                complete: true,
                stop_reason: None,
                planned_ticks: Some(traj.commands.len() as u64),
            };
            paths::write_atomic(
                &formation_world::runlog::log_paths(dir, r.index).0,
                &formation_schema::to_json(&log)?,
            )?;
        }
    }
    Ok(())
}

/// Evaluates and returns the output and the per-run results (shared by `eval` and `demo`).
pub fn evaluate(args: &EvalArgs) -> anyhow::Result<(EvalOutput, Vec<RunResult>)> {
    let scenario = Scenario::from_path(&args.scenario)?;
    let runs = args.runs.unwrap_or_else(|| scenario.runs());
    if runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let seed = args.seed.unwrap_or_else(|| scenario.seed());
    let keep_n = args
        .save_trajectories
        .unwrap_or(if runs <= 5 { runs } else { 0 });
    let keep = move |i: usize| i < keep_n;
    let (models, model_ids) = match args.controller {
        ControllerKind::Expert => {
            if args.processes {
                anyhow::bail!(
                    "--processes runs learned agents; the expert sees every robot and runs in-process only"
                );
            }
            (Vec::new(), Vec::new())
        }
        ControllerKind::Policy => {
            let default = paths::resolve_model(args.model.as_deref())?;
            let models = models_per_robot(&scenario, &default)?;
            let ids = model_ids(&models, &scenario.world_config().lidar)?;
            (models, ids)
        }
    };
    let bar = progress_bar(runs, "eval");
    let started = Instant::now();
    let results = if args.processes {
        let default = models.first().cloned().context("no robots")?;
        let evaluated = crate::runtime::eval_over_processes(
            &scenario,
            seed,
            runs,
            &default,
            crate::runtime::ClockMode::Lockstep,
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
        evaluated
            .trajectories
            .into_iter()
            .enumerate()
            .map(|(index, traj)| RunResult {
                index,
                metrics: run_metrics(&traj, &cfg),
                trajectory: keep(index).then_some(traj),
                clock: crate::runtime::ClockMode::Lockstep.as_str(),
            })
            .collect()
    } else {
        let threads = args.threads.unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        });
        let factory = controller_factory(args.controller, &scenario, &models);
        evaluate_in_process(
            &scenario,
            seed,
            runs,
            factory.as_ref(),
            threads,
            &keep,
            &|n| bar.set_position(n as u64),
        )?
    };
    bar.finish_and_clear();
    let elapsed = started.elapsed().as_secs_f64();
    let per_run: Vec<RunMetrics> = results.iter().map(|r| r.metrics.clone()).collect();
    let controller = match args.controller {
        ControllerKind::Expert => "expert",
        ControllerKind::Policy => "policy",
    };
    let out = eval_output(controller, model_ids, scenario.name(), Some(seed), per_run);
    eprintln!(
        "evaluated {runs} runs in {elapsed:.1} s ({:.2} s per run)",
        elapsed / runs as f64
    );
    Ok((out, results))
}

/// `formation eval`.
pub fn eval_command(args: &EvalArgs) -> anyhow::Result<()> {
    let (out, results) = evaluate(args)?;
    print!("{}", table_text(&out));
    if let Some(json) = &args.json {
        paths::write_atomic(json, &formation_schema::to_json_pretty(&out)?)?;
        println!("wrote {}", json.display());
    }
    if let Some(dir) = &args.out {
        write_eval_dir(dir, &out, &results)?;
        println!("wrote {}", dir.display());
    }
    Ok(())
}
