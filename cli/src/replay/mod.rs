//! `formation replay FILE.mcap [--model M] [--swap-model S]... [--robot I] [--json OUT]`: a recording's inputs fed
//! through the agent's decision again and compared with its commands ([`engine`]), tallied per
//! robot ([`divergence`]), printed as a table and written as JSON (`formation_schema::ReplayReport`).
//!
//! The recording's own models include those swapped in during the run, which the world's
//! recording stores; `--swap-model` gives one it lacks. With them every command must come back
//! bit for bit: a regression check for the renderer, the decision and the runtime. With
//! `--model`, the table says how far another model's commands are from the recorded ones. Exit
//! status: 0 when nothing differs, 1 ([`Diverged`]) when something does, 2 for an error; a
//! truncated recording is replayed up to the cut, its report written, and then refused (2) with
//! the byte where it ends.

pub mod divergence;
pub mod engine;

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use formation_schema::ReplayReport;

use crate::args::ReplayArgs;
use crate::paths;
use formation_robot_agent::pilot::OnnxPilots;

pub use engine::{ReplayFailure, ReplayOptions, Replayed, replay_recording};

/// A replay found commands that are not the recorded ones (exit status 1).
#[derive(Debug, thiserror::Error)]
#[error(
    "the replay of {recording} diverged: {robots} robot(s) with differing commands (see the \
     table above and {json})"
)]
pub struct Diverged {
    /// The recording.
    pub recording: String,
    /// How many robots differ.
    pub robots: usize,
    /// The JSON report.
    pub json: String,
}

/// Where the JSON goes by default: `FILE.replay.json` beside `FILE.mcap`.
pub fn default_json_path(recording: &Path) -> PathBuf {
    recording.with_extension("replay.json")
}

/// Runs `formation replay`.
pub fn replay_command(args: &ReplayArgs) -> anyhow::Result<()> {
    let scratch = tempfile::Builder::new()
        .prefix("formation-replay-")
        .tempdir()
        .map_err(|e| anyhow::anyhow!("cannot make a scratch folder for the models: {e}"))?;
    let options = ReplayOptions {
        model: args.model.clone(),
        robot: args.robot,
        swapped: args.swap_model.clone(),
    };
    let replayed = replay_recording(&args.file, &options, &OnnxPilots, scratch.path())?;
    let report = &replayed.report;
    // The JSON is the lasting output: a closed stdout (`| head`) must not stop it being written.
    let mut stdout = std::io::stdout().lock();
    let _ = stdout.write_all(table(report).as_bytes());
    for note in &replayed.notes {
        let _ = writeln!(stdout, "{note}");
    }
    let json = args
        .json
        .clone()
        .unwrap_or_else(|| default_json_path(&args.file));
    paths::write_atomic(&json, &formation_schema::to_json_pretty(report)?)?;
    let _ = writeln!(stdout, "replay report: {}", json.display());
    if let Some(cut) = replayed.truncated {
        return Err(cut.into());
    }
    if report.diverged {
        return Err(Diverged {
            recording: report.recording.clone(),
            robots: report
                .robots
                .iter()
                .filter(|r| r.differing + r.failed > 0)
                .count(),
            json: json.display().to_string(),
        }
        .into());
    }
    Ok(())
}

/// The report as a table: one row per robot.
pub fn table(report: &ReplayReport) -> String {
    let mut out = String::new();
    let models = report.models.join(", ");
    let whose = if report.model_override {
        "--model"
    } else {
        "recorded"
    };
    let _ = writeln!(
        out,
        "replay of {} ({} clock), {whose} model(s): {models}",
        report.recording,
        if report.clock.is_empty() {
            "unknown"
        } else {
            &report.clock
        },
    );
    let _ = writeln!(
        out,
        "{:>5} {:>7} {:>8} {:>7} {:>8} {:>9} {:>6} {:>11} {:>11} {:>11} {:>7} {:>7}",
        "robot",
        "steps",
        "compared",
        "skipped",
        "no-model",
        "differing",
        "failed",
        "p50 |d| m/s",
        "p99 |d| m/s",
        "max |d| m/s",
        "first",
        "last"
    );
    for r in &report.robots {
        let tick = |t: Option<u64>| t.map_or_else(|| "-".to_owned(), |t| t.to_string());
        let _ = writeln!(
            out,
            "{:>5} {:>7} {:>8} {:>7} {:>8} {:>9} {:>6} {:>11.3e} {:>11.3e} {:>11.3e} {:>7} {:>7}",
            r.robot,
            r.steps,
            r.compared,
            r.skipped.values().sum::<u64>(),
            r.unreplayable.values().sum::<u64>(),
            r.differing,
            r.failed,
            r.p50_abs_delta,
            r.p99_abs_delta,
            r.max_abs_delta,
            tick(r.first_differing_tick),
            tick(r.last_differing_tick),
        );
    }
    let unknown: u64 = report
        .robots
        .iter()
        .filter_map(|r| r.unreplayable.get("unknown_model"))
        .sum();
    if unknown > 0 {
        let _ = writeln!(
            out,
            "{unknown} step(s) name a model this replay does not have (one swapped in during the \
             run that the recording does not hold?): give it with --swap-model FILE.onnx"
        );
    }
    let verdict = if report.diverged {
        "DIVERGED: some replayed commands differ from the recorded ones"
    } else {
        "identical: every compared command is bit for bit the recorded one"
    };
    let _ = writeln!(out, "{verdict}");
    if let Some(reason) = &report.stop_reason {
        let _ = writeln!(
            out,
            "the run is incomplete: it stopped before its last tick ({reason}); every tick it \
             recorded was replayed"
        );
    } else if !report.complete {
        let _ = writeln!(
            out,
            "the recording is truncated: replayed up to byte {}",
            report.bytes_read
        );
    }
    out
}
