//! Closed-loop runs of a scenario in parallel (rayon), and their Table I summary.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use formation_expert::{ExpertController, ExpertGains};
use formation_robot_agent::decision::PolicyController;
use formation_schema::EvalOutput;
use formation_world::metrics::{MetricsConfig, RunMetrics, run_metrics, summarize};
use formation_world::{Controller, Scenario, Trajectory, run_episode};
use rayon::prelude::*;

use crate::LearningError;

/// What drives the robots.
#[derive(Debug, Clone, PartialEq)]
pub enum Driver {
    /// The model-based expert (sees every robot's pose), holding each robot's own neighbours
    /// under the scenario's rule.
    Expert(ExpertGains),
    /// The expert's law on each robot's own scan: one independent pilot per robot, which
    /// holds the neighbours it detects (`formation_expert::own_scan`).
    ExpertOwnScan(ExpertGains),
    /// The learned policy, one independent agent per robot: robot `i` runs `models[i]`.
    Policy {
        /// One model per robot.
        models: Vec<PathBuf>,
    },
}

impl Driver {
    /// `expert`, `expert-own-scan` or `policy`.
    pub fn name(&self) -> &'static str {
        match self {
            Driver::Expert(_) => "expert",
            Driver::ExpertOwnScan(_) => formation_expert::own_scan::OWN_SCAN_ID,
            Driver::Policy { .. } => "policy",
        }
    }

    /// The policy for `scenario`'s team: `default` for every robot, except the scenario's
    /// per-robot models (`[[agent]]`).
    pub fn policy_for(scenario: &Scenario, default: &Path) -> Result<Driver, LearningError> {
        let mut models = vec![default.to_path_buf(); scenario.n_robots()];
        for m in scenario.agent_models() {
            let robots = scenario.n_robots();
            let slot = models
                .get_mut(m.robot)
                .ok_or(LearningError::AgentOutOfTeam {
                    robot: m.robot,
                    robots,
                })?;
            *slot = m.model.clone();
        }
        Ok(Driver::Policy { models })
    }

    /// A fresh controller for `scenario`'s runs.
    pub fn controller(&self, scenario: &Scenario) -> Result<Box<dyn Controller>, LearningError> {
        match self {
            Driver::Expert(gains) => Ok(Box::new(
                ExpertController::for_world(*gains, scenario.world_config())
                    .with_neighbours(*scenario.neighbours()),
            )),
            Driver::ExpertOwnScan(gains) => {
                Ok(Box::new(formation_expert::own_scan::own_scan_team(
                    *gains,
                    scenario.world_config(),
                    *scenario.neighbours(),
                    scenario.n_robots(),
                )?))
            }
            Driver::Policy { models } => {
                let refs: Vec<&Path> = models.iter().map(PathBuf::as_path).collect();
                let world = scenario.world_config();
                // Each robot knows its own wheels, as a real one does: a policy that answers a
                // formation velocity has it shaped and bounded for them.
                let policy = PolicyController::from_model_paths(
                    &refs,
                    world.lidar,
                    world.robot.wheel_limits(),
                )
                .map_err(|source| LearningError::Policy { source })?;
                Ok(Box::new(policy))
            }
        }
    }
}

/// One evaluated run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResult {
    /// Run index.
    pub index: usize,
    /// Its metrics.
    pub metrics: RunMetrics,
    /// Its trajectory, when it was asked to be kept.
    pub trajectory: Option<Trajectory>,
}

/// Runs `runs` runs of `scenario` (base seed `base_seed`) driven by `driver`, in parallel on
/// rayon's current pool, and scores them with `cfg`. `keep(i)` says whether run `i`'s trajectory
/// is returned; `progress` is called after each finished run with the count so far. Results are
/// in run order and do not depend on the number of threads.
pub fn evaluate_runs(
    scenario: &Scenario,
    base_seed: u64,
    runs: usize,
    driver: &Driver,
    cfg: &MetricsConfig,
    keep: &(dyn Fn(usize) -> bool + Sync),
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<RunResult>, LearningError> {
    evaluate_run_range(scenario, base_seed, 0..runs, driver, cfg, keep, progress)
}

/// [`evaluate_runs`] for the runs `range` of the evaluation only (a share of a sweep): run `i`
/// is the same run, with the same result, as run `i` of the whole evaluation.
pub fn evaluate_run_range(
    scenario: &Scenario,
    base_seed: u64,
    range: std::ops::Range<usize>,
    driver: &Driver,
    cfg: &MetricsConfig,
    keep: &(dyn Fn(usize) -> bool + Sync),
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<RunResult>, LearningError> {
    // Build one controller here first, so that a model that cannot load is a typed error.
    driver.controller(scenario)?;
    let done = AtomicUsize::new(0);
    range
        .into_par_iter()
        .map_init(
            || driver.controller(scenario),
            |controller, i| {
                let controller = controller.as_mut().map_err(|e| LearningError::Setting {
                    setting: "driver",
                    problem: format!("could not be built on a worker thread: {e}"),
                })?;
                let spec = scenario.run_spec(base_seed, i);
                let traj = run_episode(&spec, controller.as_mut(), &mut |_, _| {})
                    .map_err(|source| LearningError::Run { run: i, source })?;
                let metrics = run_metrics(&traj, spec.ticks(), cfg);
                progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                Ok(RunResult {
                    index: i,
                    metrics,
                    trajectory: keep(i).then_some(traj),
                })
            },
        )
        .collect()
}

/// Runs `work` on a rayon pool of `threads` threads (`None`: rayon's global pool, one thread
/// per core).
pub fn with_threads<T: Send>(
    threads: Option<usize>,
    work: impl FnOnce() -> T + Send,
) -> Result<T, LearningError> {
    match threads {
        None => Ok(work()),
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map(|pool| pool.install(work))
            .map_err(|source| LearningError::Threads { threads, source }),
    }
}

/// The evaluation output of runs with these per-run metrics: the Table I and Fig. 9 summary.
pub fn eval_output(
    controller: &str,
    models: Vec<String>,
    scenario: &str,
    seed: Option<u64>,
    per_run: Vec<RunMetrics>,
) -> EvalOutput {
    EvalOutput::of_runs(
        controller,
        models,
        scenario,
        seed,
        summarize(&per_run),
        per_run,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(robots: usize) -> Scenario {
        let text = format!(
            "name = \"t\"\nrobots = {robots}\nduration_s = 20.0\nseed = 3\nruns = 4\n\
             [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n[lidar]\nbeams = 90\n"
        );
        Scenario::from_toml_str(&text, "t").unwrap()
    }

    #[test]
    fn parallel_runs_come_back_in_order_and_equal_whatever_the_thread_count() {
        let scenario = scenario(5);
        let driver = Driver::Expert(ExpertGains::default());
        let cfg = MetricsConfig::default();
        let run = |threads| {
            with_threads(Some(threads), || {
                evaluate_runs(&scenario, 3, 6, &driver, &cfg, &|i| i == 2, &|_| {})
            })
            .unwrap()
            .unwrap()
        };
        let one = run(1);
        let three = run(3);
        assert_eq!(one, three);
        assert_eq!(
            one.iter().map(|r| r.index).collect::<Vec<_>>(),
            (0..6).collect::<Vec<_>>()
        );
        assert!(one[2].trajectory.is_some() && one[0].trajectory.is_none());
        // The same as one run on its own.
        let spec = scenario.run_spec(3, 4);
        let mut expert = driver.controller(&scenario).unwrap();
        let traj = run_episode(&spec, expert.as_mut(), &mut |_, _| {}).unwrap();
        assert_eq!(
            one[4].metrics,
            run_metrics(&traj, traj.commands.len() as u64, &cfg)
        );
    }

    #[test]
    fn the_experts_law_on_each_robots_own_scan_forms_a_team_of_five() {
        // The full LIDAR (900 beams) at σ = 3 cm: what the detector is made for.
        let text = "name = \"t\"\nrobots = 5\nduration_s = 30.0\nseed = 3\nruns = 3\n\
                    [goal]\nv_star = 0.7\nd_star = 1.5\n[heading]\nschedule = \"random\"\n\
                    [lidar]\nnoise_std = 0.03\n";
        let scenario = Scenario::from_toml_str(text, "t").unwrap();
        let driver = Driver::ExpertOwnScan(ExpertGains::default());
        assert_eq!(driver.name(), "expert-own-scan");
        let cfg = MetricsConfig::default();
        let runs = evaluate_runs(&scenario, 3, 3, &driver, &cfg, &|_| false, &|_| {}).unwrap();
        for r in &runs {
            assert!(
                r.metrics.success_10 && r.metrics.collisions == 0,
                "run {}: {:?}",
                r.index,
                r.metrics
            );
        }
    }

    #[test]
    fn a_policy_whose_model_is_missing_is_a_typed_error_before_any_run() {
        let scenario = scenario(3);
        let driver = Driver::Policy {
            models: vec![PathBuf::from("/nonexistent/model.onnx"); 3],
        };
        let err = evaluate_runs(
            &scenario,
            1,
            2,
            &driver,
            &MetricsConfig::default(),
            &|_| false,
            &|_| {},
        )
        .unwrap_err();
        assert!(matches!(err, LearningError::Policy { .. }), "{err}");
        assert!(err.to_string().contains("/nonexistent/model.onnx"), "{err}");
    }
}
