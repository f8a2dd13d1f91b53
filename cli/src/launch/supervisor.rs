//! The launcher: starts the world and one agent per robot as child processes, supervises them,
//! and tears everything down.
//!
//! * Progress comes from the world's stdout (one JSON event per line).
//! * The launch first claims its run id with a lock (of two launches with one id exactly one
//!   wins), removes what a dead launch of the same id left (only when none of its processes
//!   lives), and draws the launch secret, which it writes as the first line of every child's
//!   standard input: only agents that prove it may drive a robot.
//! * An agent that exits while the world runs, however it exits, is restarted with exponential
//!   backoff while the restart budget lasts (the world brakes its robot meanwhile and lets the new
//!   agent rejoin); past the budget the launch fails naming the robot and its exit status. A run
//!   that ends while a robot's restart is scheduled or under way counts it as a restart; only a
//!   robot nobody restarts (a remote agent that was not started again) has lost its agent for
//!   good ([`AgentRecovery`]).
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

use formation_proto::exit::TerminationSignal;
use formation_proto::wire::{RunId, WorldEvent};
use formation_runtime::auth::LaunchSecret;
use formation_transport_iceoryx2::naming::{NamespaceError, RunNamespace};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::process::{Child, ChildStdin, Command};
use tokio::sync::{mpsc, oneshot};

use formation_runtime::RuntimeSettings;
use formation_runtime::settings::SettingsError;

use super::binaries::RuntimeBinaries;

/// Everything one launch needs.
#[derive(Debug, Clone)]
pub struct LaunchPlan {
    /// Namespaces services and files.
    pub run_id: RunId,
    /// JSON file with the resolved run specs (`Vec<RunSpec>`) the world plays, in order.
    pub run_specs: PathBuf,
    /// The world's clock mode and timeouts, handed to it whole as a JSON file next to
    /// `run_specs` ([`LaunchPlan::settings_path`]).
    pub settings: RuntimeSettings,
    /// Where the world writes its run logs.
    pub out: PathBuf,
    /// Model of each robot, in robot order.
    pub models: Vec<PathBuf>,
    /// Agent restarts allowed within any [`LaunchPlan::restart_window`] (all robots together).
    pub restart_budget: u32,
    /// The sliding window of the restart budget.
    pub restart_window: Duration,
    /// Delay before a robot's first restart in the window; doubles with each further one.
    pub restart_delay: Duration,
    /// Fault-injection mode per robot (testing only).
    pub faults: Vec<Option<String>>,
    /// How the world and the agents reach each other.
    pub network: Network,
    /// What the world records (`--record`), handed to it as a JSON file next to `run_specs`
    /// ([`LaunchPlan::record_settings_path`]).
    pub record: Option<formation_record::RecordSettings>,
    /// What the launch knows of its runs, handed to a Zenoh or ROS 2 world without `record` for
    /// the metadata of recordings made from outside (`formation record --connect`).
    pub launch_info: Option<formation_record::LaunchInfo>,
    /// Where the world serves the runs live to Foxglove (`--foxglove`, checked; the launcher
    /// has said the warning for an address other than loopback).
    pub foxglove: Option<std::net::SocketAddr>,
}

impl LaunchPlan {
    /// How many agents the launcher starts on this host (every robot but the remote ones).
    pub fn local_agent_count(&self) -> usize {
        (0..self.models.len())
            .filter(|&robot| !self.network.is_remote(robot))
            .count()
    }
}

/// How the processes of a launch reach each other.
#[derive(Debug, Clone, Default)]
pub enum Network {
    /// iceoryx2 shared memory: every process on this host.
    #[default]
    SharedMemory,
    /// Zenoh over TCP: the world listens, agents (here or on other hosts) connect.
    Zenoh(ZenohPlan),
    /// ROS 2 over rmw_zenoh: the world is a team of ROS 2 robots on a Zenoh router, every agent a
    /// ROS 2 node that drives one of them.
    Ros2(Ros2Plan),
    /// A registered transport: the world and every agent on this host take its name and
    /// endpoint.
    Plugin(PluginPlan),
}

/// A launch over a registered transport.
#[derive(Clone)]
pub struct PluginPlan {
    /// The transport.
    pub transport: &'static dyn formation_runtime::plugin::TransportPlugin,
    /// `--listen`: its endpoint, handed to the world as `--listen` and to the agents as
    /// `--connect`.
    pub endpoint: Option<String>,
}

impl std::fmt::Debug for PluginPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PluginPlan")
            .field("transport", &self.transport.name())
            .field("endpoint", &self.endpoint)
            .finish()
    }
}

impl PluginPlan {
    /// The flags that name it and its endpoint (`--listen` for the world, `--connect` for an
    /// agent).
    fn args(&self, endpoint_flag: &str) -> Vec<String> {
        let mut args = vec!["--transport".to_owned(), self.transport.name().to_owned()];
        if let Some(endpoint) = &self.endpoint {
            args.extend([endpoint_flag.to_owned(), endpoint.clone()]);
        }
        args
    }

    /// Removes what the run left over this transport once none of its processes lives.
    fn remove_leftovers(&self, run: &RunId) {
        let site = formation_runtime::plugin::RunSite {
            run,
            endpoint: self.endpoint.as_deref(),
        };
        match self.transport.remove_leftovers(&site) {
            Ok(0) => {}
            Ok(removed) => tracing::info!(
                "removed {removed} entries run {run} left over the {} transport",
                self.transport.name()
            ),
            Err(e) => eprintln!(
                "formation: could not remove what run {run} left over the {} transport: {}",
                self.transport.name(),
                formation_proto::errors::chain_text(e.as_ref())
            ),
        }
    }
}

/// A launch over ROS 2.
#[derive(Debug, Clone)]
pub struct Ros2Plan {
    /// Where the world's router listens, `tcp/ADDR:PORT`.
    pub listen: String,
    /// The ROS domain id.
    pub domain_id: u32,
    /// On a `tls/` endpoint, the credentials folder (`formation credentials --tls`): the world
    /// listens with its certificate, and each agent joins with the session configuration of its
    /// robot in the folder's `ros2/` (`ZENOH_SESSION_CONFIG_URI`, as rmw_zenoh's nodes do).
    pub credentials: Option<PathBuf>,
    /// The scenario's robot's wheels, told to each ROS 2 agent (`--max-wheel-speed`,
    /// `--max-wheel-accel`) as the world tells its other agents at each episode's start.
    pub wheels: formation_proto::WheelLimits,
}

/// Where a process on this host connects to a router listening on `listen`: the address, with an
/// any-address (`0.0.0.0`, `[::]`) replaced by loopback.
pub(crate) fn local_endpoint(listen: &str) -> String {
    listen
        .replacen("tcp/0.0.0.0:", "tcp/127.0.0.1:", 1)
        .replacen("tcp/[::]:", "tcp/[::1]:", 1)
        .replacen("tls/0.0.0.0:", "tls/127.0.0.1:", 1)
        .replacen("tls/[::]:", "tls/[::1]:", 1)
}

/// A launch over Zenoh.
#[derive(Debug, Clone)]
pub struct ZenohPlan {
    /// Where the world listens, `tcp/ADDR:PORT`.
    pub listen: String,
    /// The credentials folder (`formation credentials`): the world checks its logins, every
    /// agent logs in with its robot's, and its launch secret is the launch's.
    pub credentials: PathBuf,
    /// Robots whose agents are started by hand (on other hosts): the launcher neither starts nor
    /// restarts them.
    pub remote: Vec<usize>,
}

impl ZenohPlan {
    /// Where an agent on this host connects: the listen address, with an any-address
    /// (`0.0.0.0`, `[::]`) replaced by loopback.
    pub fn local_connect(&self) -> String {
        local_endpoint(&self.listen)
    }

    /// Whether robot `robot`'s agent is started by hand.
    pub fn is_remote(&self, robot: usize) -> bool {
        self.remote.contains(&robot)
    }
}

impl Network {
    /// The Zenoh plan, if the launch uses Zenoh.
    pub fn zenoh(&self) -> Option<&ZenohPlan> {
        match self {
            Network::Zenoh(plan) => Some(plan),
            Network::SharedMemory | Network::Ros2(_) | Network::Plugin(_) => None,
        }
    }

    fn is_remote(&self, robot: usize) -> bool {
        self.zenoh().is_some_and(|z| z.is_remote(robot))
    }
}

impl LaunchPlan {
    /// Where the launch writes [`LaunchPlan::settings`] for the world: `runtime-settings.json`
    /// next to the run specs.
    pub fn settings_path(&self) -> PathBuf {
        self.run_specs.with_file_name("runtime-settings.json")
    }

    /// Where the launch writes [`LaunchPlan::record`] for the world: `record-settings.json`
    /// next to the run specs.
    pub fn record_settings_path(&self) -> PathBuf {
        self.run_specs.with_file_name("record-settings.json")
    }
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
    /// Leftover files of a dead earlier launch of this run id that were removed first.
    pub stale_removed: usize,
    /// Per finished run: the robots that had no agent when it ended and that nobody was
    /// restarting (a remote agent not started again), as `(run index, robot, tick the agent was
    /// lost at)`.
    pub lost_for_good: Vec<LostAgent>,
    /// Per finished run: the robots that had no agent when it ended but whose restart was
    /// scheduled or under way; each counts as a restart, not as a loss.
    pub restarting_at_end: Vec<LostAgent>,
}

/// A robot without an agent at the end of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LostAgent {
    /// The run's index.
    pub run: usize,
    /// The robot.
    pub robot: usize,
    /// The tick at which the world reported the agent lost.
    pub lost_at_tick: u64,
}

/// What the launcher knows of each robot whose agent the world reported lost: which of them a
/// restart is scheduled for or under way (booked and not rejoined yet). At the end of a run, a
/// lost robot is restarting if a restart was booked for it, or if its local agent process has
/// exited and the launcher has not handled that exit yet (it is about to book one); any other is
/// lost for good.
#[derive(Debug, Default)]
pub struct AgentRecovery {
    /// Robot → the tick at which its agent was reported lost.
    lost: std::collections::BTreeMap<usize, u64>,
    /// Robots with a restart booked whose new agent has not rejoined yet.
    restarting: std::collections::BTreeSet<usize>,
}

impl AgentRecovery {
    /// The world reported robot `robot`'s agent lost at tick `tick`.
    pub fn lost(&mut self, robot: usize, tick: u64) {
        self.lost.insert(robot, tick);
    }

    /// A restart of robot `robot`'s agent was booked.
    pub fn restart_booked(&mut self, robot: usize) {
        self.restarting.insert(robot);
    }

    /// A new agent drives robot `robot` again.
    pub fn rejoined(&mut self, robot: usize) {
        self.lost.remove(&robot);
        self.restarting.remove(&robot);
    }

    /// Run `run` ended: its lost robots, split into those lost for good and those being
    /// restarted. `exited_unhandled(robot)` tells whether the robot's local agent process has
    /// exited without the launcher having handled it yet.
    pub fn at_run_end(
        &self,
        run: usize,
        exited_unhandled: impl Fn(usize) -> bool,
    ) -> (Vec<LostAgent>, Vec<LostAgent>) {
        self.lost
            .iter()
            .map(|(&robot, &lost_at_tick)| LostAgent {
                run,
                robot,
                lost_at_tick,
            })
            .partition(|lost| {
                !(self.restarting.contains(&lost.robot) || exited_unhandled(lost.robot))
            })
    }
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
    /// The run id could not be claimed (another live launch holds it) or made private.
    #[error(transparent)]
    Namespace(#[from] NamespaceError),
    /// Files of this run id exist and processes of it are alive, though no launch holds its lock.
    #[error(
        "run {run} has live processes ({nodes}) that no launch supervises; stop them (or pick \
         another --run-id) before reusing this run id"
    )]
    RunIdInUse {
        /// The run id.
        run: String,
        /// The live iceoryx2 nodes found.
        nodes: String,
    },
    /// The world's settings file could not be written.
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The world's recording settings could not be written.
    #[error(transparent)]
    RecordSettings(#[from] formation_record::RecordError),
    /// The host cannot run a team this large.
    #[error(transparent)]
    Capacity(#[from] super::capacity::CapacityError),
    /// The launch secret could not be made or handed over.
    #[error("the launch secret: {0}")]
    Secret(String),
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
    /// Remote agents did not come.
    #[error(
        "the remote agents of robots {robots:?} did not connect to {endpoint} in time; start \
         `formation-agent --transport zenoh --connect {endpoint} --run-id {run} --robot I \
         --model M --credentials robot-I.json` on each robot's host (robot-I.json from \
         {credentials}), and check that the host reaches {endpoint}"
    )]
    RemoteMissing {
        /// The robots whose agents never said hello.
        robots: Vec<usize>,
        /// Where the world listened.
        endpoint: String,
        /// The run id.
        run: String,
        /// The credentials folder.
        credentials: String,
    },
    /// The world failed.
    #[error("the world process exited ({status}); {}", world_failure_hint(*.signal))]
    WorldFailed {
        /// Its exit status.
        status: String,
        /// The signal that killed it, if one did (then it could say nothing itself).
        signal: Option<i32>,
    },
    /// Stopped by the user: SIGINT (Ctrl-C) or SIGTERM.
    #[error("interrupted by {}; all processes stopped and cleaned up", interruption_name(.0))]
    Interrupted(TerminationSignal),
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

/// How a user's interruption is named: `Ctrl-C` for SIGINT, `SIGTERM`.
pub fn interruption_name(signal: &TerminationSignal) -> &'static str {
    match signal {
        TerminationSignal::Interrupt => "Ctrl-C",
        TerminationSignal::Terminate => "SIGTERM",
    }
}

/// How long an agent may take to be admitted: a team starts all its agents at once, and on a
/// small host each one's start (loading ONNX Runtime and its model) queues behind the others', so
/// the wait grows with the team: 10 s plus 150 ms per robot (256 robots: 48 s).
pub fn connect_timeout(robots: usize) -> Duration {
    Duration::from_millis(10_000 + 150 * robots as u64)
}

/// How long the world waits for every agent: the agents' own limit plus 20 s.
pub fn startup_timeout(robots: usize) -> Duration {
    connect_timeout(robots) + Duration::from_secs(20)
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
    super::capacity::check(plan.models.len(), &super::capacity::Host::read())?;
    let namespace = RunNamespace::new(&plan.run_id);
    // Held until the end: while it lives no other launch can use this run id, and nothing
    // below touches a file of the run before it is ours.
    let lock = namespace.lock()?;
    let mut report = LaunchReport {
        stale_removed: remove_dead_launch_leftovers(&namespace)?,
        ..LaunchReport::default()
    };
    if report.stale_removed > 0 {
        eprintln!(
            "formation: removed {} file(s) that a dead launch of run {} left behind (none of its \
             processes is alive)",
            report.stale_removed, plan.run_id
        );
    }
    let secret = match plan.network.zenoh() {
        Some(zenoh) => launch_secret_of(&zenoh.credentials)?,
        None => LaunchSecret::generate().map_err(|e| LaunchError::Secret(e.to_string()))?,
    };
    let outcome = supervise(plan, &binaries, &secret, on_event, &mut report).await;
    if let Network::Plugin(plugin) = &plan.network {
        plugin.remove_leftovers(&plan.run_id);
    }
    let removed = namespace
        .remove_all()
        .map_err(|source| LaunchError::Cleanup {
            run: plan.run_id.to_string(),
            source,
        })?;
    drop(lock);
    report.cleaned_up = removed;
    outcome.map(|()| report)
}

/// The launch secret of a credentials folder, which remote agents hold too.
#[cfg(feature = "zenoh")]
fn launch_secret_of(dir: &std::path::Path) -> Result<LaunchSecret, LaunchError> {
    formation_transport_zenoh::credentials::read_secret(dir)
        .map_err(|e| LaunchError::Secret(e.to_string()))
}

/// Without Zenoh there are no credentials folders.
#[cfg(not(feature = "zenoh"))]
fn launch_secret_of(_dir: &std::path::Path) -> Result<LaunchSecret, LaunchError> {
    Err(LaunchError::Secret(
        formation_runtime::transport::TransportError::NotBuilt {
            program: "formation".into(),
            transport: formation_runtime::transport::Transport::Zenoh,
        }
        .to_string(),
    ))
}

/// With the run's lock held: the files an earlier launch of this run id left are a dead
/// launch's, unless one of its processes still lives (say, a stopped world). Removes them when
/// none does and returns how many; refuses, naming the live processes, otherwise.
fn remove_dead_launch_leftovers(namespace: &RunNamespace) -> Result<usize, LaunchError> {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    if namespace.leftovers().is_empty() {
        return Ok(0);
    }
    let mut alive = Vec::new();
    if let Ok(config) = namespace.iceoryx_config() {
        let _ = Node::<ipc::Service>::list(&config, |state| {
            if let NodeState::Alive(view) = &state {
                let name = view
                    .details()
                    .as_ref()
                    .map(|d| d.name().as_str().to_owned())
                    .unwrap_or_else(|| "unnamed node".into());
                alive.push(name);
            }
            CallbackProgression::Continue
        });
    }
    if !alive.is_empty() {
        return Err(LaunchError::RunIdInUse {
            run: namespace.run().to_string(),
            nodes: alive.join(", "),
        });
    }
    namespace
        .remove_all()
        .map_err(|source| LaunchError::Cleanup {
            run: namespace.run().to_string(),
            source,
        })
}

/// Writes the launch secret as the first line of a child's standard input.
async fn hand_secret(
    stdin: &mut Option<ChildStdin>,
    secret: &LaunchSecret,
) -> Result<(), LaunchError> {
    let Some(stdin) = stdin.as_mut() else {
        return Err(LaunchError::Secret(
            "a child's standard input is not piped".into(),
        ));
    };
    stdin
        .write_all(secret.to_line().as_bytes())
        .await
        .map_err(|e| LaunchError::Secret(format!("writing it to a child's standard input: {e}")))?;
    stdin
        .flush()
        .await
        .map_err(|e| LaunchError::Secret(format!("writing it to a child's standard input: {e}")))
}

/// Starts the world and the agents, supervises them (restarting lost agents within the budget)
/// until the runs end, fail or are interrupted, and shuts everything down.
async fn supervise(
    plan: &LaunchPlan,
    binaries: &RuntimeBinaries,
    secret: &LaunchSecret,
    on_event: &mut dyn FnMut(&WorldEvent),
    report: &mut LaunchReport,
) -> Result<(), LaunchError> {
    let mut world = spawn_world(plan, binaries)?;
    let mut world_stdin = world.stdin.take();
    if let Err(e) = hand_secret(&mut world_stdin, secret).await {
        // The world is gone already (it failed to start): its exit status tells why.
        tracing::debug!("the world did not take the launch secret: {e}");
    }
    let world_stdout = world
        .stdout
        .take()
        .ok_or_else(|| std::io::Error::other("world stdout not piped"))?;
    let mut lines = BufReader::new(world_stdout).lines();

    let (exit_tx, mut exit_rx) = mpsc::unbounded_channel::<(usize, ExitStatus)>();
    let (restart_tx, mut restart_rx) = mpsc::unbounded_channel::<usize>();
    let budget = RestartBudget::new(plan.restart_budget, plan.restart_window, plan.restart_delay);
    let mut agents = spawn_local_agents(
        plan,
        binaries,
        secret,
        &exit_tx,
        &mut world,
        &mut world_stdin,
    )
    .await?;

    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut state = Supervision::new(plan, budget, restart_tx);
    let result = loop {
        tokio::select! {
            // The world's lines first: it says that it stops before it asks the agents to exit.
            biased;
            line = lines.next_line(), if state.stdout_open => match line? {
                Some(line) => state.on_world_line(&line, plan, &agents, report, on_event),
                None => state.stdout_open = false,
            },
            status = world.wait() => break state.world_exited(status?, plan),
            Some((robot, status)) = exit_rx.recv() => {
                if let Err(e) = state.on_agent_exit(robot, status, plan, &mut agents[robot], report) {
                    break Err(e);
                }
            }
            Some(robot) = restart_rx.recv() => {
                if state.winding_down() {
                    continue;
                }
                match spawn_agent(plan, binaries, secret, robot, false, exit_tx.clone()).await {
                    Ok(new_handle) => agents[robot] = new_handle,
                    Err(e) => break Err(e),
                }
            }
            _ = tokio::signal::ctrl_c() => {
                break Err(LaunchError::Interrupted(TerminationSignal::Interrupt))
            }
            _ = sigterm.recv() => break Err(LaunchError::Interrupted(TerminationSignal::Terminate)),
        }
    };
    shutdown(&mut world, &mut world_stdin, &mut agents).await;
    result
}

/// Starts the agent of every local robot (a remote robot gets an empty handle); on a failure,
/// shuts down the world and the agents started so far.
async fn spawn_local_agents(
    plan: &LaunchPlan,
    binaries: &RuntimeBinaries,
    secret: &LaunchSecret,
    exit_tx: &mpsc::UnboundedSender<(usize, ExitStatus)>,
    world: &mut Child,
    world_stdin: &mut Option<ChildStdin>,
) -> Result<Vec<AgentHandle>, LaunchError> {
    let mut agents = Vec::with_capacity(plan.models.len());
    for robot in 0..plan.models.len() {
        if plan.network.is_remote(robot) {
            agents.push(AgentHandle {
                stdin: None,
                kill: None,
                reaper: None,
            });
            continue;
        }
        match spawn_agent(plan, binaries, secret, robot, true, exit_tx.clone()).await {
            Ok(handle) => agents.push(handle),
            Err(e) => {
                shutdown(world, world_stdin, &mut agents).await;
                return Err(e);
            }
        }
    }
    Ok(agents)
}

/// What [`supervise`] tracks of the world and the agents between events.
struct Supervision {
    /// The world said that every run is done.
    finished: bool,
    /// The world said it stops early (a failed write, a signal): agents exit because it asked.
    world_stopping: bool,
    /// The world's stdout is still open.
    stdout_open: bool,
    /// Robots whose agent the world reported lost, and whose restarts are booked.
    recovery: AgentRecovery,
    /// Remote robots whose agent has not said hello yet.
    remote_waiting: Vec<usize>,
    /// The agents' restart budget.
    budget: RestartBudget,
    /// Where a booked restart's robot is sent once its backoff is over.
    restart_tx: mpsc::UnboundedSender<usize>,
}

impl Supervision {
    /// Before the world said anything.
    fn new(
        plan: &LaunchPlan,
        budget: RestartBudget,
        restart_tx: mpsc::UnboundedSender<usize>,
    ) -> Supervision {
        Supervision {
            finished: false,
            world_stopping: false,
            stdout_open: true,
            recovery: AgentRecovery::default(),
            remote_waiting: plan
                .network
                .zenoh()
                .map(|z| z.remote.clone())
                .unwrap_or_default(),
            budget,
            restart_tx,
        }
    }

    /// Whether the runs are over or the world stops, so that agents exit because it asked.
    fn winding_down(&self) -> bool {
        self.finished || self.world_stopping
    }

    /// Handles one line of the world's stdout: an event updates the state and the report and is
    /// passed on to `on_event`; any other line is ignored.
    fn on_world_line(
        &mut self,
        line: &str,
        plan: &LaunchPlan,
        agents: &[AgentHandle],
        report: &mut LaunchReport,
        on_event: &mut dyn FnMut(&WorldEvent),
    ) {
        let Some(event) = WorldEvent::parse(line) else {
            return;
        };
        match &event {
            WorldEvent::RunDone { index, log } => {
                report.run_logs.push(log.clone());
                let (gone, restarting) = self.recovery.at_run_end(*index, |robot| {
                    !plan.network.is_remote(robot)
                        && agents
                            .get(robot)
                            .is_some_and(|a| a.reaper.as_ref().is_some_and(|r| r.is_finished()))
                });
                report.lost_for_good.extend(gone);
                report.restarting_at_end.extend(restarting);
            }
            WorldEvent::AgentLost { robot, tick, .. } => {
                self.recovery.lost(*robot, *tick);
                if let Some(zenoh) = plan.network.zenoh().filter(|z| z.is_remote(*robot)) {
                    eprintln!(
                        "formation: robot {robot}'s agent is remote: the launcher \
                         cannot restart it; start it again on its host \
                         (formation-agent --transport zenoh --connect {} \
                         --run-id {} --robot {robot} ...) and it rejoins",
                        zenoh.listen, plan.run_id
                    );
                }
            }
            WorldEvent::AgentConnected { robot, .. } => {
                self.remote_waiting.retain(|r| r != robot);
            }
            WorldEvent::AgentRejoined { robot, .. } => {
                self.recovery.rejoined(*robot);
            }
            _ => {}
        }
        self.finished |= event == WorldEvent::Finished;
        self.world_stopping |= matches!(event, WorldEvent::Stopping { .. });
        on_event(&event);
    }

    /// The launch's outcome once the world exited with `status`.
    fn world_exited(&self, status: ExitStatus, plan: &LaunchPlan) -> Result<(), LaunchError> {
        if status.success() && self.finished {
            Ok(())
        } else if let Some(zenoh) = plan
            .network
            .zenoh()
            .filter(|_| !self.remote_waiting.is_empty())
        {
            Err(LaunchError::RemoteMissing {
                robots: self.remote_waiting.clone(),
                endpoint: zenoh.listen.clone(),
                run: plan.run_id.to_string(),
                credentials: zenoh.credentials.display().to_string(),
            })
        } else {
            use std::os::unix::process::ExitStatusExt;
            Err(LaunchError::WorldFailed {
                status: describe(status),
                signal: status.signal(),
            })
        }
    }

    /// Robot `robot`'s agent exited with `status`: while the runs are under way, books its
    /// restart (its robot sent on `restart_tx` after the backoff), or fails past the restart
    /// budget.
    fn on_agent_exit(
        &mut self,
        robot: usize,
        status: ExitStatus,
        plan: &LaunchPlan,
        handle: &mut AgentHandle,
        report: &mut LaunchReport,
    ) -> Result<(), LaunchError> {
        handle.kill = None;
        handle.stdin = None;
        handle.reaper = None;
        if self.winding_down() {
            return Ok(());
        }
        // While the runs are under way an agent has no reason to exit, whatever its exit
        // code says (a stray SIGTERM, a refusal, a crash): restart it within the budget.
        let Some(backoff) = self.budget.book(robot, Instant::now()) else {
            return Err(LaunchError::AgentFailed {
                robot,
                status: describe(status),
                budget: plan.restart_budget,
                window_s: plan.restart_window.as_secs_f64(),
            });
        };
        eprintln!(
            "formation: agent of robot {robot} exited ({}); restarting in {} ms",
            describe(status),
            backoff.as_millis()
        );
        report.restarts += 1;
        self.recovery.restart_booked(robot);
        // The delay runs on its own task, so the world's progress is still read meanwhile.
        let restart_tx = self.restart_tx.clone();
        tokio::spawn(async move {
            tokio::time::sleep(backoff).await;
            let _ = restart_tx.send(robot);
        });
        Ok(())
    }
}

/// What to look at after the world failed: its own error when it exited, else what can kill a
/// process from outside, since a killed world prints nothing.
fn world_failure_hint(signal: Option<i32>) -> String {
    match signal {
        None => "see its error above".to_owned(),
        Some(6) => crashed("SIGABRT"),
        Some(11) => crashed("SIGSEGV"),
        Some(signal) => {
            let name = match signal {
                9 => " (SIGKILL)",
                15 => " (SIGTERM)",
                _ => "",
            };
            format!(
                "a signal{name} from outside formation stopped it before it could say why (the \
                 kernel's out-of-memory killer, which `dmesg` reports, or a `kill`); the run \
                 played so far is kept as an incomplete run log"
            )
        }
    }
}

/// The world crashed on `signal` itself, so it printed nothing.
fn crashed(signal: &str) -> String {
    format!(
        "it crashed ({signal}) before it could say why, which is a bug: please report it with the \
         scenario and the command; the run played so far is kept as an incomplete run log"
    )
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
    let settings = plan.settings_path();
    // The world waits for a team whose agents all start at once: longer for a larger team, and
    // never less than the plan asks for.
    // With remote agents the plan's wait (--remote-timeout-s) is the user's and stands.
    let mut world_settings = plan.settings;
    if plan.network.zenoh().is_none_or(|z| z.remote.is_empty()) {
        world_settings.startup_timeout_ms = world_settings
            .startup_timeout_ms
            .max(startup_timeout(plan.models.len()).as_millis() as u64);
    }
    world_settings.write(&settings)?;
    let mut command = Command::new(&binaries.world);
    if let Some(record) = &plan.record {
        let path = plan.record_settings_path();
        record.write(&path)?;
        command.arg("--record-settings").arg(path);
    }
    if let Some(address) = plan.foxglove {
        command.arg("--foxglove").arg(address.to_string());
    }
    let over_zenoh = matches!(plan.network, Network::Zenoh(_) | Network::Ros2(_));
    if let (None, Some(info), true) = (&plan.record, &plan.launch_info, over_zenoh) {
        let path = plan.run_specs.with_file_name("launch-info.json");
        info.write(&path)?;
        command.arg("--launch-info").arg(path);
    }
    if let Some(zenoh) = plan.network.zenoh() {
        command
            .arg("--transport")
            .arg("zenoh")
            .arg("--listen")
            .arg(&zenoh.listen)
            .arg("--credentials")
            .arg(&zenoh.credentials);
    }
    if let Network::Plugin(plugin) = &plan.network {
        command.args(plugin.args("--listen"));
    }
    if let Network::Ros2(ros2) = &plan.network {
        command
            .args(["--transport", "ros2", "--listen", &ros2.listen])
            .args(["--ros-domain-id", &ros2.domain_id.to_string()]);
        if let Some(dir) = &ros2.credentials {
            command.arg("--credentials").arg(dir);
        }
    }
    command
        .arg("--run-id")
        .arg(plan.run_id.as_str())
        .arg("--run-specs")
        .arg(&plan.run_specs)
        .arg("--out")
        .arg(&plan.out)
        .arg("--settings")
        .arg(&settings)
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

/// Starts robot `robot`'s agent and hands it the launch secret. Its fault-injection mode (if any)
/// applies to the first start only, so a restarted agent behaves and a crash test sees the robot
/// rejoin.
async fn spawn_agent(
    plan: &LaunchPlan,
    binaries: &RuntimeBinaries,
    secret: &LaunchSecret,
    robot: usize,
    first_start: bool,
    exits: mpsc::UnboundedSender<(usize, ExitStatus)>,
) -> Result<AgentHandle, LaunchError> {
    let mut command = Command::new(&binaries.agent);
    if let Some(zenoh) = plan.network.zenoh() {
        // The agent reads the launch secret from its credentials file; the launcher still writes
        // it on standard input, which the agent then leaves unread.
        command
            .arg("--transport")
            .arg("zenoh")
            .arg("--connect")
            .arg(zenoh.local_connect())
            .arg("--credentials")
            .arg(zenoh.credentials.join(format!("robot-{robot}.json")));
    }
    if let Network::Plugin(plugin) = &plan.network {
        command.args(plugin.args("--connect"));
    }
    if let Network::Ros2(ros2) = &plan.network {
        // A ROS 2 agent joins the team's ROS graph, not the run: it takes its robot's topics,
        // the team's goal topics and the stale window, and needs no secret.
        command
            .args(["--transport", "ros2", "--connect"])
            .arg(local_endpoint(&ros2.listen))
            .args(["--ros-domain-id", &ros2.domain_id.to_string()])
            .args(["--stale-ms", &plan.settings.stale_ms.to_string()]);
        if let Some(speed) = ros2.wheels.max_speed {
            command.args(["--max-wheel-speed", &speed.to_string()]);
        }
        if let Some(accel) = ros2.wheels.max_accel {
            command.args(["--max-wheel-accel", &accel.to_string()]);
        }
        #[cfg(feature = "tls")]
        if let Some(dir) = &ros2.credentials {
            use formation_transport_ros2::secure;
            let principal = formation_transport_zenoh::access::robot_user(robot);
            command.env(
                secure::SESSION_CONFIG_ENV,
                secure::session_config_file(dir, &principal),
            );
        }
    } else {
        command.arg("--run-id").arg(plan.run_id.as_str());
    }
    command
        .arg("--robot")
        .arg(robot.to_string())
        .arg("--model")
        .arg(&plan.models[robot])
        .arg("--connect-timeout-ms")
        .arg(connect_timeout(plan.models.len()).as_millis().to_string())
        .arg("--exit-on-stdin-close")
        .env_remove("FORMATION_AGENT_FAULT")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .kill_on_drop(true);
    if let Some(Some(fault)) = plan.faults.get(robot).filter(|_| first_start) {
        command.arg("--fault").arg(fault);
    }
    // Rehearsals cost a loaded host its deadlines; an explicit FORMATION_AGENT_REHEARSE_US wins.
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    if std::env::var_os("FORMATION_AGENT_REHEARSE_US").is_none()
        && !super::capacity::agents_should_rehearse(plan.local_agent_count(), cores)
    {
        command.arg("--rehearse-us").arg("0");
    }
    // So does polling for scans; an explicit FORMATION_AGENT_SPIN_US wins.
    if std::env::var_os("FORMATION_AGENT_SPIN_US").is_none()
        && !super::capacity::agents_should_spin(plan.local_agent_count(), cores)
    {
        command.arg("--spin-us").arg("0");
    }
    let mut child = command.spawn().map_err(|source| LaunchError::Spawn {
        what: format!("the agent of robot {robot}"),
        path: binaries.agent.clone(),
        source,
    })?;
    let mut stdin = child.stdin.take();
    if let Err(e) = hand_secret(&mut stdin, secret).await {
        // The agent is gone already (it failed to start): its exit status, reported below,
        // tells why.
        tracing::debug!("robot {robot}'s agent did not take the launch secret: {e}");
    }
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
    fn a_run_that_ends_during_a_restart_counts_it_as_a_restart_not_a_loss() {
        let mut recovery = AgentRecovery::default();
        let lost = |robot, lost_at_tick| LostAgent {
            run: 3,
            robot,
            lost_at_tick,
        };
        // Robot 1: restart booked (its backoff still running at the end).
        recovery.lost(1, 1190);
        recovery.restart_booked(1);
        // Robot 2: its process exited a moment ago; the launcher has not handled the exit yet.
        recovery.lost(2, 1195);
        // Robot 4: lost and nobody restarts it (a remote agent).
        recovery.lost(4, 700);
        // Robot 0: lost, restarted, rejoined.
        recovery.lost(0, 10);
        recovery.restart_booked(0);
        recovery.rejoined(0);
        let (gone, restarting) = recovery.at_run_end(3, |robot| robot == 2);
        assert_eq!(gone, [lost(4, 700)]);
        assert_eq!(restarting, [lost(1, 1190), lost(2, 1195)]);
        // A restart booked before the world reported the loss counts too.
        let mut early = AgentRecovery::default();
        early.restart_booked(5);
        early.lost(5, 40);
        assert_eq!(early.at_run_end(0, |_| false).0, []);
    }

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
