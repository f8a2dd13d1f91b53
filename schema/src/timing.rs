//! The timing log (`timing/run-NNNN.json`): per tick, when the world began it and what became of
//! every robot's command.

use formation_proto::wire::RobotTiming;
use serde::{Deserialize, Serialize};

/// One run's per-tick timing log, written by the world process. The per-robot records
/// ([`RobotTiming`], with their [`TickOutcome`](formation_proto::wire::TickOutcome)s) are filled
/// by the world's exchange, so they are defined beside the wire messages they are taken from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimingLog {
    /// Run index within the scenario.
    pub index: usize,
    /// `lockstep` or `realtime`.
    pub clock: String,
    /// The tick period the world steps with \[s\].
    pub dt_s: f64,
    /// Per tick: when the world began it (published the scans), since the first tick began \[ns\].
    pub tick_start_ns: Vec<u64>,
    /// One column-wise record per robot.
    pub robots: Vec<RobotTiming>,
}
