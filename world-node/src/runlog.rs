//! Writing one run's logs as it plays: the run journal while it goes, the final run and timing
//! logs at the end, and an incomplete run log when it ends early. The formats themselves are
//! defined once, in [`formation_world::runlog`].
//!
//! Layout under the output directory: `runs/run-NNNN.journal` while a run plays, then
//! `runs/run-NNNN.json` and `timing/run-NNNN.json`. Progress goes to stdout as one JSON object
//! per line ([`WorldEvent`]), for the launcher.

use std::path::{Path, PathBuf};

use formation_proto::WheelCmd;
use formation_proto::control::{Controller, ControllerError, Observation};
use formation_proto::wire::TickOutcome;
use formation_proto::wire::WorldEvent;
use formation_record::{Recorder, SentCommand, TickRecord};
use formation_world::metrics::{MetricsConfig, run_metrics};
use formation_world::runlog::{
    JournalHeader, RunJournal, RunLogError, journal_path, recover_journal, write_json_atomic,
};
#[allow(unused_imports)] // the rest of the binary names them from here
pub use formation_world::runlog::{RunLog, TimingLog, log_paths, write_atomic};
use formation_world::{EpisodeError, RunSpec, run_episode_recorded};

use crate::live_view::LiveView;
use formation_record::live::{LiveMessage, LiveSetup, encode};
use formation_runtime::exchange::AgentsController;
use formation_runtime::link::RecordFeed;

/// Prints one progress event line on stdout, for the launcher.
pub fn emit(event: &WorldEvent) {
    println!("{}", event.to_line());
}

/// Why a journaled run ended without its final logs.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The run journal could not be created; nothing was played.
    #[error(transparent)]
    Start(RunLogError),
    /// The agents exchange stopped the episode (a signal, the launcher, an agent refusing).
    #[error("the run stopped early{}", saved_note(saved))]
    Stopped {
        /// What stopped it.
        #[source]
        cause: ControllerError,
        /// What became of the partial run.
        saved: Saved,
    },
    /// The journal or a final log could not be written.
    #[error("the run could not be saved{}", saved_note(saved))]
    Write {
        /// The failed write.
        #[source]
        cause: RunLogError,
        /// What became of the run.
        saved: Saved,
    },
}

/// What became of a run that ended without its final logs.
#[derive(Debug)]
pub enum Saved {
    /// Written as an incomplete run log.
    Partial(PathBuf),
    /// Left in its journal, which `formation report` (or the launcher) turns into a run log.
    Journal(PathBuf),
    /// Nothing could be kept: why.
    Lost(RunLogError),
}

/// `; <what was kept>`; the cause follows as the error's source.
fn saved_note(saved: &Saved) -> String {
    match saved {
        Saved::Partial(path) => format!("; the partial run is kept in {}", path.display()),
        Saved::Journal(path) => format!(
            "; it is kept in its journal {} (`formation report` recovers it once there is room)",
            path.display()
        ),
        Saved::Lost(e) => format!("; nothing could be kept ({e})"),
    }
}

/// Plays `spec` with the agents, journaling every step to `out/runs/run-NNNN.journal`. On success
/// writes `runs/run-NNNN.json` and the timing log atomically, removes the journal and returns the
/// run log's path. When the episode ends early (the exchange stopped it, or a write failed) it
/// writes an incomplete run log recovered from the journal plus the timing log it has, and
/// returns the error saying what was kept.
pub fn play_journaled(
    out: &Path,
    clock: &str,
    spec: &RunSpec,
    agents: &mut AgentsController<'_>,
    recorder: Option<Recorder>,
    live: Option<LiveFeed<'_>>,
    mut view: Option<&mut LiveView>,
) -> Result<PathBuf, RunError> {
    let index = spec.index;
    let (log_path, timing_path) = log_paths(out, index);
    let header = JournalHeader::new(spec, clock, agents.model_ids());
    let mut journal =
        RunJournal::create(&journal_path(out, index), &header).map_err(RunError::Start)?;
    if let Some(view) = view.as_deref_mut() {
        view.begin_run(formation_record::TeamSetup::of(spec), spec.d_star);
    }
    let mut recording = RecordingAgents {
        agents: &mut *agents,
        recorder,
        live,
        view,
    };
    let played = run_episode_recorded(spec, &mut recording, &mut |_, _| {}, &mut |trajectory| {
        journal.append(trajectory)
    });
    if let Some(view) = recording.view.take() {
        view.end_run(
            played
                .as_ref()
                .ok()
                .and_then(formation_record::final_sample),
        );
    }
    if let Some(live) = recording.live.take() {
        let last = played
            .as_ref()
            .ok()
            .and_then(formation_record::final_sample);
        live.end(last);
    }
    if let Some(recorder) = recording.recorder.take() {
        // A run stopped early says so in its recording, with the run log's reason.
        let finished = match &played {
            Ok(trajectory) => recorder.finish(formation_record::final_sample(trajectory)),
            Err(e) => recorder.finish_stopped(&stop_reason(e)),
        };
        match finished {
            Ok(Some(summary)) => tracing::info!(
                "recorded {} ({} messages, {} bytes)",
                summary.path.display(),
                summary.messages,
                summary.bytes
            ),
            Ok(None) => {}
            Err(e) => report_recording_failure(&e),
        }
    }
    let mut timing = || TimingLog {
        index,
        clock: clock.to_owned(),
        dt_s: spec.world.dt,
        tick_start_ns: agents.take_tick_starts(),
        robots: agents.take_timings(),
    };
    match played {
        Ok(trajectory) => {
            let timing = timing();
            let log = RunLog {
                index,
                metrics: run_metrics(&trajectory, spec.ticks(), &MetricsConfig::default()),
                trajectory,
                clock: clock.to_owned(),
                models: agents.model_ids().to_vec(),
                complete: true,
                stop_reason: None,
                planned_ticks: Some(spec.ticks()),
            };
            let written = write_json_atomic(&log_path, &log)
                .and_then(|()| write_json_atomic(&timing_path, &timing));
            match written {
                Ok(()) => {
                    let journal_file = journal.path().to_path_buf();
                    drop(journal);
                    let _ = std::fs::remove_file(&journal_file);
                    Ok(log_path)
                }
                Err(cause) => {
                    let saved = match journal.close() {
                        Ok(path) => Saved::Journal(path),
                        Err(e) => Saved::Lost(e),
                    };
                    Err(RunError::Write { cause, saved })
                }
            }
        }
        Err(EpisodeError::Controller(cause)) => {
            let reason = cause.to_string();
            let saved = keep_partial(journal, &log_path, &timing_path, &reason, timing());
            Err(RunError::Stopped { cause, saved })
        }
        Err(EpisodeError::Record(cause)) => {
            let reason = format!("the run journal could not be written: {cause}");
            let saved = keep_partial(journal, &log_path, &timing_path, &reason, timing());
            Err(RunError::Write { cause, saved })
        }
    }
}

/// Why a run stopped early, as its incomplete run log says it.
fn stop_reason<E: std::fmt::Display>(error: &EpisodeError<E>) -> String {
    match error {
        EpisodeError::Controller(cause) => cause.to_string(),
        EpisodeError::Record(cause) => format!("the run journal could not be written: {cause}"),
    }
}

/// Says that a recording stopped, and that the run goes on.
pub fn report_recording_failure(error: &formation_record::RecordError) {
    eprintln!(
        "formation-world: recording stopped: {}; the run goes on without it, and its other \
         outputs are written as usual",
        formation_proto::errors::chain_text(error)
    );
}

/// The record channel of one run, for remote recorders (`formation record --connect`): what the
/// world's own recorder gets, encoded ([`formation_record::live`]) only while a recorder
/// listens. A failed send is said once and ends the channel for the run, never the run.
pub struct LiveFeed<'a> {
    feed: &'a mut dyn RecordFeed,
    run_index: u64,
}

impl<'a> LiveFeed<'a> {
    /// Begins run `spec` (the `nth` of `runs`) on `feed`: its setup, with the models hashed,
    /// is sent to the recorders listening and kept for those that join while it plays.
    pub fn begin(
        feed: &'a mut dyn RecordFeed,
        spec: &RunSpec,
        launch: &formation_record::LaunchInfo,
        nth: usize,
        runs: usize,
    ) -> Option<LiveFeed<'a>> {
        let setup = formation_record::RecordingSetup::for_run(spec, launch);
        let live = match LiveSetup::for_run(&setup, nth, runs, Path::new("(the record channel)")) {
            Ok(live) => live,
            Err(e) => {
                report_live_failure(&e.to_string());
                return None;
            }
        };
        if let Err(e) = feed.begin_run(encode(&LiveMessage::Setup(live))) {
            report_live_failure(&e.to_string());
            return None;
        }
        Some(LiveFeed {
            feed,
            run_index: spec.index as u64,
        })
    }

    /// Whether a recorder listens.
    fn wanted(&self) -> bool {
        self.feed.wanted()
    }

    /// Sends `tick`; false when the send failed (said).
    fn tick(&mut self, tick: TickRecord) -> bool {
        let message = LiveMessage::Tick {
            run_index: self.run_index,
            tick,
        };
        self.send(&message)
    }

    /// Sends the run's end, with the state after its last step when it played to its end.
    fn end(mut self, last: Option<formation_record::FinalSample>) {
        if self.wanted() {
            let message = LiveMessage::End {
                run_index: self.run_index,
                last,
            };
            self.send(&message);
        }
    }

    fn send(&mut self, message: &LiveMessage) -> bool {
        match self.feed.publish(encode(message)) {
            Ok(()) => true,
            Err(e) => {
                report_live_failure(&e.to_string());
                false
            }
        }
    }
}

/// Says that the record channel stopped for this run, and that the run goes on.
fn report_live_failure(error: &str) {
    eprintln!(
        "formation-world: the record channel for `formation record --connect` stopped for this \
         run: {error}; the run goes on"
    );
}

/// The agents' exchange, recording each tick it decides: the observation the agents were sent,
/// and per robot the command the world used, what its watchdog made of it, the scan's lag and
/// the model that decided (from the exchange's timing of that tick).
struct RecordingAgents<'a, 'l, 'f> {
    agents: &'a mut AgentsController<'l>,
    recorder: Option<Recorder>,
    live: Option<LiveFeed<'f>>,
    /// The live view (`--foxglove`), shown each tick while a client is connected.
    view: Option<&'a mut LiveView>,
}

impl Controller for RecordingAgents<'_, '_, '_> {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        self.agents.commands(obs, out)?;
        self.record_swaps();
        let live_wanted = self.live.as_ref().is_some_and(LiveFeed::wanted);
        let view_wanted = self.view.as_ref().is_some_and(|v| v.wants_ticks());
        if self.recorder.is_none() && !live_wanted && !view_wanted {
            return Ok(());
        }
        let tick = self.tick_record(obs, out);
        if view_wanted && let Some(view) = &mut self.view {
            view.tick(tick.clone());
        }
        if live_wanted
            && let Some(live) = &mut self.live
            && !live.tick(tick.clone())
        {
            self.live = None;
        }
        if let Some(recorder) = &mut self.recorder
            && let Err(e) = recorder.tick(tick)
        {
            report_recording_failure(&e);
            self.recorder = None;
        }
        Ok(())
    }
}

impl RecordingAgents<'_, '_, '_> {
    /// Hands the swaps the agents did since the last tick to the recording (before this tick,
    /// whose steps the new models decided), which stores their model files.
    fn record_swaps(&mut self) {
        let swaps = self.agents.take_swaps_done();
        let Some(recorder) = &mut self.recorder else {
            return;
        };
        for swap in swaps {
            if let Err(e) = recorder.swapped(swap) {
                report_recording_failure(&e);
                self.recorder = None;
                return;
            }
        }
    }

    /// The tick `obs` with the commands `out` the world used and what its watchdog made of
    /// them.
    fn tick_record(&self, obs: &Observation<'_>, out: &[WheelCmd]) -> TickRecord {
        let mut models = Vec::with_capacity(out.len());
        let sent = out
            .iter()
            .enumerate()
            .map(|(robot, &wheels)| {
                let (outcome, lag_ticks, model) =
                    self.agents
                        .last_outcome(robot)
                        .unwrap_or((TickOutcome::Fresh, 0, None));
                models.push(model.unwrap_or_default().to_owned());
                SentCommand {
                    wheels,
                    outcome,
                    lag_ticks,
                }
            })
            .collect();
        TickRecord::new(obs, sent, &models)
    }
}

/// Closes the journal, writes the incomplete run log recovered from it and the timing log, and
/// removes the journal once the run log is written.
fn keep_partial(
    journal: RunJournal,
    log_path: &Path,
    timing_path: &Path,
    reason: &str,
    timing: TimingLog,
) -> Saved {
    let journal_file = journal.path().to_path_buf();
    // A journal whose write failed is already cut back to its whole lines and closed.
    let _ = journal.close();
    let kept = recover_journal(&journal_file).and_then(|mut log| {
        if log.trajectory.poses.is_empty() {
            return Err(RunLogError::NoSamples {
                path: journal_file.clone(),
            });
        }
        log.stop_reason = Some(reason.to_owned());
        write_json_atomic(log_path, &log)
    });
    match kept {
        Ok(()) => {
            let _ = std::fs::remove_file(&journal_file);
            if let Err(e) = write_json_atomic(timing_path, &timing) {
                tracing::warn!("{e}");
            }
            Saved::Partial(log_path.to_path_buf())
        }
        Err(e @ RunLogError::NoSamples { .. }) => {
            let _ = std::fs::remove_file(&journal_file);
            Saved::Lost(e)
        }
        Err(e) if journal_file.is_file() => {
            tracing::warn!("{e}");
            Saved::Journal(journal_file)
        }
        Err(e) => Saved::Lost(e),
    }
}

#[cfg(test)]
mod tests {
    use formation_record::LaunchInfo;
    use formation_record::live::{LiveMessage, decode};
    use formation_runtime::link::{WorldLinkError, WorldResult};
    use formation_world::Scenario;

    use super::*;

    /// A record channel that keeps what it is sent; `fail` makes every send fail.
    struct FakeFeed {
        listening: bool,
        fail: bool,
        sent: Vec<Vec<u8>>,
    }

    impl FakeFeed {
        /// A channel with a recorder `listening` or not, whose sends `fail` or not.
        fn new(listening: bool, fail: bool) -> FakeFeed {
            FakeFeed {
                listening,
                fail,
                sent: Vec::new(),
            }
        }
    }

    impl RecordFeed for FakeFeed {
        fn wanted(&self) -> bool {
            self.listening
        }

        fn begin_run(&mut self, setup: Vec<u8>) -> WorldResult {
            self.publish(setup)
        }

        fn publish(&mut self, message: Vec<u8>) -> WorldResult {
            if self.fail {
                return Err(WorldLinkError::NoSuchRobot {
                    robot: 9,
                    robots: 3,
                });
            }
            self.sent.push(message);
            Ok(())
        }
    }

    fn case1() -> RunSpec {
        let text = include_str!("../../scenarios/case1.toml");
        let scenario = Scenario::from_toml_str(text, "case1.toml").expect("case 1 parses");
        scenario.run_spec(1, 4)
    }

    fn launch() -> LaunchInfo {
        LaunchInfo {
            scenario: "case1".into(),
            base_seed: Some(1),
            clock: "lockstep".into(),
            controller: "policy".into(),
            models: Vec::new(),
            shipped_models: None,
        }
    }

    #[test]
    fn a_run_on_the_record_channel_is_its_setup_then_its_end_while_a_recorder_listens() {
        let mut feed = FakeFeed::new(true, false);
        let spec = case1();
        let live = LiveFeed::begin(&mut feed, &spec, &launch(), 0, 1).expect("the channel begins");
        assert!(live.wanted());
        live.end(None);
        let messages: Vec<LiveMessage> = feed.sent.iter().map(|m| decode(m).unwrap()).collect();
        assert_eq!(messages.len(), 2, "{messages:?}");
        assert!(matches!(messages[0], LiveMessage::Setup(_)), "{messages:?}");
        assert!(
            matches!(
                messages[1],
                LiveMessage::End {
                    run_index: 4,
                    last: None
                }
            ),
            "{messages:?}"
        );
    }

    #[test]
    fn nobody_listening_gets_no_end_and_a_failed_send_ends_the_channel_not_the_run() {
        let mut quiet = FakeFeed::new(false, false);
        let spec = case1();
        let live = LiveFeed::begin(&mut quiet, &spec, &launch(), 0, 1).expect("begins");
        live.end(None);
        assert_eq!(quiet.sent.len(), 1, "only the setup, kept for late joiners");

        let mut broken = FakeFeed::new(true, true);
        assert!(LiveFeed::begin(&mut broken, &spec, &launch(), 0, 1).is_none());
    }

    #[test]
    fn what_became_of_a_run_is_said_with_its_path() {
        let partial = saved_note(&Saved::Partial(PathBuf::from("out/runs/run-0001.json")));
        assert_eq!(
            partial,
            "; the partial run is kept in out/runs/run-0001.json"
        );
        let journal = saved_note(&Saved::Journal(PathBuf::from("run-0001.journal")));
        assert!(
            journal.contains("its journal run-0001.journal"),
            "{journal}"
        );
        assert!(
            journal.contains("`formation report` recovers it"),
            "{journal}"
        );
    }

    #[test]
    fn a_run_stopped_before_its_first_sample_keeps_nothing_and_leaves_no_journal() {
        let dir = tempfile::tempdir().unwrap();
        let spec = case1();
        let journal_file = journal_path(dir.path(), spec.index);
        std::fs::create_dir_all(journal_file.parent().unwrap()).unwrap();
        let header = JournalHeader::new(&spec, "lockstep", &[]);
        let journal = RunJournal::create(&journal_file, &header).unwrap();
        let (log_path, timing_path) = log_paths(dir.path(), spec.index);
        let timing = TimingLog {
            index: spec.index,
            clock: "lockstep".into(),
            dt_s: spec.world.dt,
            tick_start_ns: Vec::new(),
            robots: Vec::new(),
        };
        let saved = keep_partial(journal, &log_path, &timing_path, "stopped", timing);
        assert!(
            matches!(saved, Saved::Lost(RunLogError::NoSamples { .. })),
            "{saved:?}"
        );
        assert!(!journal_file.exists(), "the empty journal is removed");
        assert!(!log_path.exists(), "no run log for a run without samples");
    }
}
