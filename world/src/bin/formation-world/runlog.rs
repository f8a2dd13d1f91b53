//! The run logs the world writes: per run, the trajectory with its metrics (the same shape as
//! `formation eval --out` writes, so the report reads both) and the per-tick timing log.
//!
//! Layout under the output directory: `runs/run-NNNN.json` and `timing/run-NNNN.json`. Every file
//! is written to a temporary name in the same directory and renamed, so a reader never sees half a
//! file. Progress goes to stdout as one JSON object per line ([`WorldEvent`]), for the launcher.

use std::path::{Path, PathBuf};

use formation_proto::wire::{RobotTiming, WorldEvent};
use formation_world::Trajectory;
use formation_world::metrics::RunMetrics;
use serde::{Deserialize, Serialize};

/// One run's trajectory log.
#[derive(Debug, Serialize, Deserialize)]
pub struct RunLog {
    /// Run index within the scenario.
    pub index: usize,
    /// The paper's metrics of the run.
    pub metrics: RunMetrics,
    /// The full trajectory, exactly as the world recorded it.
    pub trajectory: Trajectory,
    /// `lockstep` or `realtime`.
    pub clock: String,
    /// The model each robot's agent last reported.
    pub models: Vec<String>,
}

/// One run's per-tick timing log.
#[derive(Debug, Serialize, Deserialize)]
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

/// Prints one progress event line on stdout, for the launcher.
pub fn emit(event: &WorldEvent) {
    println!("{}", event.to_line());
}

/// Paths of run `index`'s logs under `out`.
pub fn log_paths(out: &Path, index: usize) -> (PathBuf, PathBuf) {
    let name = format!("run-{index:04}.json");
    (out.join("runs").join(&name), out.join("timing").join(name))
}

/// Writes `bytes` to `path` through a temporary file in the same directory.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    use anyhow::Context;
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))?;
    Ok(())
}
