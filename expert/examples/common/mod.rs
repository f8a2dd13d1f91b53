//! What the team-size examples share: their scenarios and metrics, and runs spread over worker
//! threads.

use std::path::Path;

use formation_world::Scenario;
use formation_world::metrics::MetricsConfig;

/// The scenario at `path` with each of `sizes` robots, in that order.
pub fn scenarios_of_sizes(
    path: &Path,
    sizes: &[usize],
) -> Result<Vec<Scenario>, Box<dyn std::error::Error>> {
    let base = Scenario::from_path(path)?;
    Ok(sizes
        .iter()
        .map(|&n| base.with_robots(n))
        .collect::<Result<_, _>>()?)
}

/// The metrics of a team: the defaults, with the team figures.
pub fn team_metrics() -> MetricsConfig {
    MetricsConfig {
        team_figures: true,
        ..MetricsConfig::default()
    }
}

/// `run(i)` of every run `i` in `0..runs`, run `i` on worker `i % threads`, in run order.
pub fn in_run_order<T: Send>(
    runs: usize,
    threads: usize,
    run: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    let run = &run;
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|w| {
                s.spawn(move || {
                    (0..runs)
                        .filter(|i| i % threads == w)
                        .map(|i| (i, run(i)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let mut all: Vec<_> = workers
            .into_iter()
            .flat_map(|w| w.join().expect("join"))
            .collect();
        all.sort_by_key(|(i, _)| *i);
        all.into_iter().map(|(_, d)| d).collect()
    })
}
