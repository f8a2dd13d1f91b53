//! The expert under wheel acceleration limits, per team size, with per-run diagnostics: for
//! tuning and for diagnosing failures (the product's command is `formation eval --controller
//! expert --robots ...`).
//!
//! ```text
//! cargo run -p formation-expert --release --example expert_accel -- SCENARIO RUNS N [N ...]
//! ```
//! Environment:
//! * `ACCEL`: the wheel acceleration limit \[m/s²\] (`none` removes it; default: the scenario's);
//! * `DURATION`: the run length \[s\] (default: the scenario's);
//! * `THREADS`: worker threads (default 2);
//! * `VERBOSE=1`: one line per run that failed or collided (its d* and v*, window errors, how
//!   often the limit bound);
//! * `DUMP=i`: robot 0's heading error and requested and applied wheels over run i's last 3 s;
//! * `GAINS`: the expert's gains as JSON (`{"k_formation_graph": 0.4}`; default: the defaults).

mod common;

use std::path::PathBuf;

use formation_expert::{ExpertController, ExpertGains};
use formation_proto::WheelCmd;
use formation_world::episode::run_episode;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics, summarize};
use formation_world::{Scenario, Trajectory};

/// One run's metrics and how often the acceleration limit bound its commands.
struct Diagnosis {
    metrics: RunMetrics,
    /// Share of robot-ticks whose applied command differs from the requested one.
    limited: f64,
    /// Share of robot-ticks of the last 20 s whose applied command differs from the requested.
    limited_window: f64,
    /// The run's d* \[m\] at its start.
    d_star: f64,
    /// The run's v* \[m/s\] (drawn per run under `goal.v_star_range`).
    v_star: f64,
}

/// What the command line and the environment ask for.
struct Options {
    /// Runs per team size.
    runs: usize,
    /// The expert's gains (`GAINS`).
    gains: ExpertGains,
    /// The wheel acceleration limit (`ACCEL`): `Some(None)` removes it, `None` keeps the
    /// scenario's.
    accel: Option<Option<f64>>,
    /// The run length \[s\] (`DURATION`), else the scenario's.
    duration: Option<f64>,
    /// Worker threads (`THREADS`).
    threads: usize,
    /// One line per run that failed or collided (`VERBOSE=1`).
    verbose: bool,
    /// The run whose last 3 s are dumped (`DUMP`).
    dump: Option<usize>,
}

/// Reads the environment's settings, in the order the usage lists them after `runs`.
fn options_from_env(runs: usize) -> Result<Options, Box<dyn std::error::Error>> {
    let gains: ExpertGains = match std::env::var("GAINS") {
        Ok(json) => serde_json::from_str(&json)?,
        Err(_) => ExpertGains::default(),
    };
    let accel: Option<Option<f64>> = match std::env::var("ACCEL") {
        Ok(a) if a == "none" => Some(None),
        Ok(a) => Some(Some(a.parse()?)),
        Err(_) => None,
    };
    let duration: Option<f64> = std::env::var("DURATION")
        .ok()
        .map(|d| d.parse())
        .transpose()?;
    let threads: usize = std::env::var("THREADS").map_or(Ok(2), |t| t.parse())?;
    let verbose = std::env::var("VERBOSE").is_ok_and(|v| v == "1");
    let dump: Option<usize> = std::env::var("DUMP").ok().map(|d| d.parse()).transpose()?;
    Ok(Options {
        runs,
        gains,
        accel,
        duration,
        threads,
        verbose,
        dump,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().ok_or("scenario")?);
    let runs: usize = args.next().ok_or("runs")?.parse()?;
    let sizes: Vec<usize> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    let options = options_from_env(runs)?;
    let cfg = common::team_metrics();
    for (scenario, n) in common::scenarios_of_sizes(&path, &sizes)?.iter().zip(sizes) {
        let started = std::time::Instant::now();
        let results = diagnose_team(scenario, &options, &cfg);
        if options.verbose {
            print_failures(n, &results);
        }
        print_summary(n, &results, started);
    }
    Ok(())
}

/// Runs every run of `scenario` on `options.threads` workers, in run order.
fn diagnose_team(scenario: &Scenario, options: &Options, cfg: &MetricsConfig) -> Vec<Diagnosis> {
    common::in_run_order(options.runs, options.threads, |i| {
        diagnose_run(scenario, i, options, cfg)
    })
}

/// Plays run `i` with the expert and measures how often the acceleration limit bound.
fn diagnose_run(
    scenario: &Scenario,
    i: usize,
    options: &Options,
    cfg: &MetricsConfig,
) -> Diagnosis {
    let mut spec = scenario.run_spec(scenario.seed(), i);
    if let Some(a) = options.accel {
        spec.world.robot.max_wheel_accel = a;
    }
    if let Some(d) = options.duration {
        spec.duration_s = d;
    }
    let window_start = spec.ticks().saturating_sub(400);
    let mut expert =
        ExpertController::for_world(options.gains, &spec.world).with_neighbours(spec.neighbours);
    let mut requested: Vec<Vec<WheelCmd>> = Vec::new();
    let traj = run_episode(&spec, &mut expert, &mut |_, cmds| {
        requested.push(cmds.to_vec())
    })
    .expect("expert");
    let (mut bound, mut bound_w, mut total, mut total_w) = (0usize, 0usize, 0usize, 0usize);
    for (k, (req, app)) in requested.iter().zip(&traj.commands).enumerate() {
        for (r, a) in req.iter().zip(app) {
            let differs = (r.left - a.left).abs() > 1e-9 || (r.right - a.right).abs() > 1e-9;
            total += 1;
            bound += usize::from(differs);
            if k as u64 >= window_start {
                total_w += 1;
                bound_w += usize::from(differs);
            }
        }
    }
    if options.dump == Some(i) {
        dump_last_seconds(&requested, &traj);
    }
    let metrics = run_metrics(&traj, spec.ticks(), cfg);
    Diagnosis {
        metrics,
        d_star: spec.goal_at(0.0).d_star,
        v_star: spec.v_star,
        limited: bound as f64 / total.max(1) as f64,
        limited_window: bound_w as f64 / total_w.max(1) as f64,
    }
}

/// Prints robot 0's heading error and requested and applied wheels over the last 60 ticks.
fn dump_last_seconds(requested: &[Vec<WheelCmd>], traj: &Trajectory) {
    let k0 = requested.len().saturating_sub(60);
    for (k, req) in requested.iter().enumerate().skip(k0) {
        let pose = traj.poses[k][0];
        let phi = traj.phi_star[k];
        let r = req[0];
        let a = traj.commands[k][0];
        eprintln!(
            "t={:.2} dtheta={:+.3} req=({:+.3},{:+.3}) applied=({:+.3},{:+.3})",
            traj.times[k],
            formation_proto::wrap_angle(pose.theta - phi),
            r.left,
            r.right,
            a.left,
            a.right
        );
    }
}

/// One line per run of team size `n` that failed at 10 % or had a collision.
fn print_failures(n: usize, results: &[Diagnosis]) {
    for (i, d) in results
        .iter()
        .enumerate()
        .filter(|(_, d)| !d.metrics.success_10 || d.metrics.collisions > 0)
    {
        let m = &d.metrics;
        let t = m.team.as_ref();
        eprintln!(
            "N={n} run {i}: d*={:.2} v*={:.3} max_window_err={:.3} mean_err={:.3} conv10={:?} heading_err={:.3} collisions={} connected={:?} anchor={:?} final_err={:?} limited={:.2} limited_window={:.2}",
            d.d_star,
            d.v_star,
            m.max_edge_window_error,
            m.rel_formation_error,
            m.convergence_s_10,
            m.orientation_error_rad,
            m.collisions,
            t.map(|t| t.connected),
            t.map(|t| t.anchor_success),
            t.map(|t| (t.final_mean_edge_error * 1000.0).round() / 1000.0),
            d.limited,
            d.limited_window,
        );
    }
}

/// The summary line of team size `n`.
fn print_summary(n: usize, results: &[Diagnosis], started: std::time::Instant) {
    let metrics: Vec<RunMetrics> = results.iter().map(|d| d.metrics.clone()).collect();
    let limited_window =
        results.iter().map(|d| d.limited_window).sum::<f64>() / results.len().max(1) as f64;
    let s = summarize(&metrics);
    println!(
        "N={n:>3} success5={:.3} success10={:.3} anchor={:.3} connected={:.3} conv={:.1} err={:.4} collisions={} limited_window={:.3} ({:.0} s)",
        s.success_rate_5,
        s.success_rate_10,
        s.anchor_success_rate.unwrap_or(f64::NAN),
        s.connected_rate.unwrap_or(f64::NAN),
        s.median_convergence_s.unwrap_or(f64::NAN),
        s.median_rel_formation_error.unwrap_or(f64::NAN),
        s.collisions,
        limited_window,
        started.elapsed().as_secs_f64(),
    );
}
