//! The launcher: starts the world and one agent per robot as child processes, supervises them,
//! and tears everything down.
//!
//! * Progress comes from the world's stdout (one JSON event per line).
//! * An agent that dies while the world runs is restarted with exponential backoff while the
//!   restart budget lasts (the world brakes its robot meanwhile and lets the new agent rejoin);
//!   past the budget the launch fails naming the robot and its exit status.
//! * Ctrl-C / SIGTERM, a failure, or the end of the runs all lead to the same shutdown: the
//!   children's standard input is closed (world and agents watch it and exit cleanly), stragglers
//!   are killed after a grace period, every child is reaped, and the run's iceoryx2 files are
//!   removed. Because children exit when their input closes, they never outlive the launcher,
//!   even if it is killed.
//!
//! Tokio drives only this supervision; the hot loops live in the world and agent processes.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::process::{ExitStatus, Stdio};
use std::time::{Duration, Instant};

use formation_proto::wire::{RunId, RunNamespace, WorldEvent};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, ChildStdin, Command};
use tokio::sync::{mpsc, oneshot};

use super::ClockMode;
use super::binaries::RuntimeBinaries;

/// Everything one launch needs.
#[derive(Debug, Clone)]
pub struct LaunchPlan {
    /// Namespaces services and files.
    pub run_id: RunId,
    /// JSON file with the resolved run specs (`Vec<RunSpec>`) the world plays, in order.
    pub run_specs: PathBuf,
    /// Clock mode.
    pub clock: ClockMode,
    /// Where the world writes its run logs.
    pub out: PathBuf,
    /// Model of each robot, in robot order.
    pub models: Vec<PathBuf>,
    /// Lockstep command timeout \[ms\].
    pub command_timeout_ms: u64,
    /// Realtime staleness limit \[ms\].
    pub stale_ms: u64,
    /// Agent restarts allowed within any [`LaunchPlan::restart_window`] (all robots together).
    pub restart_budget: u32,
    /// The sliding window of the restart budget.
    pub restart_window: Duration,
    /// Delay before a robot's first restart in the window; doubles with each further one.
    pub restart_delay: Duration,
    /// Lockstep: the least time a tick takes (zero: as fast as the agents answer).
    pub pace: Duration,
    /// Fault-injection mode per robot (testing only).
    pub faults: Vec<Option<String>>,
}

/// What a launch did.
#[derive(Debug, Clone, Default)]
pub struct LaunchReport {
    /// Logs of the finished runs, in order of completion.
    pub run_logs: Vec<PathBuf>,
    /// Agent restarts used.
    pub restarts: u32,
    /// Iceoryx2 files and directories removed after the children exited.
    pub cleaned_up: usize,
}

/// Why a launch failed.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// A runtime binary is missing.
    #[error(transparent)]
    Binaries(#[from] super::binaries::BinaryError),
    /// A child could not be started.
    #[error("could not start {what} ({path}): {source}")]
    Spawn {
        /// Which process.
        what: String,
        /// The executable.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Files of this run id already exist.
    #[error(
        "iceoryx2 files of run {run} already exist ({files}); another launch uses this run id, or a \
         crashed one left them: pick another --run-id or remove them"
    )]
    RunIdInUse {
        /// The run id.
        run: String,
        /// The files found.
        files: String,
    },
    /// An agent died and the restart budget is spent.
    #[error(
        "the agent of robot {robot} exited ({status}) and the restart budget ({budget} restarts in \
         {window_s} s) is spent; see its error above, or raise --restarts / --restart-window-s"
    )]
    AgentFailed {
        /// The robot.
        robot: usize,
        /// Its exit status.
        status: String,
        /// The budget.
        budget: u32,
        /// The budget's window \[s\].
        window_s: f64,
    },
    /// The world failed.
    #[error("the world process exited ({status}); see its error above")]
    WorldFailed {
        /// Its exit status.
        status: String,
    },
    /// Stopped by the user.
    #[error("interrupted by {0}; all processes stopped and cleaned up")]
    Interrupted(&'static str),
    /// Removing the run's files failed.
    #[error("could not remove run {run}'s iceoryx2 files: {source}")]
    Cleanup {
        /// The run id.
        run: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Supervision itself failed.
    #[error("supervising the runtime: {0}")]
    Io(#[from] std::io::Error),
}

/// How long children get to exit on their own before they are killed.
const GRACE: Duration = Duration::from_secs(3);
/// The longest restart delay.
const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// A running agent: its input (closing it asks the agent to exit) and a way to kill it.
struct AgentHandle {
    stdin: Option<ChildStdin>,
    kill: Option<oneshot::Sender<()>>,
    reaper: Option<tokio::task::JoinHandle<()>>,
}

/// The sliding-window restart budget: at most `budget` restarts within any `window`, and a delay
/// before each that doubles with the robot's own recent restarts.
#[derive(Debug)]
struct RestartBudget {
    budget: u32,
    window: Duration,
    first_delay: Duration,
    /// When each restart in the window happened, and of which robot.
    recent: VecDeque<(Instant, usize)>,
}

impl RestartBudget {
    fn new(budget: u32, window: Duration, first_delay: Duration) -> RestartBudget {
        RestartBudget {
            budget,
            window,
            first_delay,
            recent: VecDeque::new(),
        }
    }

    /// Books a restart of `robot` at `now` and returns its delay, or `None` when the budget is spent.
    fn book(&mut self, robot: usize, now: Instant) -> Option<Duration> {
        while self
            .recent
            .front()
            .is_some_and(|&(at, _)| now.duration_since(at) >= self.window)
        {
            self.recent.pop_front();
        }
        if self.recent.len() >= self.budget as usize {
            return None;
        }
        let own = self.recent.iter().filter(|&&(_, r)| r == robot).count();
        self.recent.push_back((now, robot));
        let factor = 2u32.saturating_pow(u32::try_from(own.min(16)).unwrap_or(16));
        Some((self.first_delay * factor).min(MAX_BACKOFF.max(self.first_delay)))
    }
}

/// Runs the plan to the end (or failure) and cleans up. `on_event` sees the world's progress.
pub async fn launch(
    plan: &LaunchPlan,
    on_event: &mut dyn FnMut(&WorldEvent),
) -> Result<LaunchReport, LaunchError> {
    let binaries = RuntimeBinaries::locate()?;
    let namespace = RunNamespace::new(&plan.run_id);
    let leftovers = namespace.leftovers();
    if !leftovers.is_empty() {
        return Err(LaunchError::RunIdInUse {
            run: plan.run_id.to_string(),
            files: leftovers
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let mut report = LaunchReport::default();
    let outcome = supervise(plan, &binaries, on_event, &mut report).await;
    let removed = namespace
        .remove_all()
        .map_err(|source| LaunchError::Cleanup {
            run: plan.run_id.to_string(),
            source,
        })?;
    report.cleaned_up = removed;
    outcome.map(|()| report)
}

async fn supervise(
    plan: &LaunchPlan,
    binaries: &RuntimeBinaries,
    on_event: &mut dyn FnMut(&WorldEvent),
    report: &mut LaunchReport,
) -> Result<(), LaunchError> {
    let mut world = spawn_world(plan, binaries)?;
    let mut world_stdin = world.stdin.take();
    let world_stdout = world
        .stdout
        .take()
        .ok_or_else(|| std::io::Error::other("world stdout not piped"))?;
    let mut lines = BufReader::new(world_stdout).lines();

    let (exit_tx, mut exit_rx) = mpsc::unbounded_channel::<(usize, ExitStatus)>();
    let (restart_tx, mut restart_rx) = mpsc::unbounded_channel::<usize>();
    let mut budget =
        RestartBudget::new(plan.restart_budget, plan.restart_window, plan.restart_delay);
    let mut agents = Vec::with_capacity(plan.models.len());
    for robot in 0..plan.models.len() {
        match spawn_agent(plan, binaries, robot, true, exit_tx.clone()) {
            Ok(handle) => agents.push(handle),
            Err(e) => {
                shutdown(&mut world, &mut world_stdin, &mut agents).await;
                return Err(e);
            }
        }
    }

    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut finished = false;
    let mut stdout_open = true;
    let result = loop {
        tokio::select! {
            line = lines.next_line(), if stdout_open => match line? {
                Some(line) => {
                    if let Some(event) = WorldEvent::parse(&line) {
                        if let WorldEvent::RunDone { log, .. } = &event {
                            report.run_logs.push(log.clone());
                        }
                        finished |= event == WorldEvent::Finished;
                        on_event(&event);
                    }
                }
                None => stdout_open = false,
            },
            status = world.wait() => {
                let status = status?;
                break if status.success() && finished {
                    Ok(())
                } else {
                    Err(LaunchError::WorldFailed { status: describe(status) })
                };
            }
            Some((robot, status)) = exit_rx.recv() => {
                let handle = &mut agents[robot];
                handle.kill = None;
                handle.stdin = None;
                handle.reaper = None;
                if finished || status.success() {
                    // Agents exit with success only when asked to (shutdown, signal, world gone).
                    continue;
                }
                let Some(backoff) = budget.book(robot, Instant::now()) else {
                    break Err(LaunchError::AgentFailed {
                        robot,
                        status: describe(status),
                        budget: plan.restart_budget,
                        window_s: plan.restart_window.as_secs_f64(),
                    });
                };
                eprintln!("formation: agent of robot {robot} exited ({}); restarting in {} ms",
                    describe(status), backoff.as_millis());
                report.restarts += 1;
                // The delay runs on its own task, so the world's progress is still read meanwhile.
                let restart_tx = restart_tx.clone();
                tokio::spawn(async move {
                    tokio::time::sleep(backoff).await;
                    let _ = restart_tx.send(robot);
                });
            }
            Some(robot) = restart_rx.recv() => {
                if finished {
                    continue;
                }
                match spawn_agent(plan, binaries, robot, false, exit_tx.clone()) {
                    Ok(new_handle) => agents[robot] = new_handle,
                    Err(e) => break Err(e),
                }
            }
            _ = tokio::signal::ctrl_c() => break Err(LaunchError::Interrupted("Ctrl-C")),
            _ = sigterm.recv() => break Err(LaunchError::Interrupted("SIGTERM")),
        }
    };
    shutdown(&mut world, &mut world_stdin, &mut agents).await;
    result
}

fn describe(status: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit code {code}"),
        (None, Some(signal)) => format!("killed by signal {signal}"),
        _ => status.to_string(),
    }
}

fn spawn_world(plan: &LaunchPlan, binaries: &RuntimeBinaries) -> Result<Child, LaunchError> {
    let mut command = Command::new(&binaries.world);
    command
        .arg("--run-id")
        .arg(plan.run_id.as_str())
        .arg("--run-specs")
        .arg(&plan.run_specs)
        .arg("--out")
        .arg(&plan.out)
        .arg("--clock")
        .arg(plan.clock.as_str())
        .arg("--command-timeout-ms")
        .arg(plan.command_timeout_ms.to_string())
        .arg("--stale-ms")
        .arg(plan.stale_ms.to_string())
        .arg("--pace-ms")
        .arg(plan.pace.as_millis().to_string())
        .arg("--exit-on-stdin-close")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .kill_on_drop(true);
    command.spawn().map_err(|source| LaunchError::Spawn {
        what: "the world".into(),
        path: binaries.world.clone(),
        source,
    })
}

/// Starts robot `robot`'s agent. Its fault-injection mode (if any) applies to the first start
/// only, so a restarted agent behaves and a crash test sees the robot rejoin.
fn spawn_agent(
    plan: &LaunchPlan,
    binaries: &RuntimeBinaries,
    robot: usize,
    first_start: bool,
    exits: mpsc::UnboundedSender<(usize, ExitStatus)>,
) -> Result<AgentHandle, LaunchError> {
    let mut command = Command::new(&binaries.agent);
    command
        .arg("--run-id")
        .arg(plan.run_id.as_str())
        .arg("--robot")
        .arg(robot.to_string())
        .arg("--model")
        .arg(&plan.models[robot])
        .arg("--exit-on-stdin-close")
        .env_remove("FORMATION_AGENT_FAULT")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .kill_on_drop(true);
    if let Some(Some(fault)) = plan.faults.get(robot).filter(|_| first_start) {
        command.arg("--fault").arg(fault);
    }
    let mut child = command.spawn().map_err(|source| LaunchError::Spawn {
        what: format!("the agent of robot {robot}"),
        path: binaries.agent.clone(),
        source,
    })?;
    let stdin = child.stdin.take();
    let (kill_tx, kill_rx) = oneshot::channel::<()>();
    let reaper = tokio::spawn(async move {
        let status = tokio::select! {
            status = child.wait() => status,
            _ = kill_rx => {
                // Asked to stop: kill if still running, then reap.
                let _ = child.start_kill();
                child.wait().await
            }
        };
        if let Ok(status) = status {
            let _ = exits.send((robot, status));
        }
    });
    Ok(AgentHandle {
        stdin,
        kill: Some(kill_tx),
        reaper: Some(reaper),
    })
}

/// Closes every child's input, waits up to [`GRACE`] for them to exit, kills the rest, reaps all.
async fn shutdown(
    world: &mut Child,
    world_stdin: &mut Option<ChildStdin>,
    agents: &mut [AgentHandle],
) {
    drop(world_stdin.take());
    for agent in agents.iter_mut() {
        drop(agent.stdin.take());
    }
    if tokio::time::timeout(GRACE, world.wait()).await.is_err() {
        let _ = world.start_kill();
        let _ = world.wait().await;
    }
    // Agents: their reaper tasks wait for the exit; give them the grace period, then kill.
    let deadline = tokio::time::Instant::now() + GRACE;
    for agent in agents.iter_mut() {
        let Some(mut reaper) = agent.reaper.take() else {
            continue;
        };
        if tokio::time::timeout_at(deadline, &mut reaper)
            .await
            .is_err()
        {
            if let Some(kill) = agent.kill.take() {
                let _ = kill.send(());
            }
            let _ = reaper.await;
        }
        agent.kill = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_restart_budget_slides_and_backs_off_per_robot() {
        let t0 = Instant::now();
        const FIRST_BACKOFF: Duration = Duration::from_millis(50);
        let mut budget = RestartBudget::new(3, Duration::from_secs(10), FIRST_BACKOFF);
        assert_eq!(budget.book(1, t0), Some(FIRST_BACKOFF));
        assert_eq!(budget.book(1, t0), Some(FIRST_BACKOFF * 2));
        assert_eq!(
            budget.book(2, t0),
            Some(FIRST_BACKOFF),
            "another robot starts afresh"
        );
        assert_eq!(
            budget.book(0, t0 + Duration::from_secs(5)),
            None,
            "3 in 10 s: spent"
        );
        let later = t0 + Duration::from_secs(11);
        assert_eq!(
            budget.book(1, later),
            Some(FIRST_BACKOFF),
            "old restarts left the window"
        );
    }
}
