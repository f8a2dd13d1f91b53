//! DAgger over teams: the policy drives (or, with probability `beta^k`, the expert), the expert
//! labels every robot's view at every tick, the samples are appended to the dataset as a new
//! iteration, the policy is retrained from its previous checkpoint, and each iteration's model is
//! evaluated in closed loop (the DAgger curve).
//!
//! Rollouts run in parallel with rayon. Run `i` of iteration `k` uses team size
//! `team_sizes[i % team_sizes.len()]` and the run spec `(seed + 1,000,003 k, i)` of the rollout
//! scenario resized to that team, so the samples are a pure function of the settings and the
//! model, written in run order.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use formation_expert::collect::Labeller;
use formation_expert::{ExpertController, ExpertGains};
use formation_proto::{NeighbourInput, OccupancySpec, RangeInput};
use formation_schema::EvalOutput;
use formation_trainer_bridge::dataset::{DatasetHeader, DatasetWriter, Sample};
use formation_trainer_bridge::label_law::LabelLaw;
use formation_trainer_bridge::train::{TrainOptions, TrainReport, train};
use formation_world::metrics::{MetricsConfig, RunMetrics};
use formation_world::{Controller, Scenario, run_episode};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::LearningError;
use crate::rollout::{Driver, eval_output, evaluate_runs};

/// Everything one DAgger session needs.
#[derive(Debug, Clone)]
pub struct DaggerOptions {
    /// The dataset DAgger appends to (it must exist: the expert demonstrations).
    pub data: PathBuf,
    /// What the rollouts are drawn from.
    pub rollouts: RolloutScenarios,
    /// Who labels the rollouts, and the wheel acceleration limits they are run under.
    pub labels: RolloutLabels,
    /// DAgger iterations.
    pub iterations: usize,
    /// The final model; every iteration's model is kept beside it (`<stem>-dagger<k>.onnx`).
    pub out: PathBuf,
    /// Start from this model instead of training one on the dataset first.
    pub init_model: Option<PathBuf>,
    /// Rollouts per iteration.
    pub runs: usize,
    /// Probability that the expert drives a run in iteration 1; it decays as `beta^k`.
    pub beta: f64,
    /// Training settings of every iteration (`data`, `out` and `init_from` are set per iteration).
    pub training: TrainOptions,
    /// The scenario of each iteration's closed-loop evaluation.
    pub eval_scenario: Scenario,
    /// Runs of that evaluation.
    pub eval_runs: usize,
    /// Base seed of the rollouts.
    pub seed: u64,
}

/// What one iteration did.
#[derive(Debug, Clone, PartialEq)]
pub enum DaggerEvent {
    /// Behaviour cloning on the dataset (iteration 0) started.
    Cloning,
    /// Iteration `k`'s rollouts appended `samples` samples from `runs` runs.
    Labelled {
        /// Iteration.
        k: usize,
        /// Samples appended.
        samples: usize,
        /// Rollouts.
        runs: usize,
        /// The expert's share.
        beta: f64,
    },
    /// A rollout finished (`done` of the iteration's runs).
    Rollout {
        /// Runs done so far.
        done: usize,
    },
    /// A line from the trainer.
    Trainer(String),
    /// Iteration `k`'s model was evaluated.
    Evaluated {
        /// Iteration.
        k: usize,
        /// Its closed-loop figures.
        figures: Box<EvalOutput>,
    },
}

/// What DAgger's rollouts are drawn from: a scenario, resized to each team size in turn.
#[derive(Debug, Clone)]
pub struct RolloutScenarios {
    /// The scenario the rollouts are drawn from.
    pub scenario: Scenario,
    /// Team sizes of the rollouts, used in turn (empty: the scenario's own size).
    pub team_sizes: Vec<usize>,
    /// Run lengths \[s\] of some team sizes, `(size, seconds)`, instead of the scenario's: long
    /// rollouts where large teams stall ([`team_scenarios`]).
    pub durations: Vec<(usize, f64)>,
}

impl RolloutScenarios {
    /// The scenario of each team size, run `i` playing the `i % len`-th ([`team_scenarios`]).
    pub fn per_team_size(&self) -> Result<Vec<Scenario>, LearningError> {
        team_scenarios(&self.scenario, &self.team_sizes, &self.durations)
    }
}

/// Runs DAgger; returns the DAgger curve (the closed-loop figures of iteration 0, 1, ...), which is
/// also written as `<stem>-dagger-curve.json` beside `out`, rewritten after every evaluation so
/// that an interrupted run keeps the curve of the iterations it finished.
pub fn run_dagger(
    opts: &DaggerOptions,
    on_event: &(dyn Fn(DaggerEvent) + Sync),
) -> Result<Vec<EvalOutput>, LearningError> {
    check_beta(opts.beta)?;
    let scenarios = opts.rollouts.per_team_size()?;
    let out_dir = opts
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    std::fs::create_dir_all(&out_dir).map_err(|source| LearningError::Io {
        what: "creating",
        path: out_dir.clone(),
        source,
    })?;
    let stem = opts
        .out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or("policy".into());
    let train_to =
        |out: PathBuf, init_from: Option<PathBuf>| -> Result<TrainReport, LearningError> {
            let options = TrainOptions {
                data: vec![opts.data.clone()],
                out: out.clone(),
                init_from,
                ..opts.training.clone()
            };
            train(&options, &mut |line| {
                on_event(DaggerEvent::Trainer(line.to_owned()))
            })
            .map_err(|source| LearningError::Train { out, source })
        };

    let mut model = match &opts.init_model {
        Some(m) => m.clone(),
        None => {
            let m0 = out_dir.join(format!("{stem}-dagger0.onnx"));
            on_event(DaggerEvent::Cloning);
            train_to(m0.clone(), None)?;
            m0
        }
    };
    let curve_path = out_dir.join(format!("{stem}-dagger-curve.json"));
    let mut curve = vec![evaluate_iteration(opts, 0, &model, on_event)?];
    write_curve(&curve_path, &curve)?;
    for k in 1..=opts.iterations {
        let beta = opts.beta.powi(k as i32);
        let samples = rollout_and_label(opts, &scenarios, k, beta, &model, on_event)?;
        on_event(DaggerEvent::Labelled {
            k,
            samples,
            runs: opts.runs,
            beta,
        });
        let next = if k == opts.iterations {
            opts.out.clone()
        } else {
            out_dir.join(format!("{stem}-dagger{k}.onnx"))
        };
        train_to(next.clone(), Some(warm_start_of(&model)))?;
        model = next;
        curve.push(evaluate_iteration(opts, k, &model, on_event)?);
        write_curve(&curve_path, &curve)?;
    }
    if opts.iterations == 0 && model != opts.out {
        std::fs::copy(&model, &opts.out).map_err(|source| LearningError::Io {
            what: "copying to",
            path: opts.out.clone(),
            source,
        })?;
    }
    Ok(curve)
}

/// Writes the curve so far to `path`, atomically: a reader sees the previous curve or this one.
fn write_curve(path: &Path, curve: &[EvalOutput]) -> Result<(), LearningError> {
    let json = serde_json::to_vec_pretty(curve).map_err(|e| LearningError::Io {
        what: "writing",
        path: path.to_path_buf(),
        source: e.into(),
    })?;
    formation_world::runlog::write_atomic(path, &json).map_err(|source| LearningError::Curve {
        path: path.to_path_buf(),
        source,
    })
}

/// What the next iteration trains on from: the checkpoint written beside `model` when there is
/// one (it was trained here), else the `.onnx` itself, whose weights the trainer imports (a
/// shipped model has no checkpoint beside it).
fn warm_start_of(model: &Path) -> PathBuf {
    let checkpoint = model.with_extension("pt");
    if checkpoint.is_file() {
        checkpoint
    } else {
        model.to_path_buf()
    }
}

/// Iteration `k`'s closed-loop figures on the evaluation scenario.
fn evaluate_iteration(
    opts: &DaggerOptions,
    k: usize,
    model: &Path,
    on_event: &(dyn Fn(DaggerEvent) + Sync),
) -> Result<EvalOutput, LearningError> {
    let scenario = &opts.eval_scenario;
    let driver = Driver::policy_for(scenario, model)?;
    let results = evaluate_runs(
        scenario,
        scenario.seed(),
        opts.eval_runs,
        &driver,
        &MetricsConfig::default(),
        &|_| false,
        &|_| {},
    )?;
    let per_run: Vec<RunMetrics> = results.into_iter().map(|r| r.metrics).collect();
    let figures = eval_output(
        "policy",
        vec![model.display().to_string()],
        scenario.name(),
        Some(scenario.seed()),
        per_run,
    );
    on_event(DaggerEvent::Evaluated {
        k,
        figures: Box::new(figures.clone()),
    });
    Ok(figures)
}

/// Rolls out `model` (or the expert, with probability `beta` per run) over `opts.runs` runs of
/// the team sizes in turn and appends every robot's expert-labelled view at every tick as
/// iteration `k`; returns the number of samples appended.
pub(crate) fn rollout_and_label(
    opts: &DaggerOptions,
    scenarios: &[Scenario],
    k: usize,
    beta: f64,
    model: &Path,
    on_event: &(dyn Fn(DaggerEvent) + Sync),
) -> Result<usize, LearningError> {
    let dataset = |source| LearningError::Dataset {
        path: opts.data.clone(),
        source,
    };
    let mut writer = DatasetWriter::append(&opts.data, k as u32).map_err(dataset)?;
    check_rollouts_match(
        &opts.data,
        writer.header(),
        scenarios,
        &opts.labels.label_law(),
    )?;
    let rollouts = IterationRollouts {
        scenarios,
        iteration: k,
        expert_share: beta,
        seed: opts.seed,
        occupancy: writer.header().settings.occupancy,
        ranges: writer.header().settings.ranges,
        neighbours: writer.header().settings.neighbours,
        model,
        labels: &opts.labels,
    };
    let done = AtomicUsize::new(0);
    let samples = rollouts.label_runs(0..opts.runs, &|| {
        on_event(DaggerEvent::Rollout {
            done: done.fetch_add(1, Ordering::Relaxed) + 1,
        });
    })?;
    let added = samples.len();
    for sample in samples {
        writer.push(sample).map_err(dataset)?;
    }
    writer.finish().map_err(dataset)?;
    Ok(added)
}

/// Refuses rollouts whose samples would not be the dataset's: each team scenario's LIDAR must
/// have the dataset's beams and range, and its v* be one fixed speed, the dataset's `v_train` (the speed the labels are
/// recorded at, and that a formation-velocity target subtracts the reference term at).
pub(crate) fn check_rollouts_match(
    path: &Path,
    header: &DatasetHeader,
    scenarios: &[Scenario],
    labels: &LabelLaw,
) -> Result<(), LearningError> {
    let settings = &header.settings;
    let mismatch = |what, dataset: String, rollout: String, fix| LearningError::RolloutMismatch {
        path: path.to_path_buf(),
        what,
        dataset,
        rollout,
        fix,
    };
    if *labels != settings.labels {
        return Err(mismatch(
            "label law",
            settings.labels.to_string(),
            labels.to_string(),
            "label with the law the dataset was collected with (the same --label-wheel-accel, --unshaped-labels, --label-pair-band and --own-scan-labels as its `formation collect`), or collect a new dataset",
        ));
    }
    for scenario in scenarios {
        // The sensor's contract; its range noise may differ (rollouts noisier than the
        // demonstrations are a choice).
        let lidar = scenario.world_config().lidar;
        if (lidar.beams, lidar.max_range)
            != (settings.lidar.spec.beams, settings.lidar.spec.max_range)
        {
            return Err(mismatch(
                "LIDAR",
                format!(
                    "{} beams of {} m",
                    settings.lidar.spec.beams, settings.lidar.spec.max_range
                ),
                format!("{} beams of {} m", lidar.beams, lidar.max_range),
                "roll out the scenario the dataset was collected with, or collect a new dataset",
            ));
        }
        match scenario.v_star().fixed() {
            Some(v_star) if v_star == settings.v_train => {}
            _ => {
                return Err(mismatch(
                    "v*",
                    format!("v_train {} m/s", settings.v_train),
                    format!("{:?}", scenario.v_star()),
                    "give the rollout scenario goal.v_star equal to the dataset's v_train",
                ));
            }
        }
    }
    Ok(())
}

/// The rollout scenario resized to each team size (the scenario's own size when none is given),
/// each run `durations` seconds long where they name its size (`(size, seconds)`; the
/// scenario's length otherwise): run `i` plays `team_scenarios(..)[i % len]`. A duration for a
/// size that is not rolled out is refused, naming the sizes that are.
pub fn team_scenarios(
    scenario: &Scenario,
    team_sizes: &[usize],
    durations: &[(usize, f64)],
) -> Result<Vec<Scenario>, LearningError> {
    let sizes = if team_sizes.is_empty() {
        vec![scenario.n_robots()]
    } else {
        team_sizes.to_vec()
    };
    if let Some((size, _)) = durations.iter().find(|(n, _)| !sizes.contains(n)) {
        return Err(LearningError::Setting {
            setting: "--rollout-durations",
            problem: format!(
                "names teams of {size}, but the rollouts are of {sizes:?} robots (--team-sizes)"
            ),
        });
    }
    sizes
        .iter()
        .map(|&n| {
            let resized = scenario.with_robots(n)?;
            match durations.iter().rev().find(|(size, _)| *size == n) {
                Some(&(_, seconds)) => Ok(resized.with_duration(seconds)?),
                None => Ok(resized),
            }
        })
        .collect()
}

/// The run lengths a part header records for these rollout scenarios: empty when every one is
/// `base`'s length, else each one's, in turn.
pub fn recorded_durations(base: &Scenario, scenarios: &[Scenario]) -> Vec<f64> {
    if scenarios
        .iter()
        .all(|s| s.duration_s() == base.duration_s())
    {
        Vec::new()
    } else {
        scenarios.iter().map(Scenario::duration_s).collect()
    }
}

/// Refuses a `--beta` outside [0, 1].
pub fn check_beta(beta: f64) -> Result<(), LearningError> {
    if (0.0..=1.0).contains(&beta) {
        return Ok(());
    }
    Err(LearningError::Setting {
        setting: "--beta",
        problem: format!("must be in [0, 1] (got {beta})"),
    })
}

/// Who labels DAgger's rollouts, and under which wheel acceleration limits they run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RolloutLabels {
    /// The expert's gains; [`ExpertGains::shaping_wheel_accel`] makes its labels one function
    /// of the image whatever a run's limit.
    pub gains: ExpertGains,
    /// Label each robot with the expert's law on the neighbours it detects in its own scan
    /// instead of from every pose (`--own-scan-labels`, [`LabelLaw::own_scan`]).
    pub own_scan: bool,
    /// Wheel acceleration limits \[m/s²\] (`None`: no limit) the runs use in turn, each with
    /// every team size: run `i` uses `wheel_accels[(i / team sizes) % len]`. Empty: the
    /// scenario's own.
    pub wheel_accels: Vec<Option<f64>>,
}

impl RolloutLabels {
    /// The law these labels are given by (what the dataset must record): the gains' shaping
    /// and pair weights, from every pose or from each robot's own scan.
    pub fn label_law(&self) -> LabelLaw {
        LabelLaw {
            own_scan: self.own_scan,
            ..self.gains.label_law()
        }
    }

    /// The labels of a dataset's recorded `law`: the default gains labelling by it.
    pub fn for_law(law: LabelLaw) -> RolloutLabels {
        RolloutLabels {
            gains: ExpertGains::default().with_label_law(law),
            own_scan: law.own_scan,
            wheel_accels: Vec::new(),
        }
    }

    /// The wheel acceleration limit of run `i` when `teams` team sizes are used in turn, if it
    /// overrides the scenario's.
    fn wheel_accel_of_run(&self, i: usize, teams: usize) -> Option<Option<f64>> {
        if self.wheel_accels.is_empty() {
            return None;
        }
        Some(self.wheel_accels[(i / teams.max(1)) % self.wheel_accels.len()])
    }
}

/// Iteration `k`'s rollouts: who drives, who labels, and how runs are drawn. Any range of runs
/// can be labelled on its own ([`IterationRollouts::label_runs`]): run `i` is a pure function of
/// these settings and `i`, so ranges labelled apart and concatenated in run order are the whole.
#[derive(Debug, Clone, Copy)]
pub struct IterationRollouts<'a> {
    /// The rollout scenario per team size ([`team_scenarios`]); run `i` plays `i % len`.
    pub scenarios: &'a [Scenario],
    /// The DAgger iteration (at least 1; samples carry it).
    pub iteration: usize,
    /// The probability that the expert drives a run (`beta^k`).
    pub expert_share: f64,
    /// Base seed of the DAgger rollouts; iteration `k` draws its runs from
    /// `seed + 1,000,003 k`.
    pub seed: u64,
    /// How the samples' occupancy images are rendered (the dataset's settings).
    pub occupancy: OccupancySpec,
    /// The scan's ranges recorded beside each image, if the dataset holds them.
    pub ranges: Option<RangeInput>,
    /// The neighbours detected in the scan recorded beside each image, if the dataset holds
    /// them.
    pub neighbours: Option<NeighbourInput>,
    /// The policy that drives when the expert does not.
    pub model: &'a Path,
    /// The expert's gains and the runs' wheel acceleration limits.
    pub labels: &'a RolloutLabels,
}

impl IterationRollouts<'_> {
    /// Rolls out runs `runs` in parallel (rayon) and returns every robot's expert-labelled view
    /// at every tick, in run order; `on_run_done` is called as each run finishes.
    pub fn label_runs(
        &self,
        runs: Range<usize>,
        on_run_done: &(dyn Fn() + Sync),
    ) -> Result<Vec<Sample>, LearningError> {
        let drivers = self
            .scenarios
            .iter()
            .map(|s| Driver::policy_for(s, self.model))
            .collect::<Result<Vec<_>, _>>()?;
        let per_run: Vec<Vec<Sample>> = runs
            .into_par_iter()
            // One policy per team size, built on each worker the first time it needs it.
            .map_init(
                || (0..self.scenarios.len()).map(|_| None).collect::<Vec<_>>(),
                |policies: &mut Vec<Option<Box<dyn Controller>>>, i| {
                    let samples = self.label_run(&drivers, policies, i)?;
                    on_run_done();
                    Ok(samples)
                },
            )
            .collect::<Result<_, LearningError>>()?;
        Ok(per_run.into_iter().flatten().collect())
    }

    /// Run `i`'s labelled samples, driven by the expert or by the policy of its team size
    /// (built into `policies` on first use).
    fn label_run(
        &self,
        drivers: &[Driver],
        policies: &mut [Option<Box<dyn Controller>>],
        i: usize,
    ) -> Result<Vec<Sample>, LearningError> {
        let k = self.iteration;
        let iteration_seed = self.seed.wrapping_add(1_000_003 * k as u64);
        let size = i % self.scenarios.len();
        let scenario = &self.scenarios[size];
        let mut spec = scenario.run_spec(iteration_seed, i);
        if let Some(accel) = self.labels.wheel_accel_of_run(i, self.scenarios.len()) {
            spec.world.robot.max_wheel_accel = accel;
        }
        let mut coin = rand_chacha::ChaCha8Rng::seed_from_u64(spec.seed ^ 0xDA66E5);
        let beta = self.expert_share;
        let expert_drives = beta > 0.0 && coin.random::<f64>() < beta;
        let gains = self.labels.gains;
        let mut expert =
            ExpertController::for_world(gains, &spec.world).with_neighbours(spec.neighbours);
        if policies[size].is_none() && !expert_drives {
            policies[size] = Some(drivers[size].controller(scenario)?);
        }
        let driver: &mut dyn Controller = match &mut policies[size] {
            Some(policy) if !expert_drives => policy.as_mut(),
            _ => &mut expert,
        };
        let mut labeller = Labeller::for_run(&spec, gains, self.occupancy)
            .and_then(|labeller| labeller.with_ranges(self.ranges))
            .and_then(|labeller| labeller.with_neighbour_input(self.neighbours))
            .and_then(|labeller| labeller.with_own_scan_labels(self.labels.own_scan))
            .map_err(|source| LearningError::Label { run: i, source })?;
        let mut samples = Vec::new();
        let mut failure = None;
        run_episode(&spec, driver, &mut |obs, _| {
            if failure.is_none() {
                failure = labeller
                    .label_observation(obs, k as u32, i as u32, &mut |s| samples.push(s))
                    .err();
            }
        })
        .map_err(|source| LearningError::Run { run: i, source })?;
        match failure {
            Some(source) => Err(LearningError::Label { run: i, source }),
            None => Ok(samples),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use formation_trainer_bridge::dataset::{DatasetHeader, DatasetReader, Sample};

    /// A 1 s scenario of `robots` robots, 4 runs.
    pub(crate) fn scenario(robots: usize) -> Scenario {
        let text = format!(
            "name = \"dagger-test\"\nrobots = {robots}\nduration_s = 1.0\nseed = 5\nruns = 4\n\
             [goal]\nv_star = 0.7\nd_star_choices = [1.0, 2.0]\n[heading]\nschedule = \"random\"\n"
        );
        Scenario::from_toml_str(&text, "dagger-test").unwrap()
    }

    /// The settings of a dataset of `scenario`'s first run: the paper's images, its LIDAR, v* and
    /// seed.
    fn paper_header(scenario: &Scenario) -> DatasetHeader {
        let spec = scenario.run_spec(scenario.seed(), 0);
        DatasetHeader::new(
            OccupancySpec::PAPER,
            spec.world.simulated_lidar(),
            spec.v_star,
            scenario.seed(),
            scenario.name(),
        )
    }

    /// An empty dataset in `dir/data` with the paper's images and `scenario`'s LIDAR.
    pub(crate) fn empty_dataset(dir: &Path, scenario: &Scenario) -> PathBuf {
        empty_dataset_with_header(dir, paper_header(scenario))
    }

    /// An empty dataset in `dir/data` with `header`.
    pub(crate) fn empty_dataset_with_header(dir: &Path, header: DatasetHeader) -> PathBuf {
        let path = dir.join("data");
        DatasetWriter::create(&path, header)
            .unwrap()
            .finish()
            .unwrap();
        path
    }

    /// The samples of run 0 of iteration 1 over `scenarios`, driven by the expert (`model`
    /// never drives) and labelled by `labels`, with `neighbours` recorded if given.
    fn expert_labels_of_run_0(
        scenarios: &[Scenario],
        model: &Path,
        labels: &RolloutLabels,
        neighbours: Option<NeighbourInput>,
    ) -> Vec<Sample> {
        IterationRollouts {
            scenarios,
            iteration: 1,
            expert_share: 1.0,
            seed: 4,
            occupancy: OccupancySpec::PAPER,
            ranges: None,
            neighbours,
            model,
            labels,
        }
        .label_runs(0..1, &|| {})
        .unwrap()
    }

    /// DAgger over teams of 3 and 5 from `base`, 4 runs, beta 0.5, seed 9.
    pub(crate) fn options(data: PathBuf, base: &Scenario) -> DaggerOptions {
        DaggerOptions {
            data,
            rollouts: RolloutScenarios {
                scenario: base.clone(),
                team_sizes: vec![3, 5],
                durations: Vec::new(),
            },
            labels: RolloutLabels::default(),
            iterations: 1,
            out: PathBuf::from("unused.onnx"),
            init_model: None,
            runs: 4,
            beta: 0.5,
            training: TrainOptions::default(),
            eval_scenario: base.clone(),
            eval_runs: 1,
            seed: 9,
        }
    }

    #[test]
    fn rollouts_that_would_mix_their_samples_into_the_dataset_are_refused() {
        let base = scenario(3);
        let header = paper_header(&base);
        let path = Path::new("D");
        check_rollouts_match(
            path,
            &header,
            std::slice::from_ref(&base),
            &LabelLaw::default(),
        )
        .expect("the same");
        let with = |goal: &str, lidar: &str| {
            let text = format!(
                "name = \"x\"\nrobots = 3\nduration_s = 1.0\nseed = 5\n[goal]\n{goal}\n\
                 d_star = 1.0\n[heading]\nschedule = \"random\"\n{lidar}"
            );
            Scenario::from_toml_str(&text, "x").unwrap()
        };
        for (other, what) in [
            (with("v_star = 0.5", ""), "v*"),
            (with("v_star_range = [0.5, 0.7]", ""), "v*"),
            (with("v_star = 0.7", "[lidar]\nbeams = 360"), "LIDAR"),
        ] {
            let err =
                check_rollouts_match(path, &header, &[base.clone(), other], &LabelLaw::default())
                    .unwrap_err();
            assert!(
                matches!(err, LearningError::RolloutMismatch { what: w, .. } if w == what),
                "{err}"
            );
        }
        // Another range noise is a choice, not a mix-up.
        let noisy = with("v_star = 0.7", "[lidar]\nnoise_std = 0.05");
        check_rollouts_match(path, &header, &[noisy], &LabelLaw::default())
            .expect("noise may differ");
        // Samples labelled by another law than the dataset's would mix two laws in one dataset.
        let unshaped = LabelLaw {
            unshaped: true,
            ..LabelLaw::default()
        };
        let same = std::slice::from_ref(&base);
        let err = check_rollouts_match(path, &header, same, &unshaped).unwrap_err();
        assert!(
            matches!(
                err,
                LearningError::RolloutMismatch {
                    what: "label law",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("--unshaped-labels"), "{err}");
        let unshaped_dataset = header.clone().with_labels(unshaped);
        check_rollouts_match(path, &unshaped_dataset, same, &unshaped).expect("the same law");
        // Own-scan labels may join only a dataset labelled from each robot's own scan.
        let own_scan = LabelLaw {
            own_scan: true,
            ..unshaped
        };
        let err = check_rollouts_match(path, &unshaped_dataset, same, &own_scan).unwrap_err();
        assert!(
            matches!(
                &err,
                LearningError::RolloutMismatch {
                    what: "label law",
                    rollout,
                    ..
                } if rollout.contains("own scan (--own-scan-labels)")
            ),
            "{err}"
        );
        let own_scan_dataset = header.clone().with_labels(own_scan);
        check_rollouts_match(path, &own_scan_dataset, same, &own_scan).expect("the same law");
        check_rollouts_match(path, &own_scan_dataset, same, &unshaped).unwrap_err();
    }

    /// The expert drives every run of three robots (all pairs): labelled from every pose, from
    /// each robot's own scan with the neighbours input recorded, and without it.
    #[test]
    fn own_scan_rollouts_record_the_datasets_neighbours_and_label_from_each_robots_scan() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let scenarios = team_scenarios(&scenario(3), &[], &[]).unwrap();
        let input = NeighbourInput::with_default_rule(4).unwrap();
        let label = |labels: &RolloutLabels, neighbours| {
            expert_labels_of_run_0(&scenarios, &model, labels, neighbours)
        };
        let own = RolloutLabels {
            own_scan: true,
            ..RolloutLabels::default()
        };
        let by_expert = label(&RolloutLabels::default(), Some(input));
        let by_own_scan = label(&own, Some(input));
        let without_input = label(&own, None);
        assert_eq!(by_expert.len(), 20 * 3);
        assert_eq!(by_own_scan.len(), by_expert.len());
        // The same states and neighbours (the expert drives both); other labels: the own-scan
        // law measures pairs between the centres it detects, the paper's between offset points.
        for (a, b) in by_expert.iter().zip(&by_own_scan) {
            assert_eq!((&a.occupancy, &a.neighbours), (&b.occupancy, &b.neighbours));
            assert_eq!(a.neighbours.len(), 16);
        }
        let relabelled = by_expert
            .iter()
            .zip(&by_own_scan)
            .filter(|(a, b)| a.wheels != b.wheels)
            .count();
        assert!(relabelled > by_expert.len() / 2, "{relabelled}");
        // Without the input recorded, the detections and so the labels are the same.
        assert!(without_input.iter().all(|s| s.neighbours.is_empty()));
        let wheels = |samples: &[Sample]| samples.iter().map(|s| s.wheels).collect::<Vec<_>>();
        assert_eq!(wheels(&without_input), wheels(&by_own_scan));
        // A dataset's recorded law gives the same labels back.
        assert!(own.label_law().own_scan);
        assert_eq!(RolloutLabels::for_law(own.label_law()), own);
    }

    #[test]
    fn rollout_durations_lengthen_the_named_team_sizes_and_refuse_others() {
        let base = scenario(3);
        let scenarios = team_scenarios(&base, &[3, 5], &[(5, 3.0)]).unwrap();
        assert_eq!(scenarios[0].duration_s(), base.duration_s());
        assert_eq!(
            (scenarios[1].n_robots(), scenarios[1].duration_s()),
            (5, 3.0)
        );
        assert_eq!(
            recorded_durations(&base, &scenarios),
            [base.duration_s(), 3.0]
        );
        let same = team_scenarios(&base, &[3, 5], &[]).unwrap();
        assert!(recorded_durations(&base, &same).is_empty());
        let error = team_scenarios(&base, &[3, 5], &[(8, 3.0)])
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("teams of 8") && error.contains("[3, 5]"),
            "{error}"
        );
        let error = team_scenarios(&base, &[3], &[(3, -1.0)])
            .unwrap_err()
            .to_string();
        assert!(error.contains("duration_s"), "{error}");
    }

    #[test]
    fn the_next_iteration_warm_starts_from_the_checkpoint_beside_a_model_else_from_the_model() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("shipped.onnx");
        std::fs::write(&model, b"onnx").unwrap();
        assert_eq!(warm_start_of(&model), model);
        let checkpoint = dir.path().join("shipped.pt");
        std::fs::write(&checkpoint, b"pt").unwrap();
        assert_eq!(warm_start_of(&model), checkpoint);
    }

    #[test]
    fn rollouts_over_team_sizes_label_every_robots_view_in_run_order_and_replay() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let base = scenario(3);
        let scenarios = [base.with_robots(3).unwrap(), base.with_robots(5).unwrap()];
        let dir = tempfile::tempdir().unwrap();
        let mut read = Vec::new();
        for copy in ["a", "b"] {
            let data = empty_dataset(&dir.path().join(copy), &base);
            let opts = options(data.clone(), &base);
            let added = rollout_and_label(&opts, &scenarios, 1, 0.5, &model, &|_| {}).unwrap();
            // Runs 0..4 use teams of 3, 5, 3, 5 robots, 20 ticks each, one sample per robot.
            assert_eq!(added, 20 * (3 + 5 + 3 + 5));
            let samples = DatasetReader::open(&data).unwrap().load_all().unwrap();
            assert_eq!(samples.len(), added);
            assert!(samples.iter().all(|s| s.iteration == 1));
            let robots_of_run = |run: u32| {
                samples
                    .iter()
                    .filter(|s| s.run == run)
                    .map(|s| usize::from(s.robot) + 1)
                    .max()
            };
            assert_eq!(
                (0..4).map(robots_of_run).collect::<Vec<_>>(),
                [Some(3), Some(5), Some(3), Some(5)]
            );
            read.push(samples);
        }
        assert_eq!(read[0], read[1], "the same settings give the same samples");
    }

    #[test]
    fn labelling_two_ranges_of_runs_and_concatenating_them_equals_the_whole_range() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let base = scenario(3);
        let scenarios = team_scenarios(&base, &[3, 5], &[]).unwrap();
        let rollouts = IterationRollouts {
            scenarios: &scenarios,
            iteration: 2,
            expert_share: 0.25,
            seed: 9,
            occupancy: OccupancySpec::PAPER,
            ranges: None,
            neighbours: None,
            model: &model,
            labels: &RolloutLabels::default(),
        };
        let done = AtomicUsize::new(0);
        let count = || {
            done.fetch_add(1, Ordering::Relaxed);
        };
        let whole = rollouts.label_runs(0..5, &count).unwrap();
        assert_eq!(done.load(Ordering::Relaxed), 5, "every run reports once");
        let mut parts = rollouts.label_runs(0..2, &|| {}).unwrap();
        parts.extend(rollouts.label_runs(2..5, &|| {}).unwrap());
        assert_eq!(whole.len(), 20 * (3 + 5 + 3 + 5 + 3));
        assert!(whole.iter().all(|s| s.iteration == 2));
        assert_eq!(parts, whole);
    }

    #[test]
    fn each_team_size_runs_with_each_wheel_acceleration_limit_in_turn() {
        let labels = RolloutLabels {
            wheel_accels: vec![None, Some(1.0), Some(2.0)],
            ..RolloutLabels::default()
        };
        // Two team sizes: runs 0-1 without a limit, 2-3 at 1.0, 4-5 at 2.0, then again.
        let limits: Vec<_> = (0..8).map(|i| labels.wheel_accel_of_run(i, 2)).collect();
        assert_eq!(
            limits,
            [
                None,
                None,
                Some(1.0),
                Some(1.0),
                Some(2.0),
                Some(2.0),
                None,
                None
            ]
            .map(Some)
        );
        assert_eq!(RolloutLabels::default().wheel_accel_of_run(3, 2), None);
    }

    /// The expert drives every run: one run under a 0.5 m/s² limit and labels shaped for it,
    /// against the same run without a limit and labels shaped for 0.5 m/s² all the same.
    #[test]
    fn rollouts_run_under_the_limits_asked_and_label_with_the_gains_asked() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let scenarios = team_scenarios(&scenario(5), &[], &[]).unwrap();
        let label =
            |labels: &RolloutLabels| expert_labels_of_run_0(&scenarios, &model, labels, None);
        let limited = label(&RolloutLabels {
            wheel_accels: vec![Some(0.5)],
            ..RolloutLabels::default()
        });
        let shaped_free = label(&RolloutLabels {
            gains: ExpertGains {
                shaping_wheel_accel: Some(0.5),
                ..ExpertGains::default()
            },
            own_scan: false,
            wheel_accels: vec![None],
        });
        let free = label(&RolloutLabels::default());
        let first_tick = |samples: &[Sample]| samples[..5].to_vec();
        // At tick 0 the robots stand where the run put them: the labels are the gains' alone.
        assert_eq!(first_tick(&limited), first_tick(&shaped_free));
        assert_ne!(first_tick(&limited), first_tick(&free));
        // Later the world's limit moves the robots differently.
        assert_eq!(limited.len(), shaped_free.len());
        assert_ne!(limited, shaped_free);
    }

    #[test]
    fn a_run_that_fails_in_training_keeps_the_curve_of_what_it_evaluated() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../onnx/models/policy.onnx");
        let base = scenario(3);
        let dir = tempfile::tempdir().unwrap();
        let data = empty_dataset(dir.path(), &base);
        let mut opts = options(data, &base);
        opts.init_model = Some(model);
        opts.out = dir.path().join("models").join("m.onnx");
        // Iteration 1's training cannot start: there is no such interpreter.
        opts.training.python = Some(dir.path().join("no-such-python"));
        let err = run_dagger(&opts, &|_| {}).unwrap_err();
        assert!(matches!(err, LearningError::Train { .. }), "{err}");
        let text = std::fs::read_to_string(dir.path().join("models").join("m-dagger-curve.json"))
            .expect("the curve of iteration 0 was written before iteration 1 failed");
        let curve: Vec<EvalOutput> = serde_json::from_str(&text).unwrap();
        assert_eq!(curve.len(), 1);
        assert_eq!(curve[0].summary.runs, 1);
    }

    #[test]
    fn a_beta_outside_zero_to_one_is_refused() {
        let base = scenario(3);
        let mut opts = options(PathBuf::from("/nonexistent"), &base);
        opts.beta = 1.5;
        let err = run_dagger(&opts, &|_| {}).unwrap_err();
        assert!(err.to_string().contains("--beta"), "{err}");
    }
}
