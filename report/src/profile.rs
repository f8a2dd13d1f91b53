//! Latency profiles of the multi-process runtime (`profile.json`, a
//! [`formation_schema::LatencyProfile`]), drawn as per-stage percentile glyphs beside the paper's
//! 2.1 ms inference time.
//!
//! The stages are drawn in pipeline order ([`PIPELINE_ORDER`], then other names
//! alphabetically); a stage with no samples is left out. `runs`, `used_commands` and `braked`
//! are shown in the caption. The percentiles are the ones `formation run` computed; the report
//! computes none.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::ReportError;

/// A latency profile.
#[derive(Debug, Clone, PartialEq)]
pub struct LatencyProfile {
    /// The file it was read from.
    pub source: PathBuf,
    /// Stages, in drawing order.
    pub stages: Vec<StageLatency>,
    /// The paper's reference inference time \[ms\], if given.
    pub inference_paper_ms: Option<f64>,
    /// Runs the profile covers, if given.
    pub runs: Option<u64>,
    /// Robot-ticks whose command was used, if given.
    pub used_commands: Option<u64>,
    /// Robot-ticks braked by the watchdog, by reason.
    pub braked: BTreeMap<String, u64>,
}

/// Stage names in the order a tick flows through the runtime; a map's stages are drawn in this
/// order.
pub const PIPELINE_ORDER: [&str; 6] = [
    "scan",
    "uplink",
    "occupancy",
    "inference",
    "downlink",
    "round_trip",
];

/// Percentiles of one stage, in microseconds, as drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct StageLatency {
    /// Stage name.
    pub name: String,
    /// Median.
    pub p50_us: f64,
    /// 90th percentile.
    pub p90_us: Option<f64>,
    /// 99th percentile.
    pub p99_us: Option<f64>,
    /// Largest sample.
    pub max_us: Option<f64>,
    /// Number of samples, if given.
    pub count: Option<u64>,
}

/// Parses a latency profile.
pub fn parse_profile(text: &str, source: &Path) -> Result<LatencyProfile, ReportError> {
    profile_view(
        &formation_schema::from_json(text.as_bytes(), source)?,
        source,
    )
}

/// The stages of `profile` (read from `source`) in drawing order, checked.
pub fn profile_view(
    profile: &formation_schema::LatencyProfile,
    source: &Path,
) -> Result<LatencyProfile, ReportError> {
    let mut stages: Vec<StageLatency> = profile
        .stages
        .iter()
        .map(|(name, stage)| StageLatency {
            name: name.clone(),
            p50_us: stage.p50_us,
            p90_us: Some(stage.p90_us),
            p99_us: Some(stage.p99_us),
            max_us: Some(stage.max_us),
            count: Some(stage.count as u64),
        })
        .collect();
    let rank = |name: &str| {
        PIPELINE_ORDER
            .iter()
            .position(|p| *p == name)
            .unwrap_or(PIPELINE_ORDER.len())
    };
    stages.sort_by(|a, b| (rank(&a.name), &a.name).cmp(&(rank(&b.name), &b.name)));
    stages.retain(|stage| stage.count != Some(0));
    let invalid = |reason: String| ReportError::InvalidData {
        path: source.to_path_buf(),
        reason,
    };
    if stages.is_empty() {
        return Err(invalid(
            "`stages` is empty (or every stage has `count` 0)".into(),
        ));
    }
    for stage in &stages {
        let values = [Some(stage.p50_us), stage.p90_us, stage.p99_us, stage.max_us];
        if values
            .iter()
            .flatten()
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(invalid(format!(
                "stage `{}` has a negative or non-finite latency",
                stage.name
            )));
        }
    }
    Ok(LatencyProfile {
        source: source.to_path_buf(),
        stages,
        inference_paper_ms: Some(profile.inference_paper_ms),
        runs: Some(profile.runs as u64),
        used_commands: Some(profile.used_commands as u64),
        braked: profile
            .braked
            .iter()
            .map(|(why, &n)| (why.clone(), n as u64))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_schema::StageStats;

    fn stats(count: usize, p50_us: f64) -> StageStats {
        StageStats {
            count,
            p50_us,
            p90_us: 1.2 * p50_us,
            p99_us: 1.5 * p50_us,
            max_us: 3.0 * p50_us,
            histogram: vec![(1024.0, count)],
        }
    }

    fn profile(stages: &[(&str, StageStats)]) -> formation_schema::LatencyProfile {
        formation_schema::LatencyProfile {
            runs: 2,
            clock: "lockstep".into(),
            used_commands: 1200,
            braked: BTreeMap::from([("missing".to_owned(), 3)]),
            braked_per_robot: Vec::new(),
            stages: stages
                .iter()
                .map(|(name, s)| ((*name).to_owned(), s.clone()))
                .collect(),
            per_agent: Vec::new(),
            inference_paper_ms: 2.1,
        }
    }

    #[test]
    fn stages_are_drawn_in_pipeline_order() {
        let written = profile(&[
            ("round_trip", stats(600, 900.0)),
            ("custom", stats(5, 5.0)),
            ("inference", stats(600, 700.0)),
            ("uplink", stats(0, 0.0)),
        ]);
        let text = String::from_utf8(formation_schema::to_json_pretty(&written).unwrap()).unwrap();
        let profile = parse_profile(&text, Path::new("profile.json")).expect("profile");
        let names: Vec<&str> = profile.stages.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            ["inference", "round_trip", "custom"],
            "pipeline order, empty stage left out"
        );
        assert_eq!(profile.stages[0].max_us, Some(2100.0));
        assert_eq!(profile.stages[1].p99_us, Some(1350.0));
        assert_eq!(profile.inference_paper_ms, Some(2.1));
        assert_eq!((profile.runs, profile.used_commands), (Some(2), Some(1200)));
        assert_eq!(profile.braked.get("missing"), Some(&3));
    }

    #[test]
    fn invalid_profiles_name_the_file() {
        let path = Path::new("p/profile.json");
        for written in [
            profile(&[]),
            profile(&[("uplink", stats(0, 0.0))]),
            profile(&[("a", stats(3, -1.0))]),
        ] {
            let err = profile_view(&written, path).expect_err("invalid");
            assert!(err.to_string().contains("p/profile.json"), "{err}");
        }
        let text = String::from_utf8(
            formation_schema::to_json(&profile(&[("a", stats(3, 1.0))])).unwrap(),
        )
        .unwrap();
        let err = parse_profile(&text[..text.len() / 2], path).expect_err("truncated");
        assert!(err.to_string().contains("p/profile.json"), "{err}");
    }
}
