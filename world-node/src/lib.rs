//! `formation-world`: the world process of the multi-process runtime.
//!
//! It creates every robot's iceoryx2 services in the run's namespace, waits for one agent per
//! robot, then plays the given runs (resolved run specs, written by the launcher) one after another with the agents staying alive: each run
//! begins with a begin-episode request (agents answer ready), then the unchanged in-process episode
//! loop steps the world while [`AgentsController`] trades scans for commands. After each
//! run it writes the run logs ([`runlog`]) and prints a progress event on stdout; while a run plays
//! it journals every tick, and a run that ends early (a signal, the launcher, an error) is kept as
//! an incomplete run log. At the end, or on SIGINT/SIGTERM, or when the launcher closes its
//! standard input, it asks the agents to exit. Its exit code is one of
//! [`formation_proto::exit::ProcessExit`]: 0 when every run was played, 2 on an error, 130 on
//! SIGINT or a closed input, 143 on SIGTERM.
//!
//! The first line of its standard input is the launch secret (see [`formation_runtime::auth`]): only
//! agents that prove it are let drive a robot.
//!
//! With `--transport zenoh` the agents reach it over Zenoh instead: the world listens on
//! `--listen tcp/ADDR:PORT` as a Zenoh router (see `formation_transport_zenoh`), checking the
//! logins of a credentials folder (`--credentials DIR`, from `formation credentials`) when given.
//! With the name of a transport registered in [`TRANSPORT_PLUGINS`] it opens that transport's
//! world link ([`formation_runtime::plugin::TransportPlugin::open_world`]), `--listen` being its
//! endpoint.
//!
//! Usually started by `formation run` / `formation eval --processes`, not by hand.
//!
//! The binary's `main.rs` parses [`Args`] and calls [`run`], then [`exit_for`]. Playing one run
//! with its journal, recording and record channel is [`runlog`]; the Foxglove view is
//! [`live_view`].

pub mod live_view;
pub mod runlog;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use formation_proto::exit::ProcessExit;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use crate::live_view::LiveView;
use anyhow::Context;
use clap::Parser;
use formation_proto::wire::{RunId, WorldEvent};
use formation_runtime::auth::LaunchSecret;
use formation_runtime::clock::SystemClock;
use formation_runtime::exchange::{AgentsController, ExchangeSettings, StopReason};
use formation_runtime::link::{RecordFeed, WorldLink};
use formation_runtime::plugin::{RunSite, TransportPlugin, WorldSite};
use formation_runtime::process::flag_when_stdin_closes;
use formation_runtime::transport::{Transport, TransportError, TransportParser};
use formation_runtime::{ClockMode, RuntimeSettings};
use formation_transport_iceoryx2::IceoryxWorldLink;
use formation_transport_iceoryx2::naming::RunNamespace;
use formation_world::RunSpec;

use crate::runlog::{emit, play_journaled};

/// The flags a settings file replaces.
const SETTING_FLAGS: [&str; 6] = [
    "clock",
    "command_timeout_ms",
    "stale_ms",
    "pace_ms",
    "startup_timeout_ms",
    "ready_timeout_ms",
];

/// The world process of formation's multi-process runtime.
#[derive(Debug, Parser)]
#[command(name = "formation-world", version)]
pub struct Args {
    /// Run id: namespaces the iceoryx2 services and files (letters, digits, '-', '_').
    #[arg(long)]
    pub run_id: String,
    /// JSON file with the runs to play: an array of fully resolved run specs, as
    /// `Scenario::run_spec` makes them (the launcher writes it).
    #[arg(long)]
    pub run_specs: PathBuf,
    /// Directory for the run logs (`runs/`, `timing/`).
    #[arg(long)]
    pub out: PathBuf,
    /// JSON file with the runtime settings (`RuntimeSettings`, every field; the launcher
    /// writes it). Replaces the setting flags below, which may then not be given.
    #[arg(long, conflicts_with_all = SETTING_FLAGS)]
    pub settings: Option<PathBuf>,
    /// Clock mode.
    #[arg(long, value_enum, default_value_t = RuntimeSettings::DEFAULT.clock)]
    pub clock: ClockMode,
    /// Lockstep: wait at most this long for a robot's command before braking it \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.command_timeout_ms)]
    pub command_timeout_ms: u64,
    /// Realtime: a command older than this brakes its robot \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.stale_ms)]
    pub stale_ms: u64,
    /// Lockstep: each tick takes at least this long \[ms\] (0: as fast as the agents answer).
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.pace_ms)]
    pub pace_ms: u64,
    /// How long to wait for every agent to connect \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.startup_timeout_ms)]
    pub startup_timeout_ms: u64,
    /// How long agents may take to get ready for an episode \[ms\].
    #[arg(long, default_value_t = RuntimeSettings::DEFAULT.ready_timeout_ms)]
    pub ready_timeout_ms: u64,
    /// Stop when standard input closes (set by the launcher, so the world never outlives it).
    #[arg(long)]
    pub exit_on_stdin_close: bool,
    /// How the agents reach the world: iceoryx2 shared memory on this host, Zenoh over TCP
    /// (agents on this host or others), ROS 2 over rmw_zenoh (the world as a team of ROS 2
    /// robots: `/robot_<i>/scan`, `/robot_<i>/odom`, `/robot_<i>/cmd_vel`), or a registered
    /// transport.
    #[arg(long, value_parser = TransportParser::new(TRANSPORT_PLUGINS), default_value_t = Transport::Iceoryx2)]
    pub transport: Transport,
    /// Zenoh and ROS 2: the endpoint to listen on, tcp/ADDR:PORT, as a Zenoh router (agents, and
    /// ROS 2 tools, connect to it). A registered transport: its endpoint, if it takes one.
    #[arg(long, value_name = "tcp/ADDR:PORT")]
    pub listen: Option<String>,
    /// ROS 2: the ROS domain id of the team's topics (default 0).
    #[arg(long, value_name = "ID", value_parser = clap::value_parser!(u32).range(0..=232))]
    pub ros_domain_id: Option<u32>,
    /// Zenoh: a credentials folder (`formation credentials`); only its users may connect, each to
    /// its own robot's keys. Without it, any process that reaches the endpoint may. ROS 2 on a
    /// tls/ endpoint: the folder of `formation credentials --tls`, whose certificates the nodes
    /// show, each reaching only its own robot's topics.
    #[arg(long, value_name = "DIR")]
    pub credentials: Option<PathBuf>,
    /// JSON file saying what to record to MCAP and where (`formation_record::RecordSettings`;
    /// the launcher writes it for `--record`).
    #[arg(long, value_name = "FILE")]
    pub record_settings: Option<PathBuf>,
    /// Zenoh: JSON file with what the launch knows of its runs (`formation_record::LaunchInfo`;
    /// the launcher writes it), for the metadata of a recording made from outside
    /// (`formation record --connect`) when there are no --record-settings.
    #[arg(long, value_name = "FILE")]
    pub launch_info: Option<PathBuf>,
    /// Serve the runs live to Foxglove on HOST:PORT (its WebSocket protocol; feature
    /// `foxglove`; see [`live_view`]). The launcher has warned about an address
    /// other than loopback.
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove: Option<String>,
}

impl Args {
    /// The settings file's, or else the flags' (with the defaults of [`RuntimeSettings`]).
    fn runtime_settings(&self) -> anyhow::Result<RuntimeSettings> {
        if let Some(path) = &self.settings {
            return Ok(RuntimeSettings::read(path)?);
        }
        Ok(RuntimeSettings {
            clock: self.clock,
            command_timeout_ms: self.command_timeout_ms,
            stale_ms: self.stale_ms,
            pace_ms: self.pace_ms,
            startup_timeout_ms: self.startup_timeout_ms,
            ready_timeout_ms: self.ready_timeout_ms,
            ..RuntimeSettings::DEFAULT
        })
    }
}

/// The transports this binary links (`--transport` refuses the others, naming the build that
/// has them): iceoryx2 always, Zenoh and ROS 2 with the `zenoh` feature.
pub const TRANSPORTS: &[Transport] = Transport::linked(cfg!(feature = "zenoh"));

/// The transports registered beside the first-party ones, one line each; `--transport` takes
/// their names, and [`run`] opens their links without knowing them.
pub static TRANSPORT_PLUGINS: &[&dyn TransportPlugin] =
    &[&formation_example_transport_unix_datagram::UnixDatagram];

/// How the world's runs ended as the process's exit, said on stderr.
pub fn exit_for(result: anyhow::Result<Ended>) -> ProcessExit {
    match result {
        Ok(Ended::Finished) => ProcessExit::Success,
        Ok(Ended::Stopped(StopReason::Signal(signal))) => {
            eprintln!("formation-world: stopped by {signal}; agents asked to exit");
            ProcessExit::stopped_by(signal)
        }
        Ok(Ended::Stopped(StopReason::ParentGone)) => {
            eprintln!(
                "formation-world: stopped: the launcher closed its input; agents asked to exit"
            );
            ProcessExit::Interrupted
        }
        // Said already, before the agents were asked to exit.
        Ok(Ended::Failed) => ProcessExit::Failure,
        Err(e) => {
            eprintln!(
                "formation-world: error: {}",
                formation_proto::errors::chain_text(e.as_ref())
            );
            ProcessExit::Failure
        }
    }
}

/// How the world's runs ended, once its agents were there.
pub enum Ended {
    /// Every run played.
    Finished,
    /// A signal or the launcher stopped them.
    Stopped(StopReason),
    /// An error stopped them; it is printed.
    Failed,
}

/// Sets up the link, waits for the agents, plays every run and asks the agents to exit.
pub fn run(args: &Args) -> anyhow::Result<Ended> {
    let specs = read_run_specs(&args.run_specs)?;
    let record = args
        .record_settings
        .as_deref()
        .map(formation_record::RecordSettings::read)
        .transpose()?;
    let run_id = RunId::new(&args.run_id)?;
    let namespace = RunNamespace::new(&run_id);
    let n_robots = specs[0].n_robots;
    let lidar = specs[0].world.lidar;

    let runtime = args.runtime_settings()?;
    args.transport
        .check_built_in("formation-world", TRANSPORTS)?;
    args.transport
        .refuse_network_flags(&[(args.listen.is_some(), "--listen")])?;
    // A ROS 2 team takes a credentials folder for its certificates on a tls/ endpoint.
    if args.transport != Transport::Ros2 {
        args.transport
            .refuse_zenoh_flags(&[(args.credentials.is_some(), "--credentials")])?;
    }
    args.transport
        .refuse_ros2_flags(&[(args.ros_domain_id.is_some(), "--ros-domain-id")])?;
    let secret = LaunchSecret::read_line(&mut std::io::stdin().lock())?;
    let stop = if args.exit_on_stdin_close {
        flag_when_stdin_closes()
    } else {
        Arc::new(AtomicBool::new(false))
    };

    let (mut link, feed): (Box<dyn WorldLink>, Option<Box<dyn RecordFeed>>) = match args.transport {
        Transport::Iceoryx2 => (
            Box::new(
                IceoryxWorldLink::create(&namespace, n_robots)
                    .with_context(|| format!("setting up run {run_id}'s services"))?,
            ),
            None,
        ),
        Transport::Zenoh => zenoh_link(args, &run_id, n_robots)?,
        Transport::Ros2 => ros2_link(args, &run_id, &specs[0], &runtime, secret.clone())?,
        Transport::Plugin(plugin) => (plugin_link(plugin, args, &run_id, n_robots)?, None),
    };
    let launch = launch_info(args, record.as_ref(), &runtime)?;
    let mut view = start_live_view(args.foxglove.as_deref(), n_robots)?;
    emit(&WorldEvent::Listening { robots: n_robots });
    let settings = ExchangeSettings {
        runtime,
        stop,
        run: run_id.clone(),
        secret,
    };
    let mut agents = AgentsController::new(
        link.as_mut(),
        settings,
        lidar,
        Arc::new(SystemClock),
        Box::new(emit),
    );
    let mut recording = Recording {
        settings: record,
        launch,
        feed,
        view: view.as_mut(),
    };
    let result = play(args, &runtime, &specs, &mut recording, &mut agents);
    // A world that stops early says why first, and tells the launcher before it asks the agents
    // to exit, so that their exits are not taken for crashes (and restarted).
    let ended = match (&result, agents.stopped()) {
        (_, Some(reason)) => {
            emit(&WorldEvent::Stopping {
                reason: format!("{reason:?}"),
            });
            Ended::Stopped(reason)
        }
        (Ok(()), None) => Ended::Finished,
        (Err(e), None) => {
            let text = formation_proto::errors::chain_text(e.as_ref());
            eprintln!("formation-world: error: {text}");
            emit(&WorldEvent::Stopping { reason: text });
            Ended::Failed
        }
    };
    agents.shutdown_agents();
    if matches!(ended, Ended::Finished) {
        emit(&WorldEvent::Finished);
    }
    Ok(ended)
}

/// What a world's recordings know of the launch: the recording settings', else the
/// `--launch-info` file's, else what the world itself knows (the clock).
fn launch_info(
    args: &Args,
    record: Option<&formation_record::RecordSettings>,
    runtime: &RuntimeSettings,
) -> anyhow::Result<formation_record::LaunchInfo> {
    if let Some(record) = record {
        return Ok(record.launch.clone());
    }
    if let Some(path) = &args.launch_info {
        return Ok(formation_record::LaunchInfo::read(path)?);
    }
    Ok(formation_record::LaunchInfo {
        scenario: String::new(),
        base_seed: None,
        clock: runtime.clock.as_str().to_owned(),
        controller: "policy".into(),
        models: Vec::new(),
        shipped_models: None,
    })
}

/// The world's link of a registered transport, `--listen` being its endpoint.
fn plugin_link(
    plugin: &'static dyn TransportPlugin,
    args: &Args,
    run_id: &RunId,
    n_robots: usize,
) -> Result<Box<dyn WorldLink>, TransportError> {
    let site = WorldSite {
        run: RunSite {
            run: run_id,
            endpoint: args.listen.as_deref(),
        },
        robots: n_robots,
    };
    plugin
        .open_world(&site)
        .map_err(|source| TransportError::OpenWorld {
            transport: plugin.name(),
            run: run_id.to_string(),
            source,
        })
}

/// The world's link and its record channel for remote recorders.
type LinkAndFeed = (Box<dyn WorldLink>, Option<Box<dyn RecordFeed>>);

/// The Zenoh link: a router on `--listen`, with the credentials folder's logins and rules, and
/// its record channel (`formation record --connect`).
#[cfg(feature = "zenoh")]
fn zenoh_link(args: &Args, run_id: &RunId, n_robots: usize) -> anyhow::Result<LinkAndFeed> {
    use formation_transport_zenoh::{WorldAccess, ZenohWorldLink, credentials};
    let listen = formation_transport_zenoh::required_endpoint(
        args.listen.as_deref(),
        "--listen",
        Transport::Zenoh,
    )?;
    let access = match &args.credentials {
        Some(dir) => Some(WorldAccess {
            dictionary_file: credentials::check_passwords(dir)?,
            run: run_id.clone(),
            n_robots,
        }),
        None => {
            eprintln!(
                "formation-world: warning: no --credentials: any process that reaches {listen} \
                 can read the scans and command the robots"
            );
            None
        }
    };
    let link = ZenohWorldLink::create(run_id, n_robots, &listen, access.as_ref())
        .with_context(|| format!("setting up run {run_id}'s Zenoh router on {listen}"))?;
    let feed = link.record_feed();
    with_record_feed(link, feed, run_id)
}

/// A link over a Zenoh router (Zenoh's or ROS 2's) with its record channel `feed` for remote
/// recorders.
#[cfg(feature = "zenoh")]
fn with_record_feed(
    link: impl WorldLink + 'static,
    feed: formation_runtime::link::WorldResult<formation_transport_zenoh::ZenohRecordFeed>,
    run_id: &RunId,
) -> anyhow::Result<LinkAndFeed> {
    let feed = feed.with_context(|| format!("setting up run {run_id}'s record channel"))?;
    Ok((Box::new(link), Some(Box::new(feed))))
}

/// This build has no Zenoh.
#[cfg(not(feature = "zenoh"))]
fn zenoh_link(_args: &Args, _run_id: &RunId, _n_robots: usize) -> anyhow::Result<LinkAndFeed> {
    Err(not_built(Transport::Zenoh))
}

/// Zenoh and ROS 2 are the feature `zenoh`'s, which this build lacks.
#[cfg(not(feature = "zenoh"))]
fn not_built(transport: Transport) -> anyhow::Error {
    TransportError::NotBuilt {
        program: "formation-world".into(),
        transport,
    }
    .into()
}

/// The world as a ROS 2 team: a Zenoh router on `--listen` serving each robot's LaserScan,
/// Odometry and cmd_vel, and its record channel (`formation record --connect --transport ros2`).
#[cfg(feature = "zenoh")]
fn ros2_link(
    args: &Args,
    run_id: &RunId,
    spec: &RunSpec,
    runtime: &RuntimeSettings,
    secret: LaunchSecret,
) -> anyhow::Result<LinkAndFeed> {
    use formation_transport_ros2::{Ros2Team, Ros2WorldLink};
    let listen = formation_transport_zenoh::required_endpoint(
        args.listen.as_deref(),
        "--listen",
        Transport::Ros2,
    )?;
    let team = Ros2Team {
        n_robots: spec.n_robots,
        domain_id: args.ros_domain_id.unwrap_or(0),
        wheel_separation: spec.world.robot.wheel_separation,
        max_range: spec.world.lidar.max_range,
        lossless: runtime.clock == ClockMode::Lockstep,
    };
    let link = Ros2WorldLink::create_with_credentials(
        run_id,
        team,
        &listen,
        secret,
        args.credentials.as_deref(),
    )
    .with_context(|| format!("setting up the ROS 2 team of run {run_id} on {listen}"))?;
    let feed = link.record_feed();
    with_record_feed(link, feed, run_id)
}

/// This build has no Zenoh.
#[cfg(not(feature = "zenoh"))]
fn ros2_link(
    _args: &Args,
    _run_id: &RunId,
    _spec: &RunSpec,
    _runtime: &RuntimeSettings,
    _secret: LaunchSecret,
) -> anyhow::Result<LinkAndFeed> {
    Err(not_built(Transport::Ros2))
}

/// Reads the run specs; all must have the same team size.
fn read_run_specs(path: &Path) -> anyhow::Result<Vec<RunSpec>> {
    let bytes =
        std::fs::read(path).with_context(|| format!("reading run specs {}", path.display()))?;
    parse_run_specs(&bytes, path)
}

/// The run specs in `bytes` (read from `path`, which errors name); all must have the same team
/// size, of at least one robot.
fn parse_run_specs(bytes: &[u8], path: &Path) -> anyhow::Result<Vec<RunSpec>> {
    let specs: Vec<RunSpec> = serde_json::from_slice(bytes)
        .with_context(|| format!("parsing run specs {}", path.display()))?;
    let Some(first) = specs.first() else {
        anyhow::bail!("{} holds no runs", path.display());
    };
    if let Some(other) = specs
        .iter()
        .find(|s| s.n_robots != first.n_robots || s.n_robots == 0)
    {
        anyhow::bail!(
            "{}: run {} has {} robots but run {} has {}; one world serves one team size",
            path.display(),
            other.index,
            other.n_robots,
            first.index,
            first.n_robots
        );
    }
    Ok(specs)
}

/// What a world records: its own file (`--record`) and its record channel for remote
/// recorders.
struct Recording<'v> {
    /// Where `--record` goes.
    settings: Option<formation_record::RecordSettings>,
    /// What the launch knows of its runs.
    launch: formation_record::LaunchInfo,
    /// The record channel (Zenoh and ROS 2).
    feed: Option<Box<dyn RecordFeed>>,
    /// The live view (`--foxglove`).
    view: Option<&'v mut LiveView>,
}

/// The live view `--foxglove` asks for, listening (it says where on stderr).
fn start_live_view(address: Option<&str>, n_robots: usize) -> anyhow::Result<Option<LiveView>> {
    let Some(address) = live_view::requested(address, "formation-world", false)? else {
        return Ok(None);
    };
    let view = LiveView::start(address, n_robots)?;
    eprintln!(
        "formation-world: live view on ws://{} (Foxglove: Open connection, Foxglove WebSocket)",
        view.address()
    );
    Ok(Some(view))
}

fn play(
    args: &Args,
    runtime: &RuntimeSettings,
    specs: &[RunSpec],
    recording: &mut Recording<'_>,
    agents: &mut AgentsController<'_>,
) -> anyhow::Result<()> {
    agents.await_agents(runtime.startup_timeout())?;
    emit(&WorldEvent::AgentsConnected);
    for (nth, spec) in specs.iter().enumerate() {
        let index = spec.index;
        agents
            .begin_episode(
                spec.world.dt,
                spec.world.lidar,
                spec.world.robot.wheel_limits(),
            )
            .with_context(|| format!("run {index}"))?;
        let recorder = recording
            .settings
            .as_ref()
            .and_then(|r| start_recording(r, spec, nth, specs.len()));
        let launch = &recording.launch;
        let live = recording
            .feed
            .as_deref_mut()
            .and_then(|feed| runlog::LiveFeed::begin(feed, spec, launch, nth, specs.len()));
        let log = play_journaled(
            &args.out,
            runtime.clock.as_str(),
            spec,
            agents,
            recorder,
            live,
            recording.view.as_deref_mut(),
        )
        .with_context(|| format!("run {index}"))?;
        emit(&WorldEvent::RunDone { index, log });
    }
    Ok(())
}

/// The recorder of run `spec` (the `nth` of `runs`), when it is to be recorded; a recording that
/// cannot start is said, and the run plays without it.
fn start_recording(
    record: &formation_record::RecordSettings,
    spec: &RunSpec,
    nth: usize,
    runs: usize,
) -> Option<formation_record::Recorder> {
    let path = record.target.path_for(spec.index, nth, runs)?;
    let setup = formation_record::RecordingSetup::for_run(spec, &record.launch);
    match formation_record::Recorder::start(&path, setup) {
        Ok(recorder) => Some(recorder),
        Err(e) => {
            runlog::report_recording_failure(&e);
            None
        }
    }
}
