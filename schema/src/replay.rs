//! The replay report (`formation replay --json`): per robot, how far the replayed commands are
//! from the recorded ones, computed by `formation replay`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One robot's replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayRobot {
    /// The robot.
    pub robot: u32,
    /// Replay steps read for it.
    pub steps: u64,
    /// Steps whose command was decided again and compared (the fresh ones), failed decisions
    /// included.
    pub compared: u64,
    /// Steps not compared because the world did not use an agent's fresh answer, by outcome
    /// (`missing`, `stale`, `non_finite`, `agent_failed`, `agent_down`).
    pub skipped: BTreeMap<String, u64>,
    /// Steps not compared because they cannot be decided again, by reason (`unknown_model`: a
    /// model the recording does not hold, swapped in from outside it; `scan_not_recorded`: a
    /// realtime answer to a scan older than the recording holds).
    pub unreplayable: BTreeMap<String, u64>,
    /// Compared steps whose replayed command is not bit for bit the recorded one.
    pub differing: u64,
    /// Compared steps whose replayed decision failed (no command).
    pub failed: u64,
    /// Median over the compared steps that gave a command of `max(|Δleft|, |Δright|)` \[m/s\]
    /// (nearest rank; 0 for an identical command).
    pub p50_abs_delta: f64,
    /// Its 99th percentile \[m/s\].
    pub p99_abs_delta: f64,
    /// Its largest value \[m/s\].
    pub max_abs_delta: f64,
    /// The first tick whose command differs (or whose decision failed).
    pub first_differing_tick: Option<u64>,
    /// The last such tick.
    pub last_differing_tick: Option<u64>,
    /// The first differing ticks, at most [`ReplayReport::LISTED_TICKS`].
    pub differing_ticks: Vec<u64>,
}

/// The replay of one recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayReport {
    /// The recording.
    pub recording: String,
    /// How the run was clocked (`in-process`, `lockstep`, `realtime`; empty if unknown).
    pub clock: String,
    /// The models that decided: the recording's own (by path), or the one `--model` named.
    pub models: Vec<String>,
    /// Whether `--model` replaced the recording's models.
    pub model_override: bool,
    /// Whether the whole run was replayed: false when the file is truncated (replayed up to the
    /// cut) or when the run itself stopped early (`stop_reason`), as its run log says.
    pub complete: bool,
    /// Why the recorded run stopped before its last tick (Ctrl-C, SIGTERM, an agent that
    /// stopped answering), as its recording says; absent for a run that played to its end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
    /// Bytes of the recording read.
    pub bytes_read: u64,
    /// Per robot replayed, in robot order.
    pub robots: Vec<ReplayRobot>,
    /// Whether any compared command differs or failed.
    pub diverged: bool,
}

impl ReplayReport {
    /// How many differing ticks a robot's row lists.
    pub const LISTED_TICKS: usize = 100;
}
