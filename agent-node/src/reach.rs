//! How a process reaches a run: its transport (a first-party one or one of
//! [`crate::TRANSPORT_PLUGINS`]), the endpoint to connect to and a login file, the three flags `formation-agent` and `formation swap` share ([`ReachArgs`]).
//!
//! The help texts are the agent's. A command that says them otherwise keeps the flags and
//! changes only their help, with clap's `mut_arg` on its own arguments:
//!
//! ```
//! use clap::{CommandFactory, Parser};
//! use formation_agent_node::reach::ReachArgs;
//!
//! /// Changes one robot's model.
//! #[derive(Parser)]
//! #[command(mut_arg("transport", |a| a.help("How to reach the run.")))]
//! struct Swap {
//!     #[command(flatten)]
//!     reach: ReachArgs,
//! }
//! let help = Swap::command().render_help().to_string();
//! assert!(help.contains("How to reach the run."), "{help}");
//! assert!(Swap::try_parse_from(["swap", "--transport", "zenoh"]).is_ok());
//! ```

use std::path::PathBuf;

use formation_runtime::transport::{Transport, TransportParser};

/// `--transport`, `--connect` and `--credentials`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReachArgs {
    /// How to reach the world: iceoryx2 shared memory on this host, or Zenoh over TCP; or, with
    /// ros2, drive a ROS 2 robot through its Zenoh router (rmw_zenoh); or a registered
    /// transport ([`crate::TRANSPORT_PLUGINS`]).
    #[arg(long, value_parser = TransportParser::new(crate::TRANSPORT_PLUGINS), default_value_t = Transport::Iceoryx2)]
    pub transport: Transport,
    /// Zenoh: the world's endpoint, tcp/ADDR:PORT; ROS 2: the robot's router (rmw_zenohd
    /// listens on tcp/ADDR:7447). A registered transport: its endpoint, if it takes one.
    #[arg(long, value_name = "tcp/ADDR:PORT")]
    pub connect: Option<String>,
    /// Zenoh: this robot's credentials file (`robot-<i>.json` from `formation credentials`): its
    /// login and the launch secret, which then is not read from standard input.
    #[arg(long, value_name = "FILE")]
    pub credentials: Option<PathBuf>,
}
