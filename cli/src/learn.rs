//! `formation train` and `formation dagger`: the learning pipeline's steps.
//!
//! Training itself is PyTorch, run by `trainer_bridge::train` as a subprocess. DAgger is driven
//! from here: each iteration rolls out the current policy in closed loop (optionally letting the
//! expert drive a decaying share of runs), labels every visited state of every robot with the
//! expert's action, appends those samples to the dataset as a new iteration, retrains from the
//! previous checkpoint, and reports the closed-loop Table I figures of the new model.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use formation_expert::ExpertGains;
use formation_expert::collect::Labeller;
use formation_world::{Controller, Scenario, run_episode};
use rand::{Rng, SeedableRng};
use robot_agent::decision::PolicyController;
use trainer_bridge::dataset::{DatasetWriter, Sample};
use trainer_bridge::train::{TrainOptions, TrainReport, train};

use crate::args::{ControllerKind, DaggerArgs, EvalArgs, TrainArgs};
use crate::eval;

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
        ..TrainOptions::default()
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

/// `formation dagger`.
pub fn dagger_command(args: &DaggerArgs) -> anyhow::Result<()> {
    let scenario = Scenario::from_path(&args.scenario)?;
    let runs = args.runs.unwrap_or_else(|| scenario.runs());
    let out_dir = args
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let stem = args
        .out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or("policy".into());
    let train_opts = |out: PathBuf, init_from: Option<PathBuf>| TrainOptions {
        data: vec![args.data.clone()],
        out,
        epochs: args.epochs,
        batch_size: args.batch_size,
        lr: args.lr,
        device: args.device.clone(),
        init_from,
        ..TrainOptions::default()
    };

    let mut model = match &args.init_model {
        Some(m) => m.clone(),
        None => {
            let m0 = out_dir.join(format!("{stem}-dagger0.onnx"));
            eprintln!(
                "DAgger iteration 0: behaviour cloning on {}",
                args.data.display()
            );
            run_training(&train_opts(m0.clone(), None))?;
            m0
        }
    };
    let mut curve = vec![iteration_figures(args, 0, &model)?];
    for k in 1..=args.iterations {
        let beta = args.beta.powi(k as i32);
        let started = Instant::now();
        let added = rollout_and_label(args, &scenario, runs, k, beta, &model)?;
        eprintln!(
            "DAgger iteration {k}: {added} expert-labelled samples from {runs} runs (beta {beta:.3}) in {:.1} s",
            started.elapsed().as_secs_f64()
        );
        let next = if k == args.iterations {
            args.out.clone()
        } else {
            out_dir.join(format!("{stem}-dagger{k}.onnx"))
        };
        run_training(&train_opts(next.clone(), Some(checkpoint_of(&model))))?;
        model = next;
        curve.push(iteration_figures(args, k, &model)?);
    }
    if args.iterations == 0 {
        std::fs::copy(&model, &args.out)
            .with_context(|| format!("copying {} to {}", model.display(), args.out.display()))?;
    }
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
    let curve_path = out_dir.join(format!("{stem}-dagger-curve.json"));
    crate::paths::write_atomic(&curve_path, &serde_json::to_vec_pretty(&curve)?)?;
    println!("wrote {} and {}", args.out.display(), curve_path.display());
    Ok(())
}

/// The checkpoint the trainer writes beside an ONNX model (for warm starts).
fn checkpoint_of(model: &Path) -> PathBuf {
    model.with_extension("pt")
}

fn iteration_figures(
    args: &DaggerArgs,
    k: usize,
    model: &Path,
) -> anyhow::Result<eval::EvalOutput> {
    let eval_args = EvalArgs {
        scenario: args.eval_scenario.clone(),
        controller: ControllerKind::Policy,
        model: Some(model.to_path_buf()),
        runs: Some(args.eval_runs),
        seed: None,
        json: None,
        out: None,
        save_trajectories: Some(0),
        processes: false,
        threads: None,
    };
    let (out, _) = eval::evaluate(&eval_args)?;
    eprintln!(
        "DAgger iteration {k} closed loop:\n{}",
        eval::table_text(&out)
    );
    Ok(out)
}

/// Rolls out `model` (or, with probability `beta` per run, the expert) over `runs` runs and
/// appends every robot's expert-labelled observation at every tick as iteration `k`.
fn rollout_and_label(
    args: &DaggerArgs,
    scenario: &Scenario,
    runs: usize,
    k: usize,
    beta: f64,
    model: &Path,
) -> anyhow::Result<usize> {
    let spec0 = scenario.run_spec(args.seed, 0);
    let robot = spec0.world.robot;
    let lidar = spec0.world.lidar;
    let gains = ExpertGains::default();
    let mut writer = DatasetWriter::append(&args.data, k as u32)
        .with_context(|| format!("opening {} to append DAgger samples", args.data.display()))?;
    let occupancy = writer.header().occupancy;
    let labeller = Labeller::new(gains, robot, lidar, occupancy)?;
    let models = eval::models_per_robot(scenario, model)?;
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let next = AtomicUsize::new(0);
    let per_run: Mutex<Vec<(usize, Vec<Sample>)>> = Mutex::new(Vec::new());
    let bar = eval::progress_bar(runs, &format!("dagger {k}"));
    let done = AtomicUsize::new(0);
    let iteration_seed = args.seed.wrapping_add(1_000_003 * k as u64);
    std::thread::scope(|s| -> anyhow::Result<()> {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| -> anyhow::Result<()> {
                    let refs: Vec<&Path> = models.iter().map(PathBuf::as_path).collect();
                    let mut policy = PolicyController::from_model_paths(&refs, lidar)?;
                    let mut expert = formation_expert::ExpertController::new(gains, robot);
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= runs {
                            return Ok(());
                        }
                        let spec = scenario.run_spec(iteration_seed, i);
                        let mut coin = rand_chacha::ChaCha8Rng::seed_from_u64(spec.seed ^ 0xDA66E5);
                        let expert_drives = beta > 0.0 && coin.random::<f64>() < beta;
                        let driver: &mut dyn Controller = if expert_drives {
                            &mut expert
                        } else {
                            &mut policy
                        };
                        let mut samples = Vec::new();
                        let mut failure = None;
                        run_episode(&spec, driver, &mut |obs, _| {
                            if failure.is_none() {
                                failure = labeller
                                    .label_observation(obs, k as u32, i as u32, &mut |s| {
                                        samples.push(s)
                                    })
                                    .err();
                            }
                        })
                        .with_context(|| format!("DAgger rollout {i}"))?;
                        if let Some(e) = failure {
                            return Err(e).with_context(|| format!("labelling DAgger rollout {i}"));
                        }
                        per_run
                            .lock()
                            .map_err(|_| anyhow::anyhow!("poisoned"))?
                            .push((i, samples));
                        bar.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                    }
                })
            })
            .collect();
        for w in workers {
            w.join()
                .map_err(|_| anyhow::anyhow!("a DAgger worker panicked"))??;
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    let mut per_run = per_run
        .into_inner()
        .map_err(|_| anyhow::anyhow!("poisoned"))?;
    per_run.sort_by_key(|(i, _)| *i);
    let mut added = 0;
    for (_, samples) in per_run {
        for s in samples {
            writer.push(s)?;
            added += 1;
        }
    }
    writer.finish()?;
    Ok(added)
}
