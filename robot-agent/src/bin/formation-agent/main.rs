//! `formation-agent`: one robot's decision maker as its own OS process.
//!
//! It reads the launch secret from the first line of its standard input, loads its ONNX model
//! (refusing a bad one before connecting), asks the world to drive its robot (proving the
//! secret), opens only the services the world made for it, says hello, and then blocks on a wait
//! set: each scan it receives becomes one command
//! through [`robot_agent::decision::Agent`] (occupancy rendering, then inference and speed
//! scaling, each timed), published with those timings. Control requests begin episodes (the
//! agent stays alive across runs), swap the model (loaded on a helper thread, off the hot path,
//! and put in place at a tick boundary), or shut it down.
//!
//! It exits cleanly, with a message saying why, on a shutdown request, on SIGINT/SIGTERM (SIGHUP
//! ends it by default), when its standard input closes (with `--exit-on-stdin-close`: the
//! launcher is gone), or within about a second of the world process going away. Other signals
//! (SIGCONT after a stop, SIGUSR1, SIGURG, ...) only interrupt a wait, which it simply resumes.

mod faults;
mod transport;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use formation_onnx::OnnxPolicy;
use formation_proto::auth::LaunchSecret;
use formation_proto::wire::{
    AgentStatus, AgentTimings, CmdMsg, CmdStatus, ControlRequest, RunId, RunNamespace, ScanMsg,
    wall_clock_ns,
};
use formation_proto::{LidarSpec, WheelCmd};
use robot_agent::decision::{Agent, PolicyBackend};

use crate::faults::{Fault, FaultAction};
use crate::transport::{AgentLink, IceoryxAgentLink, Wake};

/// One robot's agent process of formation's multi-process runtime.
#[derive(Debug, Parser)]
#[command(name = "formation-agent", version)]
struct Args {
    /// Run id of the world to join.
    #[arg(long)]
    run_id: String,
    /// Index of the robot this agent drives.
    #[arg(long)]
    robot: usize,
    /// ONNX policy model.
    #[arg(long)]
    model: PathBuf,
    /// How long to wait for the world's services \[ms\].
    #[arg(long, default_value_t = 10_000)]
    connect_timeout_ms: u64,
    /// Testing only: misbehave (crash-after=N, hang-after=N, late-ms=X, nan-after=N).
    #[arg(long, env = "FORMATION_AGENT_FAULT")]
    fault: Option<Fault>,
    /// Exit when standard input closes (set by the launcher, so agents never outlive it).
    #[arg(long)]
    exit_on_stdin_close: bool,
}

/// Why the agent's loop ended.
enum Exit {
    /// The world ended the run: the normal way out, nothing to tell the user.
    Shutdown,
    /// SIGINT or SIGTERM.
    Signal,
    /// Anything else, told to the user.
    Because(String),
}

/// How long the agent waits with nothing arriving before checking that the world still exists.
const IDLE_CHECK: Duration = Duration::from_millis(250);

fn main() -> ExitCode {
    formation_proto::wire::quiet_iceoryx_logs();
    let filter = tracing_subscriber::EnvFilter::try_from_env("FORMATION_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    let args = Args::parse();
    let who = format!("formation-agent (robot {})", args.robot);
    match run(&args) {
        Ok(Exit::Shutdown) => {
            tracing::info!("{who}: exiting: the world asked us to shut down");
            ExitCode::SUCCESS
        }
        Ok(Exit::Signal) => {
            eprintln!("{who}: exiting: termination signal (SIGINT or SIGTERM)");
            ExitCode::from(130)
        }
        Ok(Exit::Because(reason)) => {
            eprintln!("{who}: exiting: {reason}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{who}: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn load_policy(path: &Path) -> anyhow::Result<Box<dyn PolicyBackend>> {
    let policy =
        OnnxPolicy::load(path).with_context(|| format!("loading model {}", path.display()))?;
    Ok(Box::new(policy))
}

fn run(args: &Args) -> anyhow::Result<Exit> {
    let policy = load_policy(&args.model)?;
    let model_id = policy.model_id().to_owned();
    let run_id = RunId::new(&args.run_id)?;
    let namespace = RunNamespace::new(&run_id);
    let secret = LaunchSecret::read_line(&mut std::io::stdin().lock())?;
    let stdin_closed = Arc::new(AtomicBool::new(false));
    if args.exit_on_stdin_close {
        let flag = Arc::clone(&stdin_closed);
        std::thread::spawn(move || {
            let mut sink = [0u8; 256];
            let mut stdin = std::io::stdin();
            // Only end of file (or a real error) means the launcher is gone: a read that a
            // signal interrupted (EINTR) is simply retried.
            loop {
                match stdin.read(&mut sink) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            flag.store(true, Ordering::Relaxed);
        });
    }
    let mut link = IceoryxAgentLink::connect(
        &namespace,
        args.robot,
        &secret,
        Duration::from_millis(args.connect_timeout_ms),
    )?;
    link.publish_status(&AgentStatus::Hello {
        pid: std::process::id(),
        model_id,
    })?;
    let mut robot = RobotAgent::new(args.model.clone(), policy, args.fault);
    loop {
        if stdin_closed.load(Ordering::Relaxed) {
            return Ok(Exit::Because("the launcher closed our input".into()));
        }
        match link.wait(IDLE_CHECK)? {
            Wake::Terminated => return Ok(Exit::Signal),
            Wake::Idle => {
                if !link.world_alive()? {
                    return Ok(Exit::Because(format!(
                        "the world process of run {} went away (it exited, crashed or was \
                         killed); nothing left to drive",
                        args.run_id
                    )));
                }
            }
            Wake::Activity => {}
        }
        let mut requests = Vec::new();
        link.drain_control(&mut |r| requests.push(r))?;
        for request in requests {
            if let Some(exit) = robot.on_control(request, &mut link)? {
                return Ok(exit);
            }
        }
        if let Some(scan) = link.newest_scan()? {
            robot.on_scan(&scan, &mut link)?;
        }
    }
}

/// A model being loaded on a helper thread for a swap request.
struct PendingSwap {
    request_id: u64,
    at_tick: u64,
    path: PathBuf,
    loaded: mpsc::Receiver<anyhow::Result<Box<dyn PolicyBackend>>>,
    /// The loader's result once taken from `loaded`.
    result: Option<anyhow::Result<Box<dyn PolicyBackend>>>,
}

/// The agent's state between messages.
struct RobotAgent {
    model_path: PathBuf,
    /// The loaded policy before the first episode gives the sensor settings.
    idle_policy: Option<Box<dyn PolicyBackend>>,
    agent: Option<(Agent, LidarSpec)>,
    generation: u64,
    pending_swap: Option<PendingSwap>,
    fault: Option<Fault>,
    answered: u64,
}

impl RobotAgent {
    fn new(model_path: PathBuf, policy: Box<dyn PolicyBackend>, fault: Option<Fault>) -> Self {
        RobotAgent {
            model_path,
            idle_policy: Some(policy),
            agent: None,
            generation: 0,
            pending_swap: None,
            fault,
            answered: 0,
        }
    }

    /// Handles one control request; `Some(exit)` means exit.
    fn on_control(
        &mut self,
        request: ControlRequest,
        link: &mut dyn AgentLink,
    ) -> anyhow::Result<Option<Exit>> {
        match request {
            ControlRequest::Shutdown => return Ok(Some(Exit::Shutdown)),
            ControlRequest::BeginEpisode { generation, lidar } => {
                self.generation = generation;
                let status = match self.prepare(lidar) {
                    Ok(model_id) => AgentStatus::Ready {
                        generation,
                        model_id,
                    },
                    Err(e) => AgentStatus::Refused {
                        generation,
                        reason: format!("{e:#}"),
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
                std::thread::spawn(move || {
                    let _ = tx.send(load_policy(&load_path));
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

    /// Makes the agent ready for an episode with this sensor; returns the model id.
    fn prepare(&mut self, lidar: LidarSpec) -> anyhow::Result<String> {
        if let Some((agent, current)) = &self.agent
            && *current == lidar
        {
            return Ok(agent.model_id().to_owned());
        }
        let policy = match self.idle_policy.take() {
            Some(policy) => policy,
            None => load_policy(&self.model_path)?,
        };
        let agent = Agent::new(policy, lidar).with_context(|| {
            format!(
                "model {} does not fit this robot",
                self.model_path.display()
            )
        })?;
        let id = agent.model_id().to_owned();
        self.agent = Some((agent, lidar));
        Ok(id)
    }

    /// Puts a loaded swap model in place when its tick has come. A swap with `at_tick > 0` waits
    /// for the load at that tick (so a lockstep run swaps at exactly that tick); `at_tick == 0`
    /// swaps as soon as the model is ready. A model that fails to load or validate is refused as
    /// soon as that is known, and the current model keeps driving.
    fn apply_swap(&mut self, tick: u64, link: &mut dyn AgentLink) -> anyhow::Result<bool> {
        let Some(pending) = &mut self.pending_swap else {
            return Ok(false);
        };
        if pending.result.is_none() {
            let must_have_it = pending.at_tick > 0 && tick >= pending.at_tick;
            pending.result = if must_have_it {
                Some(pending.loaded.recv().unwrap_or_else(|_| {
                    Err(anyhow::anyhow!(
                        "the model loader thread stopped unexpectedly"
                    ))
                }))
            } else {
                match pending.loaded.try_recv() {
                    Ok(result) => Some(result),
                    Err(mpsc::TryRecvError::Empty) => None,
                    Err(mpsc::TryRecvError::Disconnected) => Some(Err(anyhow::anyhow!(
                        "the model loader thread stopped unexpectedly"
                    ))),
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
            .unwrap_or_else(|| Err(anyhow::anyhow!("the model was not loaded")));
        let outcome = outcome.and_then(|policy| match &mut self.agent {
            Some((agent, _)) => agent.swap_policy(policy).map_err(anyhow::Error::from),
            None => anyhow::bail!("no episode has begun yet"),
        });
        match outcome {
            Ok(()) => {
                self.model_path = pending.path;
                let model_id = self
                    .agent
                    .as_ref()
                    .map(|(a, _)| a.model_id().to_owned())
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
                    reason: format!("the old model keeps driving; the new one failed: {e:#}"),
                })?;
                Ok(false)
            }
        }
    }

    /// Decides and publishes the command for one scan of the current episode.
    fn on_scan(&mut self, scan: &ScanMsg, link: &mut dyn AgentLink) -> anyhow::Result<()> {
        let received_wall_ns = wall_clock_ns();
        if scan.generation != self.generation || self.agent.is_none() {
            return Ok(()); // a scan of an episode this agent is not (yet) part of
        }
        let swapped = self.apply_swap(scan.tick, link)?;
        let Some((agent, _)) = &mut self.agent else {
            return Ok(());
        };
        let started = Instant::now();
        let perceived = scan
            .ranges()
            .map_err(anyhow::Error::from)
            .and_then(|r| Ok(agent.perceive(r)?));
        let perceived_at = Instant::now();
        let decided = perceived.and_then(|()| Ok(agent.decide(scan.heading, &scan.goal())?));
        let decided_at = Instant::now();
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
                tracing::warn!(
                    "tick {}: cannot decide ({e:#}); asking for a brake",
                    scan.tick
                );
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
                    std::thread::sleep(d);
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
            agent.model_id(),
            timings,
            status,
        )?;
        link.publish_command(&msg)?;
        self.answered += 1;
        Ok(())
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}
