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

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use formation_expert::ExpertGains;
use formation_learning::Driver;
use formation_learning::rollout::with_threads;
use formation_learning::scaling::{ScalingDriver, evaluate_scaling, scaling_text};
use formation_runtime::transport::Transport;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics};
use formation_world::{RunLog, Scenario, Trajectory};

use crate::args::{ControllerKind, EvalArgs};
use crate::paths;

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

/// Model ids of the given files, as the agents would report them, beside each model's envelope,
/// after checking each model against the contract and the scenario's LIDAR (beams, range,
/// window), and the scenario's d* against each model's trained d* range (its envelope), before
/// anything runs.
pub fn checked_models(
    models: &[PathBuf],
    scenario: &Scenario,
) -> anyhow::Result<Vec<(String, formation_onnx::ModelEnvelope)>> {
    Ok(
        formation_robot_agent::decision::check_team_models_with_envelopes(
            models,
            &scenario.world_config().lidar,
            &scenario_d_stars(scenario),
        )?,
    )
}

/// Each distinct model of a team (by id, in first-use order) that records its trained team
/// sizes, against the team's size `robots`.
pub fn team_sizes_of(
    models: &[(String, formation_onnx::ModelEnvelope)],
    robots: usize,
) -> Vec<formation_schema::ModelTeamSize> {
    let mut seen = Vec::new();
    let mut out = Vec::new();
    for (id, envelope) in models {
        if seen.contains(&id) {
            continue;
        }
        seen.push(id);
        out.extend(formation_schema::ModelTeamSize::new(
            id,
            &envelope.team_sizes,
            robots,
        ));
    }
    out
}

/// Prints, on stderr, a line for each model that never saw a team of this size: a note when
/// the size is zero-shot, a warning when it is below every trained size.
pub fn print_team_size_notes(team_size: &[formation_schema::ModelTeamSize]) {
    for line in team_size.iter().filter_map(|t| t.describe()) {
        eprintln!("formation: {line}");
    }
}

/// The d* values that bound a scenario's runs: its fixed d*, each of its choices, or its
/// range's ends.
pub fn scenario_d_stars(scenario: &Scenario) -> Vec<f64> {
    scenario.d_star().bounds()
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

/// Formats Table I and the Fig. 9 medians as text, with the runs each median covers when the
/// rule leaves some out, and the incomplete runs, if any.
pub fn table_text(out: &EvalOutput) -> String {
    let mut text = table_i_text(out);
    let incomplete = out.summary.runs_incomplete.max(out.incomplete_runs.len());
    if incomplete > 0 {
        text.push_str(&format!(
            "incomplete runs: {incomplete} of {}, counted as failures (stopped early{})\n",
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

/// `  (over 3 of the 7: 4 succeeded without converging)` after a median whose rule leaves out
/// some of the runs successful at 10 %; empty when it covers them all.
fn coverage_note(coverage: Option<&formation_schema::Coverage>, left_out_because: &str) -> String {
    match coverage {
        Some(c) if c.runs < c.of => format!(
            "   over {} of the {}: {} {left_out_because}",
            c.runs,
            c.of,
            c.of - c.runs
        ),
        _ => String::new(),
    }
}

fn table_i_text(out: &EvalOutput) -> String {
    let s = &out.summary;
    let pct = |x: f64| format!("{:.1} %", 100.0 * x);
    let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map(f).unwrap_or_else(|| "-".into());
    let over = s.medians_over.as_ref();
    format!(
        "Table I ({} controller, {} runs of {}, seed {})\n\
         \x20 success at 5 %:   {:>8}   (paper: 90 %)\n\
         \x20 success at 10 %:  {:>8}   (paper: 96 %)\n\
         Fig. 9 medians over runs successful at 10 %{}\n\
         \x20 convergence time: {:>8}   (paper: ~10 s){}\n\
         \x20 formation error:  {:>8}   (paper: 2.5 %){}\n\
         \x20 orientation err.: {:>8}   (paper: 0.031 rad){}\n\
         runs with collisions: {}\n",
        out.controller,
        s.runs,
        out.scenario,
        out.seed
            .map_or_else(|| "unknown".to_owned(), |seed| seed.to_string()),
        pct(s.success_rate_5),
        pct(s.success_rate_10),
        over.map(|o| format!(" ({} runs)", o.rel_formation_error.of))
            .unwrap_or_default(),
        opt(s.median_convergence_s, &|x| format!("{x:.2} s")),
        coverage_note(
            over.map(|o| &o.convergence_s),
            "never stayed below 10 % to the end (not converged)"
        ),
        opt(s.median_rel_formation_error, &|x| format!(
            "{:.2} %",
            100.0 * x
        )),
        coverage_note(over.map(|o| &o.rel_formation_error), "without a value"),
        opt(s.median_orientation_error_rad, &|x| format!("{x:.3} rad")),
        coverage_note(over.map(|o| &o.orientation_error_rad), "without a value"),
        s.collisions,
    )
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
    let runs = args.runs.unwrap_or_else(|| scenario.runs());
    if runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let seed = args.seed.unwrap_or_else(|| scenario.seed());
    let keep_n = args
        .save_trajectories
        .unwrap_or(if runs <= 5 { runs } else { 0 });
    let keep = move |i: usize| i < keep_n;
    let mut team_size = Vec::new();
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
            let checked = checked_models(&models, &scenario)?;
            team_size = team_sizes_of(&checked, scenario.n_robots());
            print_team_size_notes(&team_size);
            (models, checked.into_iter().map(|(id, _)| id).collect())
        }
    };
    let bar = progress_bar(runs, "eval");
    let started = Instant::now();
    let results: Vec<RunResult> = if args.processes {
        let default = models.first().cloned().context("no robots")?;
        let evaluated = crate::launch::eval_over_processes(
            &scenario,
            seed,
            runs,
            &default,
            crate::launch::ClockMode::Lockstep,
            &network,
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
                metrics: run_metrics(&traj, scenario.run_spec(seed, index).ticks(), &cfg),
                trajectory: keep(index).then_some(traj),
                clock: crate::launch::ClockMode::Lockstep.as_str(),
            })
            .collect()
    } else {
        let driver = match args.controller {
            ControllerKind::Expert => Driver::Expert(ExpertGains::default()),
            ControllerKind::Policy => Driver::Policy {
                models: models.clone(),
            },
        };
        with_threads(args.threads, || {
            formation_learning::evaluate_runs(
                &scenario,
                seed,
                runs,
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
        .collect()
    };
    bar.finish_and_clear();
    let elapsed = started.elapsed().as_secs_f64();
    let per_run: Vec<RunMetrics> = results.iter().map(|r| r.metrics.clone()).collect();
    let controller = match args.controller {
        ControllerKind::Expert => "expert",
        ControllerKind::Policy => "policy",
    };
    let mut out = eval_output(controller, model_ids, scenario.name(), Some(seed), per_run);
    out.team_size = team_size;
    eprintln!(
        "evaluated {runs} runs in {elapsed:.1} s ({:.2} s per run)",
        elapsed / runs as f64
    );
    Ok((out, results))
}

/// `formation eval --robots ...`: the scaling table over team sizes.
pub fn scaling_command(args: &EvalArgs, sizes: &[usize]) -> anyhow::Result<()> {
    if args.processes || args.out.is_some() || args.save_trajectories.is_some() {
        anyhow::bail!(
            "--robots evaluates in-process and writes a table (print and --json); drop \
             --processes, --out and --save-trajectories, or evaluate one team size at a time"
        );
    }
    let base = Scenario::from_path(&args.scenario)?;
    let runs = args.runs.unwrap_or_else(|| base.runs());
    let seed = args.seed.unwrap_or_else(|| base.seed());
    let mut drivers = vec![ScalingDriver::Expert(ExpertGains::default())];
    if args.model.is_some() {
        let model = paths::resolve_model(args.model.as_deref())?;
        let (id, envelope) = checked_models(std::slice::from_ref(&model), &base)?
            .pop()
            .unwrap_or_default();
        for &robots in sizes {
            print_team_size_notes(&team_sizes_of(&[(id.clone(), envelope.clone())], robots));
        }
        drivers.push(ScalingDriver::Policy {
            model,
            id,
            trained_team_sizes: envelope.team_sizes,
        });
    }
    let bar = progress_bar(runs * sizes.len() * drivers.len(), "scaling");
    let started = Instant::now();
    let table = with_threads(args.threads, || {
        evaluate_scaling(&base, sizes, seed, runs, &drivers, &|row, done| {
            bar.set_position((row * runs + done) as u64)
        })
    })??;
    bar.finish_and_clear();
    eprintln!(
        "evaluated {} runs in {:.1} s",
        runs * table.rows.len(),
        started.elapsed().as_secs_f64()
    );
    print!("{}", scaling_text(&table));
    if let Some(json) = &args.json {
        paths::write_atomic(json, &formation_schema::to_json_pretty(&table)?)?;
        println!("wrote {}", json.display());
    }
    Ok(())
}

/// `formation eval`.
pub fn eval_command(args: &EvalArgs) -> anyhow::Result<()> {
    network_flags(args)?;
    // A path that cannot be written is refused before hours of runs, not after.
    if let Some(json) = &args.json {
        formation_proto::files::check_output_file(json)?;
    }
    if let Some(dir) = &args.out {
        formation_proto::files::check_output_dir(dir)?;
    }
    if let Some(sizes) = &args.robots {
        return scaling_command(args, sizes);
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use formation_world::metrics::TicksPlayed;

    fn run(success_10: bool, convergence_s_10: Option<f64>) -> RunMetrics {
        RunMetrics {
            success_5: success_10,
            success_10,
            convergence_s_5: convergence_s_10,
            convergence_s_10,
            rel_formation_error: 0.01,
            max_edge_window_error: 0.02,
            orientation_error_rad: 0.01,
            collisions: 0,
            team: None,
            incomplete: None,
        }
    }

    #[test]
    fn the_table_says_which_runs_each_median_covers_and_how_many_were_incomplete() {
        let mut runs: Vec<RunMetrics> = (0..7).map(|k| run(true, (k < 3).then_some(4.0))).collect();
        let mut cut = run(false, Some(2.0));
        cut.incomplete = Some(TicksPlayed {
            ticks: 392,
            planned_ticks: 1200,
        });
        runs.push(cut);
        let out = eval_output("expert", Vec::new(), "accel", Some(7), runs);
        let text = table_text(&out);
        assert!(
            text.contains("Fig. 9 medians over runs successful at 10 % (7 runs)"),
            "{text}"
        );
        assert!(
            text.contains("over 3 of the 7: 4 never stayed below 10 % to the end (not converged)"),
            "{text}"
        );
        assert!(
            text.contains("incomplete runs: 1 of 8, counted as failures"),
            "{text}"
        );
        assert!(text.contains("success at 10 %:    87.5 %"), "{text}");

        // A complete evaluation whose successful runs all converged: no note.
        let out = eval_output(
            "expert",
            Vec::new(),
            "t",
            Some(7),
            vec![run(true, Some(3.0))],
        );
        let text = table_text(&out);
        assert!(
            !text.contains(" of the ") && !text.contains("incomplete"),
            "{text}"
        );
    }
}
