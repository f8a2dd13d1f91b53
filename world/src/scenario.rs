//! Scenarios: what a run is asked to do, read from TOML, and the fully resolved [`RunSpec`] of one run.
//!
//! A [`Scenario`] describes a family of runs (team size, goal, heading schedule, how initial poses are
//! drawn, sensor and robot settings). [`Scenario::run_spec`] turns it into the [`RunSpec`] of run `i`,
//! drawing everything random from a seed derived from `(base_seed, i)` alone, so any run can be replayed
//! on its own, bit for bit, in any order and on any machine.
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
//!
//! [goal]                  # required
//! v_star = 0.7            # desired speed \[m/s\], 0 ..= robot.max_wheel_speed
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
//! [lidar]                 # optional; each key defaults to LidarSpec::default()
//! beams = 900             # 8 ..= 900 (the most a scan message carries)
//! max_range = 10.0        # 0.1 ..= 1000 \[m\]; must match the model's (checked before a run starts)
//! noise_std = 0.0         # 0 ..= 10 \[m\]
//!
//! [robot]                 # optional; each key defaults to RobotParams::default()
//! wheel_separation = 0.331  # 0.01 ..= 10 \[m\]
//! wheel_radius = 0.0975     # 0.001 ..= 10 \[m\]
//! body_radius = 0.25        # 0.01 ..= 10 \[m\]
//! max_wheel_speed = 0.9     # 0.01 ..= 10 \[m/s\]
//! # max_wheel_accel = 2.0   # optional, 0.01 ..= 1000 \[m/s^2\]; absent = unlimited
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
//! depend on how many numbers the draws above consumed.

use std::f64::consts::TAU;
use std::fmt;
use std::path::{Path, PathBuf};

use formation_proto::files::{FileRefusal, read_bounded};
use formation_proto::{Goal, LidarSpec, Pose, wrap_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use self::limits::{Bounds, Num};
pub use crate::neighbours::all_pairs;
use crate::neighbours::{GabrielRule, NeighbourRule, connected_within};
use crate::robot::RobotParams;
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
    v_star: f64,
    d_star: DStarPlan,
    heading: HeadingPlan,
    init: InitialConditions,
    neighbours: NeighbourRule,
    world: WorldConfig,
    agents: Vec<AgentModel>,
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

/// Everything one run needs, resolved: no randomness is left except the world's sensor noise, which
/// is fixed by `noise_seed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    /// Index of the run within its scenario.
    pub index: usize,
    /// The run's own seed, mixed from the base seed and the index.
    pub seed: u64,
    /// Team size.
    pub n_robots: usize,
    /// Desired pairwise distance \[m\].
    pub d_star: f64,
    /// Desired speed \[m/s\].
    pub v_star: f64,
    /// Desired heading over time.
    pub heading: HeadingSchedule,
    /// Simulated duration \[s\].
    pub duration_s: f64,
    /// Robot, sensor and time-step settings of the world.
    pub world: WorldConfig,
    /// Initial pose of each robot.
    pub initial: Vec<Pose>,
    /// Seed of the world's sensor-noise generator.
    pub noise_seed: u64,
    /// Which pairs are formation edges: the expert holds them at d* and the metrics score them,
    /// recomputed every tick from the robots' positions.
    pub neighbours: NeighbourRule,
}

impl RunSpec {
    /// Number of control ticks: `round(duration_s / dt)`.
    pub fn ticks(&self) -> u64 {
        (self.duration_s / self.world.dt).round() as u64
    }

    /// The goal every robot is given at time `t` \[s\].
    pub fn goal_at(&self, t: f64) -> Goal {
        Goal {
            phi_star: self.heading.phi_star(t),
            d_star: self.d_star,
            v_star: self.v_star,
        }
    }

    /// A fresh world in this run's initial state.
    pub fn make_world(&self) -> World {
        World::new(self.world, self.initial.clone(), self.noise_seed)
    }
}

impl Scenario {
    /// Reads and validates the scenario file at `path`. Relative `[[agent]].model` paths are resolved
    /// against the file's directory.
    ///
    /// Only a regular file of at most [`limits::MAX_FILE_BYTES`] is read; anything else is refused
    /// by its metadata before a byte is read (see [`read_scenario_text`]).
    pub fn from_path(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = read_scenario_text(path)?;
        let mut scenario = Scenario::from_toml_str(&text, &path.display().to_string())?;
        let base = path.parent().unwrap_or_else(|| Path::new(""));
        for agent in &mut scenario.agents {
            if agent.model.is_relative() {
                agent.model = base.join(&agent.model);
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

    /// Desired speed \[m/s\].
    pub fn v_star(&self) -> f64 {
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

    /// Per-robot model overrides, each with `robot < n_robots()` and at most one per robot.
    pub fn agent_models(&self) -> &[AgentModel] {
        &self.agents
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

    /// The resolved spec of run `run_index`, a pure function of `(self, base_seed, run_index)`.
    pub fn run_spec(&self, base_seed: u64, run_index: usize) -> RunSpec {
        let seed = run_seed(base_seed, run_index);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let d_star = match &self.d_star {
            DStarPlan::Fixed(d) => *d,
            DStarPlan::Choices(choices) => choices[rng.random_range(0..choices.len())],
            DStarPlan::Range { min, max } => rng.random_range(*min..=*max),
        };
        let heading = match self.heading {
            HeadingPlan::Fixed(schedule) => schedule,
            HeadingPlan::RandomConstant => HeadingSchedule::Constant {
                phi: rng.random_range(0.0..TAU),
            },
        };
        let range = sensing_range(&self.neighbours, &self.world);
        let positions = place_robots(&mut rng, self.n_robots, &self.init, range);
        // All positions are drawn before any heading.
        let initial = positions
            .into_iter()
            .map(|(x, y)| Pose {
                x,
                y,
                theta: wrap_angle(rng.random_range(0.0..TAU)),
            })
            .collect();
        RunSpec {
            index: run_index,
            seed,
            n_robots: self.n_robots,
            d_star,
            v_star: self.v_star,
            heading,
            duration_s: self.duration_s,
            world: self.world,
            initial,
            noise_seed: splitmix64(seed ^ NOISE_DOMAIN),
            neighbours: self.neighbours,
        }
    }
}

/// The text of the scenario file at `path`, read only if it is a regular file of at most
/// [`limits::MAX_FILE_BYTES`].
///
/// The file's metadata is checked before it is opened (so a FIFO is never opened and `/dev/zero`
/// never read), checked again on the opened file (it may have been replaced in between), and the
/// read stops one byte past the limit whatever the metadata said.
pub fn read_scenario_text(path: &Path) -> Result<String, ScenarioError> {
    let bytes = read_bounded(path, limits::MAX_FILE_BYTES).map_err(|refusal| {
        let path = path.to_path_buf();
        match refusal {
            FileRefusal::NotAFile { kind } => ScenarioError::NotAFile { path, kind },
            FileRefusal::TooLarge { size } => ScenarioError::TooLarge { path, size },
            FileRefusal::Io(source) => ScenarioError::Read { path, source },
        }
    })?;
    String::from_utf8(bytes).map_err(|e| ScenarioError::Read {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
    })
}

/// A byte count in messages: the number, or "more than the limit" when it is not known.
struct FileSize(Option<u64>);

impl fmt::Display for FileSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(size) => write!(f, "{size}"),
            None => write!(f, "more than {}", limits::MAX_FILE_BYTES),
        }
    }
}

/// The documented limits of every scenario value (the reference is `scenarios/README.md`).
///
/// They keep a scenario's cost bounded (memory and time grow with robots, ticks and runs) and its
/// numbers inside what the rest of the system carries: every real-valued bound is far inside the
/// `f32` range, so a value that passes stays finite and non-zero through the `f32` conversions of
/// the wire (LIDAR ranges) and the policy input (`d*`).
pub mod limits {
    use std::fmt;

    /// Largest scenario file that is read \[bytes\]: 1 MiB (the shipped ones are under 1 KiB).
    pub const MAX_FILE_BYTES: u64 = 1 << 20;
    /// Longest scenario name \[characters\]; it is echoed into logs, stdout and `summary.json`.
    pub const MAX_NAME_CHARS: usize = 128;
    /// Fewest robots: a formation needs at least one pair.
    pub const MIN_ROBOTS: usize = 2;
    /// Most robots. The runtime starts one OS process per robot and every tick ray-casts every
    /// robot's LIDAR against every other robot and scores all `n (n - 1) / 2` pairs.
    pub const MAX_ROBOTS: usize = 1024;
    /// Most runs of one evaluation (the scenario's `runs` and the `--runs` flag).
    pub const MAX_RUNS: usize = 10_000;
    /// Most `robots x ticks` of one run: a run's trajectory (about 40 bytes per robot and tick) is
    /// held in memory and written as a log, so this caps it near 400 MB.
    pub const MAX_ROBOT_TICKS: u64 = 10_000_000;
    /// Most LIDAR beams: what a scan message carries ([`formation_proto::wire::MAX_BEAMS`]).
    pub const MAX_BEAMS: usize = formation_proto::wire::MAX_BEAMS;
    /// Most `formation.nearest`.
    pub const MAX_NEAREST: usize = 16;
    /// `formation.threshold`: at most 1, so every witness lies within sensing range.
    pub const GABRIEL_THRESHOLD: Bounds = bounds(0.05, 4.0, "");
    /// Fewest LIDAR beams.
    pub const MIN_BEAMS: usize = 8;
    /// Most entries of `goal.d_star_choices`.
    pub const MAX_D_STAR_CHOICES: usize = 256;

    /// An inclusive range `[min, max]` of a real-valued setting, with its unit for messages.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Bounds {
        /// Smallest allowed value.
        pub min: f64,
        /// Largest allowed value.
        pub max: f64,
        /// Unit, e.g. `m`, `s`, `rad/s`.
        pub unit: &'static str,
    }

    impl fmt::Display for Bounds {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "[{}, {}] {}", Num(self.min), Num(self.max), self.unit)
        }
    }

    const fn bounds(min: f64, max: f64, unit: &'static str) -> Bounds {
        Bounds { min, max, unit }
    }

    /// `duration_s`: simulated seconds per run (at most an hour).
    pub const DURATION_S: Bounds = bounds(1e-3, 3600.0, "s");
    /// `dt`: the simulation step (1 kHz to 1 Hz).
    pub const DT: Bounds = bounds(1e-3, 1.0, "s");
    /// `goal.d_star` and each of `goal.d_star_choices`.
    pub const D_STAR: Bounds = bounds(0.01, 100.0, "m");
    /// `heading.phi`, `heading.phi0` and `heading.amplitude`.
    pub const ANGLE: Bounds = bounds(-1000.0, 1000.0, "rad");
    /// `heading.omega`: the heading's turn rate or angular frequency.
    pub const HEADING_RATE: Bounds = bounds(-100.0, 100.0, "rad/s");
    /// `init.disc_radius`.
    pub const DISC_RADIUS: Bounds = bounds(0.01, 1000.0, "m");
    /// `init.min_spacing` (and at least `2 * robot.body_radius`).
    pub const MIN_SPACING: Bounds = bounds(0.02, 1000.0, "m");
    /// `lidar.max_range`.
    pub const MAX_RANGE: Bounds = bounds(0.1, 1000.0, "m");
    /// `lidar.noise_std`.
    pub const NOISE_STD: Bounds = bounds(0.0, 10.0, "m");
    /// `robot.wheel_separation`.
    pub const WHEEL_SEPARATION: Bounds = bounds(0.01, 10.0, "m");
    /// `robot.wheel_radius`.
    pub const WHEEL_RADIUS: Bounds = bounds(0.001, 10.0, "m");
    /// `robot.body_radius`.
    pub const BODY_RADIUS: Bounds = bounds(0.01, 10.0, "m");
    /// `robot.max_wheel_speed` (`goal.v_star` must lie in `[0, max_wheel_speed]`).
    pub const MAX_WHEEL_SPEED: Bounds = bounds(0.01, 10.0, "m/s");
    /// `robot.max_wheel_accel`.
    pub const MAX_WHEEL_ACCEL: Bounds = bounds(0.01, 1000.0, "m/s^2");

    /// Every real-valued bound, by the keys it applies to (for tests and documentation).
    pub const ALL: [(&str, Bounds); 14] = [
        ("duration_s", DURATION_S),
        ("dt", DT),
        (
            "goal.d_star, goal.d_star_choices, goal.d_star_range",
            D_STAR,
        ),
        ("heading.phi, heading.phi0, heading.amplitude", ANGLE),
        ("heading.omega", HEADING_RATE),
        ("init.disc_radius", DISC_RADIUS),
        ("init.min_spacing", MIN_SPACING),
        ("lidar.max_range", MAX_RANGE),
        ("lidar.noise_std", NOISE_STD),
        ("robot.wheel_separation", WHEEL_SEPARATION),
        ("robot.wheel_radius", WHEEL_RADIUS),
        ("robot.body_radius", BODY_RADIUS),
        ("robot.max_wheel_speed", MAX_WHEEL_SPEED),
        ("robot.max_wheel_accel", MAX_WHEEL_ACCEL),
    ];

    /// A number in messages: plain for everyday magnitudes, scientific for huge or tiny ones (so
    /// `1e308` is not printed as 309 digits).
    pub(crate) struct Num(pub f64);

    impl fmt::Display for Num {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            let x = self.0;
            let magnitude = x.abs();
            if x.is_finite() && x != 0.0 && !(1e-4..1e7).contains(&magnitude) {
                write!(f, "{x:e}")
            } else {
                write!(f, "{x}")
            }
        }
    }
}

/// How far a robot senses its team mates \[m\]: the Gabriel rule's sensing range, else the
/// LIDAR's range.
fn sensing_range(rule: &NeighbourRule, world: &WorldConfig) -> f64 {
    match rule {
        NeighbourRule::AllPairs => world.lidar.max_range,
        NeighbourRule::Gabriel(g) => g.sensing_range,
    }
}

/// Domain-separation constants so the run seed and the noise seed are independent streams.
const RUN_DOMAIN: u64 = 0x5EED_0F0F_2A2A_0001;
const NOISE_DOMAIN: u64 = 0xA5A5_5A5A_C3C3_3C3C;

/// The seed of run `run_index` of a scenario with `base_seed`.
fn run_seed(base_seed: u64, run_index: usize) -> u64 {
    splitmix64(splitmix64(base_seed ^ RUN_DOMAIN) ^ splitmix64(run_index as u64))
}

/// SplitMix64's output function (Steele, Lea & Flood 2014) applied to `x + golden gamma`: a bijective,
/// well-avalanched mix of 64 bits.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Positions of `n` robots uniform in the disc, each at least `min_spacing` from the others, the
/// team connected through `range` (every robot reaches every other through robots at most `range`
/// apart).
///
/// Sequential rejection: each robot is redrawn until it keeps its distance from those already placed;
/// if one cannot be placed in [`POSITION_ATTEMPTS_PER_ROBOT`] draws, or the team is not connected, the
/// whole team starts over, at most [`PLACEMENT_RESTARTS`] times. For a crowded or a wide disc where this
/// keeps failing (validation guarantees that a spacing-`min_spacing` hexagonal lattice has `n` sites in
/// the disc, and that `min_spacing <= range`), `n` lattice sites are grown at random as a connected patch
/// instead, so the function always ends. The paper's settings accept nearly every draw, and a team
/// that fits in a disc of diameter `range` is always connected, so the paper's runs draw exactly what
/// they drew before teams had to be connected.
fn place_robots(
    rng: &mut ChaCha8Rng,
    n: usize,
    init: &InitialConditions,
    range: f64,
) -> Vec<(f64, f64)> {
    let spacing_sq = init.min_spacing * init.min_spacing;
    let mut placed: Vec<(f64, f64)> = Vec::with_capacity(n);
    for _ in 0..PLACEMENT_RESTARTS {
        placed.clear();
        'robots: for _ in 0..n {
            for _ in 0..POSITION_ATTEMPTS_PER_ROBOT {
                let r = init.disc_radius * rng.random::<f64>().sqrt();
                let angle = rng.random_range(0.0..TAU);
                let candidate = (r * angle.cos(), r * angle.sin());
                let clear = placed.iter().all(|&(x, y)| {
                    let (dx, dy) = (candidate.0 - x, candidate.1 - y);
                    dx * dx + dy * dy >= spacing_sq
                });
                if clear {
                    placed.push(candidate);
                    continue 'robots;
                }
            }
            break;
        }
        if placed.len() == n && connected_within(&placed, range) {
            return placed;
        }
    }
    connected_lattice_patch(rng, n, init, range)
}

/// `n` sites of the spacing-`min_spacing` hexagonal lattice in the disc, grown from a random site by
/// adding random sites within `range` of the patch, so the patch is connected through `range`.
fn connected_lattice_patch(
    rng: &mut ChaCha8Rng,
    n: usize,
    init: &InitialConditions,
    range: f64,
) -> Vec<(f64, f64)> {
    let mut free = lattice_sites(init.disc_radius, init.min_spacing, usize::MAX);
    let mut placed: Vec<(f64, f64)> = Vec::with_capacity(n);
    let range_sq = range * range;
    while placed.len() < n && !free.is_empty() {
        let reachable: Vec<usize> = (0..free.len())
            .filter(|&s| {
                placed.is_empty()
                    || placed.iter().any(|&(x, y)| {
                        let (dx, dy) = (free[s].0 - x, free[s].1 - y);
                        dx * dx + dy * dy <= range_sq
                    })
            })
            .collect();
        // A lattice in a disc is connected at its spacing, which validation keeps <= range; should
        // it not be, any free site keeps the function total.
        let pick = if reachable.is_empty() {
            rng.random_range(0..free.len())
        } else {
            reachable[rng.random_range(0..reachable.len())]
        };
        placed.push(free.swap_remove(pick));
    }
    placed
}

/// Sites of a hexagonal lattice with spacing `spacing`, centred at the origin, inside a disc of
/// `radius`; stops after `limit` sites.
fn lattice_sites(radius: f64, spacing: f64, limit: usize) -> Vec<(f64, f64)> {
    let row_height = spacing * 3f64.sqrt() / 2.0;
    let rows = (radius / row_height).floor() as i64;
    let columns = (radius / spacing).ceil() as i64 + 1;
    let mut sites = Vec::new();
    for row in -rows..=rows {
        let y = row as f64 * row_height;
        let shift = if row.rem_euclid(2) == 1 { 0.5 } else { 0.0 };
        for column in -columns..=columns {
            let x = (column as f64 + shift) * spacing;
            if x * x + y * y <= radius * radius {
                sites.push((x, y));
                if sites.len() >= limit {
                    return sites;
                }
            }
        }
    }
    sites
}

// ---------------------------------------------------------------------------------------------
// The TOML schema, as parsed before validation.

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioToml {
    name: String,
    robots: usize,
    duration_s: f64,
    #[serde(default = "default_dt")]
    dt: f64,
    seed: u64,
    #[serde(default = "default_runs")]
    runs: usize,
    goal: GoalToml,
    heading: HeadingToml,
    #[serde(default)]
    init: InitToml,
    #[serde(default)]
    formation: FormationToml,
    #[serde(default)]
    lidar: LidarToml,
    #[serde(default)]
    robot: RobotParams,
    #[serde(default)]
    agent: Vec<AgentModel>,
}

fn default_dt() -> f64 {
    DEFAULT_DT
}

fn default_runs() -> usize {
    1
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct InitToml {
    disc_radius: Option<f64>,
    min_spacing: Option<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct FormationToml {
    neighbours: Option<String>,
    sensing_range: Option<f64>,
    nearest: Option<usize>,
    threshold: Option<f64>,
    hysteresis: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GoalToml {
    v_star: f64,
    d_star: Option<f64>,
    d_star_choices: Option<Vec<f64>>,
    d_star_range: Option<[f64; 2]>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
enum ScheduleKind {
    Constant,
    Random,
    Ramp,
    Sine,
}

impl ScheduleKind {
    fn as_str(self) -> &'static str {
        match self {
            ScheduleKind::Constant => "constant",
            ScheduleKind::Random => "random",
            ScheduleKind::Ramp => "ramp",
            ScheduleKind::Sine => "sine",
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct HeadingToml {
    schedule: ScheduleKind,
    phi: Option<f64>,
    omega: Option<f64>,
    amplitude: Option<f64>,
    phi0: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct LidarToml {
    beams: usize,
    max_range: f64,
    noise_std: f64,
}

impl Default for LidarToml {
    fn default() -> Self {
        let spec = LidarSpec::default();
        LidarToml {
            beams: spec.beams,
            max_range: spec.max_range,
            noise_std: spec.noise_std,
        }
    }
}

/// Builds [`ScenarioError::Invalid`] values that name the origin.
struct Checker<'a> {
    origin: &'a str,
}

impl Checker<'_> {
    fn invalid(&self, field: impl fmt::Display, problem: impl fmt::Display) -> ScenarioError {
        ScenarioError::Invalid {
            origin: self.origin.to_string(),
            field: field.to_string(),
            problem: problem.to_string(),
        }
    }

    /// `value`, if it is a finite number within `bounds`.
    fn bounded(&self, field: &str, value: f64, bounds: Bounds) -> Result<f64, ScenarioError> {
        if !value.is_finite() {
            return Err(self.invalid(
                field,
                format_args!("must be a finite number in {bounds} (got {})", Num(value)),
            ));
        }
        if !(bounds.min..=bounds.max).contains(&value) {
            return Err(self.invalid(
                field,
                format_args!("must be in {bounds} (got {})", Num(value)),
            ));
        }
        Ok(value)
    }

    /// `value`, if it is a whole number in `min..=max`; `why` explains the bounds.
    fn count(
        &self,
        field: &str,
        value: usize,
        min: usize,
        max: usize,
        why: &str,
    ) -> Result<usize, ScenarioError> {
        if (min..=max).contains(&value) {
            Ok(value)
        } else {
            Err(self.invalid(
                field,
                format_args!("must be in [{min}, {max}]{why} (got {value})"),
            ))
        }
    }
}

impl ScenarioToml {
    fn validate(self, check: &Checker<'_>) -> Result<Scenario, ScenarioError> {
        let name = validate_name(check, self.name)?;
        let robots = check.count(
            "robots",
            self.robots,
            limits::MIN_ROBOTS,
            limits::MAX_ROBOTS,
            ", a formation needs at least one pair",
        )?;
        let duration_s = check.bounded("duration_s", self.duration_s, limits::DURATION_S)?;
        let dt = check.bounded("dt", self.dt, limits::DT)?;
        if dt > duration_s {
            return Err(check.invalid(
                "dt",
                format_args!(
                    "must be <= duration_s ({duration_s}) so a run has at least one tick (got {dt})"
                ),
            ));
        }
        let steps = duration_s / dt;
        if (steps - steps.round()).abs() > 1e-6 {
            return Err(check.invalid(
                "dt",
                format_args!(
                    "must divide duration_s ({duration_s}) into whole steps (got {dt}: {steps:.3} steps)"
                ),
            ));
        }
        check_robot_ticks(check, robots, steps.round() as u64, dt)?;
        let runs = check.count("runs", self.runs, 1, limits::MAX_RUNS, "")?;

        let robot = validate_robot(check, self.robot)?;
        let lidar = LidarSpec {
            beams: check.count(
                "lidar.beams",
                self.lidar.beams,
                limits::MIN_BEAMS,
                limits::MAX_BEAMS,
                " (a scan message carries at most 900 ranges)",
            )?,
            max_range: check.bounded("lidar.max_range", self.lidar.max_range, limits::MAX_RANGE)?,
            noise_std: check.bounded("lidar.noise_std", self.lidar.noise_std, limits::NOISE_STD)?,
        };

        let v_star = check.bounded(
            "goal.v_star",
            self.goal.v_star,
            Bounds {
                min: 0.0,
                ..limits::MAX_WHEEL_SPEED
            },
        )?;
        if v_star > robot.max_wheel_speed {
            return Err(check.invalid(
                "goal.v_star",
                format_args!(
                    "must be <= robot.max_wheel_speed ({}) or the robots cannot reach it (got {v_star})",
                    robot.max_wheel_speed
                ),
            ));
        }
        const ONE_OF: &str = "give exactly one of goal.d_star (fixed), goal.d_star_choices (one \
                              of a list per run) and goal.d_star_range (uniform per run)";
        let given = [
            self.goal.d_star.is_some(),
            self.goal.d_star_choices.is_some(),
            self.goal.d_star_range.is_some(),
        ];
        let d_star = match (
            self.goal.d_star,
            self.goal.d_star_choices,
            self.goal.d_star_range,
        ) {
            _ if given.iter().filter(|&&g| g).count() > 1 => {
                return Err(check.invalid(
                    "goal.d_star",
                    format_args!("is given more than one way; {ONE_OF}"),
                ));
            }
            (Some(d), None, None) => {
                DStarPlan::Fixed(check.bounded("goal.d_star", d, limits::D_STAR)?)
            }
            (None, Some(choices), None) => {
                if choices.is_empty() {
                    return Err(check.invalid("goal.d_star_choices", "must not be empty"));
                }
                if choices.len() > limits::MAX_D_STAR_CHOICES {
                    return Err(check.invalid(
                        "goal.d_star_choices",
                        format_args!(
                            "has {} entries, more than the {} allowed",
                            choices.len(),
                            limits::MAX_D_STAR_CHOICES
                        ),
                    ));
                }
                for (k, &d) in choices.iter().enumerate() {
                    check.bounded(&format!("goal.d_star_choices[{k}]"), d, limits::D_STAR)?;
                }
                DStarPlan::Choices(choices)
            }
            (None, None, Some([min, max])) => {
                let min = check.bounded("goal.d_star_range[0]", min, limits::D_STAR)?;
                let max = check.bounded("goal.d_star_range[1]", max, limits::D_STAR)?;
                if min >= max {
                    return Err(check.invalid(
                        "goal.d_star_range",
                        format_args!(
                            "must be [smallest, largest] with smallest < largest (got [{min}, \
                             {max}]); for one distance use goal.d_star"
                        ),
                    ));
                }
                DStarPlan::Range { min, max }
            }
            _ => {
                return Err(check.invalid("goal.d_star", format_args!("is missing; {ONE_OF}")));
            }
        };

        let heading = validate_heading(check, &self.heading)?;
        let world = WorldConfig { robot, lidar, dt };
        let neighbours = validate_formation(check, &self.formation, robots, &world)?;
        let init = validate_init(
            check,
            self.init,
            robots,
            &robot,
            sensing_range(&neighbours, &world),
        )?;

        let mut agents = self.agent;
        let mut seen = vec![false; robots];
        for (k, agent) in agents.iter_mut().enumerate() {
            if agent.robot >= robots {
                return Err(check.invalid(
                    format_args!("agent[{k}].robot"),
                    format_args!("must be < robots ({robots}) (got {})", agent.robot),
                ));
            }
            if std::mem::replace(&mut seen[agent.robot], true) {
                return Err(check.invalid(
                    format_args!("agent[{k}].robot"),
                    format_args!("gives robot {} a model a second time", agent.robot),
                ));
            }
            if agent.model.as_os_str().is_empty() {
                return Err(check.invalid(format_args!("agent[{k}].model"), "must not be empty"));
            }
        }

        Ok(Scenario {
            name,
            n_robots: robots,
            duration_s,
            seed: self.seed,
            runs,
            v_star,
            d_star,
            heading,
            init,
            neighbours,
            world,
            agents,
            given: Given {
                disc_radius: self.init.disc_radius,
                min_spacing: self.init.min_spacing,
                formation: self.formation,
                origin: check.origin.to_string(),
            },
        })
    }
}

/// The name, if it is 1 to [`limits::MAX_NAME_CHARS`] characters without control characters.
fn validate_name(check: &Checker<'_>, name: String) -> Result<String, ScenarioError> {
    if name.trim().is_empty() {
        return Err(check.invalid("name", "must not be empty"));
    }
    let chars = name.chars().count();
    if chars > limits::MAX_NAME_CHARS {
        return Err(check.invalid(
            "name",
            format_args!(
                "must be at most {} characters (got {chars}); it is echoed into logs and reports",
                limits::MAX_NAME_CHARS
            ),
        ));
    }
    if let Some(bad) = name.chars().find(|c| c.is_control()) {
        return Err(check.invalid(
            "name",
            format_args!(
                "must be printable, without control characters (found {:?})",
                bad
            ),
        ));
    }
    Ok(name)
}

fn validate_robot(check: &Checker<'_>, robot: RobotParams) -> Result<RobotParams, ScenarioError> {
    check.bounded(
        "robot.wheel_separation",
        robot.wheel_separation,
        limits::WHEEL_SEPARATION,
    )?;
    check.bounded(
        "robot.wheel_radius",
        robot.wheel_radius,
        limits::WHEEL_RADIUS,
    )?;
    check.bounded("robot.body_radius", robot.body_radius, limits::BODY_RADIUS)?;
    check.bounded(
        "robot.max_wheel_speed",
        robot.max_wheel_speed,
        limits::MAX_WHEEL_SPEED,
    )?;
    if let Some(accel) = robot.max_wheel_accel {
        check.bounded("robot.max_wheel_accel", accel, limits::MAX_WHEEL_ACCEL)?;
    }
    Ok(robot)
}

fn validate_heading(
    check: &Checker<'_>,
    heading: &HeadingToml,
) -> Result<HeadingPlan, ScenarioError> {
    let kind = heading.schedule;
    let params = [
        (
            "phi",
            heading.phi,
            kind == ScheduleKind::Constant,
            limits::ANGLE,
        ),
        (
            "omega",
            heading.omega,
            matches!(kind, ScheduleKind::Ramp | ScheduleKind::Sine),
            limits::HEADING_RATE,
        ),
        (
            "amplitude",
            heading.amplitude,
            kind == ScheduleKind::Sine,
            limits::ANGLE,
        ),
        (
            "phi0",
            heading.phi0,
            matches!(kind, ScheduleKind::Ramp | ScheduleKind::Sine),
            limits::ANGLE,
        ),
    ];
    for (name, value, used, bounds) in params {
        match value {
            Some(_) if !used => {
                return Err(check.invalid(
                    format_args!("heading.{name}"),
                    format_args!(
                        "is not a parameter of schedule \"{}\"; remove it",
                        kind.as_str()
                    ),
                ));
            }
            Some(v) => {
                check.bounded(&format!("heading.{name}"), v, bounds)?;
            }
            None => {}
        }
    }
    let required = |name: &str, value: Option<f64>| {
        value.ok_or_else(|| {
            check.invalid(
                format_args!("heading.{name}"),
                format_args!("is required by schedule \"{}\"", kind.as_str()),
            )
        })
    };
    Ok(match kind {
        ScheduleKind::Constant => HeadingPlan::Fixed(HeadingSchedule::Constant {
            phi: required("phi", heading.phi)?,
        }),
        ScheduleKind::Random => HeadingPlan::RandomConstant,
        ScheduleKind::Ramp => HeadingPlan::Fixed(HeadingSchedule::Ramp {
            omega: required("omega", heading.omega)?,
            phi0: heading.phi0.unwrap_or(0.0),
        }),
        ScheduleKind::Sine => HeadingPlan::Fixed(HeadingSchedule::Sine {
            omega: required("omega", heading.omega)?,
            amplitude: heading.amplitude.unwrap_or(1.0),
            phi0: heading.phi0.unwrap_or(0.0),
        }),
    })
}

/// Refuses a run whose trajectory would not fit in memory.
fn check_robot_ticks(
    check: &Checker<'_>,
    robots: usize,
    ticks: u64,
    dt: f64,
) -> Result<(), ScenarioError> {
    // Both factors are bounded above, so the product cannot overflow.
    let robot_ticks = ticks * robots as u64;
    if robot_ticks > limits::MAX_ROBOT_TICKS {
        return Err(check.invalid(
            "duration_s",
            format_args!(
                "with dt = {dt} gives {ticks} ticks, and robots x ticks = {robot_ticks} is over the \
                 limit of {} (a run's trajectory is held in memory); shorten duration_s, \
                 enlarge dt or use fewer robots",
                limits::MAX_ROBOT_TICKS
            ),
        ));
    }
    Ok(())
}

/// The neighbour rule the `[formation]` table asks for, with its team-size defaults.
fn validate_formation(
    check: &Checker<'_>,
    formation: &FormationToml,
    robots: usize,
    world: &WorldConfig,
) -> Result<NeighbourRule, ScenarioError> {
    let default = NeighbourRule::default_for(robots, world.lidar.max_range);
    let name = formation.neighbours.as_deref().unwrap_or(default.name());
    let gabriel_keys = [
        ("formation.sensing_range", formation.sensing_range.is_some()),
        ("formation.nearest", formation.nearest.is_some()),
        ("formation.threshold", formation.threshold.is_some()),
        ("formation.hysteresis", formation.hysteresis.is_some()),
    ];
    match name {
        "all_pairs" => {
            if let Some((key, _)) = gabriel_keys.iter().find(|(_, given)| *given) {
                return Err(check.invalid(
                    key,
                    "applies only to neighbours = \"gabriel\"; remove it or choose the gabriel rule",
                ));
            }
            Ok(NeighbourRule::AllPairs)
        }
        "gabriel" => {
            let max_range = world.lidar.max_range;
            let sensing_range = match formation.sensing_range {
                None => max_range,
                Some(r) => check.bounded(
                    "formation.sensing_range",
                    r,
                    Bounds {
                        max: max_range,
                        ..limits::MAX_RANGE
                    },
                )?,
            };
            let nearest = check.count(
                "formation.nearest",
                formation.nearest.unwrap_or(GabrielRule::DEFAULT_NEAREST),
                0,
                limits::MAX_NEAREST,
                "",
            )?;
            let threshold = check.bounded(
                "formation.threshold",
                formation
                    .threshold
                    .unwrap_or(GabrielRule::DEFAULT_THRESHOLD),
                limits::GABRIEL_THRESHOLD,
            )?;
            let hysteresis = check.bounded(
                "formation.hysteresis",
                formation
                    .hysteresis
                    .unwrap_or(GabrielRule::DEFAULT_HYSTERESIS),
                Bounds {
                    min: 0.0,
                    max: threshold - 0.01,
                    unit: "",
                },
            )?;
            Ok(NeighbourRule::Gabriel(GabrielRule {
                sensing_range,
                nearest,
                threshold,
                hysteresis,
            }))
        }
        other => Err(check.invalid(
            "formation.neighbours",
            format_args!(
                "must be one of {} (got {other:?})",
                NeighbourRule::NAMES
                    .iter()
                    .map(|n| format!("\"{n}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

fn validate_init(
    check: &Checker<'_>,
    init: InitToml,
    robots: usize,
    robot: &RobotParams,
    sensing_range: f64,
) -> Result<InitialConditions, ScenarioError> {
    let disc_radius = check.bounded(
        "init.disc_radius",
        init.disc_radius
            .unwrap_or_else(|| default_disc_radius(robots)),
        limits::DISC_RADIUS,
    )?;
    let min_spacing = check.bounded(
        "init.min_spacing",
        init.min_spacing.unwrap_or(DEFAULT_MIN_SPACING),
        limits::MIN_SPACING,
    )?;
    if min_spacing > sensing_range {
        return Err(check.invalid(
            "init.min_spacing",
            format_args!(
                "must be <= the sensing range ({sensing_range} m) or the team cannot start \
                 connected; reduce init.min_spacing or raise lidar.max_range (got {min_spacing})"
            ),
        ));
    }
    let body_diameter = 2.0 * robot.body_radius;
    if min_spacing < body_diameter {
        return Err(check.invalid(
            "init.min_spacing",
            format_args!(
                "must be >= 2 * robot.body_radius ({body_diameter}) so robots do not start overlapping \
                 (got {min_spacing})"
            ),
        ));
    }
    let sites = lattice_sites(disc_radius, min_spacing, robots).len();
    if sites < robots {
        return Err(check.invalid(
            "init.disc_radius",
            format_args!(
                "is too small to place {robots} robots {min_spacing} m apart (room for about {sites}); \
                 enlarge init.disc_radius or reduce init.min_spacing (got {disc_radius})"
            ),
        ));
    }
    Ok(InitialConditions {
        disc_radius,
        min_spacing,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SHIPPED: [(&str, &str); 5] = [
        ("case1", include_str!("../../scenarios/case1.toml")),
        ("case2", include_str!("../../scenarios/case2.toml")),
        ("case3", include_str!("../../scenarios/case3.toml")),
        ("table1", include_str!("../../scenarios/table1.toml")),
        ("collect", include_str!("../../scenarios/collect.toml")),
    ];

    const MINIMAL: &str = r#"
name = "t"
robots = 3
duration_s = 10.0
seed = 5
[goal]
v_star = 0.7
d_star = 2.0
[heading]
schedule = "constant"
phi = 1.0
"#;

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        Scenario::from_toml_str(text, "scenarios/x.toml")
    }

    fn error_text(text: &str) -> String {
        match parse(text) {
            Ok(scenario) => panic!("expected an error, parsed {scenario:?}"),
            Err(error) => error.to_string(),
        }
    }

    /// `MINIMAL` with `old` replaced by `new` (asserting `old` is there).
    fn edited(old: &str, new: &str) -> String {
        assert!(MINIMAL.contains(old), "{old:?} not in the minimal scenario");
        MINIMAL.replacen(old, new, 1)
    }

    #[test]
    fn a_d_star_range_draws_every_run_uniformly_within_it() {
        let scenario = parse(&edited("d_star = 2.0", "d_star_range = [0.8, 2.5]")).unwrap();
        assert_eq!(*scenario.d_star(), DStarPlan::Range { min: 0.8, max: 2.5 });
        assert_eq!(scenario.d_star().bounds(), [0.8, 2.5]);
        let draws: Vec<f64> = (0..400).map(|i| scenario.run_spec(9, i).d_star).collect();
        assert!(draws.iter().all(|d| (0.8..=2.5).contains(d)));
        let below_middle = draws.iter().filter(|&&d| d < 1.65).count();
        assert!(
            (150..=250).contains(&below_middle),
            "{below_middle} of 400 below the middle"
        );
        let distinct: std::collections::BTreeSet<u64> = draws.iter().map(|d| d.to_bits()).collect();
        assert_eq!(distinct.len(), 400, "a continuous draw");
        assert_eq!(
            scenario.run_spec(9, 7).d_star,
            draws[7],
            "a pure function of the run"
        );
    }

    fn invalid_field(text: &str) -> (String, String) {
        match parse(text) {
            Err(ScenarioError::Invalid {
                origin,
                field,
                problem,
            }) => {
                assert_eq!(origin, "scenarios/x.toml");
                (field, problem)
            }
            other => panic!("expected ScenarioError::Invalid, got {other:?}"),
        }
    }

    /// Every file in `scenarios/` parses, under the name of its file; the generalisation variants
    /// of table1 differ from it only where their names say.
    #[test]
    fn every_file_in_the_scenarios_folder_parses_under_its_own_name() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut parsed = std::collections::BTreeMap::new();
        for entry in std::fs::read_dir(&dir).expect("the scenarios folder") {
            let path = entry.expect("a folder entry").path();
            if path.extension().and_then(|e| e.to_str()) != Some("toml") {
                continue;
            }
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .expect("a file name");
            let scenario = Scenario::from_path(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(scenario.name(), stem, "{}", path.display());
            parsed.insert(stem.to_owned(), scenario);
        }
        assert!(parsed.len() >= 13, "{:?}", parsed.keys());
        let table1 = &parsed["table1"];
        for (name, d_star, noise) in [
            ("table1-d125", Some(1.25), 0.0),
            ("table1-d175", Some(1.75), 0.0),
            ("table1-noise", None, 0.03),
        ] {
            let variant = &parsed[name];
            assert_eq!(variant.world_config().lidar.noise_std, noise, "{name}");
            match d_star {
                Some(d) => assert_eq!(*variant.d_star(), DStarPlan::Fixed(d), "{name}"),
                None => assert_eq!(variant.d_star(), table1.d_star(), "{name}"),
            }
            assert_eq!(
                (variant.n_robots(), variant.runs(), variant.seed()),
                (table1.n_robots(), table1.runs(), table1.seed()),
                "{name}"
            );
        }
    }

    #[test]
    fn every_shipped_scenario_parses_with_the_papers_settings() {
        for (name, text) in SHIPPED {
            let scenario = Scenario::from_toml_str(text, name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(scenario.name(), name);
            assert_eq!(scenario.n_robots(), 3);
            assert_eq!(scenario.v_star(), 0.7);
            assert_eq!(scenario.world_config().dt, DEFAULT_DT);
            assert_eq!(scenario.world_config().lidar, LidarSpec::default());
            assert_eq!(*scenario.initial_conditions(), InitialConditions::default());
        }
        let case1 = parse(SHIPPED[0].1).unwrap();
        assert_eq!(
            *case1.heading(),
            HeadingPlan::Fixed(HeadingSchedule::Constant { phi: 3.76 })
        );
        assert_eq!(*case1.d_star(), DStarPlan::Fixed(2.0));
        assert_eq!((case1.seed(), case1.duration_s()), (1, 60.0));
        let case2 = parse(SHIPPED[1].1).unwrap();
        assert_eq!(
            *case2.heading(),
            HeadingPlan::Fixed(HeadingSchedule::Ramp {
                omega: 0.1,
                phi0: 0.0
            })
        );
        assert_eq!(*case2.d_star(), DStarPlan::Fixed(1.0));
        let case3 = parse(SHIPPED[2].1).unwrap();
        assert_eq!(
            *case3.heading(),
            HeadingPlan::Fixed(HeadingSchedule::Sine {
                omega: 0.2,
                amplitude: 1.0,
                phi0: 0.0
            })
        );
        assert_eq!(*case3.d_star(), DStarPlan::Fixed(1.5));
        let table1 = parse(SHIPPED[3].1).unwrap();
        assert_eq!(
            (table1.runs(), table1.seed(), table1.duration_s()),
            (100, 7, 60.0)
        );
        assert_eq!(*table1.heading(), HeadingPlan::RandomConstant);
        assert_eq!(*table1.d_star(), DStarPlan::Choices(vec![1.0, 1.5, 2.0]));
        let collect = parse(SHIPPED[4].1).unwrap();
        assert_eq!(*collect.heading(), HeadingPlan::RandomConstant);
        assert_eq!(collect.d_star(), table1.d_star());
        assert_ne!(
            collect.seed(),
            table1.seed(),
            "training runs must not replay evaluation runs"
        );
        let spec = collect.run_spec(collect.seed(), 0);
        let samples = collect.runs() as u64 * spec.ticks() * collect.n_robots() as u64;
        assert_eq!(samples, 110_160, "the paper's data set size");
    }

    #[test]
    fn defaults_fill_optional_keys_and_partial_tables() {
        let scenario = parse(&format!(
            "{MINIMAL}[lidar]\nnoise_std = 0.03\n[robot]\nmax_wheel_speed = 0.8\n"
        ))
        .unwrap();
        let lidar = scenario.world_config().lidar;
        assert_eq!(
            (lidar.beams, lidar.max_range, lidar.noise_std),
            (900, 10.0, 0.03)
        );
        let robot = scenario.world_config().robot;
        assert_eq!(robot.max_wheel_speed, 0.8);
        assert_eq!(robot.body_radius, RobotParams::default().body_radius);
        assert_eq!(scenario.runs(), 1);
        assert!(scenario.agent_models().is_empty());
    }

    #[test]
    fn unknown_keys_are_rejected_by_name_at_every_level() {
        let cases = [
            (edited("seed = 5", "seed = 5\nsed = 6"), "sed"),
            (edited("d_star = 2.0", "d_star = 2.0\ndstar = 2.0"), "dstar"),
            (edited("phi = 1.0", "phi = 1.0\nphy = 2.0"), "phy"),
            (
                format!("{MINIMAL}[init]\ndisc_radius = 3.0\nspacing = 1.0\n"),
                "spacing",
            ),
            (format!("{MINIMAL}[lidar]\nbeam = 360\n"), "beam"),
            (format!("{MINIMAL}[robot]\nmax_speed = 1.0\n"), "max_speed"),
            (
                format!("{MINIMAL}[[agent]]\nrobot = 0\nmodel = \"a.onnx\"\nweights = 1\n"),
                "weights",
            ),
            (format!("{MINIMAL}[extra]\nx = 1\n"), "extra"),
        ];
        for (text, key) in cases {
            let error = parse(&text).expect_err(key);
            assert!(
                matches!(error, ScenarioError::Parse { .. }),
                "{key}: {error:?}"
            );
            let message = error.to_string();
            assert!(message.starts_with("scenarios/x.toml: "), "{message}");
            assert!(
                message.contains(&format!("unknown field `{key}`")),
                "{key}: {message}"
            );
        }
    }

    #[test]
    fn unknown_schedule_is_rejected_with_the_valid_names() {
        let message = error_text(&edited("\"constant\"", "\"spiral\""));
        assert!(
            message.contains("spiral") && message.contains("ramp"),
            "{message}"
        );
    }

    #[test]
    fn invalid_values_name_the_field_and_the_value() {
        let (field, problem) = invalid_field(&edited("d_star = 2.0", "d_star = -1"));
        assert_eq!(
            (field.as_str(), problem.as_str()),
            ("goal.d_star", "must be in [0.01, 100] m (got -1)")
        );
        assert_eq!(
            error_text(&edited("d_star = 2.0", "d_star = -1")),
            "scenarios/x.toml: goal.d_star must be in [0.01, 100] m (got -1)"
        );

        let cases = [
            (
                edited("d_star = 2.0", "d_star = nan"),
                "goal.d_star",
                "finite",
            ),
            (
                edited("d_star = 2.0", "d_star = 0.0"),
                "goal.d_star",
                "[0.01, 100] m",
            ),
            (
                edited("d_star = 2.0", "d_star_choices = [1.0, inf]"),
                "goal.d_star_choices[1]",
                "finite",
            ),
            (
                edited("d_star = 2.0", "d_star_choices = []"),
                "goal.d_star_choices",
                "empty",
            ),
            (
                edited("d_star = 2.0", "d_star = 2.0\nd_star_choices = [1.0]"),
                "goal.d_star",
                "exactly one",
            ),
            (edited("d_star = 2.0", ""), "goal.d_star", "missing"),
            (
                edited("d_star = 2.0", "d_star_range = [2.5, 0.8]"),
                "goal.d_star_range",
                "smallest < largest",
            ),
            (
                edited("d_star = 2.0", "d_star_range = [0.8, nan]"),
                "goal.d_star_range[1]",
                "finite",
            ),
            (
                edited("d_star = 2.0", "d_star_range = [0.8, 2.5]\nd_star = 1.0"),
                "goal.d_star",
                "exactly one",
            ),
            (edited("robots = 3", "robots = 0"), "robots", "(got 0)"),
            (edited("robots = 3", "robots = 1"), "robots", "(got 1)"),
            (
                edited("duration_s = 10.0", "duration_s = inf"),
                "duration_s",
                "finite",
            ),
            (
                edited("duration_s = 10.0", "duration_s = 0.5\ndt = 1.0"),
                "dt",
                "<= duration_s",
            ),
            (
                edited("duration_s = 10.0", "duration_s = 10.0\ndt = 0.3"),
                "dt",
                "whole steps",
            ),
            (
                edited("duration_s = 10.0", "duration_s = 10.0\nruns = 0"),
                "runs",
                "[1, 10000] (got 0)",
            ),
            (
                edited("v_star = 0.7", "v_star = 1.5"),
                "goal.v_star",
                "max_wheel_speed",
            ),
            (
                edited("v_star = 0.7", "v_star = -nan"),
                "goal.v_star",
                "finite",
            ),
            (edited("phi = 1.0", "phi = nan"), "heading.phi", "finite"),
            (edited("phi = 1.0", ""), "heading.phi", "required"),
            (
                edited("phi = 1.0", "phi = 1.0\nomega = 0.1"),
                "heading.omega",
                "not a parameter",
            ),
            (
                edited("schedule = \"constant\"\nphi = 1.0", "schedule = \"ramp\""),
                "heading.omega",
                "required",
            ),
            (
                edited(
                    "schedule = \"constant\"\nphi = 1.0",
                    "schedule = \"random\"\nphi = 1.0",
                ),
                "heading.phi",
                "not a parameter",
            ),
            (
                format!("{MINIMAL}[init]\nmin_spacing = 0.3\n"),
                "init.min_spacing",
                "body_radius",
            ),
            (
                format!("{MINIMAL}[init]\ndisc_radius = 0.5\n"),
                "init.disc_radius",
                "too small",
            ),
            (
                format!("{MINIMAL}[lidar]\nbeams = 0\n"),
                "lidar.beams",
                "[8, 900]",
            ),
            (
                format!("{MINIMAL}[lidar]\nnoise_std = -0.1\n"),
                "lidar.noise_std",
                "[0, 10] m",
            ),
            (
                format!("{MINIMAL}[robot]\nmax_wheel_accel = 0.0\n"),
                "robot.max_wheel_accel",
                "[0.01, 1000] m/s^2",
            ),
            (
                format!("{MINIMAL}[robot]\nwheel_separation = nan\n"),
                "robot.wheel_separation",
                "finite",
            ),
            (
                format!("{MINIMAL}[[agent]]\nrobot = 3\nmodel = \"a.onnx\"\n"),
                "agent[0].robot",
                "< robots (3)",
            ),
            (
                format!(
                    "{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"a.onnx\"\n[[agent]]\nrobot = 1\nmodel = \"b.onnx\"\n"
                ),
                "agent[1].robot",
                "second time",
            ),
            (
                format!("{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"\"\n"),
                "agent[0].model",
                "empty",
            ),
            (edited("name = \"t\"", "name = \" \""), "name", "empty"),
        ];
        for (text, expected_field, expected_problem) in cases {
            let (field, problem) = invalid_field(&text);
            assert_eq!(field, expected_field, "{problem}");
            assert!(
                problem.contains(expected_problem),
                "{field}: {problem:?} lacks {expected_problem:?}"
            );
        }
    }

    /// Asserts that `text` is refused at `field` with a problem containing every needle.
    fn refused(text: &str, field: &str, needles: &[&str]) {
        let (found, problem) = invalid_field(text);
        assert_eq!(found, field, "{problem}");
        for needle in needles {
            assert!(
                problem.contains(needle),
                "{field}: {problem:?} lacks {needle:?}"
            );
        }
    }

    #[test]
    fn run_size_limits_are_enforced_with_the_allowed_range() {
        // Issue: duration_s = 1e12 was accepted and a run never ended.
        refused(
            &edited("duration_s = 10.0", "duration_s = 1e12"),
            "duration_s",
            &["[0.001, 3600] s", "(got 1e12)"],
        );
        refused(
            &edited("duration_s = 10.0", "duration_s = 3600.5"),
            "duration_s",
            &["[0.001, 3600] s"],
        );
        parse(&edited("duration_s = 10.0", "duration_s = 3600.0")).expect("an hour is allowed");
        refused(
            &edited("duration_s = 10.0", "duration_s = 10.0\ndt = 1e-4"),
            "dt",
            &["[0.001, 1] s", "(got 0.0001)"],
        );
        refused(
            &edited("duration_s = 10.0", "duration_s = 10.0\ndt = 2.0"),
            "dt",
            &["[0.001, 1] s", "(got 2)"],
        );
        refused(
            &edited("robots = 3", "robots = 1025"),
            "robots",
            &["[2, 1024]", "(got 1025)"],
        );
        refused(
            &edited("duration_s = 10.0", "duration_s = 10.0\nruns = 10001"),
            "runs",
            &["[1, 10000]", "(got 10001)"],
        );
        refused(
            &format!("{MINIMAL}[lidar]\nbeams = 901\n"),
            "lidar.beams",
            &["[8, 900]", "(got 901)"],
        );
        refused(
            &format!("{MINIMAL}[lidar]\nbeams = 7\n"),
            "lidar.beams",
            &["[8, 900]"],
        );
        // Each factor within its limit, the product over it: 1000 robots x 72,000 ticks.
        let crowd = edited("robots = 3", "robots = 1000")
            .replace("duration_s = 10.0", "duration_s = 3600.0")
            + "[init]\ndisc_radius = 100.0\n";
        refused(
            &crowd,
            "duration_s",
            &["robots x ticks", "72000000", "10000000"],
        );
        refused(
            &edited(
                "d_star = 2.0",
                &format!("d_star_choices = [{}]", ["1.0"; 257].join(", ")),
            ),
            "goal.d_star_choices",
            &["257 entries", "256"],
        );
    }

    #[test]
    fn numbers_must_fit_their_range_and_an_f32() {
        // Issue: d_star = 1e308 was accepted and overflowed to infinity in the f32 policy input.
        let cases: [(String, &str, &[&str]); 11] = [
            (
                edited("d_star = 2.0", "d_star = 1e308"),
                "goal.d_star",
                &["[0.01, 100] m", "(got 1e308)"],
            ),
            (
                edited("d_star = 2.0", "d_star = 1e-50"),
                "goal.d_star",
                &["[0.01, 100] m", "(got 1e-50)"],
            ),
            (
                edited("d_star = 2.0", "d_star_choices = [1.0, 1e39]"),
                "goal.d_star_choices[1]",
                &["[0.01, 100] m", "(got 1e39)"],
            ),
            (
                edited("v_star = 0.7", "v_star = -0.1"),
                "goal.v_star",
                &["[0, 10] m/s", "(got -0.1)"],
            ),
            (
                edited("phi = 1.0", "phi = 1e20"),
                "heading.phi",
                &["[-1000, 1000] rad", "(got 1e20)"],
            ),
            (
                edited(
                    "schedule = \"constant\"\nphi = 1.0",
                    "schedule = \"ramp\"\nomega = 1e300",
                ),
                "heading.omega",
                &["[-100, 100] rad/s", "(got 1e300)"],
            ),
            (
                edited(
                    "schedule = \"constant\"\nphi = 1.0",
                    "schedule = \"sine\"\nomega = 0.2\namplitude = -inf",
                ),
                "heading.amplitude",
                &["finite", "[-1000, 1000] rad", "(got -inf)"],
            ),
            (
                format!("{MINIMAL}[lidar]\nmax_range = 1e-9\n"),
                "lidar.max_range",
                &["[0.1, 1000] m", "(got 1e-9)"],
            ),
            (
                format!("{MINIMAL}[lidar]\nnoise_std = 1e40\n"),
                "lidar.noise_std",
                &["[0, 10] m", "(got 1e40)"],
            ),
            (
                format!("{MINIMAL}[robot]\nbody_radius = 1e-30\n"),
                "robot.body_radius",
                &["[0.01, 10] m"],
            ),
            (
                format!("{MINIMAL}[init]\ndisc_radius = 1e300\n"),
                "init.disc_radius",
                &["[0.01, 1000] m"],
            ),
        ];
        for (text, field, needles) in cases {
            refused(&text, field, needles);
        }
        let message = error_text(&edited("d_star = 2.0", "d_star = 1e308"));
        assert_eq!(
            message,
            "scenarios/x.toml: goal.d_star must be in [0.01, 100] m (got 1e308)"
        );
    }

    #[test]
    fn every_limit_survives_the_f32_conversion() {
        let fits = |x: f64| {
            let narrow = x as f32;
            narrow.is_finite() && (x == 0.0) == (narrow == 0.0)
        };
        for (keys, bounds) in limits::ALL {
            assert!(bounds.min <= bounds.max, "{keys}: {bounds}");
            assert!(
                fits(bounds.min) && fits(bounds.max),
                "{keys}: {bounds} must be finite and keep its sign in f32"
            );
        }
        assert_eq!(limits::MAX_BEAMS, formation_proto::wire::MAX_BEAMS);
    }

    #[test]
    fn names_are_short_and_printable() {
        let named = |name: &str| edited("name = \"t\"", &format!("name = {name:?}"));
        parse(&named(&"n".repeat(limits::MAX_NAME_CHARS))).expect("128 characters are allowed");
        parse(&named("Fall 2026 — table I, ü")).expect("printable Unicode is allowed");
        refused(
            &named(&"n".repeat(limits::MAX_NAME_CHARS + 1)),
            "name",
            &["at most 128 characters", "(got 129)"],
        );
        refused(
            &named("two\nlines"),
            "name",
            &["control characters", "'\\n'"],
        );
        refused(
            &edited("name = \"t\"", "name = \"bell\\u0007\""),
            "name",
            &["control characters"],
        );
        // A huge name is refused without being echoed back.
        let huge = named(&"x".repeat(100_000));
        let message = error_text(&huge);
        assert!(
            message.len() < 300,
            "the name was echoed: {} bytes",
            message.len()
        );
    }

    /// A scratch directory under the system temp directory, removed on drop.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(tag: &str) -> Scratch {
            use std::sync::atomic::{AtomicUsize, Ordering};
            static N: AtomicUsize = AtomicUsize::new(0);
            let dir = std::env::temp_dir().join(format!(
                "formation-scenario-{tag}-{}-{}",
                std::process::id(),
                N.fetch_add(1, Ordering::Relaxed)
            ));
            std::fs::create_dir_all(&dir).expect("scratch dir");
            Scratch(dir)
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn an_oversized_file_is_refused_by_its_size() {
        let dir = Scratch::new("big");
        let path = dir.0.join("big.toml");
        let file = std::fs::File::create(&path).expect("create");
        // Sparse: no disk space used, and a whole read would allocate over a MiB.
        file.set_len(limits::MAX_FILE_BYTES + 1).expect("set_len");
        match Scenario::from_path(&path) {
            Err(ref error @ ScenarioError::TooLarge { size, .. }) => {
                assert_eq!(size, Some(limits::MAX_FILE_BYTES + 1));
                let message = error.to_string();
                assert!(message.contains("big.toml"), "{message}");
                assert!(message.contains("1048577 bytes"), "{message}");
                assert!(message.contains("1048576-byte limit"), "{message}");
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        // Exactly at the limit it is read (and then fails to parse as TOML: all NUL bytes).
        file.set_len(limits::MAX_FILE_BYTES).expect("set_len");
        assert!(matches!(
            Scenario::from_path(&path),
            Err(ScenarioError::Parse { .. })
        ));
    }

    #[test]
    fn devices_directories_and_fifos_are_refused_before_reading() {
        let dir = Scratch::new("kinds");
        let fifo = dir.0.join("pipe.toml");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("running mkfifo");
        assert!(made.success(), "mkfifo failed");
        for (path, kind) in [
            (Path::new("/dev/zero"), "a character device"),
            (dir.0.as_path(), "a directory"),
            (fifo.as_path(), "a FIFO"),
        ] {
            // Reading /dev/zero or opening the FIFO would never return: the refusal must come first.
            match Scenario::from_path(path) {
                Err(ref error @ ScenarioError::NotAFile { kind: found, .. }) => {
                    assert!(found.starts_with(kind), "{path:?}: {found}");
                    let message = error.to_string();
                    assert!(message.contains("not a regular file"), "{message}");
                    assert!(message.contains(&path.display().to_string()), "{message}");
                }
                other => panic!("{path:?}: expected NotAFile, got {other:?}"),
            }
        }
    }

    #[test]
    fn a_scenario_file_is_read_and_its_agent_paths_resolved() {
        let dir = Scratch::new("ok");
        let path = dir.0.join("ok.toml");
        std::fs::write(
            &path,
            format!("{MINIMAL}[[agent]]\nrobot = 1\nmodel = \"m/b.onnx\"\n"),
        )
        .expect("write");
        let scenario = Scenario::from_path(&path).expect("valid");
        assert_eq!(scenario.agent_models()[0].model, dir.0.join("m/b.onnx"));
        std::fs::write(&path, b"name = \"\xff\"\n").expect("write");
        assert!(matches!(
            Scenario::from_path(&path),
            Err(ScenarioError::Read { .. })
        ));
    }

    #[test]
    fn missing_file_error_names_the_path() {
        let path = Path::new("scenarios/does-not-exist-7f3a.toml");
        let error = Scenario::from_path(path).expect_err("missing file");
        assert!(matches!(&error, ScenarioError::Read { path: p, .. } if p == path));
        assert!(
            error
                .to_string()
                .contains("scenarios/does-not-exist-7f3a.toml"),
            "{error}"
        );
    }

    #[test]
    fn agent_models_are_exposed() {
        let scenario = parse(&format!(
            "{MINIMAL}[[agent]]\nrobot = 2\nmodel = \"models/b.onnx\"\n"
        ))
        .unwrap();
        assert_eq!(
            scenario.agent_models(),
            [AgentModel {
                robot: 2,
                model: PathBuf::from("models/b.onnx")
            }]
        );
    }

    #[test]
    fn heading_schedules_follow_their_formulas() {
        let ramp = HeadingSchedule::Ramp {
            omega: 0.1,
            phi0: 0.5,
        };
        assert_eq!(ramp.phi_star(0.0), 0.5);
        assert!((ramp.phi_star(40.0) - 4.5).abs() < 1e-12);
        let sine = HeadingSchedule::Sine {
            omega: 0.2,
            amplitude: 1.0,
            phi0: 0.0,
        };
        assert!((sine.phi_star(7.0) - 1.4f64.sin()).abs() < 1e-15);
        assert_eq!(
            HeadingSchedule::Constant { phi: 3.76 }.phi_star(123.0),
            3.76
        );
    }

    fn pose_bits(spec: &RunSpec) -> Vec<[u64; 3]> {
        spec.initial
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()])
            .collect()
    }

    #[test]
    fn run_spec_is_a_deterministic_function_of_seed_and_index() {
        let table1 = parse(SHIPPED[3].1).unwrap();
        let a = table1.run_spec(7, 3);
        let b = table1.run_spec(7, 3);
        assert_eq!(a, b);
        assert_eq!(pose_bits(&a), pose_bits(&b));
        assert_eq!(a.d_star.to_bits(), b.d_star.to_bits());
        assert_eq!((a.seed, a.noise_seed, a.index), (b.seed, b.noise_seed, 3));
        assert_ne!(a.seed, a.noise_seed);

        let other_seed = table1.run_spec(8, 3);
        let other_index = table1.run_spec(7, 4);
        for other in [&other_seed, &other_index] {
            assert_ne!(other.seed, a.seed);
            assert_ne!(other.noise_seed, a.noise_seed);
            assert_ne!(pose_bits(other), pose_bits(&a));
        }
    }

    #[test]
    fn run_spec_draws_cover_the_configured_ranges() {
        let table1 = parse(SHIPPED[3].1).unwrap();
        let mut d_seen = [false; 3];
        let mut theta_signs = [false; 2];
        for index in 0..200 {
            let spec = table1.run_spec(table1.seed(), index);
            assert_eq!(spec.initial.len(), 3);
            assert_eq!(spec.neighbours, NeighbourRule::AllPairs);
            assert_eq!(spec.ticks(), 1200);
            let k = [1.0, 1.5, 2.0]
                .iter()
                .position(|&d| d == spec.d_star)
                .expect("d* from the choices");
            d_seen[k] = true;
            let HeadingSchedule::Constant { phi } = spec.heading else {
                panic!("{:?}", spec.heading)
            };
            assert!((0.0..TAU).contains(&phi), "phi* = {phi}");
            assert_eq!(
                spec.goal_at(30.0),
                Goal {
                    phi_star: phi,
                    d_star: spec.d_star,
                    v_star: 0.7
                }
            );
            for (i, pose) in spec.initial.iter().enumerate() {
                assert!(
                    pose.x.hypot(pose.y) <= 3.0,
                    "robot {i} outside the disc: {pose:?}"
                );
                assert!(pose.theta > -std::f64::consts::PI && pose.theta <= std::f64::consts::PI);
                theta_signs[usize::from(pose.theta >= 0.0)] = true;
                for other in &spec.initial[i + 1..] {
                    assert!(
                        (pose.x - other.x).hypot(pose.y - other.y) >= 0.6,
                        "spacing violated"
                    );
                }
            }
        }
        assert_eq!(d_seen, [true; 3]);
        assert_eq!(theta_signs, [true; 2]);
    }

    #[test]
    fn crowded_discs_still_place_every_robot_apart() {
        // 19 sites of a 1 m hexagonal lattice fit in a 2 m disc; random draws rarely place 19 robots.
        let text =
            edited("robots = 3", "robots = 19") + "[init]\ndisc_radius = 2.0\nmin_spacing = 1.0\n";
        let scenario = parse(&text).unwrap();
        assert_eq!(lattice_sites(2.0, 1.0, usize::MAX).len(), 19);
        let spec = scenario.run_spec(1, 0);
        assert_eq!(spec.initial.len(), 19);
        for (i, a) in spec.initial.iter().enumerate() {
            assert!(a.x.hypot(a.y) <= 2.0 + 1e-12);
            for b in &spec.initial[i + 1..] {
                assert!((a.x - b.x).hypot(a.y - b.y) >= 1.0 - 1e-9);
            }
        }
        let too_many =
            edited("robots = 3", "robots = 20") + "[init]\ndisc_radius = 2.0\nmin_spacing = 1.0\n";
        assert_eq!(invalid_field(&too_many).0, "init.disc_radius");
    }

    #[test]
    fn eleven_robots_just_work_with_the_gabriel_rule_a_grown_disc_and_a_connected_start() {
        let scenario = parse(&edited("robots = 3", "robots = 11")).unwrap();
        let NeighbourRule::Gabriel(rule) = *scenario.neighbours() else {
            panic!("{:?}", scenario.neighbours())
        };
        assert_eq!(rule, GabrielRule::with_range(10.0));
        let radius = 3.0 * (11.0_f64 / 3.0).sqrt();
        assert_eq!(scenario.initial_conditions().disc_radius, radius);
        for index in 0..20 {
            let spec = scenario.run_spec(5, index);
            assert_eq!(spec.neighbours, *scenario.neighbours());
            let positions: Vec<(f64, f64)> = spec.initial.iter().map(|p| (p.x, p.y)).collect();
            assert!(positions.iter().all(|p| p.0.hypot(p.1) <= radius));
            assert!(connected_within(&positions, rule.sensing_range));
        }
        // The shipped teams scenario is exactly that, for 8 robots.
        let teams = parse(include_str!("../../scenarios/teams.toml")).unwrap();
        assert_eq!(
            (teams.n_robots(), teams.neighbours().name()),
            (8, "gabriel")
        );
        assert_eq!(
            teams.initial_conditions().disc_radius,
            default_disc_radius(8)
        );
        // Three robots keep the paper's triangle and disc.
        let three = parse(MINIMAL).unwrap();
        assert_eq!(*three.neighbours(), NeighbourRule::AllPairs);
        assert_eq!(three.initial_conditions().disc_radius, 3.0);
    }

    #[test]
    fn the_formation_table_names_its_rule_and_refuses_a_wrong_one_with_the_valid_names() {
        let gabriel3 = parse(&format!(
            "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nsensing_range = 4.0\nnearest = 1\n"
        ))
        .unwrap();
        assert_eq!(
            *gabriel3.neighbours(),
            NeighbourRule::Gabriel(GabrielRule {
                sensing_range: 4.0,
                nearest: 1,
                ..GabrielRule::with_range(4.0)
            })
        );
        let all = parse(
            &(edited("robots = 3", "robots = 6") + "[formation]\nneighbours = \"all_pairs\"\n"),
        )
        .unwrap();
        assert_eq!(*all.neighbours(), NeighbourRule::AllPairs);
        let (field, problem) = invalid_field(&format!(
            "{MINIMAL}[formation]\nneighbours = \"delaunay\"\n"
        ));
        assert_eq!(field, "formation.neighbours");
        assert!(
            problem.contains("\"all_pairs\", \"gabriel\"") && problem.contains("delaunay"),
            "{problem}"
        );
        let (field, problem) = invalid_field(&format!(
            "{MINIMAL}[formation]\nneighbours = \"all_pairs\"\nnearest = 2\n"
        ));
        assert_eq!(field, "formation.nearest");
        assert!(
            problem.contains("only to neighbours = \"gabriel\""),
            "{problem}"
        );
        let (field, _) = invalid_field(&format!(
            "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nsensing_range = 11.0\n"
        ));
        assert_eq!(field, "formation.sensing_range");
        let (field, _) = invalid_field(&format!(
            "{MINIMAL}[formation]\nneighbours = \"gabriel\"\nhysteresis = 1.3\n"
        ));
        assert_eq!(field, "formation.hysteresis");
        assert!(
            error_text(&format!("{MINIMAL}[formation]\nrule = \"gabriel\"\n")).contains("rule"),
            "unknown keys are refused"
        );
    }

    #[test]
    fn a_team_too_large_for_its_disc_or_too_spread_for_its_range_is_a_clear_error() {
        let crowded = edited("robots = 3", "robots = 200") + "[init]\ndisc_radius = 3.0\n";
        let (field, problem) = invalid_field(&crowded);
        assert_eq!(field, "init.disc_radius");
        assert!(
            problem.contains("too small to place 200 robots"),
            "{problem}"
        );
        let spread = MINIMAL.to_owned() + "[lidar]\nmax_range = 1.0\n[init]\nmin_spacing = 1.5\n";
        let (field, problem) = invalid_field(&spread);
        assert_eq!(field, "init.min_spacing");
        assert!(problem.contains("cannot start connected"), "{problem}");
    }

    #[test]
    fn a_wide_disc_with_a_short_range_still_starts_connected_in_bounded_time() {
        // A 30 m disc and a 2 m sensing range: random draws are almost never connected, so the
        // placement ends on the connected lattice patch.
        let text = edited("robots = 3", "robots = 12")
            + "[init]\ndisc_radius = 30.0\nmin_spacing = 1.0\n[lidar]\nmax_range = 2.0\n";
        let scenario = parse(&text).unwrap();
        let spec = scenario.run_spec(1, 0);
        let positions: Vec<(f64, f64)> = spec.initial.iter().map(|p| (p.x, p.y)).collect();
        assert_eq!(positions.len(), 12);
        assert!(connected_within(&positions, 2.0));
        for (i, a) in positions.iter().enumerate() {
            for b in &positions[i + 1..] {
                assert!((a.0 - b.0).hypot(a.1 - b.1) >= 1.0 - 1e-9);
            }
        }
    }

    #[test]
    fn with_robots_keeps_what_the_file_gave_and_resizes_the_rest() {
        let file = edited("robots = 3", "robots = 4") + "[init]\nmin_spacing = 0.8\n";
        let scenario = parse(&file).unwrap();
        let big = scenario.with_robots(16).unwrap();
        assert_eq!(big.n_robots(), 16);
        assert_eq!(big.initial_conditions().min_spacing, 0.8);
        assert_eq!(
            big.initial_conditions().disc_radius,
            default_disc_radius(16)
        );
        assert_eq!(big.neighbours().name(), "gabriel");
        let three = scenario.with_robots(3).unwrap();
        assert_eq!(*three.neighbours(), NeighbourRule::AllPairs);
        assert_eq!(three.initial_conditions().disc_radius, 3.0);
        assert_eq!(three.with_robots(4).unwrap(), scenario);
        let fixed = parse(&(file + "[formation]\nneighbours = \"all_pairs\"\n")).unwrap();
        assert_eq!(
            *fixed.with_robots(8).unwrap().neighbours(),
            NeighbourRule::AllPairs
        );
        assert!(scenario.with_robots(1).is_err() && scenario.with_robots(5000).is_err());
    }

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // Reference: the first outputs of SplitMix64 seeded with 0 (state advanced by the golden gamma).
        let gamma = 0x9E37_79B9_7F4A_7C15_u64;
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(splitmix64(gamma), 0x6E78_9E6A_A1B9_65F4);
    }
}
