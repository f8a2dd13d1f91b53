//! The expert's Table I figures per team size, for tuning (the product's command is
//! `formation eval --controller expert --robots ...`).
//!
//! ```text
//! cargo run -p formation-expert --release --example expert_teams -- SCENARIO RUNS N [N ...]
//! ```
//! Environment: `K3` overrides the formation gain under a neighbour graph.

mod common;

use std::path::PathBuf;

use formation_expert::{ExpertController, ExpertGains};
use formation_world::episode::run_episode;
use formation_world::metrics::{run_metrics, summarize};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().ok_or("scenario")?);
    let runs: usize = args.next().ok_or("runs")?.parse()?;
    let sizes: Vec<usize> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    let mut gains = ExpertGains::default();
    if let Ok(k) = std::env::var("K3") {
        gains.k_formation_graph = k.parse()?;
    }
    let cfg = common::team_metrics();
    for (scenario, n) in common::scenarios_of_sizes(&path, &sizes)?.iter().zip(sizes) {
        let metrics = common::in_run_order(runs, 2, |i| {
            let spec = scenario.run_spec(scenario.seed(), i);
            let mut expert =
                ExpertController::new(gains, spec.world.robot).with_neighbours(spec.neighbours);
            let traj = run_episode(&spec, &mut expert, &mut |_, _| {}).expect("expert");
            run_metrics(&traj, spec.ticks(), &cfg)
        });
        for (i, m) in metrics.iter().enumerate().filter(|(_, m)| !m.success_10) {
            eprintln!("N={n} run {i}: {m:?}");
        }
        let s = summarize(&metrics);
        println!(
            "N={n:>3} rule={} success5={:.2} success10={:.2} anchor={:?} connected={:?} conv={:?} err={:?} collisions={}",
            scenario.neighbours().name(),
            s.success_rate_5,
            s.success_rate_10,
            s.anchor_success_rate,
            s.connected_rate,
            s.median_convergence_s,
            s.median_rel_formation_error,
            s.collisions
        );
    }
    Ok(())
}
