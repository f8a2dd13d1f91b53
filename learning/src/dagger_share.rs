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

use formation_trainer_bridge::dagger_part::{
    PartHeader, RolloutSettings, file_fnv1a64, write_part,
};
use formation_trainer_bridge::dataset::Manifest;
use formation_world::Scenario;

use crate::LearningError;
use crate::dagger::{
    IterationRollouts, RolloutLabels, RolloutScenarios, check_beta, recorded_durations,
};

/// What one share labels and where its part goes.
#[derive(Debug, Clone)]
pub struct ShareOptions {
    /// The dataset the samples are for (only its manifest is read: the image settings).
    pub data: PathBuf,
    /// What the rollouts are drawn from, as in the DAgger session.
    pub rollouts: RolloutScenarios,
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
        source: Box::new(source),
    };
    let expert_share = opts.beta.powi(opts.iteration as i32);
    let scenarios = opts.rollouts.per_team_size()?;
    // A share labels with the law the dataset was collected with.
    let labels = RolloutLabels::for_law(dataset.settings.labels);
    crate::dagger::check_rollouts_match(
        &opts.data,
        &dataset,
        &scenarios,
        &dataset.settings.labels,
    )?;
    let header = PartHeader {
        dataset,
        iteration,
        rollouts: RolloutSettings {
            scenario: opts.rollouts.scenario.name().to_owned(),
            team_sizes: scenarios.iter().map(Scenario::n_robots).collect(),
            durations_s: recorded_durations(&opts.rollouts.scenario, &scenarios),
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
        occupancy: header.dataset.settings.occupancy,
        ranges: header.dataset.settings.ranges,
        neighbours: header.dataset.settings.neighbours,
        model: &opts.model,
        labels: &labels,
    };
    let samples = rollouts.label_runs(opts.runs.clone(), on_run_done)?;
    write_part(&opts.part, &header, &samples).map_err(part_error)?;
    Ok((header, samples.len()))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::dagger::tests::{empty_dataset, empty_dataset_with_header, options, scenario};
    use crate::dagger::{DaggerOptions, rollout_and_label};
    use formation_proto::NeighbourInput;
    use formation_trainer_bridge::dagger_part::append_parts;
    use formation_trainer_bridge::dataset::{DatasetHeader, DatasetReader};
    use formation_trainer_bridge::label_law::LabelLaw;

    /// An empty dataset in `dir/data` as [`empty_dataset`] makes, its header changed by `with`.
    fn dataset_with(
        dir: &Path,
        base: &Scenario,
        with: &dyn Fn(DatasetHeader) -> DatasetHeader,
    ) -> PathBuf {
        let plain = empty_dataset(&dir.join("plain"), base);
        let header = with(Manifest::read(&plain).unwrap().header());
        empty_dataset_with_header(dir, header)
    }

    /// Labels iteration 1 of a dataset (its header changed by `with`) once whole with `labels`
    /// and once in three shares appended out of order, and checks that the two datasets are the
    /// same byte for byte; returns the whole one.
    fn shares_write_the_dataset_of_one_labelling(
        dir: &Path,
        with: &dyn Fn(DatasetHeader) -> DatasetHeader,
        labels: RolloutLabels,
    ) -> PathBuf {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let base = scenario(3);
        let whole = dataset_with(&dir.join("whole"), &base, with);
        let opts = DaggerOptions {
            labels,
            ..options(whole.clone(), &base)
        };
        let scenarios = opts.rollouts.per_team_size().unwrap();
        let added = rollout_and_label(&opts, &scenarios, 1, opts.beta, &model, &|_| {}).unwrap();

        let shared = dataset_with(&dir.join("shared"), &base, with);
        let share = |runs: Range<usize>, name: &str| {
            let share = ShareOptions {
                data: shared.clone(),
                rollouts: opts.rollouts.clone(),
                model: model.clone(),
                iteration: 1,
                beta: opts.beta,
                seed: opts.seed,
                runs,
                part: dir.join(name),
            };
            label_share(&share, &|| {}).unwrap();
            share.part
        };
        let parts = [share(3..4, "c"), share(0..1, "a"), share(1..3, "b")];
        let (_, appended) = append_parts(&shared, 1, opts.runs, &parts).unwrap();
        assert_eq!(appended, added);
        let files = |dir: &Path| {
            let mut names: Vec<_> = std::fs::read_dir(dir)
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .collect();
            names.sort();
            names
        };
        assert_eq!(files(&whole), files(&shared));
        for name in files(&whole) {
            assert_eq!(
                std::fs::read(whole.join(&name)).unwrap(),
                std::fs::read(shared.join(&name)).unwrap(),
                "{name:?}"
            );
        }
        whole
    }

    #[test]
    fn shares_appended_in_run_order_write_the_dataset_of_one_labelling_byte_for_byte() {
        let dir = tempfile::tempdir().unwrap();
        shares_write_the_dataset_of_one_labelling(dir.path(), &|h| h, RolloutLabels::default());
    }

    #[test]
    fn shares_of_a_dataset_with_neighbours_and_own_scan_labels_keep_both() {
        let dir = tempfile::tempdir().unwrap();
        let input = NeighbourInput::with_default_rule(4).unwrap();
        let law = LabelLaw {
            own_scan: true,
            ..LabelLaw::default()
        };
        let with = |h: DatasetHeader| h.with_neighbours(Some(input)).with_labels(law);
        let labels = RolloutLabels {
            own_scan: true,
            ..RolloutLabels::default()
        };
        let whole = shares_write_the_dataset_of_one_labelling(dir.path(), &with, labels);
        let reader = DatasetReader::open(&whole).unwrap();
        assert_eq!(reader.header().settings.neighbours, Some(input));
        assert!(reader.header().settings.labels.own_scan);
        let samples = reader.load_all().unwrap();
        assert!(!samples.is_empty());
        assert!(samples.iter().all(|s| s.neighbours.len() == 16));

        // A share of the dataset labels from each robot's own scan: the expert's labels from
        // every pose would differ (three robots: the paper's law between offset points).
        let plain = shares_write_the_dataset_of_one_labelling(
            &dir.path().join("plain"),
            &|h: DatasetHeader| h.with_neighbours(Some(input)),
            RolloutLabels::default(),
        );
        let by_expert = DatasetReader::open(&plain).unwrap().load_all().unwrap();
        assert_eq!(by_expert.len(), samples.len());
        assert!(
            by_expert
                .iter()
                .zip(&samples)
                .any(|(a, b)| a.wheels != b.wheels)
        );
    }

    #[test]
    fn iteration_zero_or_a_beta_outside_zero_to_one_is_refused_before_anything_runs() {
        let base = scenario(3);
        let mut opts = ShareOptions {
            data: PathBuf::from("/nonexistent"),
            rollouts: RolloutScenarios {
                scenario: base,
                team_sizes: Vec::new(),
                durations: Vec::new(),
            },
            model: PathBuf::from("/nonexistent.onnx"),
            iteration: 0,
            beta: 0.0,
            seed: 1,
            runs: 0..1,
            part: PathBuf::from("/nonexistent/part"),
        };
        let err = label_share(&opts, &|| {}).unwrap_err();
        assert!(err.to_string().contains("--iteration"), "{err}");
        opts.iteration = 1;
        opts.beta = -0.5;
        let err = label_share(&opts, &|| {}).unwrap_err();
        assert!(err.to_string().contains("--beta"), "{err}");
    }
}
