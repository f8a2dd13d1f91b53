//! The learning library: closed-loop rollouts run in parallel, evaluation over team sizes, and
//! the DAgger loop. The `formation` command only parses arguments and calls these.
//!
//! * [`rollout`]: a scenario's runs with a [`Driver`] (the expert, or the learned policy per
//!   robot), run in parallel with rayon; every run is a pure function of (scenario, base seed,
//!   run index, driver), so results do not depend on the thread count.
//! * [`scaling`]: the scaling table: Table I figures per team size and driver.
//! * [`response`]: the response gauge: each driver's formation velocity against the expert's
//!   label on its own states, binned by the label's size (`formation gauge`).
//! * [`shards`]: an evaluation spread over workers (a Ray sweep): shares of its runs, merged
//!   into the summary one evaluation writes, byte for byte.
//! * [`dagger`]: DAgger over teams of several sizes: the policy drives, the expert labels every
//!   robot's view, the dataset grows, the policy is retrained, and each iteration is evaluated.
//! * [`dagger_share`]: one share of a DAgger iteration's labelling (a Ray task), written as a
//!   part that `formation dagger-append` appends with the others, in run order.

pub mod dagger;
pub mod dagger_share;
pub mod response;
pub mod rollout;
pub mod scaling;
pub mod shards;

use std::path::PathBuf;

pub use rollout::{Driver, RunResult, eval_output, evaluate_run_range, evaluate_runs};

/// Why a rollout, an evaluation or a DAgger iteration failed.
#[derive(Debug, thiserror::Error)]
pub enum LearningError {
    /// The scenario (or its resizing to a team size) is invalid.
    #[error(transparent)]
    Scenario(#[from] formation_world::scenario::ScenarioError),
    /// A policy's models could not be loaded or do not fit the robots' sensor.
    #[error("cannot load the policy's models: {source}")]
    Policy {
        /// Why.
        #[source]
        source: formation_robot_agent::decision::DecisionError,
    },
    /// The expert's law on each robot's own scan cannot drive these robots.
    #[error(transparent)]
    OwnScan(#[from] formation_expert::own_scan::OwnScanError),
    /// The models cannot drive this scenario's robots (checked before anything runs).
    #[error(transparent)]
    TeamModels(#[from] formation_robot_agent::decision::TeamModelError),
    /// A scenario gives a robot a model that the team does not have.
    #[error("the scenario gives robot {robot} a model, but the team has {robots} robots")]
    AgentOutOfTeam {
        /// The robot named.
        robot: usize,
        /// Team size.
        robots: usize,
    },
    /// A controller stopped a run.
    #[error("run {run}: {source}")]
    Run {
        /// Run index.
        run: usize,
        /// What the controller said.
        #[source]
        source: formation_world::episode::ControllerError,
    },
    /// The expert could not label a DAgger rollout.
    #[error("labelling DAgger rollout {run}: {source}")]
    Label {
        /// Run index.
        run: usize,
        /// Why.
        #[source]
        source: formation_expert::collect::CollectError,
    },
    /// The dataset could not be opened or appended to.
    #[error("dataset {}: {source}", path.display())]
    Dataset {
        /// The dataset directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: formation_trainer_bridge::dataset::DatasetError,
    },
    /// A DAgger part could not be written.
    #[error("DAgger part {}: {source}", path.display())]
    Part {
        /// The part file.
        path: PathBuf,
        /// Why (boxed: the error names several files).
        #[source]
        source: Box<formation_trainer_bridge::dagger_part::PartError>,
    },
    /// Training failed.
    #[error("training {}: {source}", out.display())]
    Train {
        /// The model being written.
        out: PathBuf,
        /// Why.
        #[source]
        source: formation_trainer_bridge::train::TrainError,
    },
    /// A file could not be written or copied.
    #[error("{what} {}: {source}", path.display())]
    Io {
        /// What was being done (`writing`, `copying to`).
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The DAgger curve could not be written.
    #[error("cannot write the DAgger curve {}", path.display())]
    Curve {
        /// The curve's file.
        path: PathBuf,
        /// Why.
        #[source]
        source: formation_world::runlog::RunLogError,
    },
    /// The rollouts would record other samples than the dataset holds: another LIDAR, or a v*
    /// other than the speed its labels were recorded at.
    #[error(
        "the DAgger rollouts' {what} is {rollout} but dataset {}'s is {dataset}: its samples would \
         mix; {fix}",
        path.display()
    )]
    RolloutMismatch {
        /// The dataset.
        path: PathBuf,
        /// What differs (`LIDAR`, `v*`).
        what: &'static str,
        /// The dataset's value.
        dataset: String,
        /// The rollouts' value.
        rollout: String,
        /// How to make them agree.
        fix: &'static str,
    },
    /// A setting is out of range.
    #[error("{setting} {problem}")]
    Setting {
        /// The setting, as the command line names it.
        setting: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// The rayon thread pool could not be built.
    #[error("cannot start {threads} worker threads: {source}")]
    Threads {
        /// Threads asked for.
        threads: usize,
        /// Why.
        #[source]
        source: rayon::ThreadPoolBuildError,
    },
}
