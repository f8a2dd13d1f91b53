//! Scenarios: what a run is asked to do, read from TOML, and the fully resolved [`RunSpec`] of one run.
//!
//! A [`Scenario`] describes a family of runs (team size, goal, heading schedule, how initial poses are
//! drawn, sensor and robot settings). [`Scenario::run_spec`] turns it into the [`RunSpec`] of run `i`,
//! drawing everything random from a seed derived from `(base_seed, i)` alone, so any run can be replayed
//! on its own, bit for bit, in any order and on any machine.
//!
//! # Phases
//!
//! * `parse`: the file's text, read within its size limit, into the TOML schema;
//! * `validate`: every value checked against its documented range ([`limits`]);
//! * `placement`: the robots' initial positions, spaced and connected;
//! * `plan`: the resolved [`RunSpec`] of one run, with its seeds.
//!
//! # File format
//!
//! The complete reference, with every key's meaning, default and limits, is `scenarios/README.md`;
//! the limits themselves are the constants of [`limits`].
//!
//! A scenario file must be a regular file of at most [`limits::MAX_FILE_BYTES`] (1 MiB): anything
//! else (a directory, a FIFO, a device such as `/dev/zero`, an oversized file) is refused by its
//! metadata before it is read, and the read itself stops one byte past the limit.
//!
//! Every table rejects unknown keys, so a typo is an error that names the key rather than a silently
//! ignored setting. After parsing, every value is validated against its documented range; errors name
//! the file, the field, the allowed range and the value found, e.g.
//! `scenarios/x.toml: goal.d_star must be in [0.01, 100] m (got -1)`. NaN and infinities are
//! rejected everywhere. Every bound lies well inside what an `f32` carries, so a value that passes
//! validation survives the `f32` conversions of the wire and the policy input unchanged in kind
//! (finite, and non-zero where it must be).
//!
//! ```toml
//! name = "case1"          # required: 1 to 128 characters, no control characters
//! robots = 3              # required, 2 ..= 1024 (a formation needs at least one pair)
//! duration_s = 60.0       # required, 0.001 ..= 3600: simulated seconds per run
//! dt = 0.05               # optional, default 0.05 s (20 Hz), 0.001 ..= 1; ticks = round(duration_s / dt)
//! seed = 1                # required: base seed of the scenario's runs
//! runs = 1                # optional, default 1, 1 ..= 10000: runs an evaluation of this scenario makes
//!                         # robots * ticks <= 10,000,000 (a run's trajectory is held in memory)
//! model = "../onnx/models/turtlebot3/policy.onnx"  # optional: the team's model when no --model is
//!                         # given (default: the shipped model); relative to the scenario file's directory
//!
//! [goal]                  # required
//! v_star = 0.7            # desired speed \[m/s\], 0 ..= robot.max_wheel_speed ...
//! # v_star_range = [0.05, 0.2]         # ... or drawn uniformly per run, lo <= hi (exactly one of the two)
//! d_star = 2.0            # desired pairwise distance \[m\], 0.01 ..= 100 ...
//! # d_star_choices = [1.0, 1.5, 2.0]   # ... or 1 to 256 distances drawn per run
//! # d_star_range = [0.8, 2.5]          # ... or drawn uniformly per run (exactly one of the three)
//!
//! [heading]               # required: the desired common heading phi*(t)
//! schedule = "constant"   # "constant" | "random" | "ramp" | "sine"
//! phi = 3.76              # constant: phi* = phi (required); angles in -1000 ..= 1000 rad
//! # random:  phi* constant per run, drawn uniformly in [0, 2 pi); takes no parameters
//! # ramp:    phi*(t) = phi0 + omega t            (omega required, -100 ..= 100 rad/s; phi0 default 0)
//! # sine:    phi*(t) = phi0 + amplitude sin(omega t)  (omega required; amplitude default 1; phi0 default 0)
//!
//! [init]                  # optional: initial poses as in the paper
//! disc_radius = 3.0       # positions uniform in a disc of this radius \[m\] centred at the origin, 0.01 ..= 1000;
//!                         # default 3 m for up to 3 robots, 3 * sqrt(robots / 3) m beyond (the paper's density)
//! min_spacing = 0.6       # minimum distance between any two robots \[m\], 2 * robot.body_radius ..= 1000
//!                         # (and <= the sensing range, so the team can start connected)
//!
//! [formation]             # optional: which pairs are formation edges
//! neighbours = "gabriel"  # "all_pairs" | "gabriel"; default all_pairs up to 3 robots, gabriel beyond
//! sensing_range = 10.0    # gabriel only: default lidar.max_range; 0.1 ..= lidar.max_range \[m\]
//! nearest = 2             # gabriel only: nearest robots each robot always holds, 0 ..= 16
//! threshold = 1.3         # gabriel only: witness ratio that makes a pair an edge, 0.05 ..= 4
//! hysteresis = 0.0        # gabriel only: how far below threshold an edge is kept (0: memoryless), 0 ..= threshold - 0.01
//!
//! [lidar]                 # optional; each key defaults to the robot profile's (below)
//! beams = 900             # 8 ..= 900 (the most a scan message carries)
//! max_range = 10.0        # 0.1 ..= 1000 \[m\]; must match the model's (checked before a run starts)
//! noise_std = 0.0         # 0 ..= 10 \[m\]
//! # scan_rate_hz = 5.0    # 0.1 ..= 1000 \[Hz\], <= 1 / dt, whole ticks per scan; absent = every tick
//! fov_deg = 360.0         # 1 ..= 360 \[deg\]: beams outside it return nothing
//! min_range = 0.0         # 0 ..= 1000 \[m\], < max_range: a nearer hit returns nothing
//! dropout = 0.0           # 0 ..= 0.9: probability that a beam returns nothing
//!
//! [robot]                 # optional; each key defaults to the profile's
//! profile = "ideal"       # "ideal" | "pioneer-p3dx" | "turtlebot3-burger" (profile.rs)
//! wheel_separation = 0.331  # 0.01 ..= 10 \[m\]
//! wheel_radius = 0.0975     # 0.001 ..= 10 \[m\]
//! body_radius = 0.25        # 0.01 ..= 10 \[m\]
//! max_wheel_speed = 0.9     # 0.01 ..= 10 \[m/s\]
//! # max_wheel_accel = 2.0   # optional, 0.01 ..= 1000 \[m/s^2\]; absent = unlimited
//! motor_tau = 0.0           # 0 ..= 2 \[s\]: each wheel's first-order lag
//! wheel_speed_noise = 0.0   # 0 ..= 1 \[m/s\]
//! wheel_gain_asymmetry = 0.0  # -0.5 ..= 0.5: right gain minus left gain
//! command_latency = 0       # 0 ..= 20 \[ticks\]
//! spread = 0.0              # 0 ..= 0.5: each robot's parameters drawn within ±spread (relative)
//!
//! [compass]               # optional; the heading each robot receives
//! noise_std_deg = 0.0     # 0 ..= 90 \[deg\]
//! bias_deg = 0.0          # -180 ..= 180 \[deg\]
//!
//! [[agent]]               # optional, repeatable: a per-robot model for mixed teams
//! robot = 1               # < robots, at most one entry per robot
//! model = "models/other.onnx"   # relative paths are relative to the scenario file's directory
//! ```
//!
//! The `[heading]` table is one flat table with a `schedule` key rather than a serde-tagged enum: serde's
//! internally tagged enums do not combine reliably with `deny_unknown_fields`, and the flat form lets
//! validation say precisely which parameter a schedule is missing or does not use.
//!
//! # Randomness of one run
//!
//! The run seed is `splitmix64`-mixed from `(base_seed, run_index)`; a `ChaCha8Rng` seeded with it draws,
//! in this order: d* (only with `d_star_choices` or `d_star_range`), phi* (only with `schedule = "random"`), the positions of
//! robots `0..n` (each uniform in the disc, redrawn until it keeps `min_spacing` from those already
//! placed; the whole team is drawn again, up to a bounded number of times, until it is connected through
//! sensing range, and then taken from lattice sites grown as a connected patch), then the headings of
//! robots `0..n` (uniform over the circle, stored wrapped to (-pi, pi] like every [`Pose`]). The world's noise seed is mixed from the run seed in a separate domain, so it does not
//! depend on how many numbers the draws above consumed. v\* (only with `v_star_range`) is drawn from a
//! generator of its own, seeded from the run seed in another domain, so a scenario without the key
//! draws exactly what it drew before the key existed, and adding it moves no other draw.

use std::f64::consts::TAU;
use std::fmt;
use std::path::{Path, PathBuf};

use formation_proto::files::{FileRefusal, read_bounded};
use formation_proto::{Goal, LidarNoise, LidarSpec, Pose, SimulatedLidar, wrap_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub mod limits;
mod parse;
mod placement;
mod plan;
pub mod profile;
mod validate;

#[cfg(test)]
mod tests;

use self::limits::{Bounds, Num};
pub use self::parse::read_scenario_text;
use self::parse::*;
use self::placement::*;
pub use self::plan::RunSpec;
pub use self::profile::{ProfileSettings, RobotProfile, UnknownProfile};
use self::validate::*;
pub use crate::neighbours::all_pairs;
use crate::neighbours::{GabrielRule, NeighbourRule, connected_within};
use crate::reality::{CompassModel, LidarModel, MotorModel, RealityModels};
use crate::robot::RobotParams;
use crate::seed_mix::splitmix64;
use crate::world::{World, WorldConfig};

/// Default simulation step \[s\]: the LIDAR's 20 Hz.
pub const DEFAULT_DT: f64 = 0.05;
/// Default radius \[m\] of the disc initial positions are drawn from (the paper's 3 m).
pub const DEFAULT_DISC_RADIUS: f64 = 3.0;
/// The default disc radius \[m\] of a team of `n_robots`: the paper's 3 m for up to three robots,
/// grown with `sqrt(n / 3)` beyond, so the team starts at the paper's density.
pub fn default_disc_radius(n_robots: usize) -> f64 {
    if n_robots <= 3 {
        DEFAULT_DISC_RADIUS
    } else {
        DEFAULT_DISC_RADIUS * (n_robots as f64 / 3.0).sqrt()
    }
}

/// Default minimum distance \[m\] between any two initial positions.
pub const DEFAULT_MIN_SPACING: f64 = 0.6;

/// Draws allowed for one robot's position before the placement of the whole team starts over.
const POSITION_ATTEMPTS_PER_ROBOT: usize = 1_000;
/// Restarts of the whole team's placement before falling back to lattice sites.
const PLACEMENT_RESTARTS: usize = 20;

/// Why a scenario could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("cannot read scenario file {}: {source}; check the path", path.display())]
    Read {
        /// The path that was asked for.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The path names something other than a regular file (a directory, a FIFO, a device).
    #[error(
        "scenario {} is {kind}, not a regular file; pass the path of a scenario .toml file \
         (see scenarios/README.md)",
        path.display()
    )]
    NotAFile {
        /// The path that was asked for.
        path: PathBuf,
        /// What it is instead, e.g. `a directory`.
        kind: &'static str,
    },
    /// The file is larger than any scenario can be.
    #[error(
        "scenario {} is {size} bytes, over the {limit}-byte limit of a scenario file; a scenario is \
         a few dozen lines of TOML, so check that the path names the right file",
        path.display(),
        size = FileSize(*.size),
        limit = limits::MAX_FILE_BYTES
    )]
    TooLarge {
        /// The path that was asked for.
        path: PathBuf,
        /// Its size in bytes, or `None` when it grew past the limit while being read.
        size: Option<u64>,
    },
    /// The text is not valid TOML or does not fit the schema (unknown or missing key, wrong type).
    #[error("{origin}: {}", source.to_string().trim_end())]
    Parse {
        /// Where the text came from (usually the file path).
        origin: String,
        /// The parser's error, with line, column and the offending key.
        source: toml::de::Error,
    },
    /// A value parsed but is not acceptable.
    #[error("{origin}: {field} {problem}")]
    Invalid {
        /// Where the text came from (usually the file path).
        origin: String,
        /// Dotted path of the offending key, e.g. `goal.d_star`.
        field: String,
        /// What is wrong with it and, where it helps, what was found.
        problem: String,
    },
}

/// The desired common heading phi*(t) of a run.
///
/// The value is not wrapped (a ramp keeps growing); consumers compare headings with
/// [`wrap_angle`] of the difference.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "schedule", rename_all = "snake_case")]
pub enum HeadingSchedule {
    /// phi*(t) = phi.
    Constant {
        /// The heading \[rad\].
        phi: f64,
    },
    /// phi*(t) = phi0 + omega t (the paper's case 2: omega = 0.1, phi0 = 0).
    Ramp {
        /// Turn rate \[rad/s\].
        omega: f64,
        /// Heading at t = 0 \[rad\].
        phi0: f64,
    },
    /// phi*(t) = phi0 + amplitude sin(omega t) (the paper's case 3: omega = 0.2, amplitude = 1, phi0 = 0).
    Sine {
        /// Angular frequency \[rad/s\].
        omega: f64,
        /// Amplitude \[rad\].
        amplitude: f64,
        /// Mean heading \[rad\].
        phi0: f64,
    },
}

impl HeadingSchedule {
    /// The desired heading \[rad\] at time `t` \[s\], not wrapped.
    pub fn phi_star(&self, t: f64) -> f64 {
        match *self {
            HeadingSchedule::Constant { phi } => phi,
            HeadingSchedule::Ramp { omega, phi0 } => phi0 + omega * t,
            HeadingSchedule::Sine {
                omega,
                amplitude,
                phi0,
            } => phi0 + amplitude * (omega * t).sin(),
        }
    }
}

/// How a scenario chooses the heading schedule of each run.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadingPlan {
    /// Every run uses this schedule.
    Fixed(HeadingSchedule),
    /// Every run holds a constant phi* drawn uniformly in [0, 2 pi) (the paper's data collection and Table I).
    RandomConstant,
}

/// How a scenario chooses the desired distance d* of each run.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DStarPlan {
    /// Every run uses this distance \[m\].
    Fixed(f64),
    /// Each run draws one of these distances \[m\] uniformly.
    Choices(Vec<f64>),
    /// Each run draws its distance \[m\] uniformly from `[min, max]`.
    Range {
        /// Smallest distance.
        min: f64,
        /// Largest distance.
        max: f64,
    },
}

impl DStarPlan {
    /// The distances that bound every draw: the fixed one, each choice, or the range's ends
    /// (what a model's trained d* range must hold).
    pub fn bounds(&self) -> Vec<f64> {
        match self {
            DStarPlan::Fixed(d) => vec![*d],
            DStarPlan::Choices(choices) => choices.clone(),
            DStarPlan::Range { min, max } => vec![*min, *max],
        }
    }
}

/// How a scenario chooses the desired speed v* of each run.
///
/// It serializes untagged: a fixed v* as the bare number it always was (so the record of every
/// scenario without `v_star_range` is unchanged), a range as `{"min": .., "max": ..}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(untagged)]
pub enum VStarPlan {
    /// Every run uses this speed \[m/s\].
    Fixed(f64),
    /// Each run draws its speed \[m/s\] uniformly from `[min, max]` (`min <= max`).
    Range {
        /// Slowest speed.
        min: f64,
        /// Fastest speed.
        max: f64,
    },
}

impl VStarPlan {
    /// The fixed v*, or `None` when v* is drawn per run.
    pub fn fixed(&self) -> Option<f64> {
        match *self {
            VStarPlan::Fixed(v) => Some(v),
            VStarPlan::Range { .. } => None,
        }
    }

    /// The speeds that bound every draw: the fixed one, or the range's ends.
    pub fn bounds(&self) -> Vec<f64> {
        match *self {
            VStarPlan::Fixed(v) => vec![v],
            VStarPlan::Range { min, max } => vec![min, max],
        }
    }

    /// Of [`VStarPlan::bounds`], the speed farthest in ratio from `reference` (a model's
    /// training speed): the v* a note on speeds the model was not trained at must speak of.
    /// The fixed v* itself when there is one; the first end on a tie.
    pub fn farthest_from(&self, reference: f64) -> f64 {
        let distance = |v: f64| (v / reference).ln().abs();
        match *self {
            VStarPlan::Fixed(v) => v,
            VStarPlan::Range { min, max } => {
                if distance(max) > distance(min) {
                    max
                } else {
                    min
                }
            }
        }
    }

    /// The v* of the run whose seed is `run_seed`: the fixed one, or a uniform draw from a
    /// generator of its own (seeded from `run_seed` in a domain of its own), so the draw neither
    /// depends on nor moves any other draw of the run.
    pub(crate) fn draw(&self, run_seed: u64) -> f64 {
        match *self {
            VStarPlan::Fixed(v) => v,
            VStarPlan::Range { min, max } if min >= max => min,
            VStarPlan::Range { min, max } => {
                ChaCha8Rng::seed_from_u64(splitmix64(run_seed ^ plan::V_STAR_DOMAIN))
                    .random_range(min..=max)
            }
        }
    }
}

/// How the initial poses of a run are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialConditions {
    /// Radius \[m\] of the disc, centred at the origin, that positions are drawn from uniformly.
    pub disc_radius: f64,
    /// Minimum distance \[m\] between any two initial positions.
    pub min_spacing: f64,
}

impl Default for InitialConditions {
    fn default() -> Self {
        InitialConditions {
            disc_radius: DEFAULT_DISC_RADIUS,
            min_spacing: DEFAULT_MIN_SPACING,
        }
    }
}

/// A per-robot model override, for teams that mix policies.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentModel {
    /// Index of the robot, `< robots`.
    pub robot: usize,
    /// The ONNX model this robot runs. [`Scenario::from_path`] resolves a relative path against the
    /// scenario file's directory.
    pub model: PathBuf,
}

/// A validated scenario. Build it with [`Scenario::from_path`] or [`Scenario::from_toml_str`].
///
/// It serializes as a record of its resolved settings (for run logs and reports), not as scenario TOML.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scenario {
    name: String,
    n_robots: usize,
    duration_s: f64,
    seed: u64,
    runs: usize,
    v_star: VStarPlan,
    d_star: DStarPlan,
    heading: HeadingPlan,
    init: InitialConditions,
    neighbours: NeighbourRule,
    world: WorldConfig,
    /// The robot profile the file started from (`[robot] profile`; absent when ideal, so the
    /// serialized form of every scenario without one is unchanged).
    #[serde(skip_serializing_if = "RobotProfile::is_ideal")]
    profile: RobotProfile,
    agents: Vec<AgentModel>,
    /// The team's model when the command line names none (`model`; absent: the shipped default,
    /// so the serialized form of every scenario without one is unchanged).
    #[serde(skip_serializing_if = "Option::is_none")]
    model: Option<PathBuf>,
    /// What the file said, for [`Scenario::with_robots`]: the disc radius and the formation
    /// table as given (absent keys take team-size-dependent defaults).
    #[serde(skip)]
    given: Given,
}

/// The team-size-dependent settings as the file gave them.
#[derive(Debug, Clone, Default, PartialEq)]
struct Given {
    disc_radius: Option<f64>,
    min_spacing: Option<f64>,
    formation: FormationToml,
    origin: String,
}

impl Scenario {
    /// Reads and validates the scenario file at `path`. Relative `model` and `[[agent]].model` paths
    /// are resolved against the file's directory.
    ///
    /// Only a regular file of at most [`limits::MAX_FILE_BYTES`] is read; anything else is refused
    /// by its metadata before a byte is read (see [`read_scenario_text`]).
    pub fn from_path(path: &Path) -> Result<Scenario, ScenarioError> {
        Scenario::from_path_overridden(path, &[])
    }

    /// [`Scenario::from_path`] with some keys of the file replaced before validation: each
    /// `(dotted key, value)` of `overrides` (e.g. `("goal.v_star", 0.5)`) sets that key, adding
    /// it or its tables when absent, so an unknown key or a bad value is refused with the same
    /// message as in the file.
    pub fn from_path_overridden(
        path: &Path,
        overrides: &[(String, toml::Value)],
    ) -> Result<Scenario, ScenarioError> {
        let origin = path.display().to_string();
        let mut text = read_scenario_text(path)?;
        if !overrides.is_empty() {
            text = overridden_text(&text, &origin, overrides)?;
        }
        let mut scenario = Scenario::from_toml_str(&text, &origin)?;
        let base = path.parent().unwrap_or_else(|| Path::new(""));
        for model in scenario
            .agents
            .iter_mut()
            .map(|agent| &mut agent.model)
            .chain(scenario.model.as_mut())
        {
            if model.is_relative() {
                *model = base.join(&*model);
            }
        }
        Ok(scenario)
    }

    /// Parses and validates scenario text; `origin` names its source in error messages.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
        let raw: ScenarioToml = toml::from_str(text).map_err(|source| ScenarioError::Parse {
            origin: origin.to_string(),
            source,
        })?;
        raw.validate(&Checker { origin })
    }

    /// The scenario's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Team size.
    pub fn n_robots(&self) -> usize {
        self.n_robots
    }

    /// How many runs an evaluation of this scenario makes by default.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// The base seed of this scenario's runs.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Simulated duration of each run \[s\].
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// How v* is chosen per run (each run's own is [`RunSpec::v_star`]).
    pub fn v_star(&self) -> VStarPlan {
        self.v_star
    }

    /// How d* is chosen per run.
    pub fn d_star(&self) -> &DStarPlan {
        &self.d_star
    }

    /// How the heading schedule is chosen per run.
    pub fn heading(&self) -> &HeadingPlan {
        &self.heading
    }

    /// How initial poses are drawn.
    pub fn initial_conditions(&self) -> &InitialConditions {
        &self.init
    }

    /// Robot, sensor and time-step settings shared by all runs.
    pub fn world_config(&self) -> &WorldConfig {
        &self.world
    }

    /// The robot profile the file's `[robot]`, `[lidar]` and `[compass]` values start from.
    pub fn profile(&self) -> RobotProfile {
        self.profile
    }

    /// Per-robot model overrides, each with `robot < n_robots()` and at most one per robot.
    pub fn agent_models(&self) -> &[AgentModel] {
        &self.agents
    }

    /// The model the scenario names for its team (`model`), used where the command line names
    /// none; `None`: the shipped default.
    pub fn model(&self) -> Option<&Path> {
        self.model.as_deref()
    }

    /// The neighbour rule of the formation.
    pub fn neighbours(&self) -> &NeighbourRule {
        &self.neighbours
    }

    /// The same scenario for a team of `robots`: every setting the file gave is kept, and the
    /// team-size-dependent defaults (the disc radius, the neighbour rule) are those of the new
    /// size. Per-robot models (`[[agent]]`) must name robots of the new team.
    pub fn with_robots(&self, robots: usize) -> Result<Scenario, ScenarioError> {
        let check = Checker {
            origin: &self.given.origin,
        };
        let robots = check.count(
            "robots",
            robots,
            limits::MIN_ROBOTS,
            limits::MAX_ROBOTS,
            ", a formation needs at least one pair",
        )?;
        let ticks = (self.duration_s / self.world.dt).round() as u64;
        check_robot_ticks(&check, robots, ticks, self.world.dt)?;
        let neighbours = validate_formation(&check, &self.given.formation, robots, &self.world)?;
        let init = validate_init(
            &check,
            InitToml {
                disc_radius: self.given.disc_radius,
                min_spacing: self.given.min_spacing,
            },
            robots,
            &self.world.robot,
            sensing_range(&neighbours, &self.world),
        )?;
        if let Some((k, agent)) = self
            .agents
            .iter()
            .enumerate()
            .find(|(_, a)| a.robot >= robots)
        {
            return Err(check.invalid(
                format_args!("agent[{k}].robot"),
                format_args!("must be < robots ({robots}) (got {})", agent.robot),
            ));
        }
        Ok(Scenario {
            n_robots: robots,
            init,
            neighbours,
            ..self.clone()
        })
    }

    /// The same scenario with runs of `duration_s` simulated seconds (within `duration_s`'s
    /// bounds, and robots × ticks within the trajectory limit); every other setting is kept.
    pub fn with_duration(&self, duration_s: f64) -> Result<Scenario, ScenarioError> {
        let check = Checker {
            origin: &self.given.origin,
        };
        let duration_s = check.bounded("duration_s", duration_s, limits::DURATION_S)?;
        let ticks = (duration_s / self.world.dt).round() as u64;
        check_robot_ticks(&check, self.n_robots, ticks, self.world.dt)?;
        Ok(Scenario {
            duration_s,
            ..self.clone()
        })
    }
}

/// Scenario text with `overrides` (dotted keys) set in its tables.
fn overridden_text(
    text: &str,
    origin: &str,
    overrides: &[(String, toml::Value)],
) -> Result<String, ScenarioError> {
    let parse_error = |source| ScenarioError::Parse {
        origin: origin.to_owned(),
        source,
    };
    let mut root: toml::Table = toml::from_str(text).map_err(parse_error)?;
    for (key, value) in overrides {
        let invalid = |problem: String| ScenarioError::Invalid {
            origin: origin.to_owned(),
            field: key.clone(),
            problem,
        };
        let parts: Vec<&str> = key.split('.').collect();
        let Some((last, tables)) = parts.split_last() else {
            return Err(invalid("is an empty key".to_owned()));
        };
        if parts.iter().any(|p| p.is_empty()) {
            return Err(invalid(
                "has an empty part; write dotted keys such as `goal.v_star`".to_owned(),
            ));
        }
        let mut table = &mut root;
        for (depth, part) in tables.iter().enumerate() {
            let entry = table
                .entry((*part).to_owned())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            table = entry.as_table_mut().ok_or_else(|| {
                invalid(format!(
                    "cannot be set: `{}` is a value, not a table",
                    parts[..=depth].join(".")
                ))
            })?;
        }
        table.insert((*last).to_owned(), value.clone());
    }
    toml::to_string(&root).map_err(|e| ScenarioError::Invalid {
        origin: origin.to_owned(),
        field: "overrides".to_owned(),
        problem: format!("cannot be written back as TOML: {e}"),
    })
}
