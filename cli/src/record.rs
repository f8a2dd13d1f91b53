//! `--record`: what the commands share to record their runs with `formation-record`.
//!
//! `formation run`, `profile` and `demo` take `--record FILE.mcap`, `formation eval` takes
//! `--record DIR` (one `run-NNNN.mcap` per run, for at most `--record-runs` runs). The target
//! is checked before anything runs ([`formation_record::RecordTarget::check`]); in-process runs
//! are recorded here ([`record_in_process`]), runs over processes by the world process, which
//! the launcher hands a [`RecordSettings`] file. A write that fails mid-run ends the recording
//! with a message ([`report_failure`]), never the run.

use std::path::{Path, PathBuf};

use formation_proto::control::Controller;
use formation_record::{
    LaunchInfo, RecordError, RecordSettings, RecordTarget, RecordedController, Recorder,
    RecordingSetup, RecordingSummary,
};
use formation_world::{RunSpec, Scenario, Trajectory, run_episode};

/// The folder of the shipped models, which a recording references by hash.
pub fn shipped_models() -> PathBuf {
    crate::paths::repo_root().join("onnx/models")
}

/// What a launch of `scenario` knows of its runs, for their recordings.
pub fn launch_info(
    scenario: &Scenario,
    base_seed: u64,
    clock: &str,
    controller: &str,
    models: &[PathBuf],
) -> LaunchInfo {
    LaunchInfo {
        scenario: scenario.name().to_owned(),
        base_seed: Some(base_seed),
        clock: clock.to_owned(),
        controller: controller.to_owned(),
        models: models.to_vec(),
        shipped_models: Some(shipped_models()),
    }
}

/// The settings of `target` for a launch, checked before anything runs.
pub fn checked_settings(
    target: RecordTarget,
    launch: LaunchInfo,
) -> anyhow::Result<RecordSettings> {
    target.check()?;
    Ok(RecordSettings { target, launch })
}

/// Says that a recording stopped, and that the run goes on.
pub fn report_failure(error: &RecordError) {
    eprintln!(
        "formation: recording stopped: {}; the run goes on without it, and its other outputs \
         are written as usual",
        formation_proto::errors::chain_text(error)
    );
}

/// Says where a finished recording is.
pub fn report_done(summary: &RecordingSummary) {
    println!(
        "recorded {} ({} messages, {:.1} MB)",
        summary.path.display(),
        summary.messages,
        summary.bytes as f64 / 1e6
    );
}

/// Records the in-process runs that `settings` asks for, each a fresh controller from
/// `controller` replaying run `i` of `scenario` (every run is a pure function of its spec, so
/// the recording is of the very run that was evaluated: its trajectory is compared with
/// `evaluated(i)`, when there is one, bit for bit).
pub fn record_in_process(
    scenario: &Scenario,
    base_seed: u64,
    runs: usize,
    settings: &RecordSettings,
    model_ids: &[String],
    controller: &dyn Fn() -> anyhow::Result<Box<dyn Controller>>,
    evaluated: &dyn Fn(usize) -> Option<Trajectory>,
) -> anyhow::Result<()> {
    for (nth, index) in (0..runs).enumerate() {
        let Some(path) = settings.target.path_for(index, nth, runs) else {
            break;
        };
        let spec = scenario.run_spec(base_seed, index);
        let mut inner = controller()?;
        let trajectory = match record_one(&spec, &path, &settings.launch, model_ids, inner.as_mut())
        {
            Ok(t) => t,
            Err(e) => {
                report_failure(&e);
                return Ok(());
            }
        };
        if let (Some(recorded), Some(expected)) = (trajectory, evaluated(index))
            && recorded != expected
        {
            anyhow::bail!(
                "the recording of run {index} ({}) differs from the run that was evaluated: \
                 in-process runs are meant to be deterministic; please report this",
                path.display()
            );
        }
    }
    Ok(())
}

/// Records run `spec` into `path`; the trajectory when the run played to its end.
fn record_one(
    spec: &RunSpec,
    path: &Path,
    launch: &LaunchInfo,
    model_ids: &[String],
    inner: &mut dyn Controller,
) -> Result<Option<Trajectory>, RecordError> {
    let recorder = Recorder::start(path, RecordingSetup::for_run(spec, launch))?;
    let mut failure = None;
    let mut on_failure = |e: &RecordError| {
        report_failure(e);
        failure = Some(());
    };
    let mut recorded =
        RecordedController::new(inner, recorder, model_ids.to_vec(), &mut on_failure);
    let played = run_episode(spec, &mut recorded, &mut |_, _| {});
    let finished = match &played {
        Ok(trajectory) => recorded.finish(Some(trajectory)),
        Err(e) => recorded.finish_stopped(&e.to_string()),
    };
    let played = played.ok();
    match finished {
        Ok(Some(summary)) => report_done(&summary),
        Ok(None) => {}
        Err(e) => report_failure(&e),
    }
    Ok(played)
}
