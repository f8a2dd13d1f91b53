//! `formation-world`: the world process of the multi-process runtime (see
//! [`formation_world_node`] for what it does, its flags and its exit codes).

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    formation_transport_iceoryx2::naming::quiet_iceoryx_logs();
    formation_runtime::process::init_tracing(0);
    let args = formation_world_node::Args::parse();
    formation_world_node::exit_for(formation_world_node::run(&args)).into()
}
