//! The expert's own Table I / Fig. 9 figures: runs a scenario (default `scenarios/table1.toml`) with the
//! expert driving and prints the metrics summary as JSON.
//!
//! ```text
//! cargo run -p formation-expert --release --example expert_table1 -- [scenario.toml] [k_formation]
//! ```

use std::path::PathBuf;
use std::process::ExitCode;

use formation_expert::{ExpertController, ExpertGains};
use formation_world::Scenario;
use formation_world::episode::run_episode;
use formation_world::metrics::{MetricsConfig, run_metrics, summarize};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .map_or_else(|| PathBuf::from("scenarios/table1.toml"), PathBuf::from);
    let mut gains = ExpertGains::default();
    if let Some(k) = args.next() {
        match k.parse() {
            Ok(k) => gains.k_formation = k,
            Err(e) => {
                eprintln!("k_formation must be a number, got {k:?}: {e}");
                return ExitCode::from(2);
            }
        }
    }
    let scenario = match Scenario::from_path(&path) {
        Ok(scenario) => scenario,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let config = MetricsConfig::default();
    let mut metrics = Vec::with_capacity(scenario.runs());
    for run in 0..scenario.runs() {
        let spec = scenario.run_spec(scenario.seed(), run);
        let mut expert = ExpertController::new(gains, spec.world.robot);
        match run_episode(&spec, &mut expert, &mut |_, _| {}) {
            Ok(trajectory) => metrics.push(run_metrics(&trajectory, spec.ticks(), &config)),
            Err(e) => {
                eprintln!("run {run}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    for (run, m) in metrics
        .iter()
        .enumerate()
        .filter(|(_, m)| !m.success_5 || m.collisions > 0)
    {
        eprintln!("run {run}: {m:?}");
    }
    println!("gains: {gains:?}");
    match serde_json::to_string_pretty(&summarize(&metrics)) {
        Ok(json) => println!("{json}"),
        Err(e) => {
            eprintln!("cannot print the summary: {e}");
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
