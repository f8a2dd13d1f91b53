//! Demonstration collection: the expert drives, every robot's view is recorded with the expert's command.
//!
//! [`collect`] runs a scenario's runs with the [`ExpertController`] and turns every recorded tick into one
//! [`Sample`] per robot: the occupancy image rendered from that robot's own scan (by
//! [`formation_perception::occupancy::render`], the function the agents run), `delta_phi = wrap(phi* - theta_i)`,
//! `d*`, and the wheel command the expert chose for that robot. Samples go to a [`DatasetWriter`].
//!
//! [`Labeller::label_observation`] labels any observation with the expert's commands whoever drives;
//! DAgger uses it with the learned policy driving, so the data set covers the states the policy visits.
//!
//! A sample may also carry what the robot makes of its own scan beside its image: the scan's
//! ranges ([`CollectOptions::ranges`], `formation_perception::ranges::pool`) and the neighbours
//! it detects in it ([`CollectOptions::neighbours`],
//! [`NeighbourInputBuilder::fill`], the computation the agent runs). With own-scan labels
//! ([`CollectOptions::own_scan_labels`], [`LabelLaw::own_scan`]) each robot's label is the
//! expert's law on the neighbours it detects in that same scan ([`OwnView`]) instead of the
//! expert's command from every pose; the expert still drives a collection's runs.
//!
//! Nothing here reads a clock except to report throughput, and nothing does I/O but the writer.

use std::time::{Duration, Instant};

use formation_perception::neighbour_input::NeighbourInputBuilder;
use formation_perception::neighbours::{
    DetectedNeighbour, DetectorSettings, NeighbourDetector, SettingsError,
};
use formation_perception::{occupancy, ranges};
use formation_proto::{
    AuxInput, Goal, LidarSpec, NeighbourInput, NeighbourRule, OccupancySpec, RangeInput, WheelCmd,
};
use formation_trainer_bridge::dataset::{DatasetError, DatasetWriter, Sample};
use formation_trainer_bridge::label_law::LabelLaw;
use formation_world::episode::{Observation, run_episode};
use formation_world::scenario::VStarPlan;
use formation_world::{RobotParams, RunSpec, Scenario};

use crate::controller::{ExpertController, ExpertGains, InvalidGains, check_inputs};
use crate::own_scan::OwnView;

/// Why a collection stopped.
#[derive(Debug, thiserror::Error)]
pub enum CollectError {
    /// `record_every` must be at least 1.
    #[error("record_every must be >= 1 (1 records every tick), got 0")]
    RecordEveryZero,
    /// The expert's gains are unusable.
    #[error(transparent)]
    Gains(#[from] InvalidGains),
    /// Sample fields are narrow (`robot: u8`, `run: u32`); the team or the run index does not fit.
    #[error("{what} = {value} does not fit the dataset's {field} field (at most {max})")]
    FieldOverflow {
        /// What overflowed, e.g. "robot index".
        what: &'static str,
        /// The value.
        value: usize,
        /// The sample field.
        field: &'static str,
        /// Its largest value.
        max: usize,
    },
    /// The d* at which a scaled window has its nominal cells is not a positive length.
    #[error(
        "occupancy d_star_ref_m (the d* at which cells are resolution_m wide) must be finite and > 0, got {d_star_ref_m} m"
    )]
    WindowScale {
        /// The d* given \[m\].
        d_star_ref_m: f64,
    },
    /// The occupancy settings cannot be rendered.
    #[error(
        "occupancy size_px must be >= 1 and resolution_m finite and > 0, got {size_px} px of {resolution_m} m"
    )]
    Occupancy {
        /// Cells on a side.
        size_px: usize,
        /// Cell size, in metres.
        resolution_m: f64,
    },
    /// A scan did not have the configured number of beams.
    #[error(
        "robot {robot}'s scan has {actual} ranges but the LIDAR is configured for {expected} beams"
    )]
    ScanLength {
        /// Robot index.
        robot: usize,
        /// Configured beams.
        expected: usize,
        /// Ranges received.
        actual: usize,
    },
    /// The expert refused an observation (bad goal or non-finite pose).
    #[error("run {run}: {message}")]
    Expert {
        /// Run index.
        run: usize,
        /// The expert's reason.
        message: String,
    },
    /// The dataset was created for other settings than this collection's.
    #[error(
        "the dataset's {what} is {dataset} but this collection produces {collection}; \
         write to a dataset created with the collection's settings"
    )]
    WriterMismatch {
        /// Which setting differs ("occupancy settings", "LIDAR", "v_train").
        what: &'static str,
        /// The dataset header's value.
        dataset: String,
        /// The collection's value.
        collection: String,
    },
    /// The scenario draws v* per run, but a dataset records one training speed (`v_train`).
    #[error(
        "the scenario draws v* per run (goal.v_star_range = [{min}, {max}]), but a dataset \
         records one training speed (v_train) for all its samples; collect at a fixed goal.v_star \
         (e.g. override goal.v_star and drop goal.v_star_range from a copy of the scenario)"
    )]
    VStarPerRun {
        /// Slowest v* of the range \[m/s\].
        min: f64,
        /// Fastest v* of the range \[m/s\].
        max: f64,
    },
    /// The range input cannot be computed from this LIDAR.
    #[error("cannot record the scan's ranges: {source}")]
    Ranges {
        /// Why.
        source: formation_proto::RangeInputError,
    },
    /// The robots' neighbours cannot be detected in their scans (the detector refuses settings
    /// made from the robot's body radius).
    #[error(
        "cannot detect neighbours in the robots' scans (for the neighbours input or own-scan \
         labels): {source}; give the scenario's robot a body_radius the detector takes"
    )]
    Detector {
        /// Why.
        source: SettingsError,
    },
    /// Writing the dataset failed.
    #[error("writing demonstrations of run {run}: {source}")]
    Dataset {
        /// Run index whose samples were being written.
        run: usize,
        /// The dataset error.
        source: DatasetError,
    },
}

/// What to collect.
#[derive(Debug, Clone, Copy)]
pub struct CollectOptions<'a> {
    /// The scenario whose runs are driven by the expert.
    pub scenario: &'a Scenario,
    /// Runs to collect: run indices `0..runs` of the scenario.
    pub runs: usize,
    /// Base seed of the runs (normally `scenario.seed()`); run `i` is `scenario.run_spec(base_seed, i)`.
    pub base_seed: u64,
    /// How each robot's scan is rendered; recorded in the dataset header by the caller.
    pub occupancy: OccupancySpec,
    /// Record every `record_every`-th tick (1 = every tick, the paper's 20 Hz).
    pub record_every: u32,
    /// The expert's gains.
    pub gains: ExpertGains,
    /// The scan's ranges recorded beside each image (a model that takes them is trained on
    /// them), or none; recorded in the dataset header by the caller.
    pub ranges: Option<RangeInput>,
    /// The neighbours each robot detects in its own scan, recorded beside each image (a model
    /// that takes them is trained on them), or none; recorded in the dataset header by the
    /// caller.
    pub neighbours: Option<NeighbourInput>,
    /// Label each robot with the expert's law on the neighbours it detects in its own scan
    /// instead of the expert's command from every pose ([`LabelLaw::own_scan`]); recorded in the
    /// dataset header by the caller ([`CollectOptions::label_law`]).
    pub own_scan_labels: bool,
}

impl<'a> CollectOptions<'a> {
    /// The scenario's own runs and seed, the paper's occupancy window, every tick, default gains.
    pub fn for_scenario(scenario: &'a Scenario) -> CollectOptions<'a> {
        CollectOptions {
            scenario,
            runs: scenario.runs(),
            base_seed: scenario.seed(),
            occupancy: OccupancySpec::PAPER,
            record_every: 1,
            gains: ExpertGains::default(),
            ranges: None,
            neighbours: None,
            own_scan_labels: false,
        }
    }

    /// The law the samples are labelled by: the gains' shaping and pair weights, from every pose
    /// or from each robot's own scan. The dataset's header must record it.
    pub fn label_law(&self) -> LabelLaw {
        LabelLaw {
            own_scan: self.own_scan_labels,
            ..self.gains.label_law()
        }
    }
}

/// What a collection produced.
#[derive(Debug, Clone, PartialEq)]
pub struct CollectReport {
    /// Samples written (one per robot per recorded tick).
    pub samples: usize,
    /// Runs completed.
    pub runs: usize,
    /// Wall-clock time spent.
    pub elapsed: Duration,
    /// Throughput, `samples / elapsed`.
    pub samples_per_sec: f64,
}

/// Runs `opts.runs` expert-driven runs and writes one [`Sample`] per robot per recorded tick to
/// `writer`, labelled with the writer's iteration (0 for a new dataset). `progress(runs_done,
/// samples_written)` is called after every run.
///
/// Each run's occupancy settings, LIDAR and speed v* must match the dataset header; a mismatch is
/// refused before anything is written for that run.
///
/// A run's samples are rendered while it runs and written when it ends, so a failure leaves the
/// dataset with whole runs only, as far as the writer's own shards allow.
pub fn collect(
    opts: &CollectOptions<'_>,
    writer: &mut DatasetWriter,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<CollectReport, CollectError> {
    if opts.record_every == 0 {
        return Err(CollectError::RecordEveryZero);
    }
    opts.gains.validate()?;
    check_occupancy(&opts.occupancy)?;
    check_one_v_star(opts.scenario)?;
    let started = Instant::now();
    let mut samples_written = 0;
    let mut run_samples = Vec::new();
    for run in 0..opts.runs {
        let spec = opts.scenario.run_spec(opts.base_seed, run);
        check_writer(writer, &spec, opts)?;
        run_samples.clear();
        collect_run(&spec, opts, writer.iteration(), &mut run_samples)?;
        for sample in run_samples.drain(..) {
            writer
                .push(sample)
                .map_err(|source| CollectError::Dataset { run, source })?;
            samples_written += 1;
        }
        progress(run + 1, samples_written);
    }
    let elapsed = started.elapsed();
    let seconds = elapsed.as_secs_f64();
    Ok(CollectReport {
        samples: samples_written,
        runs: opts.runs,
        elapsed,
        samples_per_sec: if seconds > 0.0 {
            samples_written as f64 / seconds
        } else {
            0.0
        },
    })
}

/// Refuses a scenario that draws v* per run (`goal.v_star_range`): a dataset records one
/// training speed (`v_train`) for all its samples. [`collect`] checks it first; a caller can
/// check it before it creates the dataset.
pub fn check_one_v_star(scenario: &Scenario) -> Result<(), CollectError> {
    match scenario.v_star() {
        VStarPlan::Range { min, max } if min < max => Err(CollectError::VStarPerRun { min, max }),
        _ => Ok(()),
    }
}

/// The dataset header must describe what this run records.
fn check_writer(
    writer: &DatasetWriter,
    spec: &RunSpec,
    opts: &CollectOptions<'_>,
) -> Result<(), CollectError> {
    let settings = &writer.header().settings;
    let (occupancy, ranges, neighbours) = (&opts.occupancy, opts.ranges, opts.neighbours);
    let labels = opts.label_law();
    let mismatch = |what, dataset: &dyn std::fmt::Debug, collection: &dyn std::fmt::Debug| {
        Err(CollectError::WriterMismatch {
            what,
            dataset: format!("{dataset:?}"),
            collection: format!("{collection:?}"),
        })
    };
    if settings.occupancy != *occupancy {
        return mismatch("occupancy settings", &settings.occupancy, occupancy);
    }
    if settings.lidar != spec.world.simulated_lidar() {
        return mismatch("LIDAR", &settings.lidar, &spec.world.simulated_lidar());
    }
    if settings.v_train != spec.v_star {
        return mismatch("v_train", &settings.v_train, &spec.v_star);
    }
    if settings.ranges != ranges {
        return mismatch("range input", &settings.ranges, &ranges);
    }
    if settings.neighbours != neighbours {
        return mismatch("neighbour input", &settings.neighbours, &neighbours);
    }
    if settings.labels != labels {
        return mismatch("label law", &settings.labels, &labels);
    }
    Ok(())
}

/// Drives one run with the expert and appends its samples, labelled `iteration`, to `samples`.
fn collect_run(
    spec: &RunSpec,
    opts: &CollectOptions<'_>,
    iteration: u32,
    samples: &mut Vec<Sample>,
) -> Result<(), CollectError> {
    // A lagging robot profile's world gets its team gain (the ideal world: the gains given).
    let gains = opts.gains.for_reality(&spec.world.reality);
    let mut labeller = Labeller::new(gains, spec.world.robot, spec.world.lidar, opts.occupancy)?
        .with_neighbours(spec.neighbours)
        .with_ranges(opts.ranges)?
        .with_neighbour_input(opts.neighbours)?
        .with_own_scan_labels(opts.own_scan_labels)?;
    let run = narrow_run(spec.index)?;
    narrow_robot(spec.n_robots.saturating_sub(1))?;
    let mut expert =
        ExpertController::new(gains, spec.world.robot).with_neighbours(spec.neighbours);
    let mut failure = None;
    let mut on_tick = |obs: &Observation<'_>, commands: &[WheelCmd]| {
        if failure.is_some() || !obs.tick.is_multiple_of(u64::from(opts.record_every)) {
            return;
        }
        if let Err(e) = labeller.emit(obs, commands, iteration, run, &mut |sample| {
            samples.push(sample)
        }) {
            failure = Some(e);
        }
    };
    run_episode(spec, &mut expert, &mut on_tick).map_err(|e| CollectError::Expert {
        run: spec.index,
        message: e.message,
    })?;
    failure.map_or(Ok(()), Err)
}

/// Labels observations with the expert's commands: everything needed to turn one robot's view into a
/// [`Sample`].
///
/// It holds an [`ExpertController`], so under a neighbour rule with hysteresis it must see a run's
/// observations in tick order (tick 0 starts afresh); give each concurrent run its own clone.
#[derive(Debug, Clone)]
pub struct Labeller {
    lidar: LidarSpec,
    occupancy: OccupancySpec,
    ranges: Option<RangeInput>,
    expert: ExpertController,
    own_scan: OwnScanReader,
}

/// What a labeller reads in one robot's own scan beyond its image: the neighbours input, and
/// under own-scan labels the expert's law on the same detections; its buffers are kept from one
/// scan to the next.
#[derive(Debug, Clone, Default)]
struct OwnScanReader {
    /// The neighbours input recorded, and the builder that fills it (with the robot's body).
    input: Option<(NeighbourInput, NeighbourInputBuilder)>,
    /// Whether labels come from the robot's own scan ([`LabelLaw::own_scan`]).
    labels: bool,
    /// The detector of own-scan labels when no neighbours input is recorded.
    detector: Option<NeighbourDetector>,
    detections: Vec<DetectedNeighbour>,
    centres: Vec<(f64, f64)>,
    view: OwnView,
}

impl OwnScanReader {
    /// Fills `out` with the neighbours input of `scan` (empty when none is recorded) and, under
    /// own-scan labels, returns the command of `expert`'s law (its gains, robot and neighbour
    /// rule) on the neighbours detected in that same scan, for a robot heading `heading`.
    fn read(
        &mut self,
        scan: &[f32],
        lidar: &LidarSpec,
        heading: f64,
        goal: &Goal,
        expert: &ExpertController,
        out: &mut [f32],
    ) -> Option<WheelCmd> {
        let detections: &[DetectedNeighbour] = match (&mut self.input, &mut self.detector) {
            (Some((spec, builder)), _) => {
                builder.fill(scan, lidar, spec, goal.d_star, out);
                builder.detections()
            }
            (None, Some(detector)) if self.labels => {
                detector.detect(scan, lidar, &mut self.detections);
                &self.detections
            }
            (None, _) => return None,
        };
        if !self.labels {
            return None;
        }
        self.centres.clear();
        self.centres.extend(detections.iter().map(|d| (d.x, d.y)));
        Some(self.view.command(
            &self.centres,
            heading,
            goal,
            expert.gains(),
            expert.robot(),
            expert.neighbours(),
        ))
    }
}

impl Labeller {
    /// A labeller for robots with these parameters and LIDAR, rendering with `occupancy`.
    pub fn new(
        gains: ExpertGains,
        robot: RobotParams,
        lidar: LidarSpec,
        occupancy: OccupancySpec,
    ) -> Result<Labeller, CollectError> {
        gains.validate()?;
        check_occupancy(&occupancy)?;
        Ok(Labeller {
            lidar,
            occupancy,
            ranges: None,
            expert: ExpertController::new(gains, robot),
            own_scan: OwnScanReader::default(),
        })
    }

    /// The same labeller, also recording each robot's scan ranges as `ranges` declares (none:
    /// the default). Refused when the LIDAR has fewer beams than sectors.
    pub fn with_ranges(mut self, ranges: Option<RangeInput>) -> Result<Labeller, CollectError> {
        if let Some(spec) = &ranges {
            spec.check_beams(self.lidar.beams)
                .map_err(|source| CollectError::Ranges { source })?;
        }
        self.ranges = ranges;
        Ok(self)
    }

    /// The same labeller, also recording the neighbours each robot detects in its own scan as
    /// `neighbours` declares (none: the default), filled by [`NeighbourInputBuilder`] with a
    /// detector for the robot's body radius. Refused when the detector refuses that radius.
    pub fn with_neighbour_input(
        mut self,
        neighbours: Option<NeighbourInput>,
    ) -> Result<Labeller, CollectError> {
        self.own_scan.input = match neighbours {
            Some(spec) => Some((
                spec,
                NeighbourInputBuilder::with_body_radius(self.expert.robot().body_radius)
                    .map_err(|source| CollectError::Detector { source })?,
            )),
            None => None,
        };
        Ok(self)
    }

    /// The same labeller, labelling each robot (when `own_scan`) with the expert's law on the
    /// neighbours it detects in its own scan ([`OwnView`], with the labeller's gains, robot and
    /// neighbour rule: [`with_neighbours`](Self::with_neighbours)) instead of the expert's command
    /// from every pose ([`LabelLaw::own_scan`]). The detections are the neighbours input's when
    /// one is recorded, else a [`NeighbourDetector`]'s for the robot's body radius, so they are
    /// those the model sees. Refused when the detector refuses that radius.
    pub fn with_own_scan_labels(mut self, own_scan: bool) -> Result<Labeller, CollectError> {
        self.own_scan.labels = own_scan;
        self.own_scan.detector = if own_scan {
            let settings = DetectorSettings::with_body_radius(self.expert.robot().body_radius);
            Some(
                NeighbourDetector::new(settings)
                    .map_err(|source| CollectError::Detector { source })?,
            )
        } else {
            None
        };
        Ok(self)
    }

    /// The same labeller, labelling with the expert that holds each robot's own neighbours under
    /// `rule`.
    pub fn with_neighbours(mut self, rule: NeighbourRule) -> Labeller {
        self.expert = self.expert.with_neighbours(rule);
        self
    }

    /// A labeller for the robots and LIDAR of `spec`.
    pub fn for_run(
        spec: &RunSpec,
        gains: ExpertGains,
        occupancy: OccupancySpec,
    ) -> Result<Labeller, CollectError> {
        Ok(
            Labeller::new(gains, spec.world.robot, spec.world.lidar, occupancy)?
                .with_neighbours(spec.neighbours),
        )
    }

    /// Sends `sink` one sample per robot of `obs`, labelled with the EXPERT's command for that robot,
    /// whatever controller is driving (DAgger: the policy drives, the expert labels): from every
    /// pose, or under own-scan labels ([`with_own_scan_labels`](Self::with_own_scan_labels)) from
    /// the robot's own scan.
    pub fn label_observation(
        &mut self,
        obs: &Observation<'_>,
        iteration: u32,
        run: u32,
        sink: &mut dyn FnMut(Sample),
    ) -> Result<(), CollectError> {
        let mut commands = vec![WheelCmd::BRAKE; obs.poses.len()];
        check_inputs(obs.poses, &obs.goal, commands.len()).map_err(|e| CollectError::Expert {
            run: run as usize,
            message: e.message,
        })?;
        if !self.own_scan.labels {
            self.expert
                .compute(obs.tick, obs.poses, &obs.goal, &mut commands);
        }
        self.emit(obs, &commands, iteration, run, sink)
    }

    /// One sample per robot with the given labels `commands[i]`, or under own-scan labels the
    /// expert's law on the robot's own scan.
    fn emit(
        &mut self,
        obs: &Observation<'_>,
        commands: &[WheelCmd],
        iteration: u32,
        run: u32,
        sink: &mut dyn FnMut(Sample),
    ) -> Result<(), CollectError> {
        let cells = self.occupancy.size_px * self.occupancy.size_px;
        for (robot, ((pose, scan), command)) in
            obs.poses.iter().zip(obs.scans).zip(commands).enumerate()
        {
            if scan.len() != self.lidar.beams {
                return Err(CollectError::ScanLength {
                    robot,
                    expected: self.lidar.beams,
                    actual: scan.len(),
                });
            }
            let mut image = vec![0; cells];
            occupancy::render_at(
                scan,
                &self.lidar,
                &self.occupancy,
                obs.goal.d_star,
                &mut image,
            );
            let mut pooled = vec![0.0; self.ranges.map_or(0, |r| r.sectors)];
            if let Some(spec) = &self.ranges {
                ranges::pool(scan, &self.lidar, spec, obs.goal.d_star, &mut pooled);
            }
            let mut neighbours =
                vec![0.0; self.own_scan.input.as_ref().map_or(0, |(n, _)| n.len())];
            let command = self
                .own_scan
                .read(
                    scan,
                    &self.lidar,
                    pose.theta,
                    &obs.goal,
                    &self.expert,
                    &mut neighbours,
                )
                .unwrap_or(*command);
            sink(Sample {
                occupancy: image,
                ranges: pooled,
                neighbours,
                delta_phi: AuxInput::HeadingError.value(pose.theta, &obs.goal) as f32,
                d_star: AuxInput::DStar.value(pose.theta, &obs.goal) as f32,
                wheels: [command.left as f32, command.right as f32],
                iteration,
                run,
                robot: narrow_robot(robot)?,
            });
        }
        Ok(())
    }
}

fn check_occupancy(spec: &OccupancySpec) -> Result<(), CollectError> {
    if spec.size_px == 0 || !(spec.resolution_m.is_finite() && spec.resolution_m > 0.0) {
        return Err(CollectError::Occupancy {
            size_px: spec.size_px,
            resolution_m: spec.resolution_m,
        });
    }
    if let Some(d_star_ref_m) = spec.d_star_ref_m
        && !(d_star_ref_m.is_finite() && d_star_ref_m > 0.0)
    {
        return Err(CollectError::WindowScale { d_star_ref_m });
    }
    Ok(())
}

fn narrow_robot(robot: usize) -> Result<u8, CollectError> {
    u8::try_from(robot).map_err(|_| CollectError::FieldOverflow {
        what: "robot index",
        value: robot,
        field: "robot (u8)",
        max: usize::from(u8::MAX),
    })
}

fn narrow_run(run: usize) -> Result<u32, CollectError> {
    u32::try_from(run).map_err(|_| CollectError::FieldOverflow {
        what: "run index",
        value: run,
        field: "run (u32)",
        max: u32::MAX as usize,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{first_tick, goal};
    use formation_proto::{Pose, wrap_angle};
    use formation_world::lidar::cast_scan;

    const TINY: &str = r#"
        name = "tiny"
        robots = 3
        duration_s = 1.0
        seed = 5
        runs = 2
        [goal]
        v_star = 0.7
        d_star = 1.5
        [heading]
        schedule = "constant"
        phi = 2.0
    "#;

    fn tiny() -> Scenario {
        Scenario::from_toml_str(TINY, "tiny.toml").expect("valid test scenario")
    }

    /// A scan whose only hit is beam `beam` at `range`.
    fn scan_with_hit(lidar: &LidarSpec, beam: usize, range: f32) -> Vec<f32> {
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[beam] = range;
        scan
    }

    #[test]
    fn label_observation_uses_the_experts_commands_and_each_robots_own_view() {
        let lidar = LidarSpec::default();
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let mut labeller = Labeller::new(gains, robot, lidar, OccupancySpec::PAPER).expect("valid");
        let poses = [
            Pose::new(0.0, 0.0, 3.0),
            Pose::new(2.0, 0.5, -3.0),
            Pose::new(0.5, 3.0, 0.2),
        ];
        let scans = vec![
            scan_with_hit(&lidar, 0, 1.0),
            scan_with_hit(&lidar, 225, 1.0),
            scan_with_hit(&lidar, 450, 4.0),
        ];
        let goal = goal(-3.0, 1.5);
        let obs = Observation {
            tick: 4,
            time: 0.2,
            goal,
            poses: &poses,
            wheel_speeds: &[],
            scans: &scans,
        };

        let mut samples = Vec::new();
        labeller
            .label_observation(&obs, 3, 17, &mut |s| samples.push(s))
            .expect("labels");

        let mut expected = [WheelCmd::BRAKE; 3];
        crate::expert_commands(&poses, &goal, &gains, &robot, &mut expected);
        assert_eq!(samples.len(), 3);
        for (i, sample) in samples.iter().enumerate() {
            assert_eq!(usize::from(sample.robot), i);
            assert_eq!((sample.iteration, sample.run), (3, 17));
            assert_eq!(
                sample.wheels,
                [expected[i].left as f32, expected[i].right as f32]
            );
            assert_eq!(sample.d_star, 1.5);
            let delta = f64::from(sample.delta_phi);
            assert!(delta > -std::f64::consts::PI && delta <= std::f64::consts::PI);
            assert!((delta - wrap_angle(-3.0 - poses[i].theta)).abs() < 1e-6);
            let mut image = vec![0; 2500];
            occupancy::render(&scans[i], &lidar, &OccupancySpec::PAPER, &mut image);
            assert_eq!(sample.occupancy, image, "robot {i} sees its own scan");
        }
        // Robot 0's phi* - theta = -6 rad wraps to 0.28 rad.
        assert!((f64::from(samples[0].delta_phi) - (-6.0 + std::f64::consts::TAU)).abs() < 1e-6);
        assert_eq!(
            samples[0].occupancy[25 * 50 + 35],
            1,
            "robot 0's hit 1 m ahead"
        );
        assert_eq!(
            samples[1].occupancy[15 * 50 + 25],
            1,
            "robot 1's hit 1 m to the left"
        );
        assert!(
            samples[2].occupancy.iter().all(|&c| c == 0),
            "robot 2's only hit is beyond the window"
        );

        // A window scaled with d* (0.1 m cells at d* = 1 m) is rendered for the goal's d*:
        // at d* = 1.5 m its cells are 0.15 m, so the hit 1 m ahead lies 6.67 cells ahead.
        let scaled = OccupancySpec {
            d_star_ref_m: Some(1.0),
            ..OccupancySpec::PAPER
        };
        let mut labeller = Labeller::new(gains, robot, lidar, scaled).expect("valid");
        let mut samples = Vec::new();
        labeller
            .label_observation(&obs, 3, 17, &mut |s| samples.push(s))
            .expect("labels");
        let lit: Vec<usize> = (0..2500)
            .filter(|&c| samples[0].occupancy[c] != 0)
            .collect();
        assert_eq!(lit, [25 * 50 + 31], "robot 0's hit 1 m ahead at d* = 1.5 m");
    }

    #[test]
    fn label_observation_refuses_bad_observations() {
        let lidar = LidarSpec::default();
        let mut labeller = Labeller::new(
            ExpertGains::default(),
            RobotParams::default(),
            lidar,
            OccupancySpec::PAPER,
        )
        .expect("valid");
        let poses = [Pose::new(0.0, 0.0, 0.0), Pose::new(1.0, 0.0, 0.0)];
        let short = vec![vec![10.0_f32; 900], vec![10.0_f32; 10]];
        let goal = goal(0.0, 1.0);
        let obs = first_tick(goal, &poses, &short);
        let mut sink = |_| {};
        assert!(matches!(
            labeller.label_observation(&obs, 0, 0, &mut sink),
            Err(CollectError::ScanLength {
                robot: 1,
                expected: 900,
                actual: 10
            })
        ));
        let bad_goal = Observation {
            goal: Goal {
                d_star: -1.0,
                ..goal
            },
            ..obs
        };
        assert!(matches!(
            labeller.label_observation(&bad_goal, 0, 4, &mut sink),
            Err(CollectError::Expert { run: 4, .. })
        ));
        let bad_occupancy = OccupancySpec {
            resolution_m: 0.0,
            ..OccupancySpec::PAPER
        };
        assert!(matches!(
            Labeller::new(
                ExpertGains::default(),
                RobotParams::default(),
                lidar,
                bad_occupancy
            ),
            Err(CollectError::Occupancy { .. })
        ));
    }

    /// Three robots in a line along +y, 2 m apart, headings apart: robot 0 sees robot 1 and
    /// not robot 2, which robot 1 hides. The world's own exact scans.
    fn a_line_of_three() -> (Vec<Pose>, Vec<Vec<f32>>, LidarSpec, Goal) {
        let lidar = LidarSpec::default();
        let poses = vec![
            Pose::new(0.0, 0.0, 0.4),
            Pose::new(0.0, 2.0, -1.0),
            Pose::new(0.0, 4.0, 2.5),
        ];
        let scans = (0..poses.len())
            .map(|i| {
                let mut scan = vec![0.0; lidar.beams];
                cast_scan(&poses, i, &RobotParams::default(), &lidar, &mut scan);
                scan
            })
            .collect();
        let goal = goal(1.0, 1.5);
        (poses, scans, lidar, goal)
    }

    fn label(labeller: &mut Labeller, obs: &Observation<'_>) -> Vec<Sample> {
        let mut samples = Vec::new();
        labeller
            .label_observation(obs, 1, 2, &mut |s| samples.push(s))
            .expect("labels");
        samples
    }

    #[test]
    fn samples_carry_the_builders_neighbours_and_own_scan_labels_are_own_views_command() {
        let (poses, scans, lidar, goal) = a_line_of_three();
        let obs = first_tick(goal, &poses, &scans);
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        let spec = NeighbourInput::with_default_rule(4).expect("input");
        let labeller = || Labeller::new(gains, robot, lidar, OccupancySpec::PAPER).expect("valid");
        let mut expert_labelled = labeller().with_neighbour_input(Some(spec)).expect("input");
        let mut own_labelled = labeller()
            .with_neighbour_input(Some(spec))
            .and_then(|l| l.with_own_scan_labels(true))
            .expect("own scan");
        let mut own_without_input = labeller().with_own_scan_labels(true).expect("own scan");
        let by_expert = label(&mut expert_labelled, &obs);
        let by_own_scan = label(&mut own_labelled, &obs);
        let without_input = label(&mut own_without_input, &obs);

        let mut all_poses = [WheelCmd::BRAKE; 3];
        crate::expert_commands(&poses, &goal, &gains, &robot, &mut all_poses);
        let mut builder = NeighbourInputBuilder::default();
        let mut view = OwnView::new();
        for i in 0..3 {
            // The neighbours input is the builder's for the robot's own scan, whoever labels.
            let mut expected = vec![f32::NAN; spec.len()];
            builder.fill(&scans[i], &lidar, &spec, goal.d_star, &mut expected);
            assert_eq!(by_expert[i].neighbours, expected, "robot {i}");
            assert_eq!(by_own_scan[i].neighbours, expected, "robot {i}");
            assert!(without_input[i].neighbours.is_empty());
            // The expert's labels read every pose; own-scan labels are OwnView's command on
            // the detections of that same scan, with or without the input recorded.
            let wheels = |c: WheelCmd| [c.left as f32, c.right as f32];
            assert_eq!(by_expert[i].wheels, wheels(all_poses[i]), "robot {i}");
            let centres: Vec<(f64, f64)> =
                builder.detections().iter().map(|d| (d.x, d.y)).collect();
            let own = view.command(
                &centres,
                poses[i].theta,
                &goal,
                &gains,
                &robot,
                &NeighbourRule::AllPairs,
            );
            assert_eq!(by_own_scan[i].wheels, wheels(own), "robot {i}");
            assert_eq!(without_input[i].wheels, wheels(own), "robot {i}");
        }
        // Robot 0 detects robot 1 alone (robot 2 is hidden): two slots, held first.
        assert_eq!(
            by_own_scan[0]
                .neighbours
                .chunks(4)
                .map(|s| s[3])
                .collect::<Vec<_>>(),
            [1.0, 0.0, 0.0, 0.0]
        );
        // ... so its own-scan label leaves out the pair the expert holds with robot 2.
        let gap = (by_own_scan[0].wheels[0] - by_expert[0].wheels[0]).abs()
            + (by_own_scan[0].wheels[1] - by_expert[0].wheels[1]).abs();
        assert!(
            gap > 0.01,
            "{:?} {:?}",
            by_own_scan[0].wheels,
            by_expert[0].wheels
        );
    }

    #[test]
    fn a_collected_run_with_neighbours_and_own_scan_labels_reads_back() {
        use formation_trainer_bridge::dataset::{DatasetHeader, DatasetReader};
        let scenario = tiny();
        let opts = CollectOptions {
            record_every: 5,
            runs: 1,
            neighbours: Some(NeighbourInput::with_default_rule(4).expect("input")),
            own_scan_labels: true,
            ..CollectOptions::for_scenario(&scenario)
        };
        let spec = scenario.run_spec(opts.base_seed, 0);
        let plain = DatasetHeader::new(
            opts.occupancy,
            spec.world.simulated_lidar(),
            spec.v_star,
            opts.base_seed,
            scenario.name(),
        );
        let header = plain
            .clone()
            .with_neighbours(opts.neighbours)
            .with_labels(opts.label_law());
        assert!(header.settings.labels.own_scan);
        let dir = tempfile::tempdir().expect("tempdir");
        let mut writer = DatasetWriter::create(dir.path(), header.clone()).expect("create");
        collect(&opts, &mut writer, &mut |_, _| {}).expect("collects");
        writer.finish().expect("finish");

        let reader = DatasetReader::open(dir.path()).expect("open");
        assert_eq!(reader.header(), &header);
        let read = reader.load_all().expect("load");
        let mut direct = Vec::new();
        collect_run(&spec, &opts, 0, &mut direct).expect("collects");
        assert_eq!(read, direct);
        // 20 ticks recorded at 0, 5, 10, 15 for 3 robots, each seeing someone.
        assert_eq!(read.len(), 4 * 3);
        for sample in &read {
            assert_eq!(sample.neighbours.len(), 16);
            assert!(sample.neighbours[3] == 1.0, "{:?}", sample.neighbours);
        }

        // A dataset declared without them is refused before anything is written.
        let other = tempfile::tempdir().expect("tempdir");
        let mut writer = DatasetWriter::create(other.path(), plain).expect("create");
        let err = collect(&opts, &mut writer, &mut |_, _| {}).expect_err("mismatch");
        assert!(
            matches!(
                err,
                CollectError::WriterMismatch {
                    what: "neighbour input",
                    ..
                }
            ),
            "{err:?}"
        );
        assert_eq!(writer.samples(), 0);
    }

    #[test]
    fn a_collected_run_records_every_nth_tick_for_every_robot_with_the_driving_commands() {
        let scenario = tiny();
        let opts = CollectOptions {
            record_every: 3,
            ..CollectOptions::for_scenario(&scenario)
        };
        let spec = scenario.run_spec(opts.base_seed, 1);
        let mut samples = Vec::new();
        collect_run(&spec, &opts, 0, &mut samples).expect("collects");

        // 20 ticks, recorded at 0, 3, ..., 18: 7 ticks x 3 robots.
        assert_eq!(samples.len(), 7 * 3);
        assert!(
            samples
                .iter()
                .all(|s| s.run == 1 && s.iteration == 0 && s.d_star == 1.5)
        );
        assert_eq!(
            samples
                .iter()
                .map(|s| usize::from(s.robot))
                .collect::<Vec<_>>()[..3],
            [0, 1, 2]
        );

        // The labels are the commands the expert drove with: replay the run and compare tick 3.
        let mut expert = ExpertController::new(opts.gains, spec.world.robot);
        let trajectory = run_episode(&spec, &mut expert, &mut |_, _| {}).expect("runs");
        for robot in 0..3 {
            let applied = trajectory.commands[3][robot];
            assert_eq!(
                samples[3 + robot].wheels,
                [applied.left as f32, applied.right as f32]
            );
        }
    }
}
