//! `formation train` and `formation dagger`: the learning pipeline's steps.
//!
//! Training itself is PyTorch, run by `formation_trainer_bridge::train` as a subprocess. DAgger lives in
//! `formation_learning::dagger` (rollouts in parallel with rayon, over the team sizes asked): each
//! iteration rolls out the current policy in closed loop (optionally letting the expert drive a
//! decaying share of runs), labels every visited state of every robot with the expert's action,
//! appends those samples to the dataset as a new iteration, retrains from the previous checkpoint,
//! and reports the closed-loop Table I figures of the new model. `formation dagger-label` labels
//! one share of an iteration's runs into a part (a Ray task's work) and `formation
//! dagger-append` appends an iteration's parts in run order
//! (`formation_learning::dagger_share`, `formation_trainer_bridge::dagger_part`). This module only
//! turns the arguments into options and prints progress.

use std::time::Instant;

use anyhow::Context;
use formation_expert::ExpertGains;
use formation_learning::dagger::{
    DaggerEvent, DaggerOptions, RolloutLabels, RolloutScenarios, run_dagger,
};
use formation_learning::dagger_share::{ShareOptions, label_share};
use formation_learning::rollout::with_threads;
use formation_trainer_bridge::dagger_part::append_parts;
use formation_trainer_bridge::train::{Mirror, TrainOptions, TrainReport, train};
use formation_world::Scenario;

use crate::args::{
    DaggerAppendArgs, DaggerArgs, DaggerLabelArgs, DaggerRolloutArgs, NetworkArgs, TrainArgs,
};
use crate::eval;

/// The training options `formation train` and `formation dagger` share: the network, its
/// augmentation, its output and loss, and how much of the data an epoch draws.
fn network_options(network: &NetworkArgs) -> TrainOptions {
    TrainOptions {
        architecture: network.architecture,
        mirror: Mirror::from_flags(network.mirror, network.mirror_augment_only),
        relative_loss: network.relative_loss,
        output: network.output,
        response_weight: network.response_weight,
        samples_per_epoch: network.samples_per_epoch.map(std::num::NonZeroUsize::get),
        ..TrainOptions::default()
    }
}

/// `formation train`.
pub fn train_command(args: &TrainArgs) -> anyhow::Result<()> {
    let opts = TrainOptions {
        data: args.data.clone(),
        out: args.out.clone(),
        epochs: args.epochs,
        batch_size: args.batch_size,
        lr: args.lr,
        device: args.device.clone(),
        seed: args.seed,
        init_from: args.init_from.clone(),
        d_star_range: args.d_star_range,
        ..network_options(&args.network)
    };
    let report = run_training(&opts)?;
    println!(
        "trained {} epochs on {} samples: train loss {:.5}, val loss {:.5}; wrote {}",
        report.epochs,
        report.samples,
        report.final_train_loss,
        report.final_val_loss,
        args.out.display()
    );
    Ok(())
}

fn run_training(opts: &TrainOptions) -> anyhow::Result<TrainReport> {
    let report = train(opts, &mut |line| eprintln!("  {line}"))
        .with_context(|| format!("training {}", opts.out.display()))?;
    Ok(report)
}

/// `formation dagger`: the loop itself is `formation_learning::dagger::run_dagger`.
pub fn dagger_command(args: &DaggerArgs) -> anyhow::Result<()> {
    let rollouts = &args.rollouts;
    let scenario = Scenario::from_path(&rollouts.scenario)?;
    let eval_scenario = Scenario::from_path(&args.eval_scenario)?;
    let d_star_range = args.d_star_range.or(match scenario.d_star() {
        formation_world::scenario::DStarPlan::Range { min, max } => Some((*min, *max)),
        _ => None,
    });
    let opts = DaggerOptions {
        data: rollouts.data.clone(),
        runs: args.runs.unwrap_or_else(|| scenario.runs()),
        rollouts: rollout_scenarios(rollouts, scenario),
        labels: RolloutLabels {
            gains: ExpertGains {
                unblock_hidden_pairs: args.unblock_hidden_pairs,
                ..args.labels.shape(ExpertGains::default())
            },
            own_scan: args.own_scan_labels,
            wheel_accels: args.wheel_accels.clone(),
        },
        iterations: args.iterations,
        out: args.out.clone(),
        init_model: args.init_model.clone(),
        beta: rollouts.beta,
        training: TrainOptions {
            epochs: args.epochs,
            batch_size: args.batch_size,
            lr: args.lr,
            device: args.device.clone(),
            d_star_range,
            ..network_options(&args.network)
        },
        eval_scenario,
        eval_runs: args.eval_runs,
        seed: rollouts.seed,
    };
    let bar = eval::progress_bar(opts.runs, "dagger");
    let started = std::sync::Mutex::new(Instant::now());
    let curve = run_dagger(&opts, &|event| match event {
        DaggerEvent::Cloning => eprintln!(
            "DAgger iteration 0: behaviour cloning on {}",
            rollouts.data.display()
        ),
        DaggerEvent::Rollout { done } => bar.set_position(done as u64),
        DaggerEvent::Labelled {
            k,
            samples,
            runs,
            beta,
        } => {
            bar.finish_and_clear();
            let elapsed = started
                .lock()
                .map(|mut t| std::mem::replace(&mut *t, Instant::now()).elapsed())
                .unwrap_or_default();
            eprintln!(
                "DAgger iteration {k}: {samples} expert-labelled samples from {runs} runs \
                 (beta {beta:.3}) in {:.1} s",
                elapsed.as_secs_f64()
            );
            bar.reset();
        }
        DaggerEvent::Trainer(line) => eprintln!("  {line}"),
        DaggerEvent::Evaluated { k, figures } => {
            eprintln!(
                "DAgger iteration {k} closed loop:\n{}",
                crate::table::table_text(&figures)
            );
            // The next rollouts start now: the time reported with them is theirs alone.
            if let Ok(mut t) = started.lock() {
                *t = Instant::now();
            }
        }
    })?;
    println!(
        "DAgger curve (closed loop on {}, {} runs):",
        args.eval_scenario.display(),
        args.eval_runs
    );
    println!("  iter  success@5%  success@10%  median err  collisions");
    for (k, s) in curve.iter().enumerate() {
        println!(
            "  {k:>4}  {:>9.1}%  {:>10.1}%  {:>9}  {:>10}",
            100.0 * s.summary.success_rate_5,
            100.0 * s.summary.success_rate_10,
            s.summary
                .median_rel_formation_error
                .map(|e| format!("{:.2} %", 100.0 * e))
                .unwrap_or_else(|| "-".into()),
            s.summary.collisions
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

/// The rollouts `--team-sizes` and `--rollout-durations` draw from `scenario` (`--scenario`).
fn rollout_scenarios(rollouts: &DaggerRolloutArgs, scenario: Scenario) -> RolloutScenarios {
    RolloutScenarios {
        scenario,
        team_sizes: rollouts.team_sizes.clone(),
        durations: rollouts.rollout_durations.clone(),
    }
}

/// `formation dagger-label`: runs `A .. A + R` of iteration K, labelled into a part.
pub fn dagger_label_command(args: &DaggerLabelArgs) -> anyhow::Result<()> {
    formation_proto::files::check_output_file(&args.part)?;
    let rollouts = &args.rollouts;
    let scenario = Scenario::from_path(&rollouts.scenario)?;
    let share = eval::run_share(&scenario, args.first_run, args.runs, "label", "R")?;
    let opts = ShareOptions {
        data: rollouts.data.clone(),
        rollouts: rollout_scenarios(rollouts, scenario),
        model: args.model.clone(),
        iteration: args.iteration,
        beta: rollouts.beta,
        seed: rollouts.seed,
        runs: share.clone(),
        part: args.part.clone(),
    };
    let bar = eval::progress_bar(share.len(), "dagger share");
    let (_, samples) = with_threads(args.threads, || label_share(&opts, &|| bar.inc(1)))??;
    bar.finish_and_clear();
    println!(
        "wrote {} (iteration {}, runs {}..{}, {samples} samples)",
        args.part.display(),
        args.iteration,
        share.start,
        share.end
    );
    Ok(())
}

/// `formation dagger-append`: an iteration's parts, checked, appended in run order.
pub fn dagger_append_command(args: &DaggerAppendArgs) -> anyhow::Result<()> {
    let (manifest, added) = append_parts(&args.data, args.iteration, args.runs, &args.parts)
        .with_context(|| {
            format!(
                "appending DAgger iteration {} to {}",
                args.iteration,
                args.data.display()
            )
        })?;
    println!(
        "appended {added} samples of DAgger iteration {} ({} runs, {} parts) to {}: {} samples in all",
        args.iteration,
        args.runs,
        args.parts.len(),
        args.data.display(),
        manifest.samples
    );
    Ok(())
}
