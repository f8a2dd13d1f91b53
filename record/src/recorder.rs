//! Recording a run as it plays, off the tick loop: [`Recorder`] hands each tick to a writer
//! thread through a bounded queue, so the world's tick pays for a copy of the tick's data and
//! nothing else (the encoding, the compression and the writes run beside it), and memory stays
//! bounded: when the writer falls [`QUEUE_TICKS`] ticks behind, the tick loop waits for it.
//!
//! A write that fails (a full disk) ends the recording, not the run: the next tick (or
//! [`Recorder::finish`]) returns the error once, later ticks are dropped, and what was written up
//! to the last whole chunk stays readable. A recorder dropped without `finish` (a run stopped
//! early) closes its file as a valid, shorter recording.
//!
//! [`RecordedController`] wraps any [`Controller`] so that an in-process run records itself.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use formation_proto::control::{Controller, ControllerError, Observation};
use formation_proto::{SwapDone, WheelCmd};
use formation_world::Trajectory;

use crate::error::RecordError;
use crate::file::{RecordingFile, RecordingSummary};
use crate::setup::RecordingSetup;
use crate::tick::{FinalSample, TickRecord};

/// Ticks the writer may fall behind before the tick loop waits for it (two simulated seconds
/// at 20 Hz).
pub const QUEUE_TICKS: usize = 40;

enum Job {
    Tick(Box<TickRecord>),
    Swap(SwapDone),
    Finish(Option<FinalSample>),
    Stopped(String),
}

/// A recording being written by its own thread.
#[derive(Debug)]
pub struct Recorder {
    path: PathBuf,
    jobs: Option<SyncSender<Job>>,
    thread: Option<JoinHandle<Result<Option<RecordingSummary>, RecordError>>>,
}

impl Recorder {
    /// Creates `path` and writes what precedes the first tick on this thread (so a path that
    /// cannot be written fails here, before the run), then starts the writer thread.
    pub fn start(path: &Path, setup: RecordingSetup) -> Result<Recorder, RecordError> {
        let file = RecordingFile::create(path, setup)?;
        let (jobs, queue) = sync_channel(QUEUE_TICKS);
        let thread = std::thread::Builder::new()
            .name("formation-record".into())
            .spawn(move || write_jobs(file, &queue))
            .map_err(|e| RecordError::Write(formation_proto::files::WriteError::new(path, e)))?;
        Ok(Recorder {
            path: path.to_path_buf(),
            jobs: Some(jobs),
            thread: Some(thread),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether ticks are still being recorded (no write has failed).
    pub fn is_recording(&self) -> bool {
        self.jobs.is_some()
    }

    /// Queues one tick. Fails once, with the writer's error, when a write has failed: the
    /// recording is over, and later ticks are dropped.
    pub fn tick(&mut self, tick: TickRecord) -> Result<(), RecordError> {
        self.send(Job::Tick(Box::new(tick)))
    }

    /// Queues a model swapped in during the run, to be stored before the ticks queued after it
    /// ([`RecordingFile::write_swap`]). Fails as [`Recorder::tick`] does.
    pub fn swapped(&mut self, swap: SwapDone) -> Result<(), RecordError> {
        self.send(Job::Swap(swap))
    }

    fn send(&mut self, job: Job) -> Result<(), RecordError> {
        let Some(jobs) = &self.jobs else {
            return Ok(());
        };
        if jobs.send(job).is_ok() {
            return Ok(());
        }
        self.jobs = None;
        match self.join() {
            Err(e) => Err(e),
            Ok(_) => Err(RecordError::ThreadGone {
                path: self.path.clone(),
            }),
        }
    }

    /// Writes the state after the last step (when given) and the summary, and closes the file.
    /// `Ok(None)` when a write had failed already (its error was returned by [`Recorder::tick`]).
    pub fn finish(
        self,
        last: Option<FinalSample>,
    ) -> Result<Option<RecordingSummary>, RecordError> {
        self.end(Job::Finish(last))
    }

    /// Closes the recording of a run that stopped before its end, for `reason` (its run log's
    /// stop reason), which the recording keeps ([`crate::tick::RunEnd`]). Returns as
    /// [`Recorder::finish`] does.
    pub fn finish_stopped(self, reason: &str) -> Result<Option<RecordingSummary>, RecordError> {
        self.end(Job::Stopped(reason.to_owned()))
    }

    fn end(mut self, job: Job) -> Result<Option<RecordingSummary>, RecordError> {
        let Some(jobs) = self.jobs.take() else {
            return Ok(None);
        };
        let sent = jobs.send(job).is_ok();
        drop(jobs);
        let joined = self.join();
        match joined {
            Ok(None) if !sent => Err(RecordError::ThreadGone {
                path: self.path.clone(),
            }),
            other => other,
        }
    }

    fn join(&mut self) -> Result<Option<RecordingSummary>, RecordError> {
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(RecordError::ThreadGone {
                path: self.path.clone(),
            }),
            None => Ok(None),
        }
    }
}

impl Drop for Recorder {
    /// Closes the file as it stands (a valid recording of the ticks so far) and waits for it.
    fn drop(&mut self) {
        self.jobs = None;
        let _ = self.join();
    }
}

/// The writer thread: every queued tick, then the end. A failed write ends it with the error
/// (the file is closed as far as it can be); a queue that closes without a finish (a run
/// stopped early) closes the file without a final sample.
fn write_jobs(
    mut file: RecordingFile,
    queue: &Receiver<Job>,
) -> Result<Option<RecordingSummary>, RecordError> {
    for job in queue.iter() {
        match job {
            Job::Tick(tick) => file.write_tick(&tick)?,
            Job::Swap(swap) => {
                file.write_swap(&swap)?;
            }
            Job::Finish(last) => return file.finish(last.as_ref()).map(Some),
            Job::Stopped(reason) => return file.finish_stopped(&reason).map(Some),
        }
    }
    file.finish(None).map(Some)
}

/// The state after the last step of `trajectory`, for [`Recorder::finish`].
pub fn final_sample(trajectory: &Trajectory) -> Option<FinalSample> {
    Some(FinalSample {
        tick: trajectory.commands.len() as u64,
        time: *trajectory.times.last()?,
        poses: trajectory.poses.last()?.clone(),
    })
}

/// A [`Controller`] that records every tick its inner controller decides (an in-process run:
/// every command fresh, for its own tick). A failed write is handed to `on_failure` once and
/// ends the recording, not the run.
pub struct RecordedController<'a> {
    inner: &'a mut dyn Controller,
    recorder: Option<Recorder>,
    model_ids: Vec<String>,
    on_failure: &'a mut dyn FnMut(&RecordError),
}

impl<'a> RecordedController<'a> {
    /// Records `inner`'s ticks with `recorder`; `model_ids` names each robot's model (may be
    /// empty).
    pub fn new(
        inner: &'a mut dyn Controller,
        recorder: Recorder,
        model_ids: Vec<String>,
        on_failure: &'a mut dyn FnMut(&RecordError),
    ) -> Self {
        RecordedController {
            inner,
            recorder: Some(recorder),
            model_ids,
            on_failure,
        }
    }

    /// Closes the recording of a run that stopped before its end, for `reason` (its run log's
    /// stop reason) ([`Recorder::finish_stopped`]).
    pub fn finish_stopped(mut self, reason: &str) -> Result<Option<RecordingSummary>, RecordError> {
        match self.recorder.take() {
            Some(recorder) => recorder.finish_stopped(reason),
            None => Ok(None),
        }
    }

    /// Closes the recording after the run `trajectory` (`None`: the run did not finish).
    pub fn finish(
        mut self,
        trajectory: Option<&Trajectory>,
    ) -> Result<Option<RecordingSummary>, RecordError> {
        match self.recorder.take() {
            Some(recorder) => recorder.finish(trajectory.and_then(final_sample)),
            None => Ok(None),
        }
    }
}

impl Controller for RecordedController<'_> {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        self.inner.commands(obs, out)?;
        if let Some(recorder) = &mut self.recorder {
            let tick = TickRecord::in_process(obs, out, &self.model_ids);
            if let Err(e) = recorder.tick(tick) {
                (self.on_failure)(&e);
                self.recorder = None;
            }
        }
        Ok(())
    }
}
