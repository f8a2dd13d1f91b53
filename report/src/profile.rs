//! Latency profiles of the multi-process runtime (`profile.json`), drawn as per-stage percentile
//! glyphs beside the paper's 2.1 ms inference time.
//!
//! The schema is deliberately tolerant:
//!
//! ```json
//! { "stages": { "scan": {"p50_us": 40, "p90_us": 55, "p99_us": 90, "max_us": 300}, ... },
//!   "inference_paper_ms": 2.1 }
//! ```
//!
//! `stages` may also be a list of objects with a `name`, drawn in list order; an object map is drawn
//! in pipeline order ([`PIPELINE_ORDER`], then other names alphabetically). `p50`/`p90`/`p99`/`max`
//! are accepted without the `_us` suffix; only the median is required; a stage with `"count": 0`
//! has no samples and is left out. `runs`, `used_commands` and `braked` (what `formation profile`
//! writes) are shown in the caption; any other key (histogram bins, ...) is ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

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

/// Percentiles of one stage, in microseconds.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct StageLatency {
    /// Stage name.
    #[serde(default)]
    pub name: String,
    /// Median.
    #[serde(alias = "p50")]
    pub p50_us: f64,
    /// 90th percentile.
    #[serde(default, alias = "p90")]
    pub p90_us: Option<f64>,
    /// 99th percentile.
    #[serde(default, alias = "p99")]
    pub p99_us: Option<f64>,
    /// Largest sample.
    #[serde(default, alias = "max")]
    pub max_us: Option<f64>,
    /// Number of samples, if given.
    #[serde(default)]
    pub count: Option<u64>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawStages {
    List(Vec<StageLatency>),
    Map(BTreeMap<String, StageLatency>),
}

#[derive(Deserialize)]
struct RawProfile {
    stages: RawStages,
    #[serde(default)]
    inference_paper_ms: Option<f64>,
    #[serde(default)]
    runs: Option<u64>,
    #[serde(default)]
    used_commands: Option<u64>,
    #[serde(default)]
    braked: BTreeMap<String, u64>,
}

/// Parses a latency profile.
pub fn parse_profile(text: &str, source: &Path) -> Result<LatencyProfile, ReportError> {
    let raw: RawProfile = serde_json::from_str(text).map_err(|e| ReportError::Json {
        path: source.to_path_buf(),
        source: e,
    })?;
    let mut stages: Vec<StageLatency> = match raw.stages {
        RawStages::List(list) => list,
        RawStages::Map(map) => {
            let mut stages: Vec<StageLatency> = map
                .into_iter()
                .map(|(name, stage)| StageLatency { name, ..stage })
                .collect();
            let rank = |name: &str| {
                PIPELINE_ORDER
                    .iter()
                    .position(|p| *p == name)
                    .unwrap_or(PIPELINE_ORDER.len())
            };
            stages.sort_by(|a, b| (rank(&a.name), &a.name).cmp(&(rank(&b.name), &b.name)));
            stages
        }
    };
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
        inference_paper_ms: raw.inference_paper_ms,
        runs: raw.runs,
        used_commands: raw.used_commands,
        braked: raw.braked,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_and_list_forms() {
        // The shape `formation profile` writes.
        let map = r#"{"runs": 2, "used_commands": 1200, "braked": {"late": 3},
                      "stages": {"round_trip": {"count": 600, "p50_us": 900, "p90_us": 1000, "p99_us": 1500, "max_us": 3000,
                                                "histogram": [[1024.0, 10], [2048.0, 5]]},
                                 "custom": {"p50": 5},
                                 "inference": {"count": 600, "p50": 700, "max": 4000},
                                 "uplink": {"count": 0, "p50_us": 0}},
                      "inference_paper_ms": 2.1}"#;
        let profile = parse_profile(map, Path::new("profile.json")).expect("map form");
        let names: Vec<&str> = profile.stages.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            ["inference", "round_trip", "custom"],
            "pipeline order, empty stage left out"
        );
        assert_eq!(profile.stages[0].max_us, Some(4000.0));
        assert_eq!(profile.stages[1].p99_us, Some(1500.0));
        assert_eq!(profile.inference_paper_ms, Some(2.1));
        assert_eq!((profile.runs, profile.used_commands), (Some(2), Some(1200)));
        assert_eq!(profile.braked.get("late"), Some(&3));

        let list =
            r#"{"stages": [{"name": "world", "p50_us": 10}, {"name": "agent", "p50_us": 20}]}"#;
        let profile = parse_profile(list, Path::new("profile.json")).expect("list form");
        assert_eq!(profile.stages[0].name, "world", "list keeps its order");
    }

    #[test]
    fn invalid_profiles_name_the_file() {
        for text in [
            r#"{"stages": {}}"#,
            r#"{"stages": {"a": {"p50_us": -1}}}"#,
            r#"{"stages": "#,
        ] {
            let err = parse_profile(text, Path::new("p/profile.json")).expect_err(text);
            assert!(err.to_string().contains("p/profile.json"), "{err}");
        }
    }
}
