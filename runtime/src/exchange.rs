//! The world's side of the per-tick exchange with the agents, as a [`Controller`].
//!
//! [`AgentsController`] publishes every robot's own scan, waits for the agents' commands under the
//! clock mode's rule, and hands the chosen commands to the unchanged in-process episode loop
//! (`formation_world::run_episode`). Because the world is stepped by the very same code in the
//! very same order as in-process, a lockstep run is bit-identical to an in-process run with the
//! same model, seed and scenario.
//!
//! The choice of each robot's command ([`choose_command`]) is a pure function of what arrived and
//! when; the watchdog is part of it: a missing, stale, non-finite or failed command brakes the robot,
//! and a robot with no agent ready to drive it brakes as [`TickOutcome::AgentDown`].
//!
//! Each used command is timed from the publication of the scan it answered ([`ScanStamps`]), so
//! the round trip and the uplink of the timing log stay true under lag; each robot's outcomes
//! feed a [`LinkMonitor`], whose degraded-link reports go out as events while the run goes on.
//!
//! Around it the exchange keeps each robot's agent state: admission of candidates by the launch
//! secret (one agent per robot, each nonce once), lockstep lagging and rejoining (and the grace
//! a lost agent's successor gets, and the tick a lockstep run holds for an agent whose link
//! dropped and is reconnecting: [`WorldLink::agent_reconnecting`]), the realtime schedule with
//! its re-anchoring after a pause, and
//! the forwarding of swap requests (each swap done is kept, with the file its request named, for
//! the recording: [`AgentsController::take_swaps_done`]). It reads time only from its [`Clock`] and talks only to a
//! [`WorldLink`], so all of it runs in unit tests on an in-memory link and a fake clock.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::auth::LaunchSecret;
use formation_proto::control::{Controller, ControllerError, Observation};
use formation_proto::exit::TerminationSignal;
use formation_proto::wire::WorldEvent;
use formation_proto::wire::{
    AgentStatus, CmdMsg, CmdStatus, ControlRequest, RobotTiming, RunId, ScanMsg, SwapOutcome,
    SwapReply, SwapRequest, TickOutcome, Welcome, wall_clock_ns,
};
use formation_proto::{LidarSpec, WheelCmd, WheelLimits};

use crate::clock::Clock;
use crate::link::{Hello, WorldLink, WorldLinkError, WorldResult};
use crate::link_health::LinkMonitor;
use crate::liveness::LivenessGate;
use crate::settings::{ClockMode, RuntimeSettings};
use crate::stamps::{ScanStamp, ScanStamps};

/// What the exchange is told: the launch's timing and watchdog settings, and what admits and
/// stops agents.
#[derive(Debug, Clone)]
pub struct ExchangeSettings {
    /// Clock mode, timeouts, stale window, pace, liveness period.
    pub runtime: RuntimeSettings,
    /// Set from outside (the launcher went away) to stop at the next wake-up.
    pub stop: Arc<AtomicBool>,
    /// The run id, part of what an agent's proof covers.
    pub run: RunId,
    /// The launch secret every agent must prove.
    pub secret: LaunchSecret,
}

/// How long an accepted agent may take to open its incarnation's services and say hello before
/// another candidate may take its place.
const ADMISSION_WINDOW: Duration = Duration::from_secs(10);

/// Realtime: when a tick starts this many periods late (the world was stopped, e.g. SIGSTOP then
/// SIGCONT), the 20 Hz schedule starts afresh from now instead of rushing through missed ticks.
const PAUSE_TICKS: u32 = 4;

/// Longest single wait, so a stop request is seen promptly.
const MAX_WAIT: Duration = Duration::from_millis(250);

/// The tick period assumed until an episode gives its own.
const DEFAULT_DT: Duration = Duration::from_millis(50);

/// A command as it reached the world.
#[derive(Debug, Clone, Copy)]
pub struct Arrival {
    /// The message.
    pub msg: CmdMsg,
    /// When the world took it from its subscriber.
    pub at: Instant,
    /// The same instant on the system clock ([`wall_clock_ns`]), for the downlink latency.
    pub wall_ns: u64,
}

/// Picks robot `i`'s command for tick `tick` of episode `generation` from the newest arrival.
///
/// Lockstep accepts only this tick's command; realtime accepts the newest command of this episode
/// while the scan it answers (published at `answered_scan_at`, `None` when unknown) is at most
/// `stale_after` old: a command that arrives late is as stale as the scan it was computed from.
/// Anything else, a non-finite command or a command flagged as a failed decision, brakes the robot.
pub fn choose_command(
    clock: ClockMode,
    newest: Option<&Arrival>,
    generation: u64,
    tick: u64,
    now: Instant,
    stale_after: Duration,
    answered_scan_at: Option<Instant>,
) -> (WheelCmd, TickOutcome) {
    let Some(arrival) = newest.filter(|a| a.msg.generation == generation) else {
        return (WheelCmd::BRAKE, TickOutcome::Missing);
    };
    let usable = match clock {
        ClockMode::Lockstep => arrival.msg.tick == tick,
        ClockMode::Realtime => {
            arrival.msg.tick <= tick
                && answered_scan_at
                    .is_some_and(|at| now.saturating_duration_since(at) <= stale_after)
        }
    };
    if !usable {
        return (WheelCmd::BRAKE, TickOutcome::Stale);
    }
    if arrival.msg.status().contains(CmdStatus::DECISION_FAILED) {
        return (WheelCmd::BRAKE, TickOutcome::AgentFailed);
    }
    let cmd = arrival.msg.wheels();
    if !cmd.is_finite() {
        return (WheelCmd::BRAKE, TickOutcome::NonFinite);
    }
    (cmd, TickOutcome::Fresh)
}

/// Why a robot whose command was not used brakes: a missing or stale command of a robot that has
/// no agent ready to drive it ([`AgentState::Absent`]: its agent died and no successor said
/// hello; [`AgentState::Connected`]: a successor said hello and is not ready yet) is
/// [`TickOutcome::AgentDown`]; every other outcome stands.
pub fn brake_reason(state: AgentState, outcome: TickOutcome) -> TickOutcome {
    match (state, outcome) {
        (AgentState::Absent | AgentState::Connected, TickOutcome::Missing | TickOutcome::Stale) => {
            TickOutcome::AgentDown
        }
        _ => outcome,
    }
}

/// Where one robot's agent stands, as far as the world knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AgentState {
    /// No agent has said hello (not started, or died and not restarted yet).
    Absent,
    /// Said hello; not (yet) ready for the current episode.
    Connected,
    /// Ready for the current episode and answering in time.
    Live,
    /// Ready, but missed a lockstep deadline: not waited for until it answers again.
    Lagging,
}

/// Where the exchange reports progress (agents lost, rejoined, refused): the world process
/// prints each event as a line on stdout for the launcher; tests collect them.
pub type EventSink = Box<dyn FnMut(&WorldEvent)>;

/// The world's end of the exchange for one episode after another, over any [`WorldLink`].
pub struct AgentsController<'l> {
    link: &'l mut dyn WorldLink,
    settings: ExchangeSettings,
    clock: Arc<dyn Clock>,
    events: EventSink,
    generation: u64,
    lidar: LidarSpec,
    /// The robots' wheel limits this episode, which each agent is told.
    wheels: WheelLimits,
    states: Vec<AgentState>,
    newest: Vec<Option<Arrival>>,
    /// Per robot: when its recent scans were published, for timing the command that answers one.
    scan_stamps: Vec<ScanStamps>,
    /// Per robot: the degraded-link detector.
    link_monitors: Vec<LinkMonitor>,
    timings: Vec<RobotTiming>,
    model_ids: Vec<String>,
    schedule_start: Option<Instant>,
    last_liveness_check: Instant,
    /// When each agent was last heard from: only one quiet for a liveness period makes the
    /// world ask its transport which agents died.
    liveness: LivenessGate,
    dt: Duration,
    stopped: Option<StopReason>,
    /// Swap requests forwarded to an agent and not answered yet.
    pending_swaps: Vec<PendingSwap>,
    /// Swaps done since [`AgentsController::take_swaps_done`] last took them (at most
    /// [`MAX_SWAPS_DONE`], the oldest dropped first).
    swaps_done: VecDeque<SwapDone>,
    /// `(robot, request id)` of the latest swaps answered (at most [`MAX_SWAPS_DONE`]): an
    /// answer that comes again (an agent back from a drop answers a repeated request again, as
    /// the first answer may be what the drop lost) is not a second swap.
    swaps_answered: VecDeque<(usize, u64)>,
    /// Per robot: the pid of an agent that said hello during an episode and has not driven yet.
    rejoining: Vec<Option<u32>>,
    /// Per robot: the pid of the agent that last said hello.
    agent_pids: Vec<Option<u32>>,
    /// Per robot: an agent whose proof was accepted and that has not said hello yet, and when.
    admitted: Vec<Option<(u32, Instant)>>,
    /// Every nonce seen in a hello: a nonce is good for one greeting only.
    used_nonces: std::collections::HashSet<u64>,
    /// Per robot: the last tick of this episode whose command was applied.
    last_fresh_tick: Vec<Option<u64>>,
    /// Realtime: how far the schedule was moved on after pauses.
    schedule_shift: Duration,
    /// Lockstep, per robot: its agent was just lost, so the current tick waits (up to the command
    /// timeout) for a restarted agent to be ready before moving on without it.
    rejoin_grace: Vec<bool>,
    /// The last tick published.
    tick: u64,
    /// Per tick of this episode: when it began (published its scans), since the first tick
    /// began \[ns\]; also what realtime staleness measures a command's scan age from.
    tick_start_ns: Vec<u64>,
}

/// The most swaps done that the exchange keeps until they are taken.
pub const MAX_SWAPS_DONE: usize = 64;

pub use formation_proto::SwapDone;

/// A swap request forwarded to an agent and not answered yet.
#[derive(Debug)]
struct PendingSwap {
    request_id: u64,
    robot: usize,
    /// The model file the request named.
    path: PathBuf,
    /// The model's bytes, when they came over the network with the request.
    model: Option<Vec<u8>>,
}

/// Why the world stopped before finishing its runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT or SIGTERM.
    Signal(TerminationSignal),
    /// The launcher closed the world's standard input (it exited or is shutting down).
    ParentGone,
}

impl<'l> AgentsController<'l> {
    /// A controller over `link`, reading time from `clock` and reporting to `events`; no agent
    /// is known yet.
    pub fn new(
        link: &'l mut dyn WorldLink,
        settings: ExchangeSettings,
        lidar: LidarSpec,
        clock: Arc<dyn Clock>,
        events: EventSink,
    ) -> Self {
        let n = link.n_robots();
        let now = clock.now();
        let scan_stamps =
            vec![ScanStamps::for_window(settings.runtime.stale_after(), DEFAULT_DT); n];
        AgentsController {
            link,
            settings,
            clock,
            events,
            generation: 0,
            lidar,
            wheels: WheelLimits::default(),
            states: vec![AgentState::Absent; n],
            newest: vec![None; n],
            scan_stamps,
            link_monitors: (0..n).map(|i| LinkMonitor::new(i, DEFAULT_DT)).collect(),
            timings: (0..n).map(|_| RobotTiming::default()).collect(),
            model_ids: vec![String::new(); n],
            schedule_start: None,
            last_liveness_check: now,
            liveness: LivenessGate::new(n),
            dt: DEFAULT_DT,
            stopped: None,
            pending_swaps: Vec::new(),
            swaps_done: VecDeque::new(),
            swaps_answered: VecDeque::new(),
            rejoining: vec![None; n],
            agent_pids: vec![None; n],
            admitted: vec![None; n],
            used_nonces: std::collections::HashSet::new(),
            last_fresh_tick: vec![None; n],
            schedule_shift: Duration::ZERO,
            rejoin_grace: vec![false; n],
            tick_start_ns: Vec::new(),
            tick: 0,
        }
    }

    /// Waits until every robot's agent has said hello, or fails after `timeout` naming the
    /// robots still missing.
    pub fn await_agents(&mut self, timeout: Duration) -> Result<(), ControllerError> {
        let deadline = self.clock.now() + timeout;
        loop {
            self.poll()?;
            let missing: Vec<usize> = self.robots_in(AgentState::Absent);
            if missing.is_empty() {
                return Ok(());
            }
            let now = self.clock.now();
            if now >= deadline {
                return Err(ControllerError::new(format!(
                    "the agents of robots {missing:?} did not connect within {:.1} s; \
                     check that formation-agent starts (see its output above)",
                    timeout.as_secs_f64()
                )));
            }
            self.wait(deadline - now)?;
        }
    }

    /// Starts a new episode of robots with this LIDAR and these wheel limits: sends every
    /// connected agent a begin request and waits until all are ready. An agent that refuses
    /// (e.g. its model does not fit the sensor) fails the episode.
    pub fn begin_episode(
        &mut self,
        dt: f64,
        lidar: LidarSpec,
        wheels: WheelLimits,
    ) -> Result<(), ControllerError> {
        self.generation += 1;
        self.lidar = lidar;
        self.wheels = wheels;
        self.dt = Duration::from_secs_f64(dt);
        self.schedule_start = None;
        self.schedule_shift = Duration::ZERO;
        self.last_fresh_tick.fill(None);
        self.newest.fill(None);
        self.tick_start_ns.clear();
        self.tick = 0;
        for timing in &mut self.timings {
            *timing = RobotTiming::default();
        }
        let stale_after = self.settings.runtime.stale_after();
        for stamps in &mut self.scan_stamps {
            *stamps = ScanStamps::for_window(stale_after, self.dt);
        }
        for monitor in &mut self.link_monitors {
            monitor.begin_episode(self.dt);
        }
        for robot in 0..self.states.len() {
            if self.states[robot] != AgentState::Absent {
                self.states[robot] = AgentState::Connected;
                self.send_begin(robot)?;
            }
        }
        let deadline = self.clock.now() + self.settings.runtime.ready_timeout();
        loop {
            self.poll()?;
            let waiting = self.robots_in(AgentState::Connected);
            let absent = self.robots_in(AgentState::Absent);
            if waiting.is_empty() && absent.is_empty() {
                return Ok(());
            }
            let now = self.clock.now();
            if now >= deadline {
                return Err(ControllerError::new(format!(
                    "agents of robots {:?} were not ready for episode {} within {:.1} s",
                    [waiting, absent].concat(),
                    self.generation,
                    self.settings.runtime.ready_timeout().as_secs_f64()
                )));
            }
            self.wait(deadline - now)?;
        }
    }

    /// Asks every agent to exit.
    pub fn shutdown_agents(&mut self) {
        for robot in 0..self.states.len() {
            if let Err(e) = self.link.send_control(robot, &ControlRequest::Shutdown) {
                tracing::warn!("could not ask robot {robot}'s agent to shut down: {e}");
            }
        }
    }

    /// The per-robot timing logs of the episode that just ended.
    pub fn take_timings(&mut self) -> Vec<RobotTiming> {
        let fresh = (0..self.states.len())
            .map(|_| RobotTiming::default())
            .collect();
        std::mem::replace(&mut self.timings, fresh)
    }

    /// When each tick of the episode that just ended began, since its first tick began \[ns\].
    pub fn take_tick_starts(&mut self) -> Vec<u64> {
        std::mem::take(&mut self.tick_start_ns)
    }

    /// Set when a signal or the launcher stopped the exchange.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped
    }

    /// The id of the model each robot's agent last reported.
    pub fn model_ids(&self) -> &[String] {
        &self.model_ids
    }

    /// What robot `robot`'s last tick played came to: the watchdog's outcome, how many ticks
    /// older than that tick the scan was that the used command answered, and the model that
    /// decided it (`None` when no command was used). `None` before the episode's first tick.
    pub fn last_outcome(&self, robot: usize) -> Option<(TickOutcome, u32, Option<&str>)> {
        let timing = self.timings.get(robot)?;
        let outcome = *timing.outcome.last()?;
        let lag = timing.lag_ticks.last().copied().unwrap_or(0);
        let model = timing
            .model
            .last()
            .and_then(|&m| usize::try_from(m).ok())
            .and_then(|m| timing.model_ids.get(m))
            .map(String::as_str);
        Some((outcome, lag, model))
    }

    fn robots_in(&self, state: AgentState) -> Vec<usize> {
        (0..self.states.len())
            .filter(|&i| self.states[i] == state)
            .collect()
    }

    fn send_begin(&mut self, robot: usize) -> Result<(), ControllerError> {
        let request = ControlRequest::BeginEpisode {
            generation: self.generation,
            lidar: self.lidar,
            wheels: self.wheels,
        };
        self.link
            .send_control(robot, &request)
            .map_err(transport_error)
    }

    fn wait(&mut self, timeout: Duration) -> Result<(), ControllerError> {
        match self.link.wait(timeout.min(MAX_WAIT)) {
            Err(WorldLinkError::Terminated(signal)) => {
                self.stopped = Some(StopReason::Signal(signal));
                Err(ControllerError::new(format!(
                    "stopped by a termination signal ({signal})"
                )))
            }
            other => other.map_err(transport_error),
        }
    }

    /// Takes in everything the agents sent, and every so often asks which agents died.
    fn poll(&mut self) -> Result<(), ControllerError> {
        if self.settings.stop.load(Ordering::Relaxed) {
            self.stopped = Some(StopReason::ParentGone);
            return Err(ControllerError::new(
                "stopped: the launcher closed the world's input",
            ));
        }
        for robot in 0..self.states.len() {
            for hello in drained(|sink| self.link.drain_hellos(robot, sink))? {
                self.on_hello(robot, hello)?;
            }
            for status in drained(|sink| self.link.drain_statuses(robot, sink))? {
                self.liveness.heard(robot, self.clock.now());
                self.on_status(robot, status)?;
            }
            let newest = &mut self.newest[robot];
            let generation = self.generation;
            let clock = &self.clock;
            let (mut answered, mut sent) = (false, false);
            self.link
                .drain_commands(robot, &mut |msg| {
                    let at = clock.now();
                    sent = true;
                    answered |= msg.generation == generation;
                    if newest.is_none_or(|n| {
                        (msg.generation, msg.tick) >= (n.msg.generation, n.msg.tick)
                    }) {
                        *newest = Some(Arrival {
                            msg,
                            at,
                            wall_ns: wall_clock_ns(),
                        });
                    }
                })
                .map_err(transport_error)?;
            if sent {
                self.liveness.heard(robot, self.clock.now());
            }
            if answered && self.states[robot] == AgentState::Lagging {
                // It answers again (late, or a slow first inference after a restart): wait for
                // it from the next tick on, so it can catch up instead of lagging behind forever.
                self.states[robot] = AgentState::Live;
            }
        }
        for request in drained(|sink| self.link.drain_swap_requests(sink))? {
            self.on_swap_request(request)?;
        }
        if self
            .clock
            .now()
            .saturating_duration_since(self.last_liveness_check)
            >= self.settings.runtime.liveness_period()
        {
            self.check_liveness()?;
        }
        Ok(())
    }

    /// A liveness period ended: asks the transport which agents died, where an agent went quiet
    /// or the gate says it is time ([`LivenessGate`]), and lets their robots go.
    fn check_liveness(&mut self) -> Result<(), ControllerError> {
        self.last_liveness_check = self.clock.now();
        let states = &self.states;
        let ask = self.liveness.period_ended(
            self.last_liveness_check,
            self.settings.runtime.liveness_period(),
            |robot| states[robot] != AgentState::Absent,
            self.admitted.iter().any(Option::is_some),
        );
        if !ask {
            return Ok(());
        }
        for (robot, pid) in self.link.dead_agents().map_err(transport_error)? {
            self.agent_gone(robot, pid)?;
        }
        Ok(())
    }

    /// Agent process `pid` of `robot` is gone: if it was the robot's agent (or the one just
    /// admitted), the robot brakes until another agent is accepted.
    fn agent_gone(&mut self, robot: usize, pid: u32) -> Result<(), ControllerError> {
        if self.admitted[robot].is_some_and(|(admitted, _)| admitted == pid) {
            // Accepted, then gone before it said hello.
            self.admitted[robot] = None;
            self.link.close_incarnation(robot);
            return Ok(());
        }
        if self.agent_pids[robot] != Some(pid) {
            // A dead predecessor (its successor already said hello), or a process that never
            // drove this robot.
            return Ok(());
        }
        if self.states[robot] != AgentState::Absent {
            tracing::warn!("robot {robot}'s agent died; braking it until an agent rejoins");
            self.states[robot] = AgentState::Absent;
            self.rejoin_grace[robot] =
                self.settings.runtime.clock == ClockMode::Lockstep && self.generation > 0;
            (self.events)(&WorldEvent::AgentLost {
                robot,
                tick: self.tick,
                last_fresh_tick: self.last_fresh_tick[robot],
            });
        }
        self.link.close_incarnation(robot);
        self.fail_pending_swaps(robot, "its agent died before answering")
    }

    /// A candidate asked to drive `robot`: accept it (create its incarnation's services) when it
    /// proved the launch secret with a fresh nonce and the robot has no agent, else refuse it
    /// with the reason, which the launcher prints with the candidate's pid.
    fn on_hello(&mut self, robot: usize, hello: Hello) -> Result<(), ControllerError> {
        let mut current = self.current_agent(robot);
        if let Some(pid) = current
            && !self.link.agent_alive(robot, pid).map_err(transport_error)?
        {
            // A restarted agent can greet before the world noticed its predecessor's death
            // (the new agent's own start may even have cleaned the dead one up already).
            self.agent_gone(robot, pid)?;
            current = self.current_agent(robot);
        }
        let verdict = admit(
            &self.settings.secret,
            &self.settings.run,
            robot,
            &hello,
            &mut self.used_nonces,
            current,
        );
        match verdict {
            Ok(()) => {
                tracing::info!("robot {robot}: admitting agent pid {}", hello.pid);
                self.link
                    .open_incarnation(robot, hello.nonce)
                    .map_err(transport_error)?;
                self.admitted[robot] = Some((hello.pid, self.clock.now()));
                self.link
                    .answer_hello(robot, hello.nonce, &Welcome::Accepted)
                    .map_err(transport_error)?;
            }
            Err(reason) => {
                tracing::warn!("robot {robot}: refused pid {}: {reason}", hello.pid);
                if let Err(e) =
                    self.link
                        .answer_hello(robot, hello.nonce, &Welcome::Refused(reason.clone()))
                {
                    tracing::warn!("could not answer a refused hello: {e}");
                }
                (self.events)(&WorldEvent::AgentRefused {
                    robot,
                    pid: hello.pid,
                    reason,
                });
            }
        }
        Ok(())
    }

    /// The pid of the agent that holds `robot` now: one that drives it, or one admitted a moment
    /// ago that is still opening its services.
    fn current_agent(&self, robot: usize) -> Option<u32> {
        if self.states[robot] != AgentState::Absent {
            return self.agent_pids[robot];
        }
        self.admitted[robot]
            .filter(|(_, at)| self.clock.now().saturating_duration_since(*at) < ADMISSION_WINDOW)
            .map(|(pid, _)| pid)
    }

    /// A user asked (through `formation swap`) for robot `request.robot` to change its model:
    /// forward it to that robot's agent, or refuse it at once when there is no such agent.
    fn on_swap_request(&mut self, request: SwapRequest) -> Result<(), ControllerError> {
        let n = self.states.len();
        let refusal = if request.robot >= n {
            Some(format!(
                "robot {} does not exist: this run has {n} robots (0..={})",
                request.robot,
                n.saturating_sub(1)
            ))
        } else if self.states[request.robot] == AgentState::Absent {
            Some(format!(
                "robot {} has no agent connected right now (it died or has not started); \
                 try again once it has rejoined",
                request.robot
            ))
        } else {
            None
        };
        if let Some(reason) = refusal {
            return self.reply_swap(
                request.request_id,
                request.robot,
                SwapOutcome::Refused { reason },
            );
        }
        tracing::info!(
            "robot {}: forwarding swap request {} to {}",
            request.robot,
            request.request_id,
            request.path.display()
        );
        let control = ControlRequest::SwapModel {
            request_id: request.request_id,
            at_tick: request.at_tick,
            path: request.path.clone(),
        };
        self.link
            .send_control(request.robot, &control)
            .map_err(transport_error)?;
        let model = self
            .link
            .forwarded_swaps()
            .and_then(|swaps| swaps.take_forwarded_swap_model(request.request_id));
        self.pending_swaps.push(PendingSwap {
            request_id: request.request_id,
            robot: request.robot,
            path: request.path,
            model,
        });
        Ok(())
    }

    /// Sends the reply to a swap request; a reply nobody waits for any more is not an error.
    fn reply_swap(
        &mut self,
        request_id: u64,
        robot: usize,
        outcome: SwapOutcome,
    ) -> Result<(), ControllerError> {
        self.pending_swaps.retain(|p| p.request_id != request_id);
        let reply = SwapReply {
            request_id,
            robot,
            outcome,
        };
        if let Err(e) = self.link.publish_swap_reply(&reply) {
            tracing::warn!("could not answer swap request {request_id}: {e}");
        }
        Ok(())
    }

    /// Keeps swap `request_id` of `robot`, done at `tick` with `model_id`, for
    /// [`AgentsController::take_swaps_done`], with the model file its request named.
    fn note_swap_done(&mut self, robot: usize, request_id: u64, tick: u64, model_id: &str) {
        let pending = self
            .pending_swaps
            .iter_mut()
            .find(|p| p.request_id == request_id);
        let (path, model) = match pending {
            Some(p) => (Some(p.path.clone()), p.model.take()),
            None => (None, None),
        };
        if self.swaps_done.len() == MAX_SWAPS_DONE {
            self.swaps_done.pop_front();
        }
        self.swaps_done.push_back(SwapDone {
            robot,
            request_id,
            tick,
            model_id: model_id.to_owned(),
            path,
            model,
        });
    }

    /// Notes that robot `robot`'s agent answered swap `request_id`, so that the same answer
    /// again is recognised.
    fn note_swap_answered(&mut self, robot: usize, request_id: u64) {
        if self.swaps_answered.len() == MAX_SWAPS_DONE {
            self.swaps_answered.pop_front();
        }
        self.swaps_answered.push_back((robot, request_id));
    }

    /// The swaps done since the last call, oldest first: what a recording stores of each.
    pub fn take_swaps_done(&mut self) -> Vec<SwapDone> {
        self.swaps_done.drain(..).collect()
    }

    fn fail_pending_swaps(&mut self, robot: usize, why: &str) -> Result<(), ControllerError> {
        let failed: Vec<u64> = self
            .pending_swaps
            .iter()
            .filter(|p| p.robot == robot)
            .map(|p| p.request_id)
            .collect();
        for request_id in failed {
            let reason = format!("robot {robot}'s swap was not done: {why}");
            self.reply_swap(request_id, robot, SwapOutcome::Refused { reason })?;
        }
        Ok(())
    }

    fn on_status(&mut self, robot: usize, status: AgentStatus) -> Result<(), ControllerError> {
        match status {
            AgentStatus::Hello { pid, model_id } => {
                tracing::info!("robot {robot}: agent pid {pid} connected with model {model_id}");
                self.admitted[robot] = None;
                self.model_ids[robot] = model_id;
                self.agent_pids[robot] = Some(pid);
                self.states[robot] = AgentState::Connected;
                if self.generation == 0 {
                    let connected = self
                        .states
                        .iter()
                        .filter(|&&s| s != AgentState::Absent)
                        .count();
                    (self.events)(&WorldEvent::AgentConnected {
                        robot,
                        connected,
                        robots: self.states.len(),
                    });
                }
                if self.generation > 0 {
                    // A (re)started agent joins the episode under way.
                    self.rejoining[robot] = Some(pid);
                    self.send_begin(robot)?;
                }
            }
            AgentStatus::Ready {
                generation,
                model_id,
            } if generation == self.generation => {
                self.model_ids[robot] = model_id;
                self.states[robot] = AgentState::Live;
            }
            AgentStatus::Ready { .. } => {}
            AgentStatus::Refused { generation, reason } if generation == self.generation => {
                return Err(ControllerError::new(format!(
                    "robot {robot}'s agent refused episode {generation}: {reason}"
                )));
            }
            AgentStatus::Refused { .. } => {}
            AgentStatus::SwapDone { request_id, .. }
            | AgentStatus::SwapRefused { request_id, .. }
                if self.swaps_answered.contains(&(robot, request_id)) =>
            {
                tracing::debug!(
                    "robot {robot}: swap {request_id} answered again; answered already"
                );
            }
            AgentStatus::SwapDone {
                request_id,
                tick,
                model_id,
            } => {
                self.note_swap_answered(robot, request_id);
                tracing::info!("robot {robot}: swap {request_id} done at tick {tick}: {model_id}");
                self.model_ids[robot] = model_id.clone();
                self.note_swap_done(robot, request_id, tick, &model_id);
                self.reply_swap(request_id, robot, SwapOutcome::Done { tick, model_id })?;
            }
            AgentStatus::SwapRefused { request_id, reason } => {
                self.note_swap_answered(robot, request_id);
                tracing::warn!("robot {robot}: swap {request_id} refused: {reason}");
                self.reply_swap(request_id, robot, SwapOutcome::Refused { reason })?;
            }
        }
        Ok(())
    }

    fn all_answered(&self, tick: u64) -> bool {
        (0..self.states.len()).all(|i| {
            if self.rejoin_grace[i] {
                // Waited for until a restarted agent is ready (it cannot answer this tick's
                // scan, published before it joined, but it answers the next one).
                return self.states[i] == AgentState::Live;
            }
            self.states[i] != AgentState::Live
                || self.newest[i]
                    .is_some_and(|a| a.msg.generation == self.generation && a.msg.tick == tick)
        })
    }
}

/// Whether a candidate may drive `robot`: its nonce is fresh, its proof holds, and the robot has
/// no agent (`current`). The error is the reason, phrased for the user.
fn admit(
    secret: &LaunchSecret,
    run: &RunId,
    robot: usize,
    hello: &Hello,
    used_nonces: &mut std::collections::HashSet<u64>,
    current: Option<u32>,
) -> Result<(), String> {
    if !used_nonces.insert(hello.nonce) {
        return Err(format!(
            "process {} sent a greeting whose nonce was used before (a copied greeting); \
             robot {robot} keeps its agent or keeps braking",
            hello.pid
        ));
    }
    if !secret.verify(run, robot, hello.pid, hello.nonce, &hello.proof) {
        return Err(format!(
            "process {} did not prove this launch's secret, so this launch did not start it; \
             it may not drive robot {robot}, which keeps its agent or keeps braking (only \
             `formation run` starts the agents of run {run})",
            hello.pid
        ));
    }
    if let Some(pid) = current {
        return Err(format!(
            "robot {robot} is already driven by agent pid {pid} of this launch; one agent per \
             robot, so process {} is refused",
            hello.pid
        ));
    }
    Ok(())
}

fn transport_error(e: WorldLinkError) -> ControllerError {
    ControllerError::new(e.to_string())
}

/// What one of the link's `drain_*` calls hands its sink, in order (taken out first, so that
/// handling it may use the link again).
fn drained<T>(
    drain: impl FnOnce(&mut dyn FnMut(T)) -> WorldResult,
) -> Result<Vec<T>, ControllerError> {
    let mut items = Vec::new();
    drain(&mut |item| items.push(item)).map_err(transport_error)?;
    Ok(items)
}

impl AgentsController<'_> {
    /// Starts tick `obs.tick` at `entered`: notes the tick, anchors the schedule at the first
    /// tick, and records when this tick began since then. Returns the schedule's start.
    fn begin_tick(&mut self, obs: &Observation<'_>, entered: Instant) -> Instant {
        self.tick = obs.tick;
        let schedule_start = *self.schedule_start.get_or_insert(entered);
        self.tick_start_ns.push(
            u64::try_from(entered.duration_since(schedule_start).as_nanos()).unwrap_or(u64::MAX),
        );
        schedule_start
    }

    /// Publishes every robot's odometry and own scan of `obs`, stamping each scan's
    /// publication just before its hand-over.
    fn publish_scans(&mut self, obs: &Observation<'_>) -> Result<(), ControllerError> {
        for (robot, scan) in obs.scans.iter().enumerate() {
            let msg = ScanMsg::new(
                self.generation,
                obs.tick,
                obs.time,
                obs.poses[robot].theta,
                &obs.goal,
                scan,
            )
            .map_err(|e| ControllerError::new(e.to_string()))?;
            if let Some(odometry) = self.link.odometry() {
                let wheels = obs
                    .wheel_speeds
                    .get(robot)
                    .copied()
                    .unwrap_or(WheelCmd::BRAKE);
                odometry
                    .publish_odometry(robot, &obs.poses[robot], wheels)
                    .map_err(transport_error)?;
            }
            // Stamped before the hand-over: publishing wakes the agent, which may run on this
            // very core before the world resumes, and a stamp taken afterwards would hide that
            // agent's whole answer from the round trip.
            self.scan_stamps[robot].record(
                obs.tick,
                ScanStamp {
                    at: self.clock.now(),
                    wall_ns: msg.published_wall_ns,
                },
            );
            self.link
                .publish_scan(robot, &msg)
                .map_err(transport_error)?;
        }
        Ok(())
    }

    /// When tick `tick`, entered at `entered`, stops waiting for commands: lockstep waits the
    /// command timeout (at least the pace); realtime waits until the next tick is due on the
    /// schedule, which starts afresh from now when this tick started long after it was due.
    fn command_deadline(
        &mut self,
        tick: u64,
        entered: Instant,
        schedule_start: Instant,
    ) -> Instant {
        match self.settings.runtime.clock {
            ClockMode::Lockstep => {
                entered
                    + self
                        .settings
                        .runtime
                        .command_timeout()
                        .max(self.settings.runtime.pace())
            }
            ClockMode::Realtime => {
                let periods = |ticks: u64| self.dt * u32::try_from(ticks).unwrap_or(u32::MAX);
                let due = schedule_start + self.schedule_shift + periods(tick);
                if entered > due + self.dt * PAUSE_TICKS {
                    // The world did not run for a while (stopped and continued): start the
                    // schedule afresh rather than rush through the ticks it missed.
                    let late = entered - due;
                    tracing::warn!(
                        "tick {} started {:.2} s late (was the world stopped?); resuming the \
                         {:.0} Hz schedule from now",
                        tick,
                        late.as_secs_f64(),
                        1.0 / self.dt.as_secs_f64()
                    );
                    self.schedule_shift += late;
                }
                schedule_start + self.schedule_shift + periods(tick + 1)
            }
        }
    }

    /// Takes what the agents send until every awaited agent answered tick `tick` and the pace
    /// (`paced_until`) is kept (lockstep), or until `deadline`; lockstep spins briefly before
    /// blocking.
    fn collect_commands(
        &mut self,
        tick: u64,
        paced_until: Instant,
        deadline: Instant,
    ) -> Result<(), ControllerError> {
        // The spin is bounded on the machine's own clock (it is about this core's time, not the
        // simulation's), so a fake clock in tests never turns it into an endless loop.
        let spin = match self.settings.runtime.clock {
            ClockMode::Lockstep => Duration::from_micros(self.settings.runtime.spin_us),
            ClockMode::Realtime => Duration::ZERO,
        };
        // A poll longer than the command timeout would outlast the tick it serves (and a huge
        // `spin_us` would overflow the instant).
        let polled_from = std::time::Instant::now();
        let spin_until = polled_from
            .checked_add(spin.min(self.settings.runtime.command_timeout()))
            .unwrap_or(polled_from);
        loop {
            self.poll()?;
            let now = self.clock.now();
            let answered = match self.settings.runtime.clock {
                ClockMode::Lockstep => self.all_answered(tick),
                ClockMode::Realtime => false,
            };
            if (answered && now >= paced_until)
                || (now >= deadline && !self.held_for_reconnection(tick)?)
            {
                break;
            }
            if !answered && std::time::Instant::now() < spin_until {
                // A short bounded poll before blocking (lockstep only, `spin_us`); every empty
                // poll yields the core, so an agent that is ready runs first.
                std::thread::yield_now();
                continue;
            }
            let left = if answered { paced_until } else { deadline }.saturating_duration_since(now);
            self.wait(if left.is_zero() { MAX_WAIT } else { left })?;
        }
        Ok(())
    }

    /// Lockstep: whether a live robot that has not answered tick `tick` has an agent whose link
    /// dropped and is reconnecting ([`WorldLink::agent_reconnecting`]): the tick waits for it
    /// past the command timeout, so a drop loses no tick (the link sends the scan again when it
    /// is back, and counts the agent dead when it does not come back in time).
    fn held_for_reconnection(&mut self, tick: u64) -> Result<bool, ControllerError> {
        if self.settings.runtime.clock != ClockMode::Lockstep {
            return Ok(false);
        }
        for robot in 0..self.states.len() {
            let answered = self.newest[robot]
                .is_some_and(|a| a.msg.generation == self.generation && a.msg.tick == tick);
            if self.states[robot] != AgentState::Live || answered {
                continue;
            }
            if let Some(pid) = self.agent_pids[robot]
                && self
                    .link
                    .agent_reconnecting(robot, pid)
                    .map_err(transport_error)?
            {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Robot `robot`'s command for tick `tick` at `now`, and why it is used or braked: the
    /// watchdog's choice from its newest arrival, with the brake reason its agent's state gives.
    fn choose_robot_command(
        &self,
        robot: usize,
        tick: u64,
        now: Instant,
        schedule_start: Instant,
    ) -> (WheelCmd, TickOutcome) {
        let newest = self.newest[robot].as_ref();
        let answered_scan_at = newest.and_then(|a| {
            let began = self.tick_start_ns.get(usize::try_from(a.msg.tick).ok()?)?;
            Some(schedule_start + Duration::from_nanos(*began))
        });
        let (cmd, outcome) = choose_command(
            self.settings.runtime.clock,
            newest,
            self.generation,
            tick,
            now,
            self.settings.runtime.stale_after(),
            answered_scan_at,
        );
        (cmd, brake_reason(self.states[robot], outcome))
    }

    /// Moves robot `robot`'s agent state on by its `outcome` at tick `tick`: a live lockstep
    /// agent without a command in time lags, a lagging one that answers is live again, a used
    /// command is noted as the robot's last fresh tick, and a rejoining agent's first used
    /// command is reported.
    fn track_agent(&mut self, robot: usize, tick: u64, outcome: TickOutcome) {
        match (self.states[robot], outcome) {
            (AgentState::Live, TickOutcome::Missing | TickOutcome::Stale)
                if self.settings.runtime.clock == ClockMode::Lockstep =>
            {
                tracing::warn!("robot {robot}: no command for tick {tick} in time; braking it");
                self.states[robot] = AgentState::Lagging;
            }
            (AgentState::Lagging, TickOutcome::Fresh) => self.states[robot] = AgentState::Live,
            _ => {}
        }
        if outcome == TickOutcome::Fresh {
            self.last_fresh_tick[robot] = Some(tick);
        }
        if outcome == TickOutcome::Fresh
            && let Some(pid) = self.rejoining[robot].take()
        {
            (self.events)(&WorldEvent::AgentRejoined { robot, pid, tick });
        }
    }

    /// Records robot `robot`'s `outcome` at tick `tick` in its timing log (a used command timed
    /// from the scan it answered) and its link monitor, reporting a degraded link as an event.
    fn record_outcome(&mut self, robot: usize, tick: u64, outcome: TickOutcome, now: Instant) {
        let arrival = self.newest[robot].filter(|_| outcome == TickOutcome::Fresh);
        // Timed from the scan the command answered, which under lag is an older tick's.
        let answered_scan = arrival.and_then(|a| self.scan_stamps[robot].of(a.msg.tick));
        let round_trip = arrival
            .zip(answered_scan)
            .map(|(a, scan)| a.at.saturating_duration_since(scan.at));
        self.timings[robot].record(
            outcome,
            arrival.as_ref().map(|a| &a.msg),
            round_trip,
            answered_scan.map_or(0, |scan| scan.wall_ns),
            arrival.map_or(0, |a| a.wall_ns),
        );
        if let Some(report) = self.link_monitors[robot].observe(tick, outcome, round_trip, now) {
            (self.events)(&report);
        }
    }
}

impl Controller for AgentsController<'_> {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        let entered = self.clock.now();
        let schedule_start = self.begin_tick(obs, entered);
        self.publish_scans(obs)?;
        let paced_until = entered + self.settings.runtime.pace();
        let deadline = self.command_deadline(obs.tick, entered, schedule_start);
        self.collect_commands(obs.tick, paced_until, deadline)?;
        self.rejoin_grace.fill(false);
        let now = self.clock.now();
        for (robot, slot) in out.iter_mut().enumerate() {
            let (cmd, outcome) = self.choose_robot_command(robot, obs.tick, now, schedule_start);
            *slot = cmd;
            self.track_agent(robot, obs.tick, outcome);
            self.record_outcome(robot, obs.tick, outcome, now);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::wire::AgentTimings;

    fn arrival(generation: u64, tick: u64, left: f64, status: CmdStatus, at: Instant) -> Arrival {
        let cmd = WheelCmd { left, right: 0.1 };
        let msg = CmdMsg::new(generation, tick, cmd, "m", AgentTimings::default(), status).unwrap();
        Arrival {
            msg,
            at,
            wall_ns: 0,
        }
    }

    #[test]
    fn lockstep_uses_only_this_ticks_command_of_this_episode() {
        let now = Instant::now();
        let stale = Duration::from_millis(150);
        let ok = arrival(2, 5, 0.3, CmdStatus::OK, now);
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&ok), 2, 5, now, stale, None),
            (
                WheelCmd {
                    left: 0.3,
                    right: 0.1
                },
                TickOutcome::Fresh
            )
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&ok), 2, 6, now, stale, None).1,
            TickOutcome::Stale
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&ok), 3, 5, now, stale, None).1,
            TickOutcome::Missing
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, None, 2, 5, now, stale, None).1,
            TickOutcome::Missing
        );
    }

    #[test]
    fn realtime_uses_the_newest_command_while_the_scan_it_answers_is_fresh() {
        let then = Instant::now();
        let stale = Duration::from_millis(150);
        let older_tick = arrival(1, 3, 0.2, CmdStatus::OK, then + Duration::from_millis(20));
        let at = |ms| then + Duration::from_millis(ms);
        let choose = |now, scan_at| {
            choose_command(
                ClockMode::Realtime,
                Some(&older_tick),
                1,
                5,
                now,
                stale,
                scan_at,
            )
        };
        assert_eq!(
            choose(at(100), Some(then)),
            (older_tick.msg.wheels(), TickOutcome::Fresh)
        );
        assert_eq!(
            choose(at(200), Some(then)),
            (WheelCmd::BRAKE, TickOutcome::Stale)
        );
        // A command that just arrived but answers a scan 300 ms old is stale too (a late agent).
        let late = arrival(1, 3, 0.2, CmdStatus::OK, at(300));
        assert_eq!(
            choose_command(
                ClockMode::Realtime,
                Some(&late),
                1,
                5,
                at(301),
                stale,
                Some(then)
            )
            .1,
            TickOutcome::Stale
        );
        // A scan too old to be remembered is stale.
        assert_eq!(choose(at(1), None).1, TickOutcome::Stale);
    }

    #[test]
    fn only_a_fresh_proof_of_the_secret_for_a_free_robot_is_admitted() {
        let secret = LaunchSecret::generate().unwrap();
        let run = RunId::new("r").unwrap();
        let mut used = std::collections::HashSet::new();
        let hello = |pid, nonce, secret: &LaunchSecret| Hello {
            pid,
            nonce,
            proof: secret.prove(&run, 1, pid, nonce),
        };
        assert_eq!(
            admit(&secret, &run, 1, &hello(10, 1, &secret), &mut used, None),
            Ok(())
        );
        let replay = admit(&secret, &run, 1, &hello(10, 1, &secret), &mut used, None);
        assert!(replay.unwrap_err().contains("used before"));
        let stranger = LaunchSecret::generate().unwrap();
        let foreign = admit(&secret, &run, 1, &hello(11, 2, &stranger), &mut used, None);
        let reason = foreign.unwrap_err();
        assert!(
            reason.contains("process 11") && reason.contains("secret"),
            "{reason}"
        );
        let other_robot = admit(&secret, &run, 2, &hello(12, 3, &secret), &mut used, None);
        assert!(
            other_robot.is_err(),
            "a proof for robot 1 does not open robot 2"
        );
        let taken = admit(
            &secret,
            &run,
            1,
            &hello(13, 4, &secret),
            &mut used,
            Some(10),
        );
        assert!(
            taken
                .unwrap_err()
                .contains("already driven by agent pid 10")
        );
    }

    #[test]
    fn a_robot_without_a_ready_agent_brakes_as_agent_down_and_other_reasons_stand() {
        use TickOutcome::{AgentDown, AgentFailed, Fresh, Missing, NonFinite, Stale};
        for state in [AgentState::Absent, AgentState::Connected] {
            assert_eq!(brake_reason(state, Missing), AgentDown);
            assert_eq!(brake_reason(state, Stale), AgentDown);
            for stands in [Fresh, NonFinite, AgentFailed] {
                assert_eq!(brake_reason(state, stands), stands);
            }
        }
        for state in [AgentState::Live, AgentState::Lagging] {
            for outcome in [Fresh, Missing, Stale, NonFinite, AgentFailed] {
                assert_eq!(brake_reason(state, outcome), outcome);
            }
        }
    }

    #[test]
    fn watchdog_brakes_non_finite_and_failed_commands() {
        let now = Instant::now();
        let stale = Duration::from_millis(150);
        let nan = arrival(1, 0, f64::NAN, CmdStatus::OK, now);
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&nan), 1, 0, now, stale, None),
            (WheelCmd::BRAKE, TickOutcome::NonFinite)
        );
        let failed = arrival(1, 0, 0.4, CmdStatus::DECISION_FAILED, now);
        assert_eq!(
            choose_command(
                ClockMode::Realtime,
                Some(&failed),
                1,
                0,
                now,
                stale,
                Some(now)
            ),
            (WheelCmd::BRAKE, TickOutcome::AgentFailed)
        );
    }
}
