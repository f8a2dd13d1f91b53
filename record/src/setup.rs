//! What a recording knows before its first tick: the team (for the messages), the run (for the
//! metadata record) and the models (referenced by hash, or stored).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use formation_proto::{NeighbourRule, WheelLimits};
use formation_world::RunSpec;
use serde::{Deserialize, Serialize};

/// Models to store in a recording: each file with its attachment's name.
pub type ModelAttachments = Vec<(PathBuf, String)>;

/// Whether `model` lies in the folder of the shipped models `shipped` (none: no model is shipped).
pub fn is_shipped_in(shipped: Option<&Path>, model: &Path) -> bool {
    let Some(dir) = shipped else {
        return false;
    };
    match (model.canonicalize(), dir.canonicalize()) {
        (Ok(model), Ok(dir)) => model.starts_with(dir),
        _ => false,
    }
}

/// The run metadata's key for the robots' top wheel speed \[m/s\] as the agents were told it.
pub const MAX_WHEEL_SPEED_KEY: &str = "max_wheel_speed_mps";
/// The run metadata's key for the robots' wheel acceleration limit \[m/s²\] (absent: none).
pub const MAX_WHEEL_ACCEL_KEY: &str = "max_wheel_accel_mps2";

/// The team a recording's messages describe.
#[derive(Debug, Clone, PartialEq)]
pub struct TeamSetup {
    /// Team size.
    pub n_robots: usize,
    /// The LIDAR's maximum range \[m\]: a beam that hits nothing reads it.
    pub max_range: f64,
    /// Distance between each robot's wheels \[m\].
    pub wheel_separation: f64,
    /// Which pairs are formation edges (the edge markers follow the rule tick after tick).
    pub neighbours: NeighbourRule,
    /// Each robot's wheels as its agent was told them; a replay tells its pilots the same.
    pub wheels: WheelLimits,
}

impl TeamSetup {
    /// The team of `spec`.
    pub fn of(spec: &RunSpec) -> TeamSetup {
        TeamSetup {
            n_robots: spec.n_robots,
            max_range: spec.world.lidar.max_range,
            wheel_separation: spec.world.robot.wheel_separation,
            neighbours: spec.neighbours,
            wheels: spec.world.robot.wheel_limits(),
        }
    }
}

/// What the launch knows of its runs beyond each run's spec: the same for every run it records.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchInfo {
    /// The scenario's name.
    pub scenario: String,
    /// The base seed the runs' seeds were drawn from.
    pub base_seed: Option<u64>,
    /// How the run was clocked: `in-process`, `lockstep` or `realtime`.
    pub clock: String,
    /// What drove the robots: `policy` or `expert`.
    pub controller: String,
    /// Each robot's model file (empty for the expert).
    pub models: Vec<PathBuf>,
    /// The folder of the shipped models (`onnx/models/`): a model under it is referenced by its
    /// path and hash; any other is stored in the recording.
    pub shipped_models: Option<PathBuf>,
}

/// Everything a recording writes before its first tick.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSetup {
    /// The team.
    pub team: TeamSetup,
    /// The launch.
    pub launch: LaunchInfo,
    /// The run's index within its scenario.
    pub run_index: usize,
    /// The run's own seed.
    pub run_seed: u64,
    /// The run's time step \[s\].
    pub dt: f64,
    /// The run's planned duration \[s\].
    pub duration_s: f64,
    /// The run's desired distance d* \[m\].
    pub d_star: f64,
}

impl RecordingSetup {
    /// The recording of the run `spec` of the launch `launch`.
    pub fn for_run(spec: &RunSpec, launch: &LaunchInfo) -> RecordingSetup {
        RecordingSetup {
            team: TeamSetup::of(spec),
            launch: launch.clone(),
            run_index: spec.index,
            run_seed: spec.seed,
            dt: spec.world.dt,
            duration_s: spec.duration_s,
            d_star: spec.d_star,
        }
    }

    /// The distinct model files in order of first use, and each robot's index among them.
    pub fn distinct_models(&self) -> (Vec<&Path>, Vec<usize>) {
        let mut files: Vec<&Path> = Vec::new();
        let per_robot = self
            .launch
            .models
            .iter()
            .map(|m| match files.iter().position(|f| *f == m.as_path()) {
                Some(i) => i,
                None => {
                    files.push(m);
                    files.len() - 1
                }
            })
            .collect();
        (files, per_robot)
    }

    /// Whether `model` is one of the shipped models, referenced rather than stored.
    pub fn is_shipped(&self, model: &Path) -> bool {
        is_shipped_in(self.launch.shipped_models.as_deref(), model)
    }

    /// The run's metadata record (`formation.run`) with each distinct model referenced by its
    /// path and SHA-256, and the models to store as attachments (each with its attachment's
    /// name): every one that is not a shipped model. `recording` names the file in errors.
    pub fn metadata_with_models(
        &self,
        recording: &Path,
    ) -> Result<(BTreeMap<String, String>, ModelAttachments), crate::RecordError> {
        let mut metadata = self.run_metadata();
        let mut attachments = Vec::new();
        let (files, per_robot) = self.distinct_models();
        for (k, model) in files.into_iter().enumerate() {
            let sha256 = crate::model_files::hash_model(recording, model)?;
            metadata.insert(format!("model.{k}.path"), model.display().to_string());
            metadata.insert(format!("model.{k}.sha256"), sha256.clone());
            let stored = if self.is_shipped(model) {
                "shipped".to_owned()
            } else {
                let name = format!("models/{sha256}.onnx");
                attachments.push((model.to_path_buf(), name.clone()));
                format!("attachment {name}")
            };
            metadata.insert(format!("model.{k}.stored"), stored);
        }
        let robot_models: Vec<String> = per_robot.iter().map(usize::to_string).collect();
        metadata.insert("robot_models".into(), robot_models.join(","));
        Ok((metadata, attachments))
    }

    /// The run's metadata record (`formation.run`), without the models'.
    pub fn run_metadata(&self) -> BTreeMap<String, String> {
        let launch = &self.launch;
        let mut m = BTreeMap::new();
        let mut put = |k: &str, v: String| {
            m.insert(k.to_owned(), v);
        };
        put("scenario", launch.scenario.clone());
        put(
            "seed",
            launch.base_seed.map_or_else(String::new, |s| s.to_string()),
        );
        put("run_index", self.run_index.to_string());
        put("run_seed", self.run_seed.to_string());
        put("robots", self.team.n_robots.to_string());
        // The world's f64 range (the replay channel holds it as f32): an agent renders beams at
        // or beyond it as no return, so a replay needs it bit for bit (Display round-trips).
        put("lidar_max_range_m", self.team.max_range.to_string());
        // The wheels each agent was told (a formation-velocity policy saturates within them).
        if let Some(speed) = self.team.wheels.max_speed {
            put(MAX_WHEEL_SPEED_KEY, speed.to_string());
        }
        if let Some(accel) = self.team.wheels.max_accel {
            put(MAX_WHEEL_ACCEL_KEY, accel.to_string());
        }
        put("clock", launch.clock.clone());
        put("controller", launch.controller.clone());
        put("dt_s", self.dt.to_string());
        put("duration_s", self.duration_s.to_string());
        put("neighbours", self.team.neighbours.name().to_owned());
        put("formation_version", env!("CARGO_PKG_VERSION").to_owned());
        put(
            "replay_format",
            format!(
                "{} v{}",
                crate::replay::TYPE_NAME,
                crate::replay::FORMAT_VERSION
            ),
        );
        m
    }
}
