//! The agent's decision: `act(own scan, own heading, goal) -> wheel command`.
//!
//! An [`Agent`] holds one robot's policy and its reusable image buffers. Its decision reads nothing
//! but that robot's own LIDAR scan, its own compass heading and the goal every robot is given:
//!
//! 1. render the occupancy image from the scan ([`formation_perception::occupancy::render`], the same function the
//!    demonstration collector uses), for a model whose graph reads it
//!    ([`PolicyBackend::reads_image`]; the pair network reads none, and gets a blank image);
//! 2. the scalars the model declares beside the image, `aux` (the paper's
//!    `(wrap(phi* - theta), d*)`: see [`PolicyIo`]), the scan's ranges pooled into sectors
//!    where the model declares them ([`formation_perception::ranges::pool`], as collected), and
//!    the neighbours detected in the scan where the model declares them
//!    ([`NeighbourInputBuilder::fill`], as collected: one builder kept by each agent);
//! 3. `y = policy(image, aux, ranges, neighbours)`, what the model declares it outputs
//!    ([`PolicyOutput`]);
//! 4. for `wheels`, the wheel speeds at the training speed `v_train`: `u = K y` with
//!    `K = v* / v_train` (the paper's speed scaling); for `formation_velocity`, the formation
//!    velocity in the robot's frame: the reference term `v* (cos Δφ, sin Δφ)` is added and the
//!    point velocity turned into wheel speeds
//!    ([`policy_input::command_of_output`], shared with the Python bindings);
//! 5. under a wheel acceleration limit, the command slowed to one the robot can stop from before
//!    its body touches what the scan shows in its path, once a body there is closer than 90 %
//!    of d\* ([`stopping::keep_stopping_distance`]); without a limit, the command unchanged.
//!
//! The steps are exposed separately ([`Agent::perceive`], [`Agent::decide`]) so the agent process
//! can time them, and together as [`Agent::act`]. [`PolicyController`] runs one independent `Agent`
//! per robot inside one process: the in-process twin of the multi-process runtime.
//!
//! # Contracts checked
//!
//! A goal is checked once where it enters the agent, and held until the next one: d* positive,
//! everything finite, d* inside the model's trained range ([`Agent::hold_goal`]); each tick then
//! checks only what changes with it, the scan's length and the heading.
//!
//! A policy drives a robot only if it was trained for that robot's sensor: beams, maximum range
//! and image window ([`formation_onnx::contract::check_sensor`]), checked by [`Agent::new`] and
//! again by [`Agent::swap_policy`]. [`check_team_models`] runs the same check for every robot of
//! a launch before any process starts. A swap candidate must also give a finite command on the
//! agent's last observation before it may drive; otherwise the current policy keeps driving.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_onnx::contract::{SensorContract, SensorViolation, check_sensor};
use formation_onnx::{OnnxPolicy, PolicyError};
#[cfg(doc)]
use formation_proto::PolicyOutput;
use formation_proto::control::{Controller, ControllerError, Observation};
use formation_proto::robot::{CheckedGoal, Decentralised};
use formation_proto::{
    AuxValues, Goal, LidarSpec, OccupancySpec, PolicyInput, PolicyIo, WheelCmd, WheelLimits,
};

use formation_perception::beams::BeamDirections;
use formation_perception::neighbour_input::NeighbourInputBuilder;
use formation_perception::stopping;
use formation_perception::{occupancy, policy_input, ranges};

/// Why an agent could not decide, or could not take a policy.
#[derive(Debug, thiserror::Error)]
pub enum DecisionError {
    /// The ONNX policy failed to load, validate or run, or was trained for another sensor than
    /// this robot's ([`PolicyError::SensorMismatch`]).
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// A swap candidate gave a non-finite command on its trial observation; it was not swapped in.
    #[error(
        "candidate model {model} gives a non-finite command ({left}, {right}) on {observation}; \
         it was not swapped in: retrain or re-export it"
    )]
    SwapNonFinite {
        /// The candidate's model id.
        model: String,
        /// Which observation it was tried on.
        observation: TrialObservation,
        /// Left wheel output.
        left: f32,
        /// Right wheel output.
        right: f32,
    },
    /// A swap candidate failed to run on its trial observation; it was not swapped in.
    #[error("candidate model {model} failed its trial run on {observation}; it was not swapped in")]
    SwapTrialFailed {
        /// The candidate's model id.
        model: String,
        /// Which observation it was tried on.
        observation: TrialObservation,
        /// Why it failed.
        #[source]
        source: Box<DecisionError>,
    },
    /// A scan of the wrong length reached the agent.
    #[error("scan has {actual} ranges, the LIDAR is configured for {expected}")]
    ScanLength {
        /// Configured beams.
        expected: usize,
        /// Ranges received.
        actual: usize,
    },
    /// The policy returned a non-finite wheel speed.
    #[error("policy {model} returned a non-finite command ({left}, {right})")]
    NonFinite {
        /// Model id.
        model: String,
        /// Left wheel output.
        left: f32,
        /// Right wheel output.
        right: f32,
    },
    /// The goal's d* lies outside the range the model was trained on.
    #[error(
        "goal d* = {d_star} m is outside the d* range [{min}, {max}] m that model {model} was \
         trained on; give a d* inside it or use a model trained for this d*"
    )]
    OutsideEnvelope {
        /// Model id.
        model: String,
        /// The goal's d* \[m\].
        d_star: f64,
        /// Smallest trained d* \[m\].
        min: f64,
        /// Largest trained d* \[m\].
        max: f64,
    },
    /// The goal cannot be acted on.
    #[error("invalid goal: {reason}")]
    Goal {
        /// What is wrong.
        reason: String,
    },
}

/// The tensors a model may take from its scan beside its image: the scan's ranges, one a
/// sector, and the detected neighbours, [`formation_proto::NeighbourInput::features`] a slot;
/// each empty for a model that takes none.
#[derive(Debug, Clone, PartialEq)]
struct ScanTensors {
    ranges: Vec<f32>,
    neighbours: Vec<f32>,
}

impl ScanTensors {
    /// Sized for `io` and holding an empty observation's values: no beam returns, so every
    /// sector is the clip, and nobody is detected, so every slot is zeros.
    fn empty(io: &PolicyIo) -> ScanTensors {
        ScanTensors {
            ranges: io.ranges.map_or_else(Vec::new, |r| vec![r.clip; r.sectors]),
            neighbours: vec![0.0; io.neighbours.map_or(0, |n| n.len())],
        }
    }
}

/// Renders `scan` into the occupancy image `io` declares (`image`: `None` for a policy that does
/// not read it, [`PolicyBackend::reads_image`]), pools its ranges and fills the neighbours it
/// detects (with `builder`) where `io` takes them, under d*: one observation as a policy of `io`
/// sees it.
fn render_observation(
    scan: &[f32],
    lidar: &LidarSpec,
    io: &PolicyIo,
    d_star: f64,
    image: Option<&mut [u8]>,
    tensors: &mut ScanTensors,
    builder: &mut NeighbourInputBuilder,
) {
    if let Some(image) = image {
        occupancy::render_at(scan, lidar, &io.image, d_star, image);
    }
    if let Some(spec) = &io.ranges {
        ranges::pool(scan, lidar, spec, d_star, &mut tensors.ranges);
    }
    if let Some(spec) = &io.neighbours {
        builder.fill(scan, lidar, spec, d_star, &mut tensors.neighbours);
    }
}

/// What a swap candidate was tried on before it could drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrialObservation {
    /// The scan, heading and goal the agent last decided on, the image and the scalars
    /// made for the candidate.
    Last,
    /// No decision yet: an empty image (nothing in sight) on heading under [`TRIAL_GOAL`].
    Empty,
}

impl std::fmt::Display for TrialObservation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TrialObservation::Last => "the last observation",
            TrialObservation::Empty => "an empty observation",
        })
    }
}

/// The goal a swap candidate is tried on, on heading, before the agent has decided anything:
/// a 1 m distance at rest.
pub const TRIAL_GOAL: Goal = Goal {
    phi_star: 0.0,
    d_star: 1.0,
    v_star: 0.0,
};

/// A policy an [`Agent`] can run: maps one occupancy image and the scalars beside it to the two
/// values its model declares.
pub trait PolicyBackend: Send {
    /// One forward pass on the inputs [`PolicyBackend::io`] declares: the image
    /// (`size_px * size_px` cells, 0.0 or 1.0, row-major), its scalars in order, and the
    /// scan's ranges where it takes them.
    fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError>;
    /// What the policy takes and answers: its image, its scalars, its output and `v_train`.
    fn io(&self) -> PolicyIo;
    /// The sensor it was trained for: beams and range where it records them, and its window.
    fn sensor(&self) -> SensorContract;
    /// A short id naming the model (logged with every command).
    fn model_id(&self) -> &str;
    /// What the model was trained on beyond its sensor (d* range, team sizes, noise); empty
    /// when it records nothing.
    fn envelope(&self) -> formation_onnx::ModelEnvelope {
        formation_onnx::ModelEnvelope::default()
    }
    /// Whether its output depends on the image at all. One that does not still takes an image
    /// of the declared shape, but the agent leaves it blank instead of rendering it every tick.
    fn reads_image(&self) -> bool {
        true
    }
}

/// Refuses a goal d* outside `policy`'s trained d* range.
pub fn check_goal_envelope(policy: &dyn PolicyBackend, d_star: f64) -> Result<(), DecisionError> {
    let envelope = policy.envelope();
    match envelope.d_star {
        Some((min, max)) if !envelope.admits_d_star(d_star) => {
            Err(DecisionError::OutsideEnvelope {
                model: policy.model_id().to_owned(),
                d_star,
                min,
                max,
            })
        }
        _ => Ok(()),
    }
}

impl PolicyBackend for OnnxPolicy {
    fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError> {
        Ok(OnnxPolicy::infer(self, input)?)
    }
    fn io(&self) -> PolicyIo {
        self.metadata().io()
    }
    fn sensor(&self) -> SensorContract {
        SensorContract::from(self.metadata())
    }
    fn envelope(&self) -> formation_onnx::ModelEnvelope {
        self.metadata().envelope()
    }
    fn model_id(&self) -> &str {
        OnnxPolicy::model_id(self)
    }
    fn reads_image(&self) -> bool {
        OnnxPolicy::reads_image(self)
    }
}

/// One robot's decision maker: its policy, its sensor settings, reusable image buffers, the goal
/// it holds, and the last observation it decided on (a swap candidate's trial input).
pub struct Agent {
    policy: Box<dyn PolicyBackend>,
    /// The policy's declared input and output, read once from it.
    io: PolicyIo,
    /// Whether the policy reads its image ([`PolicyBackend::reads_image`]): the image is
    /// rendered only then, and otherwise stays blank.
    reads_image: bool,
    lidar: LidarSpec,
    image: Vec<u8>,
    image_f32: Vec<f32>,
    /// The scan's ranges and detected neighbours of the last [`Agent::perceive`], each empty
    /// for a policy that takes none.
    tensors: ScanTensors,
    /// Detects the neighbours in this robot's scans for a policy that takes them: the
    /// detector's default settings, bodies of [`formation_proto::DEFAULT_BODY_RADIUS_M`].
    neighbour_builder: NeighbourInputBuilder,
    /// The goal checked where it entered ([`Agent::hold_goal`]); `None` before the first.
    goal: Option<CheckedGoal>,
    /// The scan of the last [`Agent::perceive`]; empty before the first.
    last_scan: Vec<f32>,
    /// The heading and the scalars of the last [`Agent::decide`]; `None` before the first.
    last_decision: Option<(f64, AuxValues)>,
    /// The robot's wheels, within which a formation-velocity output is turned into wheel speeds
    /// ([`policy_input::formation_velocity_to_wheels`]); by default none told.
    wheels: WheelLimits,
    /// The direction of each beam of the LIDAR, for the stopping governor
    /// ([`stopping::keep_stopping_distance`]).
    beams: BeamDirections,
}

impl Agent {
    /// Wraps a policy after checking that it was trained for this robot's LIDAR (beams, range
    /// and image window).
    pub fn new(policy: Box<dyn PolicyBackend>, lidar: LidarSpec) -> Result<Agent, DecisionError> {
        check_policy(policy.as_ref(), &lidar)?;
        let io = policy.io();
        let cells = cells(&io.image);
        Ok(Agent {
            reads_image: policy.reads_image(),
            policy,
            io,
            lidar,
            image: vec![0; cells],
            image_f32: vec![0.0; cells],
            tensors: ScanTensors::empty(&io),
            neighbour_builder: NeighbourInputBuilder::default(),
            goal: None,
            last_scan: Vec::with_capacity(lidar.beams),
            last_decision: None,
            wheels: WheelLimits::default(),
            beams: BeamDirections::new(lidar.beams),
        })
    }

    /// Sets the robot's wheel limits (by default none told), within which a policy that answers
    /// a formation velocity has it turned into wheel speeds.
    pub fn set_wheel_limits(&mut self, wheels: WheelLimits) {
        self.wheels = wheels;
    }

    /// The robot's wheel limits this agent drives within.
    pub fn wheel_limits(&self) -> WheelLimits {
        self.wheels
    }

    /// Loads an ONNX model (validating its contract) and wraps it.
    pub fn from_model_path(path: &Path, lidar: LidarSpec) -> Result<Agent, DecisionError> {
        let policy = OnnxPolicy::load(path)?;
        Agent::new(Box::new(policy), lidar)
    }

    /// Takes a goal where it enters the robot and holds it: d* positive, phi* and v* finite, and
    /// d* inside the model's trained range. The same goal again is not checked again, so a
    /// goal that comes with every tick is checked once. On error the agent holds no goal.
    pub fn hold_goal(&mut self, goal: &Goal) -> Result<(), DecisionError> {
        if self.goal.as_ref().map(CheckedGoal::goal) == Some(goal) {
            return Ok(());
        }
        self.goal = None;
        let checked = CheckedGoal::new(*goal).map_err(|e| DecisionError::Goal {
            reason: e.to_string(),
        })?;
        check_goal_envelope(self.policy.as_ref(), goal.d_star)?;
        self.goal = Some(checked);
        Ok(())
    }

    /// The goal held, checked where it entered.
    fn held_goal(&self) -> Option<Goal> {
        self.goal.map(|goal| *goal.goal())
    }

    /// Renders this robot's occupancy image from its own scan under the goal (whose d* sets the
    /// window of a model whose window scales with d*; a fixed window ignores it), and holds the
    /// goal for [`Agent::decide`].
    pub fn perceive(&mut self, scan: &[f32], goal: &Goal) -> Result<(), DecisionError> {
        self.hold_goal(goal)?;
        if scan.len() != self.lidar.beams {
            return Err(DecisionError::ScanLength {
                expected: self.lidar.beams,
                actual: scan.len(),
            });
        }
        self.last_scan.clear();
        self.last_scan.extend_from_slice(scan);
        self.render_last_scan(goal.d_star);
        Ok(())
    }

    /// Renders the last scan into the policy's image (u8 and f32), and pools its ranges and
    /// detects its neighbours where the policy takes them, under d*: what [`Agent::perceive`]
    /// and [`Agent::rehearse`] both do.
    fn render_last_scan(&mut self, d_star: f64) {
        render_observation(
            &self.last_scan,
            &self.lidar,
            &self.io,
            d_star,
            self.reads_image.then_some(&mut self.image[..]),
            &mut self.tensors,
            &mut self.neighbour_builder,
        );
        if self.reads_image {
            for (dst, &src) in self.image_f32.iter_mut().zip(&self.image) {
                *dst = f32::from(src);
            }
        }
    }

    /// Runs the policy on the last perceived image under the goal [`Agent::perceive`] held, and
    /// turns its output into the wheel command, as the model declares it
    /// ([`policy_input::command_of_output`]), slowed under a wheel acceleration limit to one the
    /// robot can stop from before it touches what its scan shows in its path
    /// ([`stopping::keep_stopping_distance`]). The goal is checked once a tick, where it entered.
    pub fn decide(&mut self, heading: f64) -> Result<WheelCmd, DecisionError> {
        let Some(goal) = self.goal else {
            return Err(DecisionError::Goal {
                reason: "no goal held: perceive a scan under a goal before deciding".to_owned(),
            });
        };
        let goal = goal.goal();
        policy_input::check_heading(heading).map_err(|e| DecisionError::Goal {
            reason: e.to_string(),
        })?;
        let aux = self.io.aux.values(heading, goal);
        self.last_decision = Some((heading, aux));
        let [left, right] = self.policy.infer(&PolicyInput {
            image: &self.image_f32,
            aux: &aux,
            ranges: &self.tensors.ranges,
            neighbours: &self.tensors.neighbours,
        })?;
        if !(left.is_finite() && right.is_finite()) {
            return Err(DecisionError::NonFinite {
                model: self.policy.model_id().to_owned(),
                left,
                right,
            });
        }
        let command = policy_input::command_of_output(
            self.io.output,
            self.io.v_train,
            [left, right],
            heading,
            goal,
            self.wheels,
        );
        Ok(stopping::keep_stopping_distance(
            command,
            &self.last_scan,
            &self.beams,
            formation_proto::DEFAULT_BODY_RADIUS_M,
            formation_proto::DEFAULT_WHEEL_SEPARATION_M,
            goal.d_star,
            self.wheels.max_accel,
        ))
    }

    /// Runs the last decision again and throws its answer away: the occupancy rendering of the
    /// last scan and the policy on it, changing no state (the image is rendered from the same
    /// scan into the same cells). An agent idling between realtime ticks rehearses just before
    /// its next scan is due, so that the real decision finds caches warm. Does nothing before
    /// the first decision.
    pub fn rehearse(&mut self) -> Result<(), DecisionError> {
        let (Some((_, aux)), Some(goal)) = (self.last_decision, self.held_goal()) else {
            return Ok(());
        };
        self.render_last_scan(goal.d_star);
        self.policy.infer(&PolicyInput {
            image: &self.image_f32,
            aux: &aux,
            ranges: &self.tensors.ranges,
            neighbours: &self.tensors.neighbours,
        })?;
        Ok(())
    }

    /// The whole decision: [`Agent::perceive`] then [`Agent::decide`].
    pub fn act(
        &mut self,
        scan: &[f32],
        heading: f64,
        goal: &Goal,
    ) -> Result<WheelCmd, DecisionError> {
        self.perceive(scan, goal)?;
        self.decide(heading)
    }

    /// The occupancy image of the last [`Agent::perceive`] (u8 cells, row-major); blank for a
    /// policy that does not read it ([`PolicyBackend::reads_image`]).
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    /// The id of the model now driving.
    pub fn model_id(&self) -> &str {
        self.policy.model_id()
    }

    /// The policy now driving.
    pub fn policy(&self) -> &dyn PolicyBackend {
        self.policy.as_ref()
    }

    /// What the policy now driving takes and answers.
    pub fn io(&self) -> &PolicyIo {
        &self.io
    }

    /// Replaces the policy after validating the new one; on error the old policy keeps driving.
    ///
    /// The candidate must fit this robot's sensor (as in [`Agent::new`]) and must give a finite
    /// command when run once on the last observation this agent decided on: its scan, heading
    /// and goal, the image and the scalars made as the candidate declares them (which may differ
    /// from the current policy's). Before the first decision it is run on an empty image under
    /// [`TRIAL_GOAL`]. A model whose output is NaN or infinite is refused here rather than
    /// braking its robot on every tick. The goal held must lie in the candidate's trained range.
    pub fn swap_policy(&mut self, mut policy: Box<dyn PolicyBackend>) -> Result<(), DecisionError> {
        check_policy(policy.as_ref(), &self.lidar)?;
        if let Some(goal) = self.held_goal() {
            check_goal_envelope(policy.as_ref(), goal.d_star)?;
        }
        let io = policy.io();
        let reads_image = policy.reads_image();
        let n = cells(&io.image);
        let mut image = vec![0u8; n];
        let mut trial_tensors = ScanTensors::empty(&io);
        let (aux, observation) = match (self.last_decision, self.held_goal()) {
            (Some((heading, _)), Some(goal)) if self.last_scan.len() == self.lidar.beams => {
                render_observation(
                    &self.last_scan,
                    &self.lidar,
                    &io,
                    goal.d_star,
                    reads_image.then_some(&mut image[..]),
                    &mut trial_tensors,
                    &mut self.neighbour_builder,
                );
                (io.aux.values(heading, &goal), TrialObservation::Last)
            }
            _ => (io.aux.values(0.0, &TRIAL_GOAL), TrialObservation::Empty),
        };
        let image: Vec<f32> = image.into_iter().map(f32::from).collect();
        let trial = PolicyInput {
            image: &image,
            aux: &aux,
            ranges: &trial_tensors.ranges,
            neighbours: &trial_tensors.neighbours,
        };
        trial_run(policy.as_mut(), &trial, observation)?;
        self.image.resize(n, 0);
        self.image_f32.resize(n, 0.0);
        if !reads_image {
            self.image.fill(0);
            self.image_f32.fill(0.0);
        }
        self.tensors = trial_tensors;
        if let Some((heading, _)) = self.last_decision {
            let goal = self.held_goal().unwrap_or(TRIAL_GOAL);
            self.last_decision = Some((heading, io.aux.values(heading, &goal)));
        }
        self.policy = policy;
        self.io = io;
        self.reads_image = reads_image;
        Ok(())
    }
}

/// Runs a swap candidate once on its trial observation; a non-finite command or a failure is a
/// refusal naming the candidate and the observation.
fn trial_run(
    policy: &mut dyn PolicyBackend,
    input: &PolicyInput<'_>,
    observation: TrialObservation,
) -> Result<(), DecisionError> {
    let outcome = policy.infer(input);
    let model = policy.model_id().to_owned();
    let non_finite = |left, right| DecisionError::SwapNonFinite {
        model: model.clone(),
        observation,
        left,
        right,
    };
    match outcome {
        Ok([left, right]) if !(left.is_finite() && right.is_finite()) => {
            Err(non_finite(left, right))
        }
        Ok(_) => Ok(()),
        Err(
            DecisionError::Policy(PolicyError::NonFiniteOutput { left, right, .. })
            | DecisionError::NonFinite { left, right, .. },
        ) => Err(non_finite(left, right)),
        Err(source) => Err(DecisionError::SwapTrialFailed {
            model: model.clone(),
            observation,
            source: Box::new(source),
        }),
    }
}

fn cells(spec: &OccupancySpec) -> usize {
    spec.size_px * spec.size_px
}

/// The full sensor contract of `policy` against this robot's LIDAR: beams, range and window.
fn check_policy(policy: &dyn PolicyBackend, lidar: &LidarSpec) -> Result<(), DecisionError> {
    let mismatch = |reason| {
        DecisionError::Policy(PolicyError::SensorMismatch {
            model: policy.model_id().to_owned(),
            reason,
        })
    };
    check_sensor(&policy.sensor(), lidar).map_err(mismatch)?;
    match policy.io().ranges {
        Some(ranges) if ranges.check_beams(lidar.beams).is_err() => {
            Err(mismatch(SensorViolation::RangeSectors {
                sectors: ranges.sectors,
                beams: lidar.beams,
            }))
        }
        _ => Ok(()),
    }
}

/// Why a launch's models cannot drive its robots: the first robot whose model fails.
#[derive(Debug, thiserror::Error)]
#[error("robot {robot}: model {} cannot drive this scenario's robots", path.display())]
pub struct TeamModelError {
    /// The robot.
    pub robot: usize,
    /// Its model file.
    pub path: PathBuf,
    /// What is wrong: the file, the contract or the sensor.
    #[source]
    pub source: Box<DecisionError>,
}

/// Loads robot `i`'s model `models[i]` for every robot and checks it against the contract and
/// this LIDAR (beams, range, window), as each agent will when its episode begins; returns each
/// robot's model id. Each distinct file is loaded once.
///
/// The launcher calls this before any process starts, so a model that cannot drive the scenario
/// is an error naming the robot, the file, the model's value and the scenario's, instead of a
/// team of agents that all refuse (or, for a range mismatch, drive blind).
pub fn check_team_models(
    models: &[PathBuf],
    lidar: &LidarSpec,
) -> Result<Vec<String>, TeamModelError> {
    check_team_models_for(models, lidar, &[])
}

/// [`check_team_models`], and every d* of `d_stars` (the scenario's) must lie in each model's
/// trained d* range, when the model records one.
pub fn check_team_models_for(
    models: &[PathBuf],
    lidar: &LidarSpec,
    d_stars: &[f64],
) -> Result<Vec<String>, TeamModelError> {
    Ok(check_team_models_with_metadata(models, lidar, d_stars)?
        .into_iter()
        .map(|(id, _)| id)
        .collect())
}

/// [`check_team_models_for`], with each robot's model id beside the model's whole metadata (the
/// input it declares, its LIDAR and its envelope: d* range, team sizes), for the launcher to
/// report what each model is given and a team size it never saw.
pub fn check_team_models_with_metadata(
    models: &[PathBuf],
    lidar: &LidarSpec,
    d_stars: &[f64],
) -> Result<Vec<(String, formation_onnx::ModelMetadata)>, TeamModelError> {
    let mut checked: BTreeMap<&Path, (String, formation_onnx::ModelMetadata)> = BTreeMap::new();
    let mut ids = Vec::with_capacity(models.len());
    for (robot, path) in models.iter().enumerate() {
        let id = match checked.get(path.as_path()) {
            Some(id) => id.clone(),
            None => {
                let fail = |source| TeamModelError {
                    robot,
                    path: path.clone(),
                    source: Box::new(source),
                };
                let policy = OnnxPolicy::load(path).map_err(|e| fail(e.into()))?;
                check_policy(&policy, lidar).map_err(fail)?;
                for &d_star in d_stars {
                    check_goal_envelope(&policy, d_star).map_err(fail)?;
                }
                let id = (policy.model_id().to_owned(), policy.metadata().clone());
                checked.insert(path, id.clone());
                id
            }
        };
        ids.push(id);
    }
    Ok(ids)
}

/// Runs one independent [`Agent`] per robot in-process: a [`Decentralised`] team (an [`Agent`] is
/// a [`formation_proto::robot::Pilot`], `crate::pilot`), which hands robot `i` only its own input
/// (`obs.scans[i]`, `obs.poses[i].theta` and the goal).
pub struct PolicyController {
    team: Decentralised<Agent>,
}

impl PolicyController {
    /// One agent per robot, in robot order.
    pub fn new(agents: Vec<Agent>) -> PolicyController {
        PolicyController {
            team: Decentralised::new(agents),
        }
    }

    /// Loads `models[i]` for robot `i`, each driving wheels with `wheels`' limits (what a
    /// formation-velocity model's command is saturated into, as the agent process does).
    pub fn from_model_paths(
        models: &[&Path],
        lidar: LidarSpec,
        wheels: WheelLimits,
    ) -> Result<PolicyController, DecisionError> {
        let mut agents = models
            .iter()
            .map(|m| Agent::from_model_path(m, lidar))
            .collect::<Result<Vec<_>, _>>()?;
        for agent in &mut agents {
            agent.set_wheel_limits(wheels);
        }
        Ok(PolicyController::new(agents))
    }

    /// The agents, in robot order.
    pub fn agents_mut(&mut self) -> &mut [Agent] {
        self.team.pilots_mut()
    }
}

impl Controller for PolicyController {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        self.team.commands(obs, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::{BeyondWindow, wrap_angle};
    use formation_proto::{NeighbourInput, RangeInput};

    /// A transparent policy for testing the decision's plumbing: returns the aux input and the
    /// number of occupied cells, so the test can see exactly what reached the policy.
    struct Probe {
        spec: OccupancySpec,
        seen: Option<([f32; 2], f32)>,
        d_star: Option<(f64, f64)>,
        /// How often its envelope was read: the goal checks.
        envelope_reads: std::sync::Arc<std::sync::atomic::AtomicUsize>,
        /// Says it does not read its image ([`PolicyBackend::reads_image`]).
        blind: bool,
    }

    impl PolicyBackend for Probe {
        fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError> {
            let (occupancy, aux) = (input.image, input.aux);
            let occupied: f32 = occupancy.iter().sum();
            let aux = [aux[0], aux[1]];
            self.seen = Some((aux, occupied));
            Ok([aux[0], occupied])
        }
        fn io(&self) -> PolicyIo {
            PolicyIo {
                image: self.spec,
                aux: formation_proto::AuxLayout::PAPER,
                ranges: None,
                neighbours: None,
                output: formation_proto::PolicyOutput::Wheels,
                v_train: 0.5,
            }
        }
        fn sensor(&self) -> SensorContract {
            SensorContract {
                beams: Some(900),
                max_range: Some(10.0),
                occupancy: self.spec,
            }
        }
        fn model_id(&self) -> &str {
            "probe"
        }
        fn envelope(&self) -> formation_onnx::ModelEnvelope {
            self.envelope_reads
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            formation_onnx::ModelEnvelope {
                d_star: self.d_star,
                ..formation_onnx::ModelEnvelope::default()
            }
        }
        fn reads_image(&self) -> bool {
            !self.blind
        }
    }

    fn probe() -> Box<Probe> {
        Box::new(Probe {
            spec: OccupancySpec {
                size_px: 50,
                resolution_m: 0.1,
                beyond: BeyondWindow::Drop,
                d_star_ref_m: None,
            },
            seen: None,
            d_star: None,
            envelope_reads: Default::default(),
            blind: false,
        })
    }

    /// A policy that does not read its image is handed a blank one: nothing is rendered for it,
    /// and a swap to it from one that reads clears what the last one saw.
    #[test]
    fn a_policy_that_reads_no_image_is_handed_a_blank_one() {
        let lidar = LidarSpec::default();
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[..20].fill(1.0); // a neighbour ahead, 1 m away
        let goal = Goal {
            phi_star: 0.0,
            d_star: 1.5,
            v_star: 0.5,
        };
        let occupied = |agent: &Agent| agent.image().iter().filter(|&&c| c != 0).count();
        let mut agent = Agent::new(probe(), lidar).expect("probe matches the sensor");
        let seeing = agent.act(&scan, 0.0, &goal).expect("decides").right;
        assert!(
            occupied(&agent) > 0 && seeing > 0.0,
            "the seeing probe sees"
        );
        let mut blind = probe();
        blind.blind = true;
        agent.swap_policy(blind).expect("the blind probe swaps in");
        assert_eq!(occupied(&agent), 0, "the swap clears the image");
        let cells = agent.act(&scan, 0.0, &goal).expect("decides").right;
        assert_eq!((occupied(&agent), cells), (0, 0.0), "nothing rendered");
        let mut blind = probe();
        blind.blind = true;
        let mut agent = Agent::new(blind, lidar).expect("probe matches the sensor");
        agent.act(&scan, 0.0, &goal).expect("decides");
        assert_eq!(occupied(&agent), 0, "nothing rendered from the start");
    }

    /// Issue 35: d* is checked once, where the goal enters, not on every tick; a refused goal
    /// leaves the agent holding none, and a swap candidate must admit the goal held.
    /// The model input an [`Echo`] declares: a range input of `K` sectors (clip 3 m, wheel
    /// output) or a neighbour input of `K` slots (the default rule, formation-velocity output).
    #[derive(Clone, Copy)]
    enum Echoed {
        Ranges(usize),
        Neighbours(usize),
    }

    /// What an [`Echo`] was fed, one entry a call.
    type EchoLog = std::sync::Arc<std::sync::Mutex<Vec<Vec<f32>>>>;

    /// A policy that declares one model input ([`Echoed`]), logs the values it is fed of it and
    /// answers with the first two.
    struct Echo {
        input: Echoed,
        seen: EchoLog,
    }

    impl Echo {
        /// An echo of `input` and the log of what it is fed.
        fn logged(input: Echoed) -> (Box<Echo>, EchoLog) {
            let seen = EchoLog::default();
            let echo = Echo {
                input,
                seen: std::sync::Arc::clone(&seen),
            };
            (Box::new(echo), seen)
        }
    }

    /// Rehearses `agent`, checking that its echo (logging to `seen`) is fed `expected` again, then
    /// swaps in an echo of `candidate` and returns the log of what that one is fed.
    fn rehearse_then_swap(
        agent: &mut Agent,
        seen: &EchoLog,
        expected: &[f32],
        candidate: Echoed,
    ) -> EchoLog {
        agent.rehearse().expect("rehearses");
        assert_eq!(
            seen.lock().unwrap()[1],
            expected,
            "a rehearsal feeds the same"
        );
        let (candidate, candidate_seen) = Echo::logged(candidate);
        agent.swap_policy(candidate).expect("swaps");
        candidate_seen
    }

    impl PolicyBackend for Echo {
        fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError> {
            let fed = match self.input {
                Echoed::Ranges(_) => input.ranges,
                Echoed::Neighbours(_) => {
                    assert!(input.ranges.is_empty(), "it takes no ranges");
                    input.neighbours
                }
            };
            self.seen.lock().expect("log").push(fed.to_vec());
            Ok([fed[0], fed[1]])
        }
        fn io(&self) -> PolicyIo {
            let (ranges, neighbours, output) = match self.input {
                Echoed::Ranges(sectors) => (
                    Some(RangeInput::new(sectors, 3.0).expect("valid")),
                    None,
                    formation_proto::PolicyOutput::Wheels,
                ),
                Echoed::Neighbours(slots) => (
                    None,
                    Some(NeighbourInput::with_default_rule(slots).expect("valid")),
                    formation_proto::PolicyOutput::FormationVelocity,
                ),
            };
            PolicyIo {
                image: OccupancySpec::PAPER,
                aux: formation_proto::AuxLayout::PAPER,
                ranges,
                neighbours,
                output,
                v_train: 0.7,
            }
        }
        fn sensor(&self) -> SensorContract {
            // Beams unrecorded, so that the input's own check is the one that speaks.
            SensorContract {
                beams: None,
                max_range: None,
                occupancy: OccupancySpec::PAPER,
            }
        }
        fn model_id(&self) -> &str {
            match self.input {
                Echoed::Ranges(_) => "ranges-echo",
                Echoed::Neighbours(_) => "neighbours-echo",
            }
        }
    }

    #[test]
    fn a_policy_that_takes_ranges_is_fed_its_own_scan_pooled_as_collected() {
        let lidar = LidarSpec::default();
        let (echo, seen) = Echo::logged(Echoed::Ranges(100));
        let mut agent = Agent::new(echo, lidar).expect("fits the sensor");
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[0] = 1.5; // sector 0
        scan[9] = 0.75; // sector 1
        let goal = Goal {
            phi_star: 0.0,
            d_star: 1.5,
            v_star: 0.7,
        };
        agent.act(&scan, 0.0, &goal).expect("decides");
        let mut expected = vec![0.0; 100];
        ranges::pool(
            &scan,
            &lidar,
            &RangeInput::new(100, 3.0).unwrap(),
            1.5,
            &mut expected,
        );
        assert_eq!(seen.lock().unwrap().as_slice(), &[expected.clone()]);
        assert_eq!((expected[0], expected[1], expected[2]), (1.0, 0.5, 3.0));
        // A swap candidate that takes other sectors is tried on the last scan, pooled its way.
        let candidate_seen = rehearse_then_swap(&mut agent, &seen, &expected, Echoed::Ranges(50));
        let tried = candidate_seen.lock().unwrap()[0].clone();
        assert_eq!(tried.len(), 50);
        assert_eq!(tried[0], 1.0, "beam 0 is in sector 0 of 50 too");

        // More sectors than beams cannot be pooled: refused, naming both.
        let few = LidarSpec { beams: 60, ..lidar };
        let err = Agent::new(Echo::logged(Echoed::Ranges(100)).0, few)
            .err()
            .expect("refused");
        assert!(err.to_string().contains("100 sectors"), "{err}");
    }

    /// Under a wheel acceleration limit the agent slows a command that would carry its body into
    /// one closer than 90 % of d* in its path, keeping the turn; without a limit, or with the
    /// body at d*, the policy's command goes out as it is.
    #[test]
    fn under_an_acceleration_limit_the_agent_keeps_its_stopping_distance() {
        let lidar = LidarSpec::default();
        // The blind probe answers (Δφ, 0): at Δφ = 0.8 and v* = v_train, wheels (0.8, 0).
        let goal = Goal::new(0.8, 1.0, 0.5);
        let command = |bodies: &[(f64, f64)], max_accel: Option<f64>| {
            let mut blind = probe();
            blind.blind = true;
            let mut agent = Agent::new(blind, lidar).expect("probe matches the sensor");
            agent.set_wheel_limits(WheelLimits {
                max_speed: None,
                max_accel,
            });
            agent
                .act(&scan_among(&lidar, bodies), 0.0, &goal)
                .expect("decides")
        };
        let free = WheelCmd {
            left: f64::from(0.8f32),
            right: 0.0,
        };
        let close = [(0.65, 0.0)];
        assert_eq!(command(&close, None), free, "no limit, no governor");
        assert_eq!(command(&[(1.0, 0.0)], Some(1.0)), free, "a body at d*");
        assert_eq!(command(&[(-0.65, 0.0)], Some(1.0)), free, "a body behind");
        // Centres 0.65 apart: the probe's tight right turn (wheels 0.8 and 0) carries the body,
        // grown by the margin, into it; the speed is what it can stop from on that arc.
        let governed = command(&close, Some(1.0));
        let speed = 0.5 * (governed.left + governed.right);
        let path = stopping::Course::of_command(free, formation_proto::DEFAULT_WHEEL_SEPARATION_M)
            .expect("the probe's command moves");
        let travel = stopping::clearance(
            &scan_among(&lidar, &close),
            &BeamDirections::new(lidar.beams),
            formation_proto::DEFAULT_BODY_RADIUS_M + stopping::SAFETY_MARGIN_M,
            path,
            f64::INFINITY,
        );
        let allowed = (2.0 * stopping::BRAKING_SHARE * travel).sqrt();
        assert!(speed < 0.5 * free.left, "{governed:?}");
        assert!(
            (speed - allowed).abs() < 1e-12,
            "{governed:?}: {speed} against {allowed}"
        );
        assert!(
            (governed.right - governed.left + free.left).abs() < 1e-12,
            "the turn is kept"
        );
    }

    /// The exact scan of a robot at the origin, heading +x, among bodies of the default radius
    /// centred at `bodies` (body frame, metres).
    fn scan_among(lidar: &LidarSpec, bodies: &[(f64, f64)]) -> Vec<f32> {
        let r = formation_proto::DEFAULT_BODY_RADIUS_M;
        (0..lidar.beams)
            .map(|k| {
                let bearing = std::f64::consts::TAU * k as f64 / lidar.beams as f64;
                let (dx, dy) = (bearing.cos(), bearing.sin());
                let hit = bodies
                    .iter()
                    .filter_map(|&(cx, cy)| {
                        // |t d - c|^2 = r^2, the nearer root ahead of the sensor.
                        let along = dx * cx + dy * cy;
                        let off_sq = cx * cx + cy * cy - along * along;
                        let half = (r * r - off_sq).sqrt();
                        (half.is_finite() && along - half > 0.0).then_some(along - half)
                    })
                    .fold(lidar.max_range, f64::min);
                hit as f32
            })
            .collect()
    }

    #[test]
    fn a_policy_that_takes_neighbours_is_fed_those_detected_in_its_own_scan_as_collected() {
        let lidar = LidarSpec::default();
        let (echo, seen) = Echo::logged(Echoed::Neighbours(4));
        let mut agent = Agent::new(echo, lidar).expect("fits the sensor");
        // Two robots: 1.5 m to the right, 2 m ahead.
        let scan = scan_among(&lidar, &[(2.0, 0.0), (0.0, -1.5)]);
        let goal = Goal {
            phi_star: 0.0,
            d_star: 1.5,
            v_star: 0.7,
        };
        agent.act(&scan, 0.0, &goal).expect("decides");
        let spec = NeighbourInput::with_default_rule(4).unwrap();
        let mut expected = vec![f32::NAN; spec.len()];
        NeighbourInputBuilder::default().fill(&scan, &lidar, &spec, 1.5, &mut expected);
        assert_eq!(seen.lock().unwrap().as_slice(), &[expected.clone()]);
        // Both held (the two nearest), the nearer first, in units of d*; the rest empty.
        let want = [0.0, -1.0, 1.0, 1.0, 4.0 / 3.0, 0.0, 1.0, 1.0];
        for (got, want) in expected.iter().zip(want) {
            assert!((got - want).abs() < 1e-3, "{expected:?}");
        }
        assert_eq!(&expected[8..], &[0.0; 8]);
        // A swap candidate with fewer slots is tried on the last scan, filled its way.
        let candidate_seen =
            rehearse_then_swap(&mut agent, &seen, &expected, Echoed::Neighbours(1));
        assert_eq!(candidate_seen.lock().unwrap()[0], &expected[..4]);
        agent.act(&scan, 0.0, &goal).expect("the candidate drives");
        assert_eq!(candidate_seen.lock().unwrap()[1], &expected[..4]);

        // Before any decision a candidate is tried on an empty observation: nobody detected.
        let mut fresh = Agent::new(Echo::logged(Echoed::Neighbours(2)).0, lidar).expect("fits");
        let (candidate, fresh_seen) = Echo::logged(Echoed::Neighbours(3));
        fresh.swap_policy(candidate).expect("swaps");
        assert_eq!(fresh_seen.lock().unwrap().as_slice(), &[vec![0.0; 12]]);
    }

    /// An agent of `probe` on the default LIDAR, and a scan with no return.
    fn agent_and_open_scan(probe: Box<Probe>) -> (Agent, Vec<f32>) {
        let lidar = LidarSpec::default();
        let agent = Agent::new(probe, lidar).expect("probe matches the sensor");
        (agent, vec![lidar.max_range as f32; lidar.beams])
    }

    /// A goal of d* `d_star` at v* 0.7 m/s, straight ahead.
    fn goal_at(d_star: f64) -> Goal {
        Goal {
            phi_star: 0.0,
            d_star,
            v_star: 0.7,
        }
    }

    #[test]
    fn a_goal_is_checked_once_where_it_enters_and_held() {
        let mut probe = probe();
        probe.d_star = Some((0.8, 2.5));
        let envelope_reads = std::sync::Arc::clone(&probe.envelope_reads);
        let (mut agent, scan) = agent_and_open_scan(probe);
        let goal = |d_star| Goal {
            phi_star: 0.5,
            ..goal_at(d_star)
        };
        let checks = |_: &Agent| envelope_reads.load(std::sync::atomic::Ordering::Relaxed);
        for tick in 0..5 {
            agent
                .act(&scan, 0.1 * f64::from(tick), &goal(1.5))
                .expect("inside the range");
        }
        assert_eq!(checks(&agent), 1, "one goal, one check, over five ticks");
        agent.act(&scan, 0.0, &goal(2.0)).expect("a new goal");
        assert_eq!(checks(&agent), 2, "a new goal is checked when it enters");
        for _ in 0..2 {
            assert!(matches!(
                agent.act(&scan, 0.0, &goal(-1.0)),
                Err(DecisionError::Goal { .. })
            ));
            assert!(matches!(
                agent.act(&scan, 0.0, &goal(3.0)),
                Err(DecisionError::OutsideEnvelope { .. })
            ));
        }
        agent
            .act(&scan, 0.0, &goal(2.0))
            .expect("a good goal again");
        let narrow = Probe {
            d_star: Some((0.5, 1.0)),
            ..*self::probe()
        };
        assert!(matches!(
            agent.swap_policy(Box::new(narrow)),
            Err(DecisionError::OutsideEnvelope { .. })
        ));
        assert_eq!(agent.model_id(), "probe");
    }

    #[test]
    fn a_goal_outside_the_models_d_star_range_is_refused_naming_the_range_and_the_model() {
        let mut probe = probe();
        probe.d_star = Some((0.8, 2.5));
        let (mut agent, scan) = agent_and_open_scan(probe);
        agent
            .act(&scan, 0.0, &goal_at(2.5))
            .expect("inside the range");
        let err = agent.act(&scan, 0.0, &goal_at(3.0)).unwrap_err();
        assert!(
            matches!(err, DecisionError::OutsideEnvelope { .. }),
            "{err}"
        );
        let text = err.to_string();
        assert!(
            text.contains("d* = 3 m") && text.contains("[0.8, 2.5] m") && text.contains("probe"),
            "{text}"
        );
    }

    /// A model whose window scales with d* sees a neighbour held at d* in the same cell at every
    /// spacing: the agent renders with the goal's d*, as the collector did.
    #[test]
    fn a_window_scaled_with_d_star_is_rendered_for_the_goals_d_star() {
        let lidar = LidarSpec::default();
        let mut probe = probe();
        probe.spec.d_star_ref_m = Some(1.0);
        let mut agent = Agent::new(probe, lidar).expect("probe matches the sensor");
        let lit_cells = |agent: &Agent| -> Vec<usize> {
            let image = agent.image();
            (0..image.len()).filter(|&i| image[i] != 0).collect()
        };
        let mut seen = Vec::new();
        for d_star in [0.8, 1.6, 2.4] {
            let mut scan = vec![lidar.max_range as f32; lidar.beams];
            scan[0] = d_star as f32; // the neighbour ahead, at d*
            let goal = Goal {
                phi_star: 0.0,
                d_star,
                v_star: 0.7,
            };
            agent.act(&scan, 0.0, &goal).expect("decides");
            seen.push(lit_cells(&agent));
        }
        assert_eq!(
            seen,
            vec![vec![25 * 50 + 35]; 3],
            "10 cells ahead at every d*"
        );
        let err = agent
            .perceive(
                &vec![1.0; lidar.beams],
                &Goal {
                    phi_star: 0.0,
                    d_star: f64::NAN,
                    v_star: 0.7,
                },
            )
            .expect_err("no window for a NaN d*");
        assert!(err.to_string().contains("d* must be > 0"), "{err}");
    }

    #[test]
    fn act_scales_by_v_star_over_v_train_and_feeds_wrapped_delta_phi() {
        let lidar = LidarSpec::default();
        let mut agent = Agent::new(probe(), lidar).expect("probe matches the sensor");
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[0] = 1.0; // one hit straight ahead
        let goal = Goal {
            phi_star: 3.0,
            d_star: 1.5,
            v_star: 0.7,
        };
        let cmd = agent.act(&scan, -3.0, &goal).expect("decides");
        let delta = wrap_angle(6.0);
        let k = 0.7 / 0.5;
        assert!((cmd.left - k * f64::from(delta as f32)).abs() < 1e-12);
        assert!(
            (cmd.right - k * 1.0).abs() < 1e-12,
            "exactly one occupied cell reached the policy"
        );
    }

    #[test]
    fn a_rehearsal_runs_the_last_decision_again_and_changes_nothing() {
        let lidar = LidarSpec::default();
        let mut agent = Agent::new(probe(), lidar).expect("probe matches the sensor");
        agent
            .rehearse()
            .expect("nothing to rehearse before the first decision");
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[0] = 1.0;
        scan[450] = 2.0;
        let goal = Goal {
            phi_star: 1.0,
            d_star: 1.5,
            v_star: 0.7,
        };
        let first = agent.act(&scan, 0.5, &goal).expect("decides");
        let image = agent.image().to_vec();
        agent.rehearse().expect("rehearses");
        assert_eq!(agent.image(), image, "the same image");
        let again = agent.decide(0.5).expect("decides again");
        assert_eq!(first, again, "the same command after a rehearsal");
    }

    #[test]
    fn sensor_mismatch_and_bad_goal_are_refused() {
        let lidar = LidarSpec {
            beams: 360,
            ..LidarSpec::default()
        };
        assert!(matches!(
            Agent::new(probe(), lidar),
            Err(DecisionError::Policy(PolicyError::SensorMismatch {
                reason: SensorViolation::Beams {
                    trained: 900,
                    actual: 360
                },
                ..
            }))
        ));
        let mut agent = Agent::new(probe(), LidarSpec::default()).expect("matches");
        let scan = vec![10.0; 900];
        let bad = Goal {
            phi_star: 0.0,
            d_star: 0.0,
            v_star: 0.7,
        };
        assert!(matches!(
            agent.act(&scan, 0.0, &bad),
            Err(DecisionError::Goal { .. })
        ));
        assert!(matches!(
            agent.act(&scan[..10], 0.0, &Goal { d_star: 1.0, ..bad }),
            Err(DecisionError::ScanLength {
                expected: 900,
                actual: 10
            })
        ));
    }

    /// Every input a [`Fake`] was run on: (aux, occupied cells).
    type CallLog = std::sync::Arc<std::sync::Mutex<Vec<([f32; 2], f32)>>>;

    /// A configurable policy: fixed output, recorded sensor settings, and a shared log of every
    /// input it was run on (aux, occupied cells), readable after it was moved into an agent.
    struct Fake {
        id: &'static str,
        beams: Option<usize>,
        max_range: Option<f64>,
        output: Result<[f32; 2], fn() -> DecisionError>,
        seen: CallLog,
    }

    impl Fake {
        fn new(id: &'static str, output: [f32; 2]) -> Fake {
            Fake {
                id,
                beams: Some(900),
                max_range: Some(10.0),
                output: Ok(output),
                seen: Default::default(),
            }
        }

        fn calls(&self) -> CallLog {
            std::sync::Arc::clone(&self.seen)
        }
    }

    impl PolicyBackend for Fake {
        fn infer(&mut self, input: &PolicyInput<'_>) -> Result<[f32; 2], DecisionError> {
            let (occupancy, aux) = (input.image, input.aux);
            let occupied = occupancy.iter().sum();
            self.seen
                .lock()
                .expect("log")
                .push(([aux[0], aux[1]], occupied));
            self.output.map_err(|make| make())
        }
        fn io(&self) -> PolicyIo {
            PolicyIo {
                image: OccupancySpec::PAPER,
                aux: formation_proto::AuxLayout::PAPER,
                ranges: None,
                neighbours: None,
                output: formation_proto::PolicyOutput::Wheels,
                v_train: 0.7,
            }
        }
        fn sensor(&self) -> SensorContract {
            SensorContract {
                beams: self.beams,
                max_range: self.max_range,
                occupancy: OccupancySpec::PAPER,
            }
        }
        fn model_id(&self) -> &str {
            self.id
        }
    }

    fn goal() -> Goal {
        Goal::new(1.0, 1.5, 0.7)
    }

    /// A scan with one hit 1 m straight ahead.
    fn one_hit(lidar: &LidarSpec) -> Vec<f32> {
        let mut scan = vec![lidar.max_range as f32; lidar.beams];
        scan[0] = 1.0;
        scan
    }

    #[test]
    fn the_full_sensor_contract_is_checked_range_and_window_too() {
        // Issue: lidar.max_range = 1e-9 ran a model trained for 10 m; only beams were compared.
        let short = LidarSpec {
            max_range: 5.0,
            ..LidarSpec::default()
        };
        match Agent::new(Box::new(Fake::new("ten-metres", [0.1, 0.1])), short) {
            Err(err @ DecisionError::Policy(PolicyError::SensorMismatch { .. })) => {
                let DecisionError::Policy(PolicyError::SensorMismatch { reason, .. }) = &err else {
                    unreachable!()
                };
                assert_eq!(
                    *reason,
                    SensorViolation::MaxRange {
                        trained: 10.0,
                        actual: 5.0
                    }
                );
                let message = err.to_string();
                assert!(message.contains("ten-metres"), "{message}");
                assert!(
                    message.contains("10 m") && message.contains("5 m"),
                    "{message}"
                );
            }
            Err(other) => panic!("expected a range mismatch, got {other}"),
            Ok(_) => panic!("a 10 m model must not drive a 5 m sensor"),
        }

        // A policy that does not record its range must still see its whole 5 m window.
        let unrecorded = || Fake {
            max_range: None,
            ..Fake::new("no-range", [0.1, 0.1])
        };
        let blind = LidarSpec {
            max_range: 1.0,
            ..LidarSpec::default()
        };
        assert!(matches!(
            Agent::new(Box::new(unrecorded()), blind),
            Err(DecisionError::Policy(PolicyError::SensorMismatch {
                reason: SensorViolation::Window { .. },
                ..
            }))
        ));
        Agent::new(Box::new(unrecorded()), LidarSpec::default()).expect("10 m covers the window");

        // And a swap candidate is held to the same contract.
        let mut agent = Agent::new(
            Box::new(Fake::new("current", [0.2, 0.2])),
            LidarSpec::default(),
        )
        .expect("fits");
        let wrong = Fake {
            max_range: Some(20.0),
            ..Fake::new("twenty-metres", [0.1, 0.1])
        };
        assert!(matches!(
            agent.swap_policy(Box::new(wrong)),
            Err(DecisionError::Policy(PolicyError::SensorMismatch {
                reason: SensorViolation::MaxRange { trained, .. },
                ..
            })) if trained == 20.0
        ));
        assert_eq!(agent.model_id(), "current");
    }

    #[test]
    fn a_nan_swap_candidate_is_refused_on_the_last_observation_and_the_old_policy_drives_on() {
        let lidar = LidarSpec::default();
        let current = Fake::new("current", [0.35, 0.35]);
        let mut agent = Agent::new(Box::new(current), lidar).expect("fits");
        let scan = one_hit(&lidar);
        let before = agent.act(&scan, 0.25, &goal()).expect("decides");
        let last_aux = formation_proto::AuxLayout::PAPER.values(0.25, &goal());
        let last_aux = [last_aux[0], last_aux[1]];

        for output in [[f32::NAN, 0.1], [0.1, f32::INFINITY], [f32::NAN, f32::NAN]] {
            let candidate = Fake::new("broken", output);
            let calls = candidate.calls();
            let err = agent
                .swap_policy(Box::new(candidate))
                .expect_err("a non-finite candidate must be refused");
            match &err {
                DecisionError::SwapNonFinite {
                    model,
                    observation,
                    left,
                    right,
                } => {
                    assert_eq!(model, "broken");
                    assert_eq!(*observation, TrialObservation::Last);
                    assert_eq!(left.to_bits(), output[0].to_bits());
                    assert_eq!(right.to_bits(), output[1].to_bits());
                }
                other => panic!("expected SwapNonFinite, got {other:?}"),
            }
            let message = err.to_string();
            assert!(message.contains("non-finite"), "{message}");
            assert!(message.contains("the last observation"), "{message}");
            // Tried exactly once, on what the agent last decided on: the aux and the one hit.
            assert_eq!(*calls.lock().expect("log"), vec![(last_aux, 1.0)]);
            // The old policy keeps driving, with the same command for the same input.
            assert_eq!(agent.model_id(), "current");
            assert_eq!(agent.act(&scan, 0.25, &goal()).expect("decides"), before);
        }

        // A backend that reports the non-finite output as an error is refused the same way.
        let reporting = Fake {
            output: Err(|| DecisionError::NonFinite {
                model: "reporting".into(),
                left: f32::NAN,
                right: 0.0,
            }),
            ..Fake::new("reporting", [0.0, 0.0])
        };
        assert!(matches!(
            agent.swap_policy(Box::new(reporting)),
            Err(DecisionError::SwapNonFinite { .. })
        ));
        // Any other failure of the trial run is refused with its cause kept.
        let failing = Fake {
            output: Err(|| DecisionError::Goal {
                reason: "boom".into(),
            }),
            ..Fake::new("failing", [0.0, 0.0])
        };
        match agent.swap_policy(Box::new(failing)) {
            Err(err @ DecisionError::SwapTrialFailed { .. }) => {
                let cause = std::error::Error::source(&err).expect("cause kept");
                assert!(cause.to_string().contains("boom"), "{cause}");
            }
            other => panic!("expected SwapTrialFailed, got {other:?}"),
        }
        assert_eq!(agent.model_id(), "current");

        // A finite candidate is swapped in and drives from the next decision.
        agent
            .swap_policy(Box::new(Fake::new("next", [0.5, 0.0])))
            .expect("a finite candidate is accepted");
        assert_eq!(agent.model_id(), "next");
        let after = agent.act(&scan, 0.25, &goal()).expect("decides");
        assert_eq!(
            (after.left, after.right),
            (0.5, 0.0),
            "v* = v_train: unscaled"
        );
    }

    #[test]
    fn before_any_decision_a_candidate_is_tried_on_an_empty_observation() {
        let lidar = LidarSpec::default();
        let mut agent =
            Agent::new(Box::new(Fake::new("current", [0.1, 0.1])), lidar).expect("fits");
        let candidate = Fake::new("broken", [f32::NAN, f32::NAN]);
        let calls = candidate.calls();
        match agent.swap_policy(Box::new(candidate)) {
            Err(DecisionError::SwapNonFinite { observation, .. }) => {
                assert_eq!(observation, TrialObservation::Empty);
            }
            other => panic!("expected SwapNonFinite, got {other:?}"),
        }
        assert_eq!(*calls.lock().expect("log"), vec![([0.0, 1.0], 0.0)]);
        assert_eq!(agent.model_id(), "current");
    }
}
