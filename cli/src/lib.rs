//! The `formation` command-line tool, as a library so integration tests can drive it.
//!
//! [`args`] parses the command line; each command's module runs it; [`launch`] starts and
//! supervises the runtime's processes. Dependencies point one way (arguments ← commands ←
//! launcher helpers), with no module cycle.
//!
//! Every subcommand is a thin layer over the library crates: it parses arguments, loads inputs
//! with errors that name the file and the fix, calls the pure logic, and writes outputs.
//!
//! * [`eval`]: in-process (or, with `--processes`, multi-process) evaluation with the paper's metrics.
//! * [`gauge`]: the response gauge, a controller's corrections against the expert's labels.
//! * [`collect`]: expert demonstrations into a dataset.
//! * [`learn`]: `train` (runs the PyTorch trainer), `dagger` (policy drives, expert labels,
//!   retrain), and `dagger-label` / `dagger-append` (one iteration's labelling in shares).
//! * [`launch`]: the multi-process launcher (`run`, `profile`, `swap`, `credentials`).
//! * `record_connect` (feature `zenoh`): `formation record --connect`, recording a live team
//!   from outside.
//! * [`report`]: the HTML report with the paper's figures.
//! * [`table`] and [`team_models`]: Table I as text, and the checked models of a team, shared by
//!   the evaluating commands and the launcher.
//! * [`replay`]: a recording's inputs through the agent's decision again, compared with its
//!   commands.
//! * [`demo`]: the README's main job: the paper's cases and Table I with the shipped model, then a report.

pub mod args;
pub mod collect;
pub mod demo;
pub mod eval;
pub mod gauge;
pub mod ladder;
pub mod launch;
pub mod learn;
pub mod paths;
pub mod record;
#[cfg(feature = "zenoh")]
pub mod record_connect;
pub mod replay;
pub mod report;
pub mod table;
pub mod team_models;

use clap::Parser;
use formation_proto::exit::ProcessExit;

/// The transports the `formation` command links, one line each (`--transport` refuses the
/// others, naming the build that has them): iceoryx2 always, Zenoh and ROS 2 with the `zenoh`
/// feature.
pub const TRANSPORTS: &[formation_runtime::transport::Transport] = &[
    formation_runtime::transport::Transport::Iceoryx2,
    #[cfg(feature = "zenoh")]
    formation_runtime::transport::Transport::Zenoh,
    #[cfg(feature = "zenoh")]
    formation_runtime::transport::Transport::Ros2,
];

/// The transports registered beside the first-party ones, one line each: `formation run`,
/// `profile` and `eval --processes` take their names and hand them to the world and the agents
/// (which register them too), `formation swap` uses their swap client.
pub static TRANSPORT_PLUGINS: &[&dyn formation_runtime::plugin::TransportPlugin] =
    &[&formation_example_transport_unix_datagram::UnixDatagram];

/// How `formation` exits after `error`: 130 or 143 when the user interrupted a launch with
/// SIGINT (Ctrl-C) or SIGTERM, 1 when a replay found differing commands, 2 for any other error.
/// (Bad flags exit 2 through clap.)
pub fn exit_for_error(error: &anyhow::Error) -> ProcessExit {
    if error.downcast_ref::<replay::Diverged>().is_some() {
        return ProcessExit::Diverged;
    }
    let interrupted = error.chain().find_map(|cause| {
        match cause.downcast_ref::<launch::supervisor::LaunchError>() {
            Some(launch::supervisor::LaunchError::Interrupted(signal)) => Some(*signal),
            _ => None,
        }
    });
    interrupted.map_or(ProcessExit::Failure, ProcessExit::stopped_by)
}

/// Parses the command line and runs the chosen subcommand.
pub fn main_with_args() -> anyhow::Result<()> {
    let cli = args::Cli::parse();
    formation_runtime::process::init_tracing(cli.verbose);
    formation_transport_iceoryx2::naming::quiet_iceoryx_logs();
    match cli.command {
        args::Command::Eval(a) if a.ladder.is_some() => ladder::ladder_command(&a),
        args::Command::Eval(a) => eval::eval_command(&a),
        args::Command::Gauge(a) => gauge::gauge_command(&a),
        args::Command::Merge(a) => eval::merge_command(&a),
        args::Command::Collect(a) => collect::collect_command(&a),
        args::Command::Train(a) => learn::train_command(&a),
        args::Command::Dagger(a) => learn::dagger_command(&a),
        args::Command::DaggerLabel(a) => learn::dagger_label_command(&a),
        args::Command::DaggerAppend(a) => learn::dagger_append_command(&a),
        args::Command::Run(a) => launch::run_command(&a),
        args::Command::Profile(a) => launch::profile_command(&a),
        args::Command::Swap(a) => launch::swap_command(&a),
        args::Command::Credentials(a) => launch::credentials_command(&a),
        args::Command::Record(a) => record_command(&a),
        args::Command::Report(a) => report::report_command(&a),
        args::Command::Demo(a) => demo::demo_command(&a),
        args::Command::Replay(a) => replay::replay_command(&a),
    }
}

/// `formation record --connect` ([`record_connect`]).
#[cfg(feature = "zenoh")]
fn record_command(args: &args::RecordArgs) -> anyhow::Result<()> {
    record_connect::record_command(args)
}

/// `formation record --connect` needs Zenoh.
#[cfg(not(feature = "zenoh"))]
fn record_command(_args: &args::RecordArgs) -> anyhow::Result<()> {
    Err(formation_runtime::transport::TransportError::NotBuilt {
        program: "formation".into(),
        transport: formation_runtime::transport::Transport::Zenoh,
    }
    .into())
}
