//! Per-stage latency statistics of a multi-process run, from the world's timing logs
//! (`<out>/timing/run-NNNN.json`, one [`RobotTiming`] per robot), written as `<out>/profile.json`
//! in the schema the report draws.
//!
//! Stages: `round_trip` (scan published → command received by the world, the tick loop's
//! latency, on the world's clock), `uplink` (scan published → taken by the agent, system clock),
//! `occupancy` and `inference` (measured inside the agent), `downlink` (command published → taken
//! by the world, system clock). Only ticks whose command was used count.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context;
use formation_proto::wire::{RobotTiming, TickOutcome};
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
    /// Robot-ticks whose command was used.
    pub used_commands: usize,
    /// Robot-ticks braked by the watchdog, by reason.
    pub braked: BTreeMap<String, usize>,
    /// Per-stage statistics, by stage name.
    pub stages: BTreeMap<String, StageStats>,
    /// The paper's single-sample inference time \[ms\], for comparison in the report.
    pub inference_paper_ms: f64,
}

/// The paper's reported inference time \[ms\].
pub const PAPER_INFERENCE_MS: f64 = 2.1;

/// Quantile by nearest rank of sorted samples.
fn quantile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Statistics of nanosecond samples.
pub fn stage_stats(mut samples_ns: Vec<u64>) -> StageStats {
    samples_ns.sort_unstable();
    let us = |ns: u64| ns as f64 / 1000.0;
    let mut histogram: Vec<(f64, usize)> = Vec::new();
    for &ns in &samples_ns {
        let edge_us = (us(ns).max(1.0)).log2().ceil().exp2();
        match histogram.last_mut() {
            Some((edge, count)) if *edge == edge_us => *count += 1,
            _ => histogram.push((edge_us, 1)),
        }
    }
    StageStats {
        count: samples_ns.len(),
        p50_us: us(quantile(&samples_ns, 0.50)),
        p90_us: us(quantile(&samples_ns, 0.90)),
        p99_us: us(quantile(&samples_ns, 0.99)),
        max_us: us(samples_ns.last().copied().unwrap_or(0)),
        histogram,
    }
}

/// The profile of in-memory timing logs.
pub fn profile(runs: &[Vec<RobotTiming>]) -> LatencyProfile {
    let mut columns: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    let mut braked: BTreeMap<String, usize> = BTreeMap::new();
    let mut used = 0;
    for robots in runs {
        for robot in robots {
            for tick in 0..robot.ticks() {
                if robot.outcome[tick] != TickOutcome::Fresh {
                    let name = serde_json::to_value(robot.outcome[tick])
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_owned))
                        .unwrap_or_default();
                    *braked.entry(name).or_default() += 1;
                    continue;
                }
                used += 1;
                let mut push = |stage, column: &[u64]| {
                    if let Some(&v) = column.get(tick) {
                        columns.entry(stage).or_default().push(v);
                    }
                };
                push("round_trip", &robot.round_trip_ns);
                push("uplink", &robot.uplink_ns);
                push("occupancy", &robot.occupancy_ns);
                push("inference", &robot.inference_ns);
                push("downlink", &robot.downlink_ns);
            }
        }
    }
    LatencyProfile {
        runs: runs.len(),
        used_commands: used,
        braked,
        stages: columns
            .into_iter()
            .map(|(k, v)| (k.to_owned(), stage_stats(v)))
            .collect(),
        inference_paper_ms: PAPER_INFERENCE_MS,
    }
}

/// Reads every timing log under `<out>/timing/` and profiles them.
pub fn profile_dir(out: &Path) -> anyhow::Result<LatencyProfile> {
    #[derive(Deserialize)]
    struct TimingLog {
        robots: Vec<RobotTiming>,
    }
    let dir = out.join("timing");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading timing logs in {}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    let runs = files
        .iter()
        .map(|path| {
            let bytes =
                std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            let log: TimingLog = serde_json::from_slice(&bytes)
                .with_context(|| format!("parsing {}", path.display()))?;
            Ok(log.robots)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(profile(&runs))
}

/// A short text table of the profile.
pub fn summary_text(profile: &LatencyProfile) -> String {
    let mut text = format!(
        "latency over {} run(s), {} commands used{}\n",
        profile.runs,
        profile.used_commands,
        if profile.braked.is_empty() {
            String::new()
        } else {
            format!(", braked: {:?}", profile.braked)
        }
    );
    for (stage, s) in &profile.stages {
        text.push_str(&format!(
            "  {stage:<11} p50 {:>9.1} us  p90 {:>9.1} us  p99 {:>9.1} us  max {:>9.1} us\n",
            s.p50_us, s.p90_us, s.p99_us, s.max_us
        ));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_use_nearest_rank() {
        let samples: Vec<u64> = (1..=100).map(|k| k * 1000).collect();
        let stats = stage_stats(samples);
        assert_eq!(
            (stats.count, stats.p50_us, stats.p99_us, stats.max_us),
            (100, 50.0, 99.0, 100.0)
        );
        assert_eq!(stats.histogram.iter().map(|(_, n)| n).sum::<usize>(), 100);
        assert_eq!(stage_stats(Vec::new()).p50_us, 0.0);
    }

    #[test]
    fn only_used_commands_count_and_brakes_are_tallied() {
        let robot = RobotTiming {
            model_ids: vec!["m".into()],
            model: vec![0, -1, 0],
            outcome: vec![TickOutcome::Fresh, TickOutcome::Missing, TickOutcome::Fresh],
            round_trip_ns: vec![2000, 0, 4000],
            uplink_ns: vec![500, 0, 700],
            occupancy_ns: vec![10, 0, 20],
            inference_ns: vec![30, 0, 40],
            downlink_ns: vec![100, 0, 200],
        };
        let p = profile(&[vec![robot]]);
        assert_eq!(p.used_commands, 2);
        assert_eq!(p.braked.get("missing"), Some(&1));
        assert_eq!(p.stages["round_trip"].max_us, 4.0);
        assert_eq!(p.stages["round_trip"].count, 2);
    }
}
