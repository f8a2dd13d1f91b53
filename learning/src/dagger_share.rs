//! One share of a DAgger iteration's labelling, for a sweep over workers (a Ray cluster): runs
//! `A .. A + R` of iteration `k`, rolled out and labelled as [`crate::dagger::run_dagger`] does,
//! written as a DAgger part ([`formation_trainer_bridge::dagger_part`]), which
//! `formation dagger-append` appends with the iteration's other parts, in run order.
//!
//! Run `i` of iteration `k` is a pure function of the settings and `i`, so the parts of all the
//! shares appended in run order make the dataset one `formation dagger` iteration writes, byte
//! for byte.

use std::ops::Range;
use std::path::PathBuf;

use formation_trainer_bridge::dagger_part::{PartHeader, RolloutSettings, file_fnv1a64, write_part};
use formation_trainer_bridge::dataset::Manifest;
use formation_world::Scenario;

use crate::LearningError;
use crate::dagger::{IterationRollouts, check_beta, team_scenarios};

/// What one share labels and where its part goes.
#[derive(Debug, Clone)]
pub struct ShareOptions {
    /// The dataset the samples are for (only its manifest is read: the image settings).
    pub data: PathBuf,
    /// The rollout scenario.
    pub scenario: Scenario,
    /// Team sizes of the rollouts, used in turn (empty: the scenario's own size).
    pub team_sizes: Vec<usize>,
    /// The policy that drives this iteration (the previous iteration's model).
    pub model: PathBuf,
    /// The DAgger iteration, at least 1 (iteration 0 is the expert demonstrations).
    pub iteration: usize,
    /// `--beta` of the DAgger session: the expert drives a run with probability `beta^k`.
    pub beta: f64,
    /// Base seed of the DAgger rollouts.
    pub seed: u64,
    /// The runs of the iteration this share labels.
    pub runs: Range<usize>,
    /// The part file to write.
    pub part: PathBuf,
}

/// Labels the share's runs and writes them as a part, atomically; returns the part's header and
/// its sample count.
pub fn label_share(
    opts: &ShareOptions,
    on_run_done: &(dyn Fn() + Sync),
) -> Result<(PartHeader, usize), LearningError> {
    check_beta(opts.beta)?;
    if opts.iteration == 0 {
        return Err(LearningError::Setting {
            setting: "--iteration",
            problem: "must be at least 1 (iteration 0 is the expert demonstrations)".into(),
        });
    }
    let iteration = u32::try_from(opts.iteration).map_err(|_| LearningError::Setting {
        setting: "--iteration",
        problem: format!("{} is too large", opts.iteration),
    })?;
    let manifest = Manifest::read(&opts.data).map_err(|source| LearningError::Dataset {
        path: opts.data.clone(),
        source,
    })?;
    let dataset = manifest.header();
    let part_error = |source| LearningError::Part {
        path: opts.part.clone(),
        source,
    };
    let expert_share = opts.beta.powi(opts.iteration as i32);
    let scenarios = team_scenarios(&opts.scenario, &opts.team_sizes)?;
    let header = PartHeader {
        dataset,
        iteration,
        rollouts: RolloutSettings {
            scenario: opts.scenario.name().to_owned(),
            team_sizes: scenarios.iter().map(Scenario::n_robots).collect(),
            seed: opts.seed,
            expert_share,
            model_fnv1a64: file_fnv1a64(&opts.model).map_err(part_error)?,
        },
        first_run: opts.runs.start,
        runs: opts.runs.len(),
    };
    let rollouts = IterationRollouts {
        scenarios: &scenarios,
        iteration: opts.iteration,
        expert_share,
        seed: opts.seed,
        occupancy: header.dataset.occupancy,
        model: &opts.model,
    };
    let samples = rollouts.label_runs(opts.runs.clone(), on_run_done)?;
    write_part(&opts.part, &header, &samples).map_err(part_error)?;
    Ok((header, samples.len()))
}
