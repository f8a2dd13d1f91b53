//! The latency profile (`profile.json`): per-stage latency statistics of a multi-process run,
//! computed from its timing logs by `formation run`, `formation profile` and
//! `formation eval --processes --out`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Statistics of one stage, in microseconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageStats {
    /// Samples.
    pub count: usize,
    /// Median \[us\].
    pub p50_us: f64,
    /// 90th percentile \[us\].
    pub p90_us: f64,
    /// 99th percentile \[us\].
    pub p99_us: f64,
    /// Largest \[us\].
    pub max_us: f64,
    /// Histogram: upper bucket edges \[us\] (powers of two) and counts.
    pub histogram: Vec<(f64, usize)>,
}

/// The latency profile of a run directory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatencyProfile {
    /// Runs read.
    pub runs: usize,
    /// `lockstep` or `realtime` (of the first run; empty when unknown).
    pub clock: String,
    /// Robot-ticks whose command was used.
    pub used_commands: usize,
    /// Robot-ticks braked by the watchdog, by reason.
    pub braked: BTreeMap<String, usize>,
    /// Per robot: its ticks braked by the watchdog, by reason (empty maps for robots never
    /// braked). Absent in profiles written before it existed.
    #[serde(default)]
    pub braked_per_robot: Vec<BTreeMap<String, usize>>,
    /// Per-stage statistics over every agent and tick, by stage name.
    pub stages: BTreeMap<String, StageStats>,
    /// Per agent (robot index): its per-command stages.
    pub per_agent: Vec<BTreeMap<String, StageStats>>,
    /// The paper's single-sample inference time \[ms\], for comparison in the report.
    pub inference_paper_ms: f64,
}
