//! Success by the runs' d*: reads the summaries that `formation eval --scenario S --json F`
//! wrote (one per controller or model, the same runs) and bins their runs by the d* the scenario
//! drew for each, for a model card's per-d* table.
//!
//! ```text
//! cargo run -p formation-learning --release --example by_d_star -- SCENARIO EDGES F.json [F.json ...]
//! ```
//! `EDGES` are the bins' bounds in metres, comma-separated (`0.8,1.2,1.6,2.0,2.5`). Each file
//! must hold the scenario's runs from run 0 on, at its seed.

use formation_schema::EvalOutput;
use formation_world::Scenario;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scenario, edges, files @ ..] = args.as_slice() else {
        return Err("usage: by_d_star SCENARIO EDGES F.json [F.json ...]".into());
    };
    let scenario = Scenario::from_path(std::path::Path::new(scenario))?;
    let edges: Vec<f64> = edges.split(',').map(str::parse).collect::<Result<_, _>>()?;
    let outputs: Vec<(String, EvalOutput)> = files
        .iter()
        .map(|f| -> Result<_, Box<dyn std::error::Error>> {
            let text = std::fs::read_to_string(f)?;
            Ok((f.clone(), serde_json::from_str(&text)?))
        })
        .collect::<Result<_, _>>()?;
    let runs = outputs.first().map_or(0, |(_, o)| o.per_run.len());
    if let Some((name, _)) = outputs.iter().find(|(_, o)| o.per_run.len() != runs) {
        return Err(format!(
            "{name} holds another number of runs than {}: evaluate every file over the same runs",
            files[0]
        )
        .into());
    }
    print!("| d* | runs |");
    for (name, out) in &outputs {
        print!(" {} ({}) |", out.controller, name);
    }
    println!();
    for bin in edges.windows(2) {
        let (low, high) = (bin[0], bin[1]);
        let seed = outputs
            .first()
            .and_then(|(_, o)| o.seed)
            .unwrap_or(scenario.seed());
        let runs: Vec<usize> = (0..runs)
            .filter(|&i| {
                let d = scenario.run_spec(seed, i).d_star;
                low <= d && d < high
            })
            .collect();
        print!("| {low:.1}–{high:.1} m | {} |", runs.len());
        for (_, out) in &outputs {
            let rate = |pick: fn(&formation_schema::RunMetrics) -> bool| {
                let hits = runs.iter().filter(|&&i| pick(&out.per_run[i])).count();
                100.0 * hits as f64 / runs.len().max(1) as f64
            };
            print!(
                " {:.0} / {:.0} % |",
                rate(|m| m.success_5),
                rate(|m| m.success_10)
            );
        }
        println!();
    }
    Ok(())
}
