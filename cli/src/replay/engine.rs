//! The replay itself: each robot's recorded inputs fed through the agent's decision, the result
//! compared with the recorded command.
//!
//! The decision runs exactly as in an agent: the runtime's [`PilotMaker`] loads the model and
//! makes a [`Pilot`] for the robot's LIDAR, and each step is `perceive(ranges, goal)` then
//! `decide(heading, goal)`, as `formation_runtime::agent::AgentLoop` does on a scan
//! ([`formation_robot_agent::pilot::OnnxPilots`] for the `formation` command: the same ONNX session options, the
//! same renderer). A test may hand in another maker (one whose renderer is changed, say) to see
//! the replay catch it.
//!
//! Which model decides a step: with `--model`, that one; otherwise the recording's model whose
//! id the step names (a swap within the recording changes it; a model swapped in with
//! `formation swap` is stored in the recording by the world that recorded it, found by its
//! `formation.swapped_model` record, and is given with `--swap-model` when the recording lacks
//! it, as one made from outside does), or the robot's model in the metadata for a step without
//! one. A realtime step answers the scan of `tick - lag_ticks`,
//! which is fed instead of its own. Steps the world did not take a fresh answer for are counted,
//! not compared. A step naming a model whose swap record comes later in the file (a command that
//! overtook the agent's report of the swap) is held back until the record comes
//! (`HELD_STEPS` at most).

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::{Path, PathBuf};

use formation_proto::wire::TickOutcome;
use formation_proto::{Goal, LidarSpec};
use formation_record::models::{self, ModelFileError};
use formation_record::{
    ReadError, RecordingItem, RecordingReader, ReplayStep, RunEnd, RunInfo, SwapStorage,
    SwappedModel,
};
use formation_runtime::agent::{BoxError, Pilot, PilotMaker};
use formation_schema::ReplayReport;

use super::divergence::{RobotTally, Unreplayable};

/// How many of a robot's recent scans are kept for realtime steps that answer an older one.
const SCAN_HISTORY: usize = 256;

/// How many steps (all robots together) are held back waiting for the record of the model they
/// name (see `Replay::offer`) before the oldest is replayed as it stands.
const HELD_STEPS: usize = 256;

/// What to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// Replay every step with this model instead of the recording's own.
    pub model: Option<PathBuf>,
    /// Replay only this robot.
    pub robot: Option<u32>,
    /// Models swapped in during the run (`formation swap`), which the recording names only by
    /// id: each decides the steps whose model id is its own (ignored with `model`).
    pub swapped: Vec<PathBuf>,
}

/// A finished replay: the report, and why the file stopped early when it was cut short.
#[derive(Debug)]
pub struct Replayed {
    /// The report.
    pub report: ReplayReport,
    /// The truncation the replay stopped at (the report covers the steps before it).
    pub truncated: Option<ReadError>,
    /// Models swapped in during the run that the recording does not hold, each with why.
    pub notes: Vec<String>,
}

/// Why a replay could not be done.
#[derive(Debug, thiserror::Error)]
pub enum ReplayFailure {
    /// The recording could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// A recorded model could not be found or does not match its hash.
    #[error(transparent)]
    Model(#[from] ModelFileError),
    /// The recording names no models (an expert's run), and no `--model` was given.
    #[error(
        "{}: the recording names no model (its run was driven by the expert, or it has no \
         formation.run metadata): give one with --model",
        recording.display()
    )]
    NoModel {
        /// The recording.
        recording: PathBuf,
    },
    /// A model could not be loaded, or cannot drive the recorded robot's sensor.
    #[error("{}: model {} cannot replay robot {robot}", recording.display(), model.display())]
    Pilot {
        /// The recording.
        recording: PathBuf,
        /// The model file.
        model: PathBuf,
        /// The robot.
        robot: u32,
        /// Why.
        #[source]
        source: BoxError,
    },
    /// `--robot` names a robot the recording does not hold.
    #[error(
        "{}: --robot {robot}: the recording holds robots {}: choose one of them",
        recording.display(), list(held)
    )]
    NoSuchRobot {
        /// The recording.
        recording: PathBuf,
        /// The robot asked for.
        robot: u32,
        /// The robots it holds.
        held: Vec<u32>,
    },
}

fn list(robots: &[u32]) -> String {
    match robots {
        [] => "none".into(),
        [only] => only.to_string(),
        [first, .., last] => format!("{first} to {last}"),
    }
}

/// One scan as its agent received it.
#[derive(Debug, Clone)]
struct SentScan {
    tick: u64,
    ranges: Vec<f32>,
    heading: f64,
    goal: Goal,
}

/// The replay under way.
struct Replay<'m, M: PilotMaker> {
    recording: PathBuf,
    maker: &'m M,
    options: ReplayOptions,
    /// The model files, by index; with `--model`, that one alone.
    files: Vec<PathBuf>,
    /// What the report calls each model: its recorded path (or `--model`'s).
    labels: Vec<String>,
    /// Model id → index in `files`.
    ids: HashMap<String, usize>,
    info: Option<RunInfo>,
    pilots: HashMap<(u32, usize), M::Pilot>,
    /// What the replay has to say about models swapped in during the run that it lacks.
    notes: Vec<String>,
    /// Per robot, its steps held back, oldest first: the first names a model not known yet.
    held: BTreeMap<u32, VecDeque<ReplayStep>>,
    scans: HashMap<u32, VecDeque<SentScan>>,
    tallies: BTreeMap<u32, RobotTally>,
    /// How the run ended, as the recording says (none in recordings made before it was written).
    end: Option<RunEnd>,
}

/// Replays the recording at `recording` through `maker`'s pilots; attached models are written
/// into `scratch` (a folder of the caller's, removed by it).
pub fn replay_recording<M: PilotMaker>(
    recording: &Path,
    options: &ReplayOptions,
    maker: &M,
    scratch: &Path,
) -> Result<Replayed, ReplayFailure> {
    let mut reader = RecordingReader::open(recording)?;
    let mut replay = Replay {
        recording: recording.to_path_buf(),
        maker,
        options: options.clone(),
        files: Vec::new(),
        labels: Vec::new(),
        ids: HashMap::new(),
        info: None,
        pilots: HashMap::new(),
        notes: Vec::new(),
        held: BTreeMap::new(),
        scans: HashMap::new(),
        tallies: BTreeMap::new(),
        end: None,
    };
    if let Some(model) = &options.model {
        replay.add_model(model.clone(), model.display().to_string())?;
    }
    let truncated = loop {
        match reader.next_item() {
            Ok(Some(RecordingItem::Model { name, bytes })) => {
                if options.model.is_none() {
                    models::save_attachment(recording, scratch, &name, &bytes)?;
                }
            }
            Ok(Some(RecordingItem::Run(info))) => replay.take_run(info, scratch)?,
            Ok(Some(RecordingItem::Swap(swapped))) => {
                replay.take_swap(&swapped, scratch)?;
                replay.release_held(false)?;
            }
            Ok(Some(RecordingItem::Step(step))) => replay.offer(step)?,
            Ok(Some(RecordingItem::End(end))) => replay.end = Some(end),
            Ok(None) => break None,
            Err(e @ ReadError::Truncated { .. }) => break Some(e),
            Err(e) => return Err(e.into()),
        }
    };
    replay.release_held(true)?;
    let bytes_read = reader.bytes_read();
    replay.finish(truncated, bytes_read)
}

impl<M: PilotMaker> Replay<'_, M> {
    /// Loads `file` once for its id and adds it to the models.
    fn add_model(&mut self, file: PathBuf, label: String) -> Result<(), ReplayFailure> {
        let model = self
            .maker
            .load(&file)
            .map_err(|source| self.pilot_error(&file, 0, source))?;
        let id = self.maker.model_id(&model).to_owned();
        self.ids.entry(id).or_insert(self.files.len());
        self.files.push(file);
        self.labels.push(label);
        Ok(())
    }

    fn pilot_error(&self, model: &Path, robot: u32, source: BoxError) -> ReplayFailure {
        ReplayFailure::Pilot {
            recording: self.recording.clone(),
            model: model.to_path_buf(),
            robot,
            source,
        }
    }

    /// The run's metadata: its models, unless `--model` replaces them.
    fn take_run(&mut self, info: RunInfo, scratch: &Path) -> Result<(), ReplayFailure> {
        if self.options.model.is_none() {
            let files = models::recorded_model_files(&self.recording, &info, scratch)?;
            for (file, model) in files.into_iter().zip(&info.models) {
                self.add_model(file, model.path.display().to_string())?;
            }
            // After the recorded ones, whose indices the metadata's robot_models name.
            for file in self.options.swapped.clone() {
                let label = format!("{} (swapped in)", file.display());
                self.add_model(file, label)?;
            }
        }
        self.info = Some(info);
        Ok(())
    }

    /// A model swapped in during the run: from the recording when it holds it (unless
    /// `--model` replaces every model, or `--swap-model` gave it), else a note saying why not.
    fn take_swap(&mut self, swapped: &SwappedModel, scratch: &Path) -> Result<(), ReplayFailure> {
        if self.options.model.is_some() || self.ids.contains_key(&swapped.model_id) {
            return Ok(());
        }
        match models::swapped_model_file(&self.recording, swapped, scratch, &self.files)? {
            Some(file) => {
                let label = format!(
                    "{} (swapped in for robot {} at tick {}, stored in the recording)",
                    swapped.path.display(),
                    swapped.robot,
                    swapped.tick
                );
                self.add_model(file, label)
            }
            None => {
                if let SwapStorage::NotStored(why) = &swapped.storage {
                    self.notes.push(format!(
                        "the model {} swapped in for robot {} at tick {} is not stored in the \
                         recording ({why}): give it with --swap-model FILE.onnx",
                        swapped.model_id, swapped.robot, swapped.tick
                    ));
                }
                Ok(())
            }
        }
    }

    /// Which model decides `step`, or why none can.
    fn model_for(&self, step: &ReplayStep) -> Result<usize, Unreplayable> {
        if self.options.model.is_some() {
            return Ok(0);
        }
        if step.model_id.is_empty() {
            let by_robot = self
                .info
                .as_ref()
                .and_then(|info| info.robot_models.get(step.robot as usize).copied());
            return by_robot.ok_or(Unreplayable::UnknownModel);
        }
        self.ids
            .get(&step.model_id)
            .copied()
            .ok_or(Unreplayable::UnknownModel)
    }

    /// Whether `step` names a model this replay does not know (yet).
    fn names_unknown_model(&self, step: &ReplayStep) -> bool {
        self.options.model.is_none()
            && !step.model_id.is_empty()
            && !self.ids.contains_key(&step.model_id)
    }

    /// Takes `step` in file order. The world records a swap when its agent reports it done, and
    /// over Zenoh the first command of the new model can overtake that report, so the record of
    /// a swapped-in model can follow the first steps it decided: a step that names a model not
    /// known yet is held back (with its robot's later steps, to keep their order) until the
    /// model's record comes, up to [`HELD_STEPS`] in all.
    fn offer(&mut self, step: ReplayStep) -> Result<(), ReplayFailure> {
        if self.options.robot.is_some_and(|r| r != step.robot) {
            return Ok(());
        }
        let waiting = self.held.get(&step.robot).is_some_and(|q| !q.is_empty());
        if !waiting && !self.names_unknown_model(&step) {
            return self.step(&step);
        }
        self.held.entry(step.robot).or_default().push_back(step);
        if self.held.values().map(VecDeque::len).sum::<usize>() > HELD_STEPS {
            let longest = self
                .held
                .iter()
                .max_by_key(|(_, q)| q.len())
                .map(|(&robot, _)| robot);
            if let Some(oldest) = longest.and_then(|r| self.held.get_mut(&r)?.pop_front()) {
                self.step(&oldest)?;
            }
            self.release_held(false)?;
        }
        Ok(())
    }

    /// Replays the held steps whose models are known now, each robot's in order up to one that
    /// still names an unknown model; `all`: every held step (the file ended).
    fn release_held(&mut self, all: bool) -> Result<(), ReplayFailure> {
        let robots: Vec<u32> = self.held.keys().copied().collect();
        for robot in robots {
            loop {
                let front_unknown = match self.held.get(&robot).and_then(VecDeque::front) {
                    None => break,
                    Some(front) => self.names_unknown_model(front),
                };
                if front_unknown && !all {
                    break;
                }
                let Some(step) = self.held.get_mut(&robot).and_then(VecDeque::pop_front) else {
                    break;
                };
                self.step(&step)?;
            }
        }
        Ok(())
    }

    /// One step: kept as the scan its agent received, and compared when it was used fresh.
    fn step(&mut self, step: &ReplayStep) -> Result<(), ReplayFailure> {
        if self.options.robot.is_some_and(|r| r != step.robot) {
            return Ok(());
        }
        if self.files.is_empty() {
            return Err(ReplayFailure::NoModel {
                recording: self.recording.clone(),
            });
        }
        let model = self.model_for(step);
        let history = self.scans.entry(step.robot).or_default();
        if history.len() == SCAN_HISTORY {
            history.pop_front();
        }
        history.push_back(SentScan {
            tick: step.tick,
            ranges: step.ranges.clone(),
            heading: step.heading,
            goal: step.goal,
        });
        let tally = self.tallies.entry(step.robot).or_default();
        tally.read_step();
        if step.outcome != TickOutcome::Fresh {
            tally.skip(step.outcome);
            return Ok(());
        }
        let answered = step.tick.checked_sub(u64::from(step.lag_ticks));
        let scan = answered.and_then(|t| history.iter().rev().find(|s| s.tick == t).cloned());
        let (model, scan) = match (model, scan) {
            (Ok(model), Some(scan)) => (model, scan),
            (Err(why), _) => {
                tally.unreplayable(why);
                return Ok(());
            }
            (Ok(_), None) => {
                tally.unreplayable(Unreplayable::ScanNotRecorded);
                return Ok(());
            }
        };
        let lidar = self.lidar_of(step);
        let pilot = self.pilot(step.robot, model, lidar)?;
        let decided = pilot
            .perceive(&scan.ranges, &scan.goal)
            .and_then(|()| pilot.decide(scan.heading, &scan.goal));
        if let Err(e) = &decided {
            tracing::debug!(
                "robot {} tick {}: the replayed decision failed: {e}",
                step.robot,
                step.tick
            );
        }
        if let Some(tally) = self.tallies.get_mut(&step.robot) {
            tally.compare(step.tick, step.command, decided.ok());
        }
        Ok(())
    }

    /// The robot's LIDAR as its agent was told it: the step's beams, and the world's `f64`
    /// range from the metadata (the step's `f32` for a recording made before it was written).
    fn lidar_of(&self, step: &ReplayStep) -> LidarSpec {
        let max_range = self
            .info
            .as_ref()
            .and_then(|info| info.lidar_max_range_m)
            .unwrap_or_else(|| f64::from(step.max_range));
        LidarSpec {
            beams: step.ranges.len(),
            max_range,
        }
    }

    /// The robot's pilot for model `model`, made on first use as an agent makes it.
    fn pilot(
        &mut self,
        robot: u32,
        model: usize,
        lidar: LidarSpec,
    ) -> Result<&mut M::Pilot, ReplayFailure> {
        if !self.pilots.contains_key(&(robot, model)) {
            let file = &self.files[model];
            let mut made = self
                .maker
                .load(file)
                .and_then(|loaded| self.maker.pilot(loaded, lidar))
                .map_err(|source| self.pilot_error(file, robot, source))?;
            // The wheels the agent was told, as its episode began.
            made.set_wheel_limits(self.info.as_ref().map(|i| i.wheels).unwrap_or_default());
            self.pilots.insert((robot, model), made);
        }
        self.pilots
            .get_mut(&(robot, model))
            .ok_or_else(|| ReplayFailure::NoModel {
                recording: self.recording.clone(),
            })
    }

    /// The report, once the file is read (to its end, or to a cut).
    fn finish(
        self,
        truncated: Option<ReadError>,
        bytes_read: u64,
    ) -> Result<Replayed, ReplayFailure> {
        if let Some(robot) = self.options.robot
            && !self.tallies.contains_key(&robot)
            && truncated.is_none()
        {
            let held = match &self.info {
                Some(info) => info.raw.get("robots").and_then(|n| n.parse::<u32>().ok()),
                None => None,
            };
            return Err(ReplayFailure::NoSuchRobot {
                recording: self.recording,
                robot,
                held: (0..held.unwrap_or(0)).collect(),
            });
        }
        let diverged = self.tallies.values().any(RobotTally::diverged);
        let robots = self
            .tallies
            .into_iter()
            .map(|(robot, tally)| tally.finish(robot))
            .collect();
        let report = ReplayReport {
            recording: self.recording.display().to_string(),
            clock: self.info.map(|i| i.clock).unwrap_or_default(),
            models: self.labels,
            model_override: self.options.model.is_some(),
            complete: truncated.is_none() && self.end.as_ref().is_none_or(|end| end.complete),
            stop_reason: self.end.and_then(|end| end.stop_reason),
            bytes_read,
            robots,
            diverged,
        };
        Ok(Replayed {
            report,
            truncated,
            notes: self.notes,
        })
    }
}
