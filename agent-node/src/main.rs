//! `formation-agent`: one robot's decision maker as its own OS process (see
//! [`formation_agent_node`] for what it does, its flags and its exit codes).

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // First, before any thread: ONNX Runtime then writes nothing outside the run's folders.
    formation_robot_agent::disable_telemetry_before_threads();
    formation_transport_iceoryx2::naming::quiet_iceoryx_logs();
    formation_runtime::process::init_tracing(0);
    let args = formation_agent_node::Args::parse();
    let who = formation_agent_node::who(&args);
    formation_agent_node::exit_for(&who, formation_agent_node::run(&args)).into()
}
