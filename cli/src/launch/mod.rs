//! The multi-process runtime launcher: `formation run`, `formation profile`, and the engine of
//! `formation eval --processes`.
//!
//! One world process (`formation-world`) and one agent process per robot (`formation-agent`)
//! exchange scans and wheel commands over iceoryx2 shared memory in a namespace of their own
//! (see [`formation_proto::wire`]). This module plans a launch (models per robot, run id, output
//! directory), hands it to the [`supervisor`], and reads back the run logs the world wrote.
//!
//! * [`binaries`]: finding the two executables next to the running one.
//! * [`capacity`]: refusing, before anything starts, a team the host cannot run.
//! * [`supervisor`]: spawning, supervising, restarting, stopping and cleaning up (tokio).
//! * [`profile`]: per-stage latency statistics from the world's timing logs.
//! * [`swap`]: `formation swap`, a model change requested of a running launch.

pub mod binaries;
pub mod capacity;
pub mod profile;
pub mod supervisor;
pub mod swap;

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use formation_proto::wire::RunId;
use formation_runtime::RuntimeSettings;
use formation_runtime::link_health::degraded_link_message;
use formation_runtime::transport::{Transport, TransportError};
use formation_world::{RunLog, RunSpec, Scenario, Trajectory, recover_journals};

use crate::args::{CredentialsArgs, ProfileArgs, RunArgs, SwapArgs};
use crate::paths;
use crate::team_models::{checked_team_models, models_per_robot};
use formation_proto::wire::WorldEvent;
use supervisor::{LaunchPlan, Network, PluginPlan, ZenohPlan};

/// How the world process paces ticks (defined once, in the runtime library).
pub use formation_runtime::ClockMode;

/// `formation credentials`: writes the folder and says what goes where; `--tls` adds the
/// certificates, `--renew` renews one principal's.
pub fn credentials_command(args: &CredentialsArgs) -> anyhow::Result<()> {
    if let Some(principal) = &args.renew {
        renew_certificate(&args.out, principal, args.valid_days)?;
        println!(
            "renewed the key and certificate of {principal} in {dir} ({principal}.pem, \
             {principal}.key.pem, valid {days} days); copy them privately to its host and \
             restart it; the other principals' certificates stay valid",
            dir = args.out.display(),
            days = args.valid_days
        );
        return Ok(());
    }
    let robots = args.robots.unwrap_or_default();
    create_credentials(&args.out, robots, args.tls.then_some(args.valid_days))?;
    let dir = args.out.display();
    if args.tls {
        println!(
            "certificates valid {} days: ca.pem for every principal; ca.key.pem stays with you \
             (renewing needs it); world.pem/world.key.pem with the world; robot-I.pem and \
             robot-I.key.pem with robot-I.json; operator.* and recorder.* with their logins; \
             listen and connect on tls/HOST:PORT",
            args.valid_days
        );
    }
    println!(
        "credentials for robots 0..{} in {dir} (owner-only):\n  \
         passwords, launch-secret: stay with the world (formation run --transport zenoh \
         --credentials {dir})\n  robot-I.json: copy privately (scp) to robot I's host \
         (formation-agent --credentials robot-I.json)\n  operator.json: for formation swap \
         --credentials\n  recorder.json: read-only, for formation record --connect --credentials",
        robots.saturating_sub(1)
    );
    Ok(())
}

/// `value` seconds as a duration, or an error naming `flag` when it is not a positive number.
pub(crate) fn positive_seconds(flag: &str, value: f64) -> anyhow::Result<Duration> {
    if value.is_finite() && value > 0.0 {
        Ok(Duration::from_secs_f64(value))
    } else {
        anyhow::bail!("{flag} must be a positive number of seconds, got {value}")
    }
}

/// Parses `ROBOT:MODE` fault flags into one optional mode per robot.
pub fn faults_per_robot(flags: &[String], n_robots: usize) -> anyhow::Result<Vec<Option<String>>> {
    let mut faults = vec![None; n_robots];
    for flag in flags {
        let (robot, mode) = flag.split_once(':').with_context(|| {
            format!("--fault {flag:?}: expected ROBOT:MODE, e.g. 1:crash-after=100")
        })?;
        let robot: usize = robot
            .parse()
            .with_context(|| format!("--fault {flag:?}: {robot:?} is not a robot index"))?;
        let slot = faults.get_mut(robot).with_context(|| {
            format!("--fault {flag:?}: robot {robot} out of range (0..{n_robots})")
        })?;
        *slot = Some(mode.to_owned());
    }
    Ok(faults)
}

fn block_on<T>(future: impl std::future::Future<Output = T>) -> anyhow::Result<T> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the launcher's async runtime")?;
    Ok(runtime.block_on(future))
}

/// Resolves the run specs of runs `first..first + runs` and writes them where the world reads them.
fn write_run_specs(
    scenario: &Scenario,
    base_seed: u64,
    first: usize,
    runs: usize,
    path: &Path,
) -> anyhow::Result<()> {
    let specs: Vec<RunSpec> = (first..first + runs)
        .map(|i| scenario.run_spec(base_seed, i))
        .collect();
    Ok(paths::write_atomic(path, &serde_json::to_vec(&specs)?)?)
}

/// The launch plan of `args`, its scenario and the base seed of its runs.
/// What `formation run` launches: the plan, the scenario, the base seed, and the team size
/// against each model's trained sizes beside the input each model declares.
struct PlannedRun {
    plan: LaunchPlan,
    scenario: Scenario,
    base_seed: u64,
    notes: crate::team_models::TeamModelNotes,
}

fn plan_from_args(args: &RunArgs) -> anyhow::Result<PlannedRun> {
    let scenario = Scenario::from_path(&args.scenario)?;
    if args.runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    if args.first_run.checked_add(args.runs).is_none() {
        anyhow::bail!(
            "--first-run {} plus --runs {} overflows the run index; use a smaller --first-run",
            args.first_run,
            args.runs
        );
    }
    // `--model`, else the scenario's own (its key named when unusable), else the shipped default.
    let default_model = paths::resolve_model_for(args.model.as_deref(), &scenario)?;
    let (models, notes) = checked_team_models(&scenario, &default_model)?;
    let run_id = match &args.run_id {
        Some(id) => RunId::new(id)?,
        None => RunId::generate(),
    };
    // Every target is checked before anything is written (the credentials and run specs below):
    // a refusal leaves nothing behind.
    formation_proto::files::check_output_dir(&args.out)?;
    let mut inputs: Vec<(&'static str, &Path)> = vec![("--scenario", &args.scenario)];
    inputs.extend(models.iter().map(|m| ("--model", m.as_path())));
    let record_file = args.record.as_deref().map(|r| ("--record", r, "run.mcap"));
    paths::refuse_overwriting_inputs(record_file.as_slice(), &[("--out", &args.out)], &inputs)?;
    let base_seed = args.seed.unwrap_or_else(|| scenario.seed());
    let launch_info =
        crate::record::launch_info(&scenario, base_seed, args.clock.as_str(), "policy", &models);
    let record = match &args.record {
        Some(file) => Some(crate::record::checked_settings(
            formation_record::RecordTarget::File(file.clone()),
            launch_info.clone(),
        )?),
        None => None,
    };
    let faults = faults_per_robot(&args.faults, models.len())?;
    let restart_window = positive_seconds("--restart-window-s", args.restart_window_s)?;
    let wheels = scenario.world_config().robot.wheel_limits();
    let network = network_from_args(args, &run_id, models.len(), wheels)?;
    let run_specs = args.out.join("run-specs.json");
    write_run_specs(&scenario, base_seed, args.first_run, args.runs, &run_specs)?;
    let mut startup_timeout_ms = RuntimeSettings::DEFAULT.startup_timeout_ms;
    if network.zenoh().is_some_and(|z| !z.remote.is_empty()) {
        let wait = positive_seconds("--remote-timeout-s", args.remote_timeout_s)?;
        startup_timeout_ms = wait.as_millis().clamp(1, u64::MAX as u128) as u64;
    }
    let plan = LaunchPlan {
        run_id,
        run_specs,
        settings: RuntimeSettings {
            clock: args.clock,
            command_timeout_ms: args.timeout_ms,
            stale_ms: args.stale_ms,
            pace_ms: args.pace_ms,
            spin_us: args.spin_us,
            startup_timeout_ms,
            ..RuntimeSettings::DEFAULT
        },
        network,
        out: args.out.clone(),
        faults,
        models,
        restart_budget: args.restarts,
        restart_window,
        restart_delay: Duration::from_millis(args.restart_delay_ms),
        record,
        launch_info: Some(launch_info),
        foxglove: formation_world_node::live_view::requested(
            args.foxglove.as_deref(),
            "formation",
            true,
        )?,
    };
    Ok(PlannedRun {
        plan,
        scenario,
        base_seed,
        notes,
    })
}

/// How a launch's processes are to reach each other, as its flags give it: `--transport`, and
/// for Zenoh `--listen`, `--remote` and `--credentials`. `formation run` and `profile` take all
/// four; `formation eval --processes` the first two (its agents are all local, with fresh
/// credentials).
#[derive(Debug, Clone, Default)]
pub struct NetworkFlags {
    /// `--transport`.
    pub transport: Transport,
    /// `--listen tcp/ADDR:PORT`.
    pub listen: Option<String>,
    /// `--remote`: robots whose agents are started by hand.
    pub remote: Vec<usize>,
    /// `--credentials DIR`.
    pub credentials: Option<PathBuf>,
    /// `--ros-domain-id` (ROS 2).
    pub ros_domain_id: Option<u32>,
}

impl NetworkFlags {
    /// The flags of `formation run` / `profile`.
    pub fn of_run(args: &RunArgs) -> NetworkFlags {
        NetworkFlags {
            transport: args.transport,
            listen: args.listen.clone(),
            remote: args.remote.clone(),
            credentials: args.credentials.clone(),
            ros_domain_id: args.ros_domain_id,
        }
    }

    /// `Ok` unless a flag was given with a transport it is not for (the error names it):
    /// `--listen` is Zenoh's and ROS 2's, `--remote` and `--credentials` Zenoh's,
    /// `--ros-domain-id` ROS 2's.
    pub fn refuse_misplaced(&self) -> Result<(), TransportError> {
        self.transport
            .refuse_network_flags(&[(self.listen.is_some(), "--listen")])?;
        self.transport
            .refuse_zenoh_flags(&[(!self.remote.is_empty(), "--remote")])?;
        // ROS 2 takes a credentials folder for its certificates on a tls/ endpoint.
        if self.transport != Transport::Ros2 {
            self.transport
                .refuse_zenoh_flags(&[(self.credentials.is_some(), "--credentials")])?;
        }
        self.transport
            .refuse_ros2_flags(&[(self.ros_domain_id.is_some(), "--ros-domain-id")])
    }

    /// `--listen`, checked, for the transports over Zenoh.
    fn listen(&self) -> anyhow::Result<String> {
        let listen = self.listen.clone().ok_or(TransportError::MissingEndpoint {
            flag: "--listen",
            transport: self.transport,
        })?;
        #[cfg(feature = "zenoh")]
        formation_transport_zenoh::Endpoint::parse(&listen)?;
        Ok(listen)
    }

    /// A ROS 2 launch's certificates: none on `tcp/` (`--credentials` is refused there); on
    /// `tls/` the `--credentials` folder or fresh ones in `fresh`, with the ROS 2 nodes' session
    /// configurations written into its `ros2/` for this host's agents.
    fn ros2_credentials(
        &self,
        listen: &str,
        n_robots: usize,
        fresh: &Path,
    ) -> anyhow::Result<Option<PathBuf>> {
        if !listen.starts_with("tls/") {
            if self.credentials.is_some() {
                anyhow::bail!(
                    "--credentials with --transport ros2 is the certificates of a tls/ endpoint; \
                     {listen} is not one (use --listen tls/HOST:PORT, or drop --credentials)"
                );
            }
            return Ok(None);
        }
        let dir = match &self.credentials {
            Some(dir) => dir.clone(),
            None => {
                create_credentials(fresh, n_robots, Some(FRESH_CERTIFICATE_DAYS))?;
                fresh.to_path_buf()
            }
        };
        write_ros2_session_configs(&dir, &supervisor::local_endpoint(listen), n_robots)?;
        Ok(Some(dir))
    }

    /// The launch's network for a team of `n_robots`: flags of Zenoh need it, the transport
    /// must be built in, Zenoh needs `--listen` (a valid endpoint), a remote robot must exist in
    /// the scenario, and a Zenoh launch without `--credentials` gets fresh ones in `fresh`.
    /// `wheels` are the scenario's robot's, which ROS 2 agents are told.
    pub fn network(
        &self,
        n_robots: usize,
        wheels: formation_proto::WheelLimits,
        fresh: &Path,
    ) -> anyhow::Result<Network> {
        self.refuse_misplaced()?;
        self.transport
            .check_built_in("formation", crate::TRANSPORTS)?;
        match self.transport {
            Transport::Iceoryx2 => return Ok(Network::SharedMemory),
            Transport::Plugin(transport) => {
                return Ok(Network::Plugin(PluginPlan {
                    transport,
                    endpoint: self.listen.clone(),
                }));
            }
            Transport::Ros2 => {
                let listen = self.listen()?;
                let credentials = self.ros2_credentials(&listen, n_robots, fresh)?;
                return Ok(Network::Ros2(supervisor::Ros2Plan {
                    listen,
                    domain_id: self.ros_domain_id.unwrap_or(0),
                    credentials,
                    wheels,
                }));
            }
            Transport::Zenoh => {}
        }
        let listen = self.listen()?;
        if let Some(&robot) = self.remote.iter().find(|&&r| r >= n_robots) {
            anyhow::bail!(
                "--remote {robot}: the scenario has {n_robots} robots (0..{}); remote robots must \
                 be among them",
                n_robots.saturating_sub(1)
            );
        }
        let mut remote = self.remote.clone();
        remote.sort_unstable();
        remote.dedup();
        if remote.len() == n_robots && n_robots > 0 {
            tracing::info!("every robot is remote: the launcher starts only the world");
        }
        let credentials = match &self.credentials {
            Some(dir) => dir.clone(),
            None => {
                let tls = listen.starts_with("tls/").then_some(FRESH_CERTIFICATE_DAYS);
                create_credentials(fresh, n_robots, tls)?;
                fresh.to_path_buf()
            }
        };
        Ok(Network::Zenoh(ZenohPlan {
            listen,
            credentials,
            remote,
        }))
    }
}

/// How the launch's processes reach each other ([`NetworkFlags::network`]); a Zenoh launch
/// without `--credentials` gets fresh ones in `<out>/credentials/<run id>/`.
/// A ROS 2 launch takes no `--fault` (fault injection is the other transports' agents').
fn network_from_args(
    args: &RunArgs,
    run_id: &RunId,
    n_robots: usize,
    wheels: formation_proto::WheelLimits,
) -> anyhow::Result<Network> {
    let fresh = args.out.join("credentials").join(run_id.as_str());
    let network = NetworkFlags::of_run(args).network(n_robots, wheels, &fresh)?;
    if matches!(network, Network::Ros2(_)) && !args.faults.is_empty() {
        anyhow::bail!(
            "--fault injects faults into agents of the iceoryx2 and zenoh transports; a ROS 2 \
             agent takes none (stop or kill it instead)"
        );
    }
    Ok(network)
}

/// How long the certificates of a launch's fresh credentials are valid, in days.
const FRESH_CERTIFICATE_DAYS: u32 = 30;

/// `formation credentials`: writes logins for robots `0..robots` and the operator, and a launch
/// secret, into `dir` (owner-only); with `tls_days`, also the team's certificates, valid that
/// many days.
#[cfg(feature = "zenoh")]
pub fn create_credentials(dir: &Path, robots: usize, tls_days: Option<u32>) -> anyhow::Result<()> {
    use formation_transport_zenoh::credentials;
    match tls_days {
        None => credentials::create(dir, robots)?,
        Some(days) => credentials::create_with_tls(dir, robots, days)?,
    }
    Ok(())
}

/// Writes the ROS 2 nodes' session configurations of credentials folder `dir` for a router at
/// `connect` (`dir/ros2/<principal>.json5`).
#[cfg(feature = "tls")]
fn write_ros2_session_configs(dir: &Path, connect: &str, n_robots: usize) -> anyhow::Result<()> {
    let connect = formation_transport_zenoh::Endpoint::parse(connect)?;
    formation_transport_ros2::secure::write_session_configs(dir, &connect, n_robots)?;
    Ok(())
}

/// Without TLS there is no tls/ endpoint ([`formation_transport_zenoh::Endpoint::parse`] refused
/// it already).
#[cfg(not(feature = "tls"))]
fn write_ros2_session_configs(_dir: &Path, connect: &str, _n_robots: usize) -> anyhow::Result<()> {
    anyhow::bail!("{connect}: this build has no TLS: build with `--features tls`")
}

/// `formation credentials --tls --renew PRINCIPAL`.
#[cfg(feature = "zenoh")]
fn renew_certificate(dir: &Path, principal: &str, days: u32) -> anyhow::Result<()> {
    formation_transport_zenoh::credentials::renew_certificate(dir, principal, days)?;
    Ok(())
}

/// Without Zenoh there are no certificates to renew.
#[cfg(not(feature = "zenoh"))]
fn renew_certificate(_dir: &Path, _principal: &str, _days: u32) -> anyhow::Result<()> {
    create_credentials(_dir, 0, None)
}

/// Without Zenoh there are no credentials to make.
#[cfg(not(feature = "zenoh"))]
pub fn create_credentials(
    _dir: &Path,
    _robots: usize,
    _tls_days: Option<u32>,
) -> anyhow::Result<()> {
    Err(TransportError::NotBuilt {
        program: "formation".into(),
        transport: Transport::Zenoh,
    }
    .into())
}

/// What the user must do for each remote robot: copy its credentials, start its agent.
fn remote_instructions(plan: &LaunchPlan) -> Option<String> {
    let zenoh = plan.network.zenoh().filter(|z| !z.remote.is_empty())?;
    let endpoint = if zenoh.listen.contains("0.0.0.0") || zenoh.listen.contains("[::]") {
        "tcp/<this host's address>:<port>".to_string()
    } else {
        zenoh.listen.clone()
    };
    let mut text = format!(
        "waiting for the remote agents of robots {:?}; on each robot's host, with robot-I.json \
         copied privately (scp) from {}:\n",
        zenoh.remote,
        zenoh.credentials.display()
    );
    for &robot in &zenoh.remote {
        text.push_str(&format!(
            "  formation-agent --transport zenoh --connect {endpoint} --run-id {} --robot {robot} \
             --model {} --credentials robot-{robot}.json\n",
            plan.run_id,
            plan.models[robot].display()
        ));
    }
    Some(text)
}

/// `formation run`: launches the world and one agent per robot, plays the runs, writes the logs
/// and a latency summary, and cleans up.
pub fn run_command(args: &RunArgs) -> anyhow::Result<()> {
    let PlannedRun {
        plan,
        scenario,
        base_seed,
        notes,
    } = plan_from_args(args)?;
    crate::team_models::print_team_size_notes(&notes.team_size);
    crate::team_models::print_goal_speed_notes(&notes.goal_speed);
    println!(
        "formation run {}: {} robots, {} run(s) of {}, {} clock",
        plan.run_id,
        plan.models.len(),
        args.runs,
        scenario.name(),
        plan.settings.clock.as_str()
    );
    if let Some(text) = remote_instructions(&plan) {
        print!("{text}");
    }
    let started = std::time::SystemTime::now();
    let launched = launch_with_progress(&plan)?;
    let report = match launched {
        Ok(report) => {
            // Journals an earlier, killed launch left in this directory.
            report_recovered(&recover_journals(
                &plan.out,
                "an earlier launch ended before its world saved the run",
            ));
            report
        }
        Err(error) => {
            let runs = args.first_run..args.first_run + args.runs;
            keep_partial_runs(&plan.out, runs, started, &error, scenario.name(), base_seed);
            return Err(error.into());
        }
    };
    write_run_outputs(&plan, &report, scenario.name(), base_seed, notes)?;
    print_recordings(&plan, args.first_run, args.runs);
    print_launch_outcome(&plan, &report)
}

/// Prints each recording the world wrote (`--record`), as `eval --record` does.
fn print_recordings(plan: &LaunchPlan, first_run: usize, runs: usize) {
    let Some(settings) = &plan.record else {
        return;
    };
    for (nth, index) in (first_run..first_run + runs).enumerate() {
        let Some(path) = settings.target.path_for(index, nth, runs) else {
            continue;
        };
        match std::fs::metadata(&path) {
            Ok(meta) if meta.is_file() => println!(
                "recorded {} ({:.1} MB)",
                path.display(),
                meta.len() as f64 / 1e6
            ),
            _ => eprintln!(
                "formation: run {index} was to be recorded into {}, which the world did not \
                 write (see its message above)",
                path.display()
            ),
        }
    }
}

/// Runs the launch, printing the world's events as they come and the agents' readiness on a
/// terminal.
fn launch_with_progress(
    plan: &LaunchPlan,
) -> anyhow::Result<Result<supervisor::LaunchReport, supervisor::LaunchError>> {
    // Readiness of a large team on a terminal (hidden when stderr is not one).
    let readiness = indicatif::ProgressBar::new(plan.models.len() as u64).with_style(
        indicatif::ProgressStyle::with_template("agents ready {bar:40} {pos}/{len} ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    block_on(supervisor::launch(plan, &mut |event| {
        print_world_event(event, &readiness, plan.models.len());
    }))
}

/// What `formation run` prints for one of the world's events (`agents`: the team's size).
fn print_world_event(event: &WorldEvent, readiness: &indicatif::ProgressBar, agents: usize) {
    match event {
        WorldEvent::AgentConnected { connected, .. } => readiness.set_position(*connected as u64),
        WorldEvent::AgentsConnected => {
            readiness.finish_and_clear();
            println!("all {agents} agents connected")
        }
        WorldEvent::RunDone { index, log } => println!("run {index} done: {}", log.display()),
        WorldEvent::AgentLost {
            robot,
            tick,
            last_fresh_tick,
        } => println!("{}", lost_message(*robot, *tick, *last_fresh_tick)),
        WorldEvent::AgentRefused { robot, pid, reason } => {
            eprintln!("formation: robot {robot}: refused process {pid}: {reason}")
        }
        WorldEvent::AgentRejoined { robot, pid, tick } => {
            println!("robot {robot}: agent pid {pid} rejoined, driving from tick {tick}")
        }
        WorldEvent::LinkDegraded { .. } => {
            if let Some(line) = degraded_link_message(event) {
                eprintln!("formation: {line}");
            }
        }
        WorldEvent::Listening { .. } | WorldEvent::Finished | WorldEvent::Stopping { .. } => {}
    }
}

/// After a launch that succeeded: writes and prints the summary (Table I) and the latency
/// profile (`profile.json`, `profile.svg`).
fn write_run_outputs(
    plan: &LaunchPlan,
    report: &supervisor::LaunchReport,
    scenario: &str,
    base_seed: u64,
    notes: crate::team_models::TeamModelNotes,
) -> anyhow::Result<()> {
    let latency = profile::profile_dir(&plan.out)?;
    let table = write_summary(
        &plan.out,
        &report.run_logs,
        scenario,
        Some(base_seed),
        latency.braked_per_robot.clone(),
        notes,
    )?;
    print!("{}", crate::table::table_text(&table));
    let path = plan.out.join("profile.json");
    paths::write_atomic(&path, &formation_schema::to_json_pretty(&latency)?)?;
    profile::profile_svg(&latency, &plan.out.join("profile.svg"))?;
    print!("{}", profile::summary_text(&latency));
    Ok(())
}

/// Prints where the logs are, the restarts and the agents being restarted when a run ended;
/// fails when a robot lost its agent for good.
fn print_launch_outcome(
    plan: &LaunchPlan,
    report: &supervisor::LaunchReport,
) -> anyhow::Result<()> {
    println!(
        "logs in {}; {} agent restart(s); removed {} iceoryx2 file(s)",
        plan.out.display(),
        report.restarts,
        report.cleaned_up
    );
    for restarting in &report.restarting_at_end {
        println!(
            "run {}: robot {}'s agent (lost at tick {}) was being restarted when the run ended; \
             counted as a restart, its braked ticks are in {}",
            restarting.run,
            restarting.robot,
            restarting.lost_at_tick,
            plan.out.join("summary.json").display()
        );
    }
    if !report.lost_for_good.is_empty() {
        let lost: Vec<String> = report
            .lost_for_good
            .iter()
            .map(|lost| {
                format!(
                    "run {}: robot {} (lost at tick {})",
                    lost.run, lost.robot, lost.lost_at_tick
                )
            })
            .collect();
        anyhow::bail!(
            "runs ended with robots that had lost their agent for good, so their results are not \
             the policy's: {}; see braked_ticks in {}",
            lost.join(", "),
            plan.out.join("summary.json").display()
        );
    }
    Ok(())
}

/// What `formation run` says when the world lost a robot's agent: from which tick the robot is
/// braked, and whether the dead agent's last command still drove it up to then.
fn lost_message(robot: usize, tick: u64, last_fresh_tick: Option<u64>) -> String {
    match last_fresh_tick {
        Some(last) => format!(
            "robot {robot}: agent lost (noticed at tick {tick}; its last command drove tick \
             {last}); braking it from tick {} until an agent rejoins",
            last + 1
        ),
        None => format!(
            "robot {robot}: agent lost (noticed at tick {tick}, before it drove this run); \
             braking it until an agent rejoins"
        ),
    }
}

/// The Table I summary of a launch's run logs, in the schema `formation eval` writes, so that
/// `formation report` reads a run directory like an eval directory. Runs that stopped early are
/// listed in `incomplete_runs`.
fn run_summary(
    run_logs: &[PathBuf],
    scenario: &str,
    seed: Option<u64>,
) -> anyhow::Result<formation_schema::EvalOutput> {
    let mut logs = run_logs
        .iter()
        .map(|path| RunLog::read(path))
        .collect::<Result<Vec<_>, _>>()?;
    logs.sort_by_key(|log| log.index);
    let models = logs.first().map(|l| l.models.clone()).unwrap_or_default();
    let incomplete_runs = logs
        .iter()
        .filter(|log| !log.complete)
        .map(|log| formation_schema::IncompleteRun {
            index: log.index,
            ticks: log.ticks(),
            planned_ticks: log.planned_ticks,
            stop_reason: log.stop_reason.clone(),
        })
        .collect();
    let per_run = logs
        .iter()
        .map(formation_world::runlog::log_metrics)
        .collect();
    let mut table = formation_learning::eval_output("policy", models, scenario, seed, per_run);
    table.incomplete_runs = incomplete_runs;
    Ok(table)
}

/// Writes `out/summary.json` over `run_logs` (see [`run_summary`]) and returns it. Without a
/// seed (unknown, for runs recovered after their launcher was killed) the key is left out, as
/// the report allows.
fn write_summary(
    out: &Path,
    run_logs: &[PathBuf],
    scenario: &str,
    seed: Option<u64>,
    braked_ticks: Vec<std::collections::BTreeMap<String, usize>>,
    notes: crate::team_models::TeamModelNotes,
) -> anyhow::Result<formation_schema::EvalOutput> {
    let mut table = run_summary(run_logs, scenario, seed)?;
    table.braked_ticks = braked_ticks;
    table.team_size = notes.team_size;
    table.goal_speed = notes.goal_speed;
    table.model_inputs = notes.model_inputs;
    paths::write_atomic(
        &out.join("summary.json"),
        &formation_schema::to_json_pretty(&table)?,
    )?;
    Ok(table)
}

/// Why a launch stopped, as an incomplete run log records it.
fn stop_reason(error: &supervisor::LaunchError) -> String {
    use supervisor::LaunchError;
    match error {
        LaunchError::Interrupted(signal) => {
            format!("interrupted by {}", supervisor::interruption_name(signal))
        }
        LaunchError::AgentFailed { robot, status, .. } => {
            format!("the agent of robot {robot} exited ({status}) and the restart budget was spent")
        }
        LaunchError::WorldFailed { status, .. } => format!("the world process exited ({status})"),
        other => other.to_string(),
    }
}

/// After a launch that ended abnormally, keeps what it played: turns the journals a killed world
/// left into incomplete run logs, marks the runs the launcher stopped (Ctrl-C, SIGTERM, a spent
/// restart budget) with the launcher's reason, and writes `summary.json` over this launch's run
/// logs (those of `runs` written since `started`), the incomplete ones listed as such. Problems
/// are reported on stderr; the launch's own error stays the one returned.
fn keep_partial_runs(
    out: &Path,
    runs: std::ops::Range<usize>,
    started: std::time::SystemTime,
    error: &supervisor::LaunchError,
    scenario: &str,
    seed: u64,
) {
    let reason = stop_reason(error);
    report_recovered(&recover_journals(
        out,
        &format!("{reason} before the world saved the run"),
    ));
    // File times are coarse; a log written just after the launch began may look a little older.
    let since = started
        .checked_sub(Duration::from_secs(2))
        .unwrap_or(started);
    let logs: Vec<PathBuf> = formation_world::runlog::run_logs_in(out)
        .into_iter()
        .filter(|(index, path)| {
            runs.contains(index)
                && std::fs::metadata(path)
                    .and_then(|m| m.modified())
                    .is_ok_and(|at| at >= since)
        })
        .map(|(_, path)| path)
        .collect();
    if logs.is_empty() {
        let journals = formation_world::runlog::journals_in(out);
        if journals.is_empty() {
            eprintln!("formation: no run log was written in {}", out.display());
        } else {
            eprintln!(
                "formation: {} run journal(s) kept in {}; `formation report` turns them into run logs once they can be written",
                journals.len(),
                out.join("runs").display()
            );
        }
        return;
    }
    let launcher_stopped = matches!(
        error,
        supervisor::LaunchError::Interrupted(_) | supervisor::LaunchError::AgentFailed { .. }
    );
    if launcher_stopped {
        // The world only saw its input close (or a signal); the launcher knows why.
        for path in &logs {
            if let Ok(mut log) = RunLog::read(path)
                && !log.complete
            {
                log.stop_reason = Some(reason.clone());
                if let Err(e) = formation_world::runlog::write_json_atomic(path, &log) {
                    eprintln!(
                        "formation: could not record why run {} stopped: {e}",
                        log.index
                    );
                }
            }
        }
    }
    let braked = profile::profile_dir(out)
        .map(|p| p.braked_per_robot)
        .unwrap_or_default();
    match write_summary(out, &logs, scenario, Some(seed), braked, Default::default()) {
        Ok(table) => {
            print!("{}", crate::table::table_text(&table));
            eprintln!(
                "formation: kept {} run(s) in {} ({} incomplete, stopped early: {reason})",
                logs.len(),
                out.display(),
                table.incomplete_runs.len()
            );
        }
        Err(e) => eprintln!(
            "formation: could not write the summary of the partial runs: {}",
            formation_proto::errors::chain_text(e.as_ref())
        ),
    }
}

/// Says on stderr what journal recovery did.
pub fn report_recovered(recovered: &[formation_world::runlog::JournalRecovery]) {
    for recovery in recovered {
        match &recovery.outcome {
            Ok(run) => eprintln!(
                "formation: recovered run {} ({} ticks, incomplete) from its journal {} into {}",
                run.index,
                run.ticks,
                recovery.journal.display(),
                run.log.display()
            ),
            Err(e) => eprintln!("formation: {e}"),
        }
    }
}

/// Recovers the journals in every run directory under `dir` and writes the `summary.json` a
/// run directory lacks (its launcher was killed, or could not write it), so `formation report`
/// shows those runs. Says on stderr what it did.
pub fn recover_run_dirs(dir: &Path) {
    use formation_world::runlog::{RunLogError, find_run_dirs, run_logs_in};
    for out in find_run_dirs(dir) {
        let recovered = recover_journals(
            &out,
            "the world and its launcher were killed before the run was saved",
        );
        report_recovered(&recovered);
        let in_use = recovered
            .iter()
            .any(|r| matches!(r.outcome, Err(RunLogError::InUse { .. })));
        if in_use || out.join("summary.json").exists() {
            continue;
        }
        let logs: Vec<PathBuf> = run_logs_in(&out).into_iter().map(|(_, p)| p).collect();
        match write_summary(&out, &logs, "", None, Vec::new(), Default::default()) {
            Ok(table) => eprintln!(
                "formation: wrote {} over {} run log(s) that had none ({} incomplete)",
                out.join("summary.json").display(),
                logs.len(),
                table.incomplete_runs.len()
            ),
            Err(e) => eprintln!(
                "formation: could not summarize the run logs in {}: {}",
                out.display(),
                formation_proto::errors::chain_text(e.as_ref())
            ),
        }
    }
}

/// `formation profile`: `formation run` whose latency statistics are the point.
pub fn profile_command(args: &ProfileArgs) -> anyhow::Result<()> {
    run_command(&args.run)
}

/// `formation swap`: asks a running launch to change one robot's model and reports the tick from
/// which the new model drives.
pub fn swap_command(args: &SwapArgs) -> anyhow::Result<()> {
    let timeout = positive_seconds("--timeout-s", args.timeout_s)?;
    let done = match args.reach.transport {
        Transport::Iceoryx2 => {
            args.reach.transport.refuse_zenoh_flags(&[
                (args.reach.connect.is_some(), "--connect"),
                (args.reach.credentials.is_some(), "--credentials"),
            ])?;
            swap::request_swap(args, timeout)?
        }
        Transport::Zenoh => swap_over_zenoh(args, timeout)?,
        Transport::Ros2 => anyhow::bail!(
            "a ROS 2 agent cannot be swapped through the world: stop it and start \
             `formation-agent --transport ros2` with the other --model (the robot brakes \
             meanwhile)"
        ),
        Transport::Plugin(transport) => {
            args.reach
                .transport
                .refuse_zenoh_flags(&[(args.reach.credentials.is_some(), "--credentials")])?;
            args.reach
                .transport
                .refuse_network_flags(&[(args.reach.connect.is_some(), "--connect")])?;
            let endpoint = args.reach.connect.as_deref();
            swap::request_swap_over_plugin(transport, endpoint, args, timeout)?
        }
    };
    println!(
        "robot {} of run {} drives with model {} from tick {}",
        args.robot, args.run, done.model_id, done.tick
    );
    Ok(())
}

/// `formation swap --transport zenoh`.
#[cfg(feature = "zenoh")]
fn swap_over_zenoh(args: &SwapArgs, timeout: Duration) -> anyhow::Result<swap::SwapDone> {
    let connect = args
        .reach
        .connect
        .as_deref()
        .ok_or(TransportError::MissingEndpoint {
            flag: "--connect",
            transport: Transport::Zenoh,
        })?;
    swap::request_swap_over_zenoh(connect, args, timeout)
}

/// Without Zenoh.
#[cfg(not(feature = "zenoh"))]
fn swap_over_zenoh(_args: &SwapArgs, _timeout: Duration) -> anyhow::Result<swap::SwapDone> {
    Err(TransportError::NotBuilt {
        program: "formation".into(),
        transport: Transport::Zenoh,
    }
    .into())
}

/// What an evaluation over processes gives: the trajectories in run order and the latency
/// profile of all its ticks.
#[derive(Debug)]
pub struct ProcessEval {
    /// One trajectory per run, in run order.
    pub trajectories: Vec<Trajectory>,
    /// Per-stage latency over every run.
    pub latency: profile::LatencyProfile,
}

/// The lockstep command timeout of an evaluation over processes \[ms\], longer than
/// [`RuntimeSettings::DEFAULT`]'s: an evaluation has no restarts and must not brake a robot
/// because one inference was slow on a loaded machine, which would change its trajectory.
const EVAL_COMMAND_TIMEOUT_MS: u64 = 5000;

/// Evaluates `evaluation.runs` runs of its scenario (from `base_seed`) with every robot's policy
/// in its own process. Robots the scenario assigns a model to run that model, the others
/// `default_model`. The agents reach the world as `network` says ([`NetworkFlags::network`]):
/// over iceoryx2, or over Zenoh on the `listen` endpoint with fresh credentials made in the
/// evaluation's temporary folder (every agent is local; `remote` and `credentials` must be
/// unset). `on_run_done(n)` is called after each finished run with the number finished so far.
/// In lockstep the trajectories are bit-identical to in-process evaluation, whatever the
/// transport.
pub fn eval_over_processes(
    evaluation: &ProcessEvalRuns<'_>,
    on_run_done: &mut dyn FnMut(usize),
) -> anyhow::Result<ProcessEval> {
    eval_over_processes_recorded(evaluation, None, None, on_run_done)
}

/// What an evaluation over processes runs, and how ([`eval_over_processes`]).
#[derive(Debug, Clone, Copy)]
pub struct ProcessEvalRuns<'a> {
    /// The scenario whose runs are played.
    pub scenario: &'a Scenario,
    /// The base seed of the runs.
    pub base_seed: u64,
    /// How many runs.
    pub runs: usize,
    /// The model of the robots the scenario assigns none.
    pub default_model: &'a Path,
    /// How the world paces ticks.
    pub clock: ClockMode,
    /// How the agents reach the world.
    pub network: &'a NetworkFlags,
}

/// [`eval_over_processes`], with the world recording the runs `record` asks for and serving
/// them live on `foxglove` (`formation demo --foxglove`).
pub fn eval_over_processes_recorded(
    evaluation: &ProcessEvalRuns<'_>,
    record: Option<formation_record::RecordSettings>,
    foxglove: Option<std::net::SocketAddr>,
    on_run_done: &mut dyn FnMut(usize),
) -> anyhow::Result<ProcessEval> {
    let &ProcessEvalRuns {
        scenario,
        base_seed,
        clock,
        network,
        ..
    } = evaluation;
    if !network.remote.is_empty() || network.credentials.is_some() {
        anyhow::bail!(
            "an evaluation over processes starts every agent itself, with fresh credentials: \
             drop --remote and --credentials"
        );
    }
    network.refuse_misplaced()?;
    let models = models_per_robot(scenario, evaluation.default_model)?;
    let run_id = RunId::generate();
    let work = std::env::temp_dir().join(format!("formation-eval-{run_id}"));
    let result = (|| {
        let wheels = scenario.world_config().robot.wheel_limits();
        let network = network.network(models.len(), wheels, &work.join("credentials"))?;
        let run_specs = work.join("run-specs.json");
        write_run_specs(scenario, base_seed, 0, evaluation.runs, &run_specs)?;
        let launch_info =
            crate::record::launch_info(scenario, base_seed, clock.as_str(), "policy", &models);
        let plan = LaunchPlan {
            run_id,
            run_specs,
            settings: RuntimeSettings {
                clock,
                command_timeout_ms: EVAL_COMMAND_TIMEOUT_MS,
                ..RuntimeSettings::DEFAULT
            },
            out: work.join("out"),
            faults: vec![None; models.len()],
            models,
            restart_budget: 0,
            restart_window: Duration::from_secs(60),
            restart_delay: Duration::from_millis(50),
            network,
            launch_info: Some(launch_info),
            record,
            foxglove,
        };
        let mut done = 0;
        let report = block_on(supervisor::launch(&plan, &mut |event| {
            if matches!(event, WorldEvent::RunDone { .. }) {
                done += 1;
                on_run_done(done);
            }
            if let Some(line) = degraded_link_message(event) {
                eprintln!("formation: {line}");
            }
        }))??;
        let trajectories = report
            .run_logs
            .iter()
            .map(|log| read_trajectory(log))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let latency = profile::profile_dir(&plan.out)?;
        Ok(ProcessEval {
            trajectories,
            latency,
        })
    })();
    let _ = std::fs::remove_dir_all(&work);
    result
}

/// The trajectory of one run log written by the world.
pub fn read_trajectory(log: &Path) -> anyhow::Result<Trajectory> {
    Ok(formation_schema::read_run_log(log)?.trajectory)
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_world::runlog::{JournalHeader, RunJournal, journal_path, log_paths};
    use formation_world::{Controller, Observation, run_episode_recorded};

    struct Forward;

    impl Controller for Forward {
        fn commands(
            &mut self,
            _: &Observation<'_>,
            out: &mut [formation_proto::WheelCmd],
        ) -> Result<(), formation_world::episode::ControllerError> {
            out.fill(formation_proto::WheelCmd {
                left: 0.3,
                right: 0.35,
            });
            Ok(())
        }
    }

    fn spec(index: usize) -> RunSpec {
        let text = "name = \"t\"\nrobots = 3\nduration_s = 2.0\nseed = 3\n[goal]\nv_star = 0.7\nd_star = 2.0\n[heading]\nschedule = \"constant\"\nphi = 1.0\n[lidar]\nbeams = 36\n";
        Scenario::from_toml_str(text, "t")
            .expect("scenario")
            .run_spec(3, index)
    }

    /// Journals run `index` of [`spec`] into `out`, stopping after `ticks` ticks.
    fn journal(out: &Path, index: usize, ticks: usize) {
        let spec = spec(index);
        let header = JournalHeader::new(&spec, "lockstep", &vec!["m".to_owned(); 3]);
        let mut journal = RunJournal::create(&journal_path(out, index), &header).expect("journal");
        let _ = run_episode_recorded(&spec, &mut Forward, &mut |_, _| {}, &mut |t| {
            journal.append(t).map_err(|e| e.to_string())?;
            if t.commands.len() == ticks {
                Err("stop".to_owned())
            } else {
                Ok(())
            }
        });
        journal.close().expect("close");
    }

    #[test]
    fn partial_runs_are_summarized_and_marked_incomplete() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("run");
        // Run 0 finished; run 1 was journaled by a world that was killed after 12 ticks.
        let full =
            formation_world::run_episode(&spec(0), &mut Forward, &mut |_, _| {}).expect("episode");
        let log = RunLog {
            index: 0,
            metrics: formation_world::metrics::run_metrics(
                &full,
                full.commands.len() as u64,
                &Default::default(),
            ),
            trajectory: full,
            clock: "lockstep".into(),
            models: vec!["m".into(); 3],
            complete: true,
            stop_reason: None,
            planned_ticks: Some(40),
        };
        formation_world::runlog::write_json_atomic(&log_paths(&out, 0).0, &log).expect("log");
        journal(&out, 1, 12);

        let error = supervisor::LaunchError::WorldFailed {
            status: "killed by signal 9".into(),
            signal: Some(9),
        };
        // Issue 39: a killed world printed nothing, and the message does not point above.
        let message = error.to_string();
        assert!(!message.contains("see its error above"), "{message}");
        assert!(message.contains("SIGKILL"), "{message}");
        keep_partial_runs(&out, 0..2, std::time::SystemTime::now(), &error, "t", 3);
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary.json"))
                .expect("json");
        assert_eq!(summary["runs"], 2);
        assert_eq!(summary["seed"], 3);
        let incomplete = summary["incomplete_runs"].as_array().expect("listed");
        assert_eq!(incomplete.len(), 1, "{summary}");
        assert_eq!(incomplete[0]["index"], 1);
        assert_eq!(incomplete[0]["ticks"], 12);
        assert_eq!(
            incomplete[0]["stop_reason"],
            "the world process exited (killed by signal 9) before the world saved the run"
        );
        assert!(
            !journal_path(&out, 1).exists(),
            "the journal became a run log"
        );
        let recovered = RunLog::read(&log_paths(&out, 1).0).expect("recovered log");
        assert!(!recovered.complete);

        // A launcher stop rewrites the reason the world gave.
        let mut log = recovered;
        log.stop_reason = Some("stopped: the launcher closed the world's input".into());
        formation_world::runlog::write_json_atomic(&log_paths(&out, 1).0, &log).expect("log");
        keep_partial_runs(
            &out,
            0..2,
            std::time::SystemTime::now(),
            &supervisor::LaunchError::Interrupted(
                formation_proto::exit::TerminationSignal::Terminate,
            ),
            "t",
            3,
        );
        let log = RunLog::read(&log_paths(&out, 1).0).expect("log");
        assert_eq!(log.stop_reason.as_deref(), Some("interrupted by SIGTERM"));
    }

    #[test]
    fn orphan_journals_get_a_run_log_and_a_summary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("nested").join("run");
        journal(&out, 0, 7);
        recover_run_dirs(dir.path());
        let summary: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join("summary.json")).expect("summary.json written"),
        )
        .expect("json");
        assert!(
            summary.get("seed").is_none(),
            "the seed is unknown: {summary}"
        );
        assert_eq!(summary["incomplete_runs"][0]["ticks"], 7);
        assert!(log_paths(&out, 0).0.is_file());
        // A directory with a summary is left as it is.
        journal(&out, 1, 3);
        std::fs::write(out.join("summary.json"), b"{}").expect("write");
        recover_run_dirs(dir.path());
        assert_eq!(
            std::fs::read(out.join("summary.json")).expect("summary"),
            b"{}"
        );
        assert!(
            log_paths(&out, 1).0.is_file(),
            "the journal is still recovered"
        );
    }

    #[test]
    fn a_lost_agent_is_reported_with_the_tick_its_robot_brakes_from() {
        let used_to_the_end = lost_message(1, 40, Some(40));
        assert!(
            used_to_the_end.contains("its last command drove tick 40")
                && used_to_the_end.contains("braking it from tick 41"),
            "{used_to_the_end}"
        );
        let earlier = lost_message(1, 40, Some(38));
        assert!(earlier.contains("braking it from tick 39"), "{earlier}");
        let never = lost_message(2, 5, None);
        assert!(never.contains("before it drove this run"), "{never}");
    }

    #[test]
    fn fault_flags_map_to_robots_and_bad_flags_are_explained() {
        let faults =
            faults_per_robot(&["2:crash-after=5".into(), "0:late-ms=30".into()], 3).unwrap();
        assert_eq!(
            faults,
            vec![
                Some("late-ms=30".into()),
                None,
                Some("crash-after=5".into())
            ]
        );
        let err = faults_per_robot(&["5:nan-after=1".into()], 3).unwrap_err();
        assert!(err.to_string().contains("out of range"), "{err}");
        assert!(faults_per_robot(&["crash".into()], 3).is_err());
    }
}
