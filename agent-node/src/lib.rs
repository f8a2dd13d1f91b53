//! `formation-agent`: one robot's decision maker as its own OS process.
//!
//! It reads the launch secret from the first line of its standard input, loads its ONNX model
//! (refusing a bad one before connecting), asks the world to drive its robot (proving the
//! secret), opens only the services the world made for it over iceoryx2, says hello, and then
//! runs the runtime's agent loop ([`formation_runtime::agent::AgentLoop`]): each scan becomes one
//! command through [`formation_robot_agent::decision::Agent`]; control requests begin episodes (the agent
//! stays alive across runs), swap the model (loaded off the hot path, put in place at a tick
//! boundary), or shut it down.
//!
//! With `--transport zenoh --connect tcp/ADDR:PORT` it reaches the world over Zenoh instead,
//! from this host or another; `--credentials robot-<i>.json` (from `formation credentials`) then
//! gives its login and the launch secret, in place of standard input.
//!
//! With the name of a transport registered in [`TRANSPORT_PLUGINS`] it connects over that
//! transport ([`formation_runtime::plugin::TransportPlugin::connect_agent`]), `--connect` being
//! its endpoint, the launch secret read from standard input as over iceoryx2.
//!
//! With `--transport ros2 --connect tcp/ROUTER:7447` it is a ROS 2 node instead
//! (`formation_transport_ros2`): it takes a robot's LaserScan and orientation and publishes its
//! Twist, with no world and no ROS installation; see [`ros2`] for its flags.
//!
//! It exits cleanly, with a message saying why, on a shutdown request, on SIGINT/SIGTERM (SIGHUP
//! ends it by default), when its standard input closes (with `--exit-on-stdin-close`: the
//! launcher is gone), or within about a second of the world process going away. Other signals
//! (SIGCONT after a stop, SIGUSR1, SIGURG, ...) only interrupt a wait, which it simply resumes.
//! Its exit code is one of [`formation_proto::exit::ProcessExit`]: 0 when it leaves cleanly, 2 on
//! an error, 130 on SIGINT, 143 on SIGTERM (in every mode, and while it connects too).
//!
//! The binary's `main.rs` parses [`Args`] and calls [`run`], then [`exit_for`]; the robot's
//! ONNX decision the agent loop drives is `formation_robot_agent::pilot`.

pub mod reach;
pub mod ros2;

use std::path::PathBuf;

use formation_proto::exit::ProcessExit;
use formation_runtime::link::AgentLinkError;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Parser;
use formation_proto::wire::RunId;
use formation_robot_agent::pilot::OnnxPilots;
use formation_runtime::agent::{AgentExit, AgentLoop, load_model};
use formation_runtime::auth::LaunchSecret;
use formation_runtime::clock::SystemClock;
use formation_runtime::faults::Fault;
use formation_runtime::link::AgentLink;
use formation_runtime::plugin::{AgentSite, RunSite, TransportPlugin};
use formation_runtime::process::flag_when_stdin_closes;
use formation_runtime::transport::{Transport, TransportError};
use formation_transport_iceoryx2::IceoryxAgentLink;
use formation_transport_iceoryx2::naming::RunNamespace;

/// One robot's agent process of formation's multi-process runtime.
#[derive(Debug, Parser)]
#[command(name = "formation-agent", version)]
pub struct Args {
    /// Run id of the world to join (iceoryx2 and zenoh).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Index of the robot this agent drives. With ROS 2: the simulated team's robot whose topics
    /// (`/robot_<i>/scan`, `/robot_<i>/odom`, `/robot_<i>/cmd_vel`) are the defaults.
    #[arg(long)]
    pub robot: Option<usize>,
    /// ONNX policy model.
    #[arg(long)]
    pub model: PathBuf,
    /// How long to wait for the world's services \[ms\].
    #[arg(long, default_value_t = 10_000)]
    pub connect_timeout_ms: u64,
    /// Testing only: misbehave (crash-after=N, hang-after=N, late-ms=X, nan-after=N).
    #[arg(long, env = "FORMATION_AGENT_FAULT")]
    pub fault: Option<Fault>,
    /// Exit when standard input closes (set by the launcher, so agents never outlive it).
    #[arg(long)]
    pub exit_on_stdin_close: bool,
    /// `--transport`, `--connect` and `--credentials`: how to reach the world.
    #[command(flatten)]
    pub reach: reach::ReachArgs,
    /// Rehearse the last decision this long before the next scan is due \[µs\] (0: never), so
    /// that an agent idling between realtime ticks decides with warm caches (measured on 2
    /// cores, realtime case 1: inference p50 from 140–166 µs down to 72–88 µs, for one extra
    /// decision per tick, about 0.3 % of a core). The launcher turns it off (`--rehearse-us 0`)
    /// for the agents it starts when more than 8 share a core of this host, where the burst of
    /// rehearsals before each scan would cost the world its deadlines, unless
    /// `FORMATION_AGENT_REHEARSE_US` is set.
    #[arg(long, env = "FORMATION_AGENT_REHEARSE_US", default_value_t = 2_000)]
    pub rehearse_us: u64,
    /// Poll for the next scan this long (at most 10 ms) after each command before blocking
    /// \[µs\] (0: never),
    /// yielding the core between polls, while scans have come that soon (an unpaced lockstep run
    /// of a few agents; never in realtime), so that the agent takes its scan without a
    /// wake-up. The launcher turns it off (`--spin-us 0`) for the agents it starts when more
    /// than 2 share a core of this host, unless `FORMATION_AGENT_SPIN_US` is set.
    #[arg(long, env = "FORMATION_AGENT_SPIN_US", default_value_t = 300)]
    pub spin_us: u64,
    /// ROS 2 mode's flags.
    #[command(flatten)]
    pub ros2: ros2::Ros2Args,
}

/// How a run of this agent ends as the process's exit, said on stderr (`who` names the agent).
pub fn exit_for(who: &str, result: anyhow::Result<AgentExit>) -> ProcessExit {
    match result {
        Ok(AgentExit::Shutdown) => {
            tracing::info!("{who}: exiting: the world asked us to shut down");
            ProcessExit::Success
        }
        Ok(AgentExit::Signal(signal)) => {
            eprintln!("{who}: exiting: termination signal ({signal})");
            ProcessExit::stopped_by(signal)
        }
        Ok(AgentExit::Because(reason)) => {
            eprintln!("{who}: exiting: {reason}");
            ProcessExit::Success
        }
        // A registered transport's connection error is wrapped in one that names it.
        Err(e) => match e.chain().find_map(|c| c.downcast_ref::<AgentLinkError>()) {
            Some(AgentLinkError::Terminated(signal)) => {
                eprintln!("{who}: exiting: termination signal ({signal}) while connecting");
                ProcessExit::stopped_by(*signal)
            }
            _ => {
                eprintln!(
                    "{who}: error: {}",
                    formation_proto::errors::chain_text(e.as_ref())
                );
                ProcessExit::Failure
            }
        },
    }
}

/// The transports this binary links (`--transport` refuses the others, naming the build that
/// has them): iceoryx2 always, Zenoh and ROS 2 with the `zenoh` feature.
pub const TRANSPORTS: &[Transport] = Transport::linked(cfg!(feature = "zenoh"));

/// The transports registered beside the first-party ones, one line each; `--transport` takes
/// their names ([`reach::ReachArgs`]), and [`run`] connects over them without knowing them.
pub static TRANSPORT_PLUGINS: &[&dyn TransportPlugin] =
    &[&formation_example_transport_unix_datagram::UnixDatagram];

/// The name this agent goes by in its messages: `formation-agent (robot I)`.
pub fn who(args: &Args) -> String {
    match args.robot {
        Some(robot) => format!("formation-agent (robot {robot})"),
        None => "formation-agent".to_string(),
    }
}

/// Loads the model, connects over the chosen transport and runs the agent loop until it ends.
pub fn run(args: &Args) -> anyhow::Result<AgentExit> {
    let pilots = Arc::new(OnnxPilots);
    let model = load_model(&*pilots, &args.model)?;
    args.reach
        .transport
        .check_built_in("formation-agent", TRANSPORTS)?;
    args.reach
        .transport
        .refuse_network_flags(&[(args.reach.connect.is_some(), "--connect")])?;
    args.reach
        .transport
        .refuse_zenoh_flags(&[(args.reach.credentials.is_some(), "--credentials")])?;
    args.reach.transport.refuse_ros2_flags(&args.ros2.given())?;
    if args.reach.transport == Transport::Ros2 {
        return ros2::run(args, model, &stop_flag(args));
    }
    let (Some(run_id), Some(robot)) = (&args.run_id, args.robot) else {
        anyhow::bail!(
            "--transport {} needs --run-id and --robot (the run and robot to join)",
            args.reach.transport
        );
    };
    let run_id = RunId::new(run_id)?;
    let timeout = Duration::from_millis(args.connect_timeout_ms);
    let mut link: Box<dyn AgentLink> = match args.reach.transport {
        Transport::Iceoryx2 => {
            let namespace = RunNamespace::new(&run_id);
            let secret = LaunchSecret::read_line(&mut std::io::stdin().lock())?;
            Box::new(IceoryxAgentLink::connect(
                &namespace, robot, &secret, timeout,
            )?)
        }
        Transport::Zenoh => zenoh_link(args, &run_id, robot, timeout)?,
        Transport::Plugin(plugin) => plugin_link(plugin, args, &run_id, robot, timeout)?,
        Transport::Ros2 => unreachable!("handled above"),
    };
    // Only now: the launch secret has been read from standard input, and the watcher must not
    // race that read.
    let stop = stop_flag(args);
    let mut agent = AgentLoop::new(
        pilots,
        args.model.clone(),
        model,
        args.fault,
        Arc::new(SystemClock),
    )
    .with_rehearsal(Duration::from_micros(args.rehearse_us))
    .with_spin(Duration::from_micros(args.spin_us));
    agent.greet(link.as_mut(), std::process::id())?;
    Ok(agent.run(link.as_mut(), &stop, run_id.as_str())?)
}

/// Set when standard input closes (the launcher went away), with `--exit-on-stdin-close`. Its
/// watcher reads standard input, so it starts only after the launch secret has been read.
fn stop_flag(args: &Args) -> Arc<AtomicBool> {
    if args.exit_on_stdin_close {
        flag_when_stdin_closes()
    } else {
        Arc::new(AtomicBool::new(false))
    }
}

/// The link of a registered transport, `--connect` being its endpoint; the launch secret comes
/// on standard input.
fn plugin_link(
    plugin: &'static dyn TransportPlugin,
    args: &Args,
    run_id: &RunId,
    robot: usize,
    timeout: Duration,
) -> anyhow::Result<Box<dyn AgentLink>> {
    let secret = LaunchSecret::read_line(&mut std::io::stdin().lock())?;
    let site = AgentSite {
        run: RunSite {
            run: run_id,
            endpoint: args.reach.connect.as_deref(),
        },
        robot,
        pid: std::process::id(),
        secret: &secret,
        connect_timeout: timeout,
    };
    plugin.connect_agent(&site).map_err(|source| {
        TransportError::ConnectAgent {
            transport: plugin.name(),
            robot,
            run: run_id.to_string(),
            source,
        }
        .into()
    })
}

/// The Zenoh link to the world at `--connect`, logged in with `--credentials` when given.
#[cfg(feature = "zenoh")]
fn zenoh_link(
    args: &Args,
    run_id: &RunId,
    robot: usize,
    timeout: Duration,
) -> anyhow::Result<Box<dyn AgentLink>> {
    use formation_transport_zenoh::{ZenohAgentLink, credentials};
    let endpoint = formation_transport_zenoh::required_endpoint(
        args.reach.connect.as_deref(),
        "--connect",
        Transport::Zenoh,
    )?;
    let (login, secret) = match &args.reach.credentials {
        Some(path) => {
            let found = credentials::read_robot(path, robot)?;
            (Some(found.login), found.secret)
        }
        None => (None, LaunchSecret::read_line(&mut std::io::stdin().lock())?),
    };
    let link = ZenohAgentLink::connect(&endpoint, login.as_ref(), run_id, robot, &secret, timeout)?;
    Ok(Box::new(link))
}

/// This build has no Zenoh.
#[cfg(not(feature = "zenoh"))]
fn zenoh_link(
    _args: &Args,
    _run_id: &RunId,
    _robot: usize,
    _timeout: Duration,
) -> anyhow::Result<Box<dyn AgentLink>> {
    Err(TransportError::NotBuilt {
        program: "formation-agent".into(),
        transport: Transport::Zenoh,
    }
    .into())
}
