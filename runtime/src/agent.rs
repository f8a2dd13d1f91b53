//! The agent's loop: one robot's decision maker between its link and its pilot.
//!
//! [`AgentLoop`] waits on its [`AgentLink`], answers control requests (begin an episode: get
//! ready or refuse with the reason; swap the model: load it on a helper thread, off the hot path,
//! and put it in place at a tick boundary; shut down), and turns each scan of the current episode
//! into one command through its [`Pilot`] (perceive, then decide, each timed), optionally altered
//! by an injected [`Fault`]. It knows nothing of ONNX: a [`PilotMaker`] loads models and makes
//! pilots of them (`formation_robot_agent::pilot::OnnxPilots` in the `formation-agent` binary, a
//! double in unit tests); both traits are `formation_proto::robot`'s. It reads time
//! only from its [`Clock`].
//!
//! The same loop drives a ROS 2 robot (`formation_transport_ros2::run_agent`), which runs free
//! of any world: there the link stands in for the world (it begins the one episode, is never
//! gone, and turns commands into Twists), and the loop only says another reason for its stop
//! ([`AgentLoop::with_stop_reason`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use formation_proto::wire::{
    AgentStatus, AgentTimings, CmdMsg, CmdStatus, ControlRequest, ScanMsg, WireError, wall_clock_ns,
};
use formation_proto::{LidarSpec, WheelCmd, WheelLimits};

use formation_proto::exit::TerminationSignal;

use crate::clock::Clock;
use crate::faults::{Fault, FaultAction};
use crate::link::{AgentLink, AgentLinkError, Wake};

/// One robot's decision as this loop drives it, and what loads its models: the traits live with
/// the robot's input type in `formation_proto::robot`, so that the robot's decision
/// (`formation-robot-agent`) implements them without knowing this crate.
pub use formation_proto::robot::{BoxError, Pilot, PilotMaker};

/// Why a model could not drive.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// It could not be loaded or validated.
    #[error("loading model {}", path.display())]
    Load {
        /// The model file.
        path: PathBuf,
        /// Why.
        #[source]
        source: BoxError,
    },
    /// It was made for another sensor.
    #[error("model {} does not fit this robot", path.display())]
    Unfit {
        /// The model file.
        path: PathBuf,
        /// Why.
        #[source]
        source: BoxError,
    },
    /// The helper thread loading a swap model ended without an answer.
    #[error("the model loader thread stopped unexpectedly")]
    LoaderGone,
    /// A swap arrived before any episode gave the sensor settings.
    #[error("no episode has begun yet")]
    NoEpisode,
    /// The pilot refused the loaded model.
    #[error(transparent)]
    Refused(BoxError),
}

/// Why the agent's loop failed.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// The link failed.
    #[error(transparent)]
    Link(#[from] AgentLinkError),
    /// A command could not be encoded.
    #[error(transparent)]
    Wire(#[from] WireError),
}

/// Why the agent's loop ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AgentExit {
    /// The world ended the run: the normal way out, nothing to tell the user.
    Shutdown,
    /// SIGINT or SIGTERM.
    Signal(TerminationSignal),
    /// Anything else, told to the user.
    Because(String),
}

/// How long the agent waits with nothing arriving before checking that the world still exists.
pub const IDLE_CHECK: Duration = Duration::from_millis(250);

/// Why an agent of run `run` exits when the world is gone, and what to do about it: the agent
/// does not wait for a world that may never come back, so the user starts it again (the
/// launcher's own agents go with their launcher, which says why).
pub fn world_gone(run: &str) -> String {
    format!(
        "the world process of run {run} went away (it exited, crashed or was killed, or, over a \
         network, its link was down past the lease), so there is nothing left to drive; start \
         this agent again, with the same command, once the world of run {run} is back"
    )
}

/// `error: source: source of source ...`, the whole chain on one line.
pub fn error_chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

/// When to rehearse before the scan after one of simulation time `sim_time` answered at `now`:
/// `ahead` before one scan period (the simulation time since the `previous` answered scan)
/// from now. `None` without a previous scan, for a period that is not positive, or one of at
/// least [`IDLE_CHECK`] (no agent idles that long between ticks of a live run).
pub fn rehearsal_due(
    previous: Option<(f64, std::time::Instant)>,
    sim_time: f64,
    now: std::time::Instant,
    ahead: Duration,
) -> Option<std::time::Instant> {
    let (previous_time, _) = previous?;
    let period = sim_time - previous_time;
    if !(period.is_finite() && period > 0.0 && period < IDLE_CHECK.as_secs_f64()) {
        return None;
    }
    (now + Duration::from_secs_f64(period)).checked_sub(ahead)
}

/// Loads the model at `path` with `maker`, naming the file on error.
pub fn load_model<M: PilotMaker>(maker: &M, path: &Path) -> Result<M::Model, ModelError> {
    maker.load(path).map_err(|source| ModelError::Load {
        path: path.to_owned(),
        source,
    })
}

/// A model being loaded on a helper thread for a swap request.
struct PendingSwap<T> {
    request_id: u64,
    at_tick: u64,
    path: PathBuf,
    loaded: mpsc::Receiver<Result<T, ModelError>>,
    /// The loader's result once taken from `loaded`.
    result: Option<Result<T, ModelError>>,
}

/// One robot's agent between messages: its pilot, its episode, a swap under way.
pub struct AgentLoop<M: PilotMaker> {
    maker: Arc<M>,
    clock: Arc<dyn Clock>,
    model_path: PathBuf,
    /// The loaded model before the first episode gives the sensor settings.
    idle_model: Option<M::Model>,
    pilot: Option<(M::Pilot, LidarSpec)>,
    generation: u64,
    pending_swap: Option<PendingSwap<M::Model>>,
    fault: Option<Fault>,
    answered: u64,
    /// How long before the next scan is due the pilot rehearses (zero: never).
    rehearse_ahead: Duration,
    /// When the next scan is due, from the scan period seen so far, while not yet rehearsed.
    rehearse_at: Option<std::time::Instant>,
    /// Simulation time of the last answered scan, and when it was answered.
    last_answer: Option<(f64, std::time::Instant)>,
    /// Why the loop ended when its `stop` flag was set ([`AgentLoop::with_stop_reason`]).
    stop_reason: &'static str,
    /// How long after answering the agent polls for its next scan before it blocks (zero:
    /// never), while scans have been coming that soon ([`AgentLoop::with_spin`]).
    spin: Duration,
    /// When the last command went out, on the machine's clock.
    answered_at: Option<std::time::Instant>,
    /// From the command before to the scan after it, the last time one came \[machine clock\].
    recent_gap: Option<Duration>,
}

/// The longest poll for the next scan [`AgentLoop::with_spin`] accepts.
pub const MAX_SPIN: Duration = Duration::from_millis(10);

/// Why an agent's loop ends when its `stop` flag is set, unless told otherwise: the launcher that
/// started it closed its standard input.
pub const LAUNCHER_CLOSED_INPUT: &str = "the launcher closed our input";

impl<M: PilotMaker> AgentLoop<M> {
    /// An agent that will drive with `model` (loaded from `model_path` by `maker`), misbehaving
    /// as `fault` says (testing only), reading time from `clock`.
    pub fn new(
        maker: Arc<M>,
        model_path: PathBuf,
        model: M::Model,
        fault: Option<Fault>,
        clock: Arc<dyn Clock>,
    ) -> Self {
        AgentLoop {
            maker,
            clock,
            model_path,
            idle_model: Some(model),
            pilot: None,
            generation: 0,
            pending_swap: None,
            fault,
            answered: 0,
            rehearse_ahead: Duration::ZERO,
            rehearse_at: None,
            last_answer: None,
            stop_reason: LAUNCHER_CLOSED_INPUT,
            spin: Duration::ZERO,
            answered_at: None,
            recent_gap: None,
        }
    }

    /// Says `reason` as the loop's end when its `stop` flag is set, in place of
    /// [`LAUNCHER_CLOSED_INPUT`]: a ROS 2 agent belongs to its robot rather than to a run, and
    /// its launcher, whatever it is, simply went away.
    pub fn with_stop_reason(mut self, reason: &'static str) -> Self {
        self.stop_reason = reason;
        self
    }

    /// Makes the pilot rehearse its last decision `ahead` before the next scan is due (zero:
    /// never). The next scan is expected one scan period (the simulation time between the last
    /// two scans) after the last one was answered, so this acts only when the agent idles
    /// between ticks, as in realtime; in an unpaced lockstep run the next scan always comes
    /// first. It costs one extra decision per tick and changes no command.
    pub fn with_rehearsal(mut self, ahead: Duration) -> Self {
        self.rehearse_ahead = ahead;
        self
    }

    /// Makes the agent poll for its next scan for up to `spin` after each command, yielding the
    /// core between polls, before it blocks in [`AgentLink::wait`] (zero: never) — but only
    /// while the last scan came within `spin` of the command before it, as in an unpaced
    /// lockstep run of a few agents. A realtime run (a scan every 50 ms) or a team too big for
    /// its cores never spins. A poll sees the scan in about a microsecond where a blocking
    /// wake-up costs tens, and the decision runs on a core that is already awake. It changes
    /// no command.
    /// At most [`MAX_SPIN`]: a poll never keeps the agent from its idle checks for long.
    pub fn with_spin(mut self, spin: Duration) -> Self {
        self.spin = spin.min(MAX_SPIN);
        self
    }

    /// Says hello on a freshly connected link: this process (`pid`) is up with its model.
    pub fn greet(&mut self, link: &mut dyn AgentLink, pid: u32) -> Result<(), AgentError> {
        let model_id = match (&self.idle_model, &self.pilot) {
            (Some(model), _) => self.maker.model_id(model).to_owned(),
            (None, Some((pilot, _))) => pilot.model_id().to_owned(),
            (None, None) => String::new(),
        };
        link.publish_status(&AgentStatus::Hello { pid, model_id })?;
        Ok(())
    }

    /// Runs until the world shuts the agent down, a signal arrives, `stop` is set (the launcher
    /// closed the agent's input), or the world of run `run` goes away (checked whenever nothing
    /// arrived for [`IDLE_CHECK`]).
    pub fn run(
        &mut self,
        link: &mut dyn AgentLink,
        stop: &AtomicBool,
        run: &str,
    ) -> Result<AgentExit, AgentError> {
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(AgentExit::Because(self.stop_reason.into()));
            }
            let now = self.clock.now();
            let wait = self.rehearse_at.map_or(IDLE_CHECK, |at| {
                at.saturating_duration_since(now).min(IDLE_CHECK)
            });
            match link.wait(wait)? {
                Wake::Terminated(signal) => return Ok(AgentExit::Signal(signal)),
                Wake::Idle if wait < IDLE_CHECK => {
                    self.rehearse_at = None;
                    if let Some((pilot, _)) = &mut self.pilot
                        && let Err(e) = pilot.rehearse()
                    {
                        tracing::debug!("rehearsal failed: {}", error_chain(e.as_ref()));
                    }
                }
                Wake::Idle => {
                    if !link.world_alive()? {
                        return Ok(AgentExit::Because(world_gone(run)));
                    }
                }
                Wake::Activity => {}
            }
            if let Some(exit) = self.handle(link)? {
                return Ok(exit);
            }
            if let Some(exit) = self.spin_for_next_scan(link, stop)? {
                return Ok(exit);
            }
        }
    }

    /// Polls for the next scan while [`AgentLoop::with_spin`] says to, handling what arrives;
    /// returns when the spin ran out, the stop flag is set, or the agent should exit. Each round
    /// starts with a wait that does not block, so that a termination signal ends the agent even
    /// while scans keep coming within the spin and it never blocks.
    pub(crate) fn spin_for_next_scan(
        &mut self,
        link: &mut dyn AgentLink,
        stop: &AtomicBool,
    ) -> Result<Option<AgentExit>, AgentError> {
        loop {
            let (Some(answered_at), Some(gap)) = (self.answered_at, self.recent_gap) else {
                return Ok(None);
            };
            if self.spin.is_zero() || gap > self.spin {
                return Ok(None);
            }
            if let Wake::Terminated(signal) = link.wait(Duration::ZERO)? {
                return Ok(Some(AgentExit::Signal(signal)));
            }
            // Bounded on the machine's own clock: it is about this core's time.
            let until = answered_at.checked_add(self.spin).unwrap_or(answered_at);
            loop {
                if stop.load(Ordering::Relaxed) || std::time::Instant::now() >= until {
                    return Ok(None);
                }
                let answered_before = self.answered_at;
                if let Some(exit) = self.handle(link)? {
                    return Ok(Some(exit));
                }
                if self.answered_at != answered_before {
                    break; // answered a scan: spin again after this command
                }
                std::thread::yield_now();
            }
        }
    }

    /// Handles everything that arrived: control requests first, then the newest scan.
    /// `Some(exit)` means exit.
    pub fn handle(&mut self, link: &mut dyn AgentLink) -> Result<Option<AgentExit>, AgentError> {
        let mut requests = Vec::new();
        link.drain_control(&mut |r| requests.push(r))?;
        for request in requests {
            if let Some(exit) = self.on_control(request, link)? {
                return Ok(Some(exit));
            }
        }
        if let Some(scan) = link.newest_scan()? {
            self.on_scan(&scan, link)?;
        }
        Ok(None)
    }

    /// Handles one control request; `Some(exit)` means exit.
    fn on_control(
        &mut self,
        request: ControlRequest,
        link: &mut dyn AgentLink,
    ) -> Result<Option<AgentExit>, AgentError> {
        match request {
            ControlRequest::Shutdown => return Ok(Some(AgentExit::Shutdown)),
            ControlRequest::BeginEpisode {
                generation,
                lidar,
                wheels,
            } => {
                self.generation = generation;
                let status = match self.prepare(lidar, wheels) {
                    Ok(model_id) => AgentStatus::Ready {
                        generation,
                        model_id,
                    },
                    Err(e) => AgentStatus::Refused {
                        generation,
                        reason: error_chain(&e),
                    },
                };
                link.publish_status(&status)?;
            }
            ControlRequest::SwapModel {
                request_id,
                at_tick,
                path,
            } => {
                let (tx, rx) = mpsc::channel();
                let load_path = path.clone();
                let maker = Arc::clone(&self.maker);
                std::thread::spawn(move || {
                    let _ = tx.send(load_model(&*maker, &load_path));
                });
                if let Some(previous) = self.pending_swap.replace(PendingSwap {
                    request_id,
                    at_tick,
                    path,
                    loaded: rx,
                    result: None,
                }) {
                    link.publish_status(&AgentStatus::SwapRefused {
                        request_id: previous.request_id,
                        reason: format!("superseded by swap request {request_id}"),
                    })?;
                }
            }
        }
        Ok(None)
    }

    /// Makes the agent ready for an episode with this sensor and these wheel limits; returns
    /// the model id.
    fn prepare(&mut self, lidar: LidarSpec, wheels: WheelLimits) -> Result<String, ModelError> {
        if let Some((pilot, current)) = &mut self.pilot
            && *current == lidar
        {
            pilot.set_wheel_limits(wheels);
            return Ok(pilot.model_id().to_owned());
        }
        let model = match self.idle_model.take() {
            Some(model) => model,
            None => load_model(&*self.maker, &self.model_path)?,
        };
        let mut pilot = self
            .maker
            .pilot(model, lidar)
            .map_err(|source| ModelError::Unfit {
                path: self.model_path.clone(),
                source,
            })?;
        pilot.set_wheel_limits(wheels);
        let id = pilot.model_id().to_owned();
        self.pilot = Some((pilot, lidar));
        Ok(id)
    }

    /// Puts a loaded swap model in place when its tick has come. A swap with `at_tick > 0` waits
    /// for the load at that tick (so a lockstep run swaps at exactly that tick); `at_tick == 0`
    /// swaps as soon as the model is ready. A model that fails to load or validate is refused as
    /// soon as that is known, and the current model keeps driving.
    fn apply_swap(&mut self, tick: u64, link: &mut dyn AgentLink) -> Result<bool, AgentError> {
        let Some(pending) = &mut self.pending_swap else {
            return Ok(false);
        };
        if pending.result.is_none() {
            let must_have_it = pending.at_tick > 0 && tick >= pending.at_tick;
            pending.result = if must_have_it {
                Some(pending.loaded.recv().unwrap_or(Err(ModelError::LoaderGone)))
            } else {
                match pending.loaded.try_recv() {
                    Ok(result) => Some(result),
                    Err(mpsc::TryRecvError::Empty) => None,
                    Err(mpsc::TryRecvError::Disconnected) => Some(Err(ModelError::LoaderGone)),
                }
            };
        }
        let ready = match &pending.result {
            None => return Ok(false),
            Some(Ok(_)) => tick >= pending.at_tick,
            Some(Err(_)) => true,
        };
        if !ready {
            return Ok(false);
        }
        let Some(pending) = self.pending_swap.take() else {
            return Ok(false);
        };
        let outcome = pending
            .result
            .unwrap_or(Err(ModelError::LoaderGone))
            .and_then(|model| match &mut self.pilot {
                Some((pilot, _)) => pilot.swap(model).map_err(ModelError::Refused),
                None => Err(ModelError::NoEpisode),
            });
        match outcome {
            Ok(()) => {
                self.model_path = pending.path;
                let model_id = self
                    .pilot
                    .as_ref()
                    .map(|(p, _)| p.model_id().to_owned())
                    .unwrap_or_default();
                link.publish_status(&AgentStatus::SwapDone {
                    request_id: pending.request_id,
                    tick,
                    model_id,
                })?;
                Ok(true)
            }
            Err(e) => {
                link.publish_status(&AgentStatus::SwapRefused {
                    request_id: pending.request_id,
                    reason: format!(
                        "the old model keeps driving; the new one failed: {}",
                        error_chain(&e)
                    ),
                })?;
                Ok(false)
            }
        }
    }

    /// Decides and publishes the command for one scan of the current episode.
    fn on_scan(&mut self, scan: &ScanMsg, link: &mut dyn AgentLink) -> Result<(), AgentError> {
        let received_wall_ns = wall_clock_ns();
        if let Some(answered_at) = self.answered_at {
            self.recent_gap = Some(answered_at.elapsed());
        }
        if scan.generation != self.generation || self.pilot.is_none() {
            return Ok(()); // a scan of an episode this agent is not (yet) part of
        }
        let swapped = self.apply_swap(scan.tick, link)?;
        let Some((pilot, _)) = &mut self.pilot else {
            return Ok(());
        };
        let started = self.clock.now();
        if !self.rehearse_ahead.is_zero() {
            self.rehearse_at = rehearsal_due(
                self.last_answer,
                scan.sim_time,
                started,
                self.rehearse_ahead,
            );
            self.last_answer = Some((scan.sim_time, started));
        }
        let goal = scan.goal();
        let perceived = scan
            .ranges()
            .map_err(BoxError::from)
            .and_then(|r| pilot.perceive(r, &goal));
        let perceived_at = self.clock.now();
        let decided = perceived.and_then(|()| pilot.decide(scan.heading, &goal));
        let decided_at = self.clock.now();
        let timings = AgentTimings {
            received_wall_ns,
            occupancy_ns: nanos(perceived_at - started),
            inference_ns: nanos(decided_at - perceived_at),
        };
        let mut status = if swapped {
            CmdStatus::MODEL_SWAPPED
        } else {
            CmdStatus::OK
        };
        let mut cmd = match decided {
            Ok(cmd) => cmd,
            Err(e) => {
                link.decision_failed(scan.tick, &error_chain(e.as_ref()));
                status = status.with(CmdStatus::DECISION_FAILED);
                WheelCmd::BRAKE
            }
        };
        if let Some(fault) = self.fault {
            match fault.action(self.answered) {
                FaultAction::None => {}
                FaultAction::Crash => {
                    eprintln!(
                        "formation-agent: injected crash after {} commands",
                        self.answered
                    );
                    std::process::abort();
                }
                FaultAction::Hang => {
                    eprintln!(
                        "formation-agent: injected hang after {} commands",
                        self.answered
                    );
                    loop {
                        std::thread::sleep(Duration::from_secs(3600));
                    }
                }
                FaultAction::Delay(d) => {
                    self.clock.sleep(d);
                    status = status.with(CmdStatus::FAULT_INJECTED);
                }
                FaultAction::Nan => {
                    cmd = WheelCmd {
                        left: f64::NAN,
                        right: f64::NAN,
                    };
                    status = status.with(CmdStatus::FAULT_INJECTED);
                }
            }
        }
        let msg = CmdMsg::new(
            scan.generation,
            scan.tick,
            cmd,
            pilot.model_id(),
            timings,
            status,
        )?;
        link.publish_command(&msg)?;
        self.answered_at = Some(std::time::Instant::now());
        self.answered += 1;
        Ok(())
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}
