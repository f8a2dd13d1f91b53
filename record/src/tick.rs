//! What a recording takes from one tick of a run, owned so that it can cross to the writer's
//! thread: the state before the step, what each agent received and what it sent; and how the
//! run ended ([`RunEnd`]), written at the end of the recording.

use std::collections::BTreeMap;
use std::path::Path;

use formation_proto::control::Observation;
use formation_proto::wire::TickOutcome;
use formation_proto::{Goal, Pose, WheelCmd};

/// One robot's command at one tick and what the world made of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SentCommand {
    /// The wheel speeds as the agent sent them (the world's copy: bit for bit the agent's
    /// `f64`s), or the brake when nothing usable came.
    pub wheels: WheelCmd,
    /// What the world's watchdog made of it.
    pub outcome: TickOutcome,
    /// How many ticks older than this one the scan was that the command answered.
    pub lag_ticks: u32,
}

impl SentCommand {
    /// A command decided in-process for this very tick: fresh, or non-finite (which the world
    /// replaces by the brake).
    pub fn in_process(wheels: WheelCmd) -> SentCommand {
        SentCommand {
            wheels,
            outcome: if wheels.is_finite() {
                TickOutcome::Fresh
            } else {
                TickOutcome::NonFinite
            },
            lag_ticks: 0,
        }
    }
}

/// One tick of a run, before its step.
#[derive(Debug, Clone, PartialEq)]
pub struct TickRecord {
    /// Tick index `k`.
    pub tick: u64,
    /// Simulated time `k dt` \[s\].
    pub time: f64,
    /// The team's goal.
    pub goal: Goal,
    /// Every robot's true pose (its heading is what its compass reads).
    pub poses: Vec<Pose>,
    /// Every robot's wheel speeds over the last step, as its encoders measure them.
    pub wheel_speeds: Vec<WheelCmd>,
    /// Every robot's scan, as it was sent to the robot's agent.
    pub scans: Vec<Vec<f32>>,
    /// Every robot's command.
    pub commands: Vec<SentCommand>,
    /// The model that decided each robot's command (empty when unknown, or for the expert).
    pub model_ids: Vec<String>,
}

impl TickRecord {
    /// The tick of `obs` with the commands `commands` decided for it and the models that decided
    /// them (`model_ids` may be empty: no model).
    pub fn new(obs: &Observation<'_>, commands: Vec<SentCommand>, model_ids: &[String]) -> Self {
        TickRecord {
            tick: obs.tick,
            time: obs.time,
            goal: obs.goal,
            poses: obs.poses.to_vec(),
            wheel_speeds: obs.wheel_speeds.to_vec(),
            scans: obs.scans.to_vec(),
            commands,
            model_ids: model_ids.to_vec(),
        }
    }

    /// The tick of an in-process run: every command decided for this very tick.
    pub fn in_process(obs: &Observation<'_>, commands: &[WheelCmd], model_ids: &[String]) -> Self {
        let sent = commands
            .iter()
            .map(|&c| SentCommand::in_process(c))
            .collect();
        TickRecord::new(obs, sent, model_ids)
    }
}

/// The state after the last step: the run log's last sample, which no tick precedes.
#[derive(Debug, Clone, PartialEq)]
pub struct FinalSample {
    /// Tick index of the sample (the number of ticks played).
    pub tick: u64,
    /// Its simulated time \[s\].
    pub time: f64,
    /// Every robot's pose.
    pub poses: Vec<Pose>,
}

/// The name of the metadata record that says how a recorded run ended.
pub const RUN_END_METADATA: &str = "formation.run_end";

/// How a recorded run ended, as its run log says it (`complete`, `stop_reason`): the recording
/// of a run stopped early (Ctrl-C, SIGTERM, an agent that stopped answering) is a whole MCAP
/// file, and this record is what tells it from a full run's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunEnd {
    /// Whether the run played to its last tick.
    pub complete: bool,
    /// Why it stopped, when it did not.
    pub stop_reason: Option<String>,
}

impl RunEnd {
    /// The reason recorded when the writer was closed without being told why the run stopped.
    pub const UNKNOWN_REASON: &'static str = "the run stopped before its last tick";

    /// A run that played to its last tick.
    pub fn complete() -> RunEnd {
        RunEnd {
            complete: true,
            stop_reason: None,
        }
    }

    /// A run that stopped early, for `reason`.
    pub fn stopped(reason: &str) -> RunEnd {
        RunEnd {
            complete: false,
            stop_reason: Some(reason.to_owned()),
        }
    }

    /// The metadata record's keys: `complete` (`true` / `false`) and `stop_reason`.
    pub fn to_metadata(&self) -> BTreeMap<String, String> {
        let mut metadata = BTreeMap::new();
        metadata.insert("complete".to_owned(), self.complete.to_string());
        if let Some(reason) = &self.stop_reason {
            metadata.insert("stop_reason".to_owned(), reason.clone());
        }
        metadata
    }

    /// Reads the record's keys back (`path` names the file in errors).
    pub fn from_metadata(
        path: &Path,
        metadata: &BTreeMap<String, String>,
    ) -> Result<RunEnd, crate::read_error::ReadError> {
        let complete = match metadata.get("complete").map(String::as_str) {
            Some("true") => true,
            Some("false") => false,
            _ => {
                return Err(crate::read_error::ReadError::Metadata {
                    path: path.to_path_buf(),
                    record: RUN_END_METADATA,
                    key: "complete".to_owned(),
                    why: "neither `true` nor `false`".to_owned(),
                });
            }
        };
        Ok(RunEnd {
            complete,
            stop_reason: metadata.get("stop_reason").cloned(),
        })
    }
}
