//! Per-stage latency statistics of a multi-process run, from the world's timing logs
//! (`<out>/timing/run-NNNN.json`, a [`TimingLog`] with one [`RobotTiming`] per robot), written as
//! `<out>/profile.json` (a [`LatencyProfile`]), which the report draws. Percentiles are computed
//! here only, by [`stage_stats`] (an HDR histogram, 3 significant digits).
//!
//! Stages per command: `round_trip` (scan published → command received by the world, the tick
//! loop's latency, on the world's clock), `uplink` (scan published → taken by the agent, system
//! clock), `occupancy` and `inference` (measured inside the agent), `downlink` (command published
//! → taken by the world, system clock); only ticks whose command was used count. They are given
//! overall and per agent. Stages per tick: `tick` (from one tick's start to the next: the exchange,
//! the world step and, in realtime or paced lockstep, the wait for the clock) and, in realtime,
//! `tick_jitter` (how late each tick started against the 20 Hz schedule).

use std::collections::BTreeMap;
use std::path::Path;

use formation_proto::wire::{RobotTiming, TickOutcome};
use hdrhistogram::Histogram;

/// The profile and the timing logs it is computed from: defined in [`formation_schema`].
pub use formation_schema::{LatencyProfile, StageStats, TimingLog};

/// The paper's reported inference time \[ms\].
pub const PAPER_INFERENCE_MS: f64 = 2.1;

/// Significant digits the percentiles keep: within 0.1 % of the exact nearest-rank value.
const SIGNIFICANT_DIGITS: u8 = 3;

/// Statistics of nanosecond samples: the percentiles from an HDR histogram (within 0.1 % of the
/// nearest-rank value, never above the largest sample), the exact largest sample, and counts in
/// power-of-two microsecond buckets. This is the one place percentiles of the runtime are
/// computed; the report reads them from `profile.json`.
pub fn stage_stats(samples_ns: &[u64]) -> StageStats {
    let us = |ns: u64| ns as f64 / 1000.0;
    let max = samples_ns.iter().copied().max().unwrap_or(0);
    let mut hdr = Histogram::<u64>::new(SIGNIFICANT_DIGITS)
        .expect("3 significant digits are within hdrhistogram's range");
    let mut buckets: BTreeMap<i32, usize> = BTreeMap::new();
    for &ns in samples_ns {
        // The histogram grows to hold the value; only one past its largest trackable value (far
        // beyond any latency) is clamped.
        if hdr.record(ns).is_err() {
            hdr.saturating_record(ns);
        }
        let exponent = us(ns).max(1.0).log2().ceil() as i32;
        *buckets.entry(exponent).or_default() += 1;
    }
    let percentile = |q: f64| {
        if samples_ns.is_empty() {
            0.0
        } else {
            us(hdr.value_at_quantile(q).min(max))
        }
    };
    StageStats {
        count: samples_ns.len(),
        p50_us: percentile(0.50),
        p90_us: percentile(0.90),
        p99_us: percentile(0.99),
        max_us: us(max),
        histogram: buckets
            .into_iter()
            .map(|(exponent, count)| (f64::from(exponent).exp2(), count))
            .collect(),
    }
}

/// The per-command stage columns of a robot timing log, by stage name.
const COMMAND_STAGES: [&str; 5] = ["round_trip", "uplink", "occupancy", "inference", "downlink"];

fn column<'a>(robot: &'a RobotTiming, stage: &str) -> &'a [u64] {
    match stage {
        "round_trip" => &robot.round_trip_ns,
        "uplink" => &robot.uplink_ns,
        "occupancy" => &robot.occupancy_ns,
        "inference" => &robot.inference_ns,
        _ => &robot.downlink_ns,
    }
}

/// The profile of in-memory timing logs.
pub fn profile(runs: &[TimingLog]) -> LatencyProfile {
    let mut overall: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    let mut per_agent: Vec<BTreeMap<&str, Vec<u64>>> = Vec::new();
    let mut braked: BTreeMap<String, usize> = BTreeMap::new();
    let mut braked_per_robot: Vec<BTreeMap<String, usize>> = Vec::new();
    let mut used = 0;
    for run in runs {
        let starts = &run.tick_start_ns;
        for pair in starts.windows(2) {
            overall
                .entry("tick")
                .or_default()
                .push(pair[1].saturating_sub(pair[0]));
        }
        if run.clock == "realtime" && run.dt_s > 0.0 {
            let dt_ns = run.dt_s * 1e9;
            for (k, &start) in starts.iter().enumerate() {
                let scheduled = (k as f64 * dt_ns).round() as u64;
                overall
                    .entry("tick_jitter")
                    .or_default()
                    .push(start.abs_diff(scheduled));
            }
        }
        if per_agent.len() < run.robots.len() {
            per_agent.resize_with(run.robots.len(), BTreeMap::new);
            braked_per_robot.resize_with(run.robots.len(), BTreeMap::new);
        }
        for (index, robot) in run.robots.iter().enumerate() {
            for tick in 0..robot.ticks() {
                if robot.outcome[tick] != TickOutcome::Fresh {
                    let name = robot.outcome[tick].name();
                    *braked_per_robot[index].entry(name.to_owned()).or_default() += 1;
                    *braked.entry(name.to_owned()).or_default() += 1;
                    continue;
                }
                used += 1;
                for stage in COMMAND_STAGES {
                    if let Some(&v) = column(robot, stage).get(tick) {
                        overall.entry(stage).or_default().push(v);
                        per_agent[index].entry(stage).or_default().push(v);
                    }
                }
            }
        }
    }
    let stats = |columns: BTreeMap<&str, Vec<u64>>| -> BTreeMap<String, StageStats> {
        columns
            .into_iter()
            .map(|(k, v)| (k.to_owned(), stage_stats(&v)))
            .collect()
    };
    LatencyProfile {
        runs: runs.len(),
        clock: runs.first().map(|r| r.clock.clone()).unwrap_or_default(),
        used_commands: used,
        braked,
        braked_per_robot,
        stages: stats(overall),
        per_agent: per_agent.into_iter().map(stats).collect(),
        inference_paper_ms: PAPER_INFERENCE_MS,
    }
}

/// Reads every timing log under `<out>/timing/` and profiles them.
pub fn profile_dir(out: &Path) -> anyhow::Result<LatencyProfile> {
    let dir = out.join("timing");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .map_err(|e| anyhow::anyhow!("reading timing logs in {}: {e}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    let runs = files
        .iter()
        .map(|path| formation_schema::read_timing_log(path))
        .collect::<Result<Vec<_>, _>>()?;
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
    if let Some(inference) = profile.stages.get("inference") {
        text.push_str(&format!(
            "  inference p50 {:.3} ms vs the paper's {} ms\n",
            inference.p50_us / 1000.0,
            profile.inference_paper_ms
        ));
    }
    if profile.per_agent.len() > 1 {
        text.push_str("  per agent (us):  round_trip p50 / p99    inference p50 / p99\n");
        for (robot, stages) in profile.per_agent.iter().enumerate() {
            let pair = |stage: &str| {
                stages
                    .get(stage)
                    .map(|s| format!("{:>8.1} / {:>8.1}", s.p50_us, s.p99_us))
                    .unwrap_or_else(|| format!("{:>19}", "-"))
            };
            text.push_str(&format!(
                "    robot {robot:<3}     {}    {}\n",
                pair("round_trip"),
                pair("inference")
            ));
        }
    }
    text
}

/// Draws the profile's stages (per-stage percentile glyphs beside the paper's inference time) as
/// an SVG, with the same drawing as the report.
pub fn profile_svg(profile: &LatencyProfile, path: &Path) -> anyhow::Result<()> {
    let parsed = formation_report::profile::profile_view(profile, path)?;
    let figure = formation_report::figures::latency_figure(
        "latency",
        &parsed.stages,
        parsed.inference_paper_ms,
    )?;
    Ok(crate::paths::write_atomic(path, figure.svg.as_bytes())?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank_within_a_thousandth() {
        let samples: Vec<u64> = (1..=100).rev().map(|k| k * 1000).collect();
        let stats = stage_stats(&samples);
        assert_eq!((stats.count, stats.max_us), (100, 100.0));
        for (got, exact) in [
            (stats.p50_us, 50.0),
            (stats.p90_us, 90.0),
            (stats.p99_us, 99.0),
        ] {
            assert!((got - exact).abs() <= exact * 1e-3, "{got} vs {exact}");
        }
        assert!(stats.p50_us <= stats.p90_us && stats.p99_us <= stats.max_us);
        assert_eq!(stats.histogram.iter().map(|(_, n)| n).sum::<usize>(), 100);
        assert_eq!(stats.histogram.first(), Some(&(1.0, 1)), "1 us");
        assert_eq!(stats.histogram.last(), Some(&(128.0, 36)), "65..=100 us");
        // Small values are exact; the percentiles never exceed the largest sample.
        let small = stage_stats(&[3, 1500, 1999, 1999]);
        assert_eq!(
            (small.p50_us, small.p99_us, small.max_us),
            (1.5, 1.999, 1.999)
        );
        let one = stage_stats(&[123_456_789]);
        assert_eq!(one.p50_us, one.max_us);
        assert_eq!(stage_stats(&[]).p50_us, 0.0);
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
            lag_ticks: vec![0, 0, 0],
        };
        let run = TimingLog {
            index: 0,
            clock: "realtime".into(),
            dt_s: 0.05,
            tick_start_ns: vec![0, 50_000_000, 101_000_000],
            robots: vec![robot.clone(), robot],
        };
        let p = profile(&[run]);
        assert_eq!(p.used_commands, 4);
        assert_eq!(p.braked.get("missing"), Some(&2));
        assert_eq!(p.braked_per_robot.len(), 2);
        assert_eq!(p.braked_per_robot[1].get("missing"), Some(&1));
        assert_eq!(p.stages["round_trip"].max_us, 4.0);
        assert_eq!(p.stages["round_trip"].count, 4);
        assert_eq!(p.per_agent.len(), 2);
        assert_eq!(p.per_agent[1]["inference"].count, 2);
        assert_eq!(p.stages["tick"].count, 2);
        assert_eq!(p.stages["tick"].max_us, 51_000.0);
        // The third tick started 1 ms late against the 50 ms schedule.
        assert_eq!(p.stages["tick_jitter"].max_us, 1000.0);
    }
}
