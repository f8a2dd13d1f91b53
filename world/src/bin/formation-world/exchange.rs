//! The world's side of the per-tick exchange with the agents, as a [`Controller`].
//!
//! [`AgentsController`] publishes every robot's own scan, waits for the agents' commands under the
//! clock mode's rule, and hands the chosen commands to the unchanged in-process episode loop
//! ([`formation_world::run_episode`]). Because the world is stepped by the very same code in the
//! very same order as in-process, a lockstep run is bit-identical to an in-process run with the
//! same model, seed and scenario.
//!
//! The choice of each robot's command ([`choose_command`]) is a pure function of what arrived and
//! when; the watchdog is part of it: a missing, stale, non-finite or failed command brakes the robot.

use std::time::{Duration, Instant};

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use formation_proto::wire::{
    AgentStatus, CmdMsg, CmdStatus, ControlRequest, RobotTiming, ScanMsg, TickOutcome,
    wall_clock_ns,
};
use formation_proto::{LidarSpec, WheelCmd};
use formation_world::episode::{Controller, ControllerError, Observation};

use crate::transport::{TransportError, WorldLink};

/// How the world paces ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ClockMode {
    /// Wait for every live agent's command of this tick (up to a timeout), then step.
    /// Deterministic: equal bit for bit to the in-process loop.
    Lockstep,
    /// Step at the simulation's own rate (20 Hz for dt = 50 ms) on the wall clock, with the
    /// newest fresh command of each robot.
    Realtime,
}

impl ClockMode {
    /// The name used on the command line and in logs.
    pub fn as_str(&self) -> &'static str {
        match self {
            ClockMode::Lockstep => "lockstep",
            ClockMode::Realtime => "realtime",
        }
    }
}

/// Timing and watchdog settings of the exchange.
#[derive(Debug, Clone)]
pub struct ExchangeSettings {
    /// Clock mode.
    pub clock: ClockMode,
    /// Lockstep: how long to wait for a robot's command before braking it and moving on.
    pub command_timeout: Duration,
    /// Realtime: a command older than this is stale and brakes its robot.
    pub stale_after: Duration,
    /// How long agents may take to answer a begin-episode request.
    pub ready_timeout: Duration,
    /// How often to ask the transport which agents died.
    pub liveness_period: Duration,
    /// Set from outside (the launcher went away) to stop at the next wake-up.
    pub stop: Arc<AtomicBool>,
}

/// Longest single wait, so a stop request is seen promptly.
const MAX_WAIT: Duration = Duration::from_millis(250);

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
/// that is at most `stale_after` old. Anything else, a non-finite command or a command flagged as a
/// failed decision, brakes the robot.
pub fn choose_command(
    clock: ClockMode,
    newest: Option<&Arrival>,
    generation: u64,
    tick: u64,
    now: Instant,
    stale_after: Duration,
) -> (WheelCmd, TickOutcome) {
    let Some(arrival) = newest.filter(|a| a.msg.generation == generation) else {
        return (WheelCmd::BRAKE, TickOutcome::Missing);
    };
    let usable = match clock {
        ClockMode::Lockstep => arrival.msg.tick == tick,
        ClockMode::Realtime => {
            arrival.msg.tick <= tick && now.saturating_duration_since(arrival.at) <= stale_after
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

/// Where one robot's agent stands, as far as the world knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AgentState {
    /// No agent has said hello (not started, or died and not restarted yet).
    Absent,
    /// Said hello; not (yet) ready for the current episode.
    Connected,
    /// Ready for the current episode and answering in time.
    Live,
    /// Ready, but missed a lockstep deadline: no longer waited for until it answers in time again.
    Lagging,
}

/// The world's end of the exchange for one episode after another, over any [`WorldLink`].
pub struct AgentsController<'l> {
    link: &'l mut dyn WorldLink,
    settings: ExchangeSettings,
    generation: u64,
    lidar: LidarSpec,
    states: Vec<AgentState>,
    newest: Vec<Option<Arrival>>,
    published_at: Vec<Instant>,
    published_wall_ns: Vec<u64>,
    timings: Vec<RobotTiming>,
    model_ids: Vec<String>,
    schedule_start: Option<Instant>,
    last_liveness_check: Instant,
    dt: Duration,
    stopped: Option<StopReason>,
}

/// Why the world stopped before finishing its runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT or SIGTERM.
    Signal,
    /// The launcher closed the world's standard input (it exited or is shutting down).
    ParentGone,
}

impl<'l> AgentsController<'l> {
    /// A controller over `link`; no agent is known yet.
    pub fn new(link: &'l mut dyn WorldLink, settings: ExchangeSettings, lidar: LidarSpec) -> Self {
        let n = link.n_robots();
        AgentsController {
            link,
            settings,
            generation: 0,
            lidar,
            states: vec![AgentState::Absent; n],
            newest: vec![None; n],
            published_at: vec![Instant::now(); n],
            published_wall_ns: vec![0; n],
            timings: (0..n).map(|_| RobotTiming::default()).collect(),
            model_ids: vec![String::new(); n],
            schedule_start: None,
            last_liveness_check: Instant::now(),
            dt: Duration::from_millis(50),
            stopped: None,
        }
    }

    /// Waits until every robot's agent has said hello, or fails after `timeout` naming the
    /// robots still missing.
    pub fn await_agents(&mut self, timeout: Duration) -> Result<(), ControllerError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.poll()?;
            let missing: Vec<usize> = self.robots_in(AgentState::Absent);
            if missing.is_empty() {
                return Ok(());
            }
            let now = Instant::now();
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

    /// Starts a new episode: sends every connected agent a begin request and waits until all are
    /// ready. An agent that refuses (e.g. its model does not fit the sensor) fails the episode.
    pub fn begin_episode(&mut self, dt: f64, lidar: LidarSpec) -> Result<(), ControllerError> {
        self.generation += 1;
        self.lidar = lidar;
        self.dt = Duration::from_secs_f64(dt);
        self.schedule_start = None;
        self.newest.fill(None);
        for timing in &mut self.timings {
            *timing = RobotTiming::default();
        }
        for robot in 0..self.states.len() {
            if self.states[robot] != AgentState::Absent {
                self.states[robot] = AgentState::Connected;
                self.send_begin(robot)?;
            }
        }
        let deadline = Instant::now() + self.settings.ready_timeout;
        loop {
            self.poll()?;
            let waiting = self.robots_in(AgentState::Connected);
            let absent = self.robots_in(AgentState::Absent);
            if waiting.is_empty() && absent.is_empty() {
                return Ok(());
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(ControllerError::new(format!(
                    "agents of robots {:?} were not ready for episode {} within {:.1} s",
                    [waiting, absent].concat(),
                    self.generation,
                    self.settings.ready_timeout.as_secs_f64()
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

    /// Set when a signal or the launcher stopped the exchange.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped
    }

    /// The id of the model each robot's agent last reported.
    pub fn model_ids(&self) -> &[String] {
        &self.model_ids
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
        };
        self.link
            .send_control(robot, &request)
            .map_err(transport_error)
    }

    fn wait(&mut self, timeout: Duration) -> Result<(), ControllerError> {
        match self.link.wait(timeout.min(MAX_WAIT)) {
            Err(TransportError::Terminated) => {
                self.stopped = Some(StopReason::Signal);
                Err(ControllerError::new("stopped by a termination signal"))
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
            let mut statuses = Vec::new();
            self.link
                .drain_statuses(robot, &mut |s| statuses.push(s))
                .map_err(transport_error)?;
            for status in statuses {
                self.on_status(robot, status)?;
            }
            let newest = &mut self.newest[robot];
            self.link
                .drain_commands(robot, &mut |msg, at| {
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
        }
        if self.last_liveness_check.elapsed() >= self.settings.liveness_period {
            self.last_liveness_check = Instant::now();
            for robot in self.link.dead_agents().map_err(transport_error)? {
                if self.states[robot] != AgentState::Absent {
                    tracing::warn!("robot {robot}'s agent died; braking it until an agent rejoins");
                    self.states[robot] = AgentState::Absent;
                }
            }
        }
        Ok(())
    }

    fn on_status(&mut self, robot: usize, status: AgentStatus) -> Result<(), ControllerError> {
        match status {
            AgentStatus::Hello { pid, model_id } => {
                tracing::info!("robot {robot}: agent pid {pid} connected with model {model_id}");
                self.model_ids[robot] = model_id;
                self.states[robot] = AgentState::Connected;
                if self.generation > 0 {
                    // A (re)started agent joins the episode under way.
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
            AgentStatus::SwapDone {
                request_id,
                tick,
                model_id,
            } => {
                tracing::info!("robot {robot}: swap {request_id} done at tick {tick}: {model_id}");
                self.model_ids[robot] = model_id;
            }
            AgentStatus::SwapRefused { request_id, reason } => {
                tracing::warn!("robot {robot}: swap {request_id} refused: {reason}");
            }
        }
        Ok(())
    }

    fn all_answered(&self, tick: u64) -> bool {
        (0..self.states.len()).all(|i| {
            self.states[i] != AgentState::Live
                || self.newest[i]
                    .is_some_and(|a| a.msg.generation == self.generation && a.msg.tick == tick)
        })
    }
}

fn transport_error(e: TransportError) -> ControllerError {
    ControllerError::new(e.to_string())
}

impl Controller for AgentsController<'_> {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        let entered = Instant::now();
        let schedule_start = *self.schedule_start.get_or_insert(entered);
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
            self.link
                .publish_scan(robot, &msg)
                .map_err(transport_error)?;
            self.published_at[robot] = Instant::now();
            self.published_wall_ns[robot] = msg.published_wall_ns;
        }
        let deadline = match self.settings.clock {
            ClockMode::Lockstep => entered + self.settings.command_timeout,
            ClockMode::Realtime => {
                schedule_start + self.dt * u32::try_from(obs.tick + 1).unwrap_or(u32::MAX)
            }
        };
        loop {
            self.poll()?;
            let now = Instant::now();
            let done = match self.settings.clock {
                ClockMode::Lockstep => self.all_answered(obs.tick),
                ClockMode::Realtime => false,
            };
            if done || now >= deadline {
                break;
            }
            self.wait(deadline - now)?;
        }
        let now = Instant::now();
        for (robot, slot) in out.iter_mut().enumerate() {
            let newest = self.newest[robot].as_ref();
            let (cmd, outcome) = choose_command(
                self.settings.clock,
                newest,
                self.generation,
                obs.tick,
                now,
                self.settings.stale_after,
            );
            *slot = cmd;
            match (self.states[robot], outcome) {
                (AgentState::Live, TickOutcome::Missing | TickOutcome::Stale)
                    if self.settings.clock == ClockMode::Lockstep =>
                {
                    tracing::warn!(
                        "robot {robot}: no command for tick {} in time; braking it",
                        obs.tick
                    );
                    self.states[robot] = AgentState::Lagging;
                }
                (AgentState::Lagging, TickOutcome::Fresh) => self.states[robot] = AgentState::Live,
                _ => {}
            }
            let arrival = newest.filter(|_| outcome == TickOutcome::Fresh);
            self.timings[robot].record(
                outcome,
                arrival.map(|a| &a.msg),
                arrival.map(|a| a.at.saturating_duration_since(self.published_at[robot])),
                self.published_wall_ns[robot],
                arrival.map_or(0, |a| a.wall_ns),
            );
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
            choose_command(ClockMode::Lockstep, Some(&ok), 2, 5, now, stale),
            (
                WheelCmd {
                    left: 0.3,
                    right: 0.1
                },
                TickOutcome::Fresh
            )
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&ok), 2, 6, now, stale).1,
            TickOutcome::Stale
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&ok), 3, 5, now, stale).1,
            TickOutcome::Missing
        );
        assert_eq!(
            choose_command(ClockMode::Lockstep, None, 2, 5, now, stale).1,
            TickOutcome::Missing
        );
    }

    #[test]
    fn realtime_uses_the_newest_command_while_it_is_fresh() {
        let then = Instant::now();
        let stale = Duration::from_millis(150);
        let older_tick = arrival(1, 3, 0.2, CmdStatus::OK, then);
        let (cmd, outcome) = choose_command(
            ClockMode::Realtime,
            Some(&older_tick),
            1,
            5,
            then + Duration::from_millis(100),
            stale,
        );
        assert_eq!((cmd.left, outcome), (0.2, TickOutcome::Fresh));
        let (cmd, outcome) = choose_command(
            ClockMode::Realtime,
            Some(&older_tick),
            1,
            5,
            then + Duration::from_millis(200),
            stale,
        );
        assert_eq!((cmd, outcome), (WheelCmd::BRAKE, TickOutcome::Stale));
    }

    #[test]
    fn watchdog_brakes_non_finite_and_failed_commands() {
        let now = Instant::now();
        let stale = Duration::from_millis(150);
        let nan = arrival(1, 0, f64::NAN, CmdStatus::OK, now);
        assert_eq!(
            choose_command(ClockMode::Lockstep, Some(&nan), 1, 0, now, stale),
            (WheelCmd::BRAKE, TickOutcome::NonFinite)
        );
        let failed = arrival(1, 0, 0.4, CmdStatus::DECISION_FAILED, now);
        assert_eq!(
            choose_command(ClockMode::Realtime, Some(&failed), 1, 0, now, stale),
            (WheelCmd::BRAKE, TickOutcome::AgentFailed)
        );
    }
}
