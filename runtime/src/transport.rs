//! Which transport joins the world and its agents ([`Transport`]): iceoryx2 shared memory on one
//! host (the default), Zenoh over TCP for agents on other hosts, ROS 2 over rmw_zenoh (agents
//! that drive ROS 2 robots, the world as a ROS 2 team), or a transport a binary registered by
//! name ([`crate::plugin::TransportPlugin`]). Each is a crate of its own; a binary's package links
//! the ones its build asks for (the `zenoh` cargo feature adds Zenoh and ROS 2, off in the demo's
//! build) and says which with [`Transport::check_built_in`]; `--transport` takes a name through
//! [`TransportParser`], which knows the binary's registered plugins.

use std::ffi::OsStr;
use std::fmt;

use crate::link::{AgentLinkError, TransportFailure, WorldLinkError};
use crate::plugin::{TransportPlugin, find_plugin};

/// The transport between the world and its agents.
#[derive(Clone, Copy, Default)]
pub enum Transport {
    /// iceoryx2 shared memory: every process on this host.
    #[default]
    Iceoryx2,
    /// Zenoh over TCP: the world listens (`--listen`), agents connect (`--connect`), from this
    /// host or others.
    Zenoh,
    /// ROS 2 over rmw_zenoh: LaserScan and orientation in, Twist out, through a Zenoh router
    /// (the robot's `rmw_zenohd`, or the world's `--listen`).
    Ros2,
    /// A transport the binary registered by name; generic code opens its links.
    Plugin(&'static dyn TransportPlugin),
}

/// The first-party transports' names and help lines, as `--transport` lists them.
const FIRST_PARTY: [(Transport, &str); 3] = [
    (
        Transport::Iceoryx2,
        "iceoryx2 shared memory: every process on this host",
    ),
    (
        Transport::Zenoh,
        "Zenoh over TCP: the world listens (`--listen`), agents connect (`--connect`), from this \
         host or others",
    ),
    (
        Transport::Ros2,
        "ROS 2 over rmw_zenoh: LaserScan and orientation in, Twist out, through a Zenoh router \
         (the robot's `rmw_zenohd`, or the world's `--listen`)",
    ),
];

impl PartialEq for Transport {
    fn eq(&self, other: &Transport) -> bool {
        self.as_str() == other.as_str()
    }
}

impl Eq for Transport {}

impl fmt::Debug for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Transport::Iceoryx2 => f.write_str("Iceoryx2"),
            Transport::Zenoh => f.write_str("Zenoh"),
            Transport::Ros2 => f.write_str("Ros2"),
            Transport::Plugin(plugin) => write!(f, "Plugin({:?})", plugin.name()),
        }
    }
}

impl Transport {
    /// The first-party transports a binary links, one line each (`--transport` refuses the
    /// others, naming the build that has them): iceoryx2 always, Zenoh and ROS 2 where the
    /// binary's build has them (`zenoh`, its `zenoh` cargo feature).
    pub const fn linked(zenoh: bool) -> &'static [Transport] {
        if zenoh {
            &[Transport::Iceoryx2, Transport::Zenoh, Transport::Ros2]
        } else {
            &[Transport::Iceoryx2]
        }
    }

    /// The name the flags use.
    pub fn as_str(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Zenoh => "zenoh",
            Transport::Ros2 => "ros2",
            Transport::Plugin(plugin) => plugin.name(),
        }
    }

    /// The registered transport, if this is one.
    pub fn plugin(self) -> Option<&'static dyn TransportPlugin> {
        match self {
            Transport::Plugin(plugin) => Some(plugin),
            _ => None,
        }
    }

    /// `Ok` when `built` (the transports the calling binary links) holds this one, else the
    /// error naming it and how to build it.
    /// A registered transport is built in by its registration.
    pub fn check_built_in(self, program: &str, built: &[Transport]) -> Result<(), TransportError> {
        if self.plugin().is_some() || built.contains(&self) {
            Ok(())
        } else {
            Err(TransportError::NotBuilt {
                program: program.to_string(),
                transport: self,
            })
        }
    }

    /// `Ok` unless one of Zenoh's own flags (`(given, "--flag")`) was given with another
    /// transport, which is then the error naming the first such flag.
    pub fn refuse_zenoh_flags(self, flags: &[(bool, &'static str)]) -> Result<(), TransportError> {
        self.refuse_flags_unless(self == Transport::Zenoh, "zenoh", flags)
    }

    /// `Ok` unless one of ROS 2's own flags (`(given, "--flag")`) was given with another
    /// transport, which is then the error naming the first such flag.
    pub fn refuse_ros2_flags(self, flags: &[(bool, &'static str)]) -> Result<(), TransportError> {
        self.refuse_flags_unless(self == Transport::Ros2, "ros2", flags)
    }

    /// `Ok` when `fits`, else the error naming the first flag given (`(given, "--flag")`), which
    /// works only with `needs`.
    fn refuse_flags_unless(
        self,
        fits: bool,
        needs: &'static str,
        flags: &[(bool, &'static str)],
    ) -> Result<(), TransportError> {
        if fits {
            return Ok(());
        }
        match flags.iter().find(|(given, _)| *given) {
            Some(&(_, flag)) => Err(TransportError::FlagNeedsTransport {
                flag,
                needs,
                transport: self,
            }),
            None => Ok(()),
        }
    }

    /// Whether the transport runs over a Zenoh session (and so takes `--listen`/`--connect`).
    pub fn over_zenoh(self) -> bool {
        matches!(self, Transport::Zenoh | Transport::Ros2)
    }

    /// Whether the transport takes an endpoint (`--listen`, `--connect`): those over Zenoh, and
    /// a registered one that says what its endpoint means.
    pub fn takes_endpoint(self) -> bool {
        self.over_zenoh() || self.plugin().is_some_and(|p| p.endpoint().is_some())
    }

    /// `Ok` unless one of the network flags (`--listen`, `--connect`) was given with a transport
    /// that takes no endpoint.
    pub fn refuse_network_flags(
        self,
        flags: &[(bool, &'static str)],
    ) -> Result<(), TransportError> {
        self.refuse_flags_unless(self.takes_endpoint(), "zenoh or ros2", flags)
    }
}

impl fmt::Display for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A transport that cannot be used as asked.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The binary was built without it.
    #[error(
        "{program} was built without the {transport} transport; rebuild it with the `zenoh` \
         feature: `cargo build --release --features zenoh` (the demo's build leaves it out)"
    )]
    NotBuilt {
        /// The binary.
        program: String,
        /// The transport asked for.
        transport: Transport,
    },
    /// A flag that needs another transport.
    #[error("{flag} needs --transport {needs} (the transport is {transport})")]
    FlagNeedsTransport {
        /// The flag given.
        flag: &'static str,
        /// The transports it works with, e.g. `zenoh or ros2`.
        needs: &'static str,
        /// The transport in use.
        transport: Transport,
    },
    /// Zenoh without the endpoint it needs.
    #[error("--transport {transport} needs {flag} tcp/HOST:PORT")]
    MissingEndpoint {
        /// `--listen` or `--connect`.
        flag: &'static str,
        /// The transport.
        transport: Transport,
    },
    /// A registered transport could not open the world's side of a run.
    #[error("the {transport} transport could not open the world's side of run {run}")]
    OpenWorld {
        /// The transport.
        transport: &'static str,
        /// The run id.
        run: String,
        /// What failed.
        #[source]
        source: WorldLinkError,
    },
    /// A registered transport could not connect an agent.
    #[error("the {transport} transport could not connect robot {robot}'s agent to run {run}")]
    ConnectAgent {
        /// The transport.
        transport: &'static str,
        /// The robot.
        robot: usize,
        /// The run id.
        run: String,
        /// What failed (a signal while connecting is [`AgentLinkError::Terminated`]).
        #[source]
        source: AgentLinkError,
    },
    /// A registered transport failed at something else a tool asked of it (a swap, a cleanup).
    #[error("the {transport} transport could not {action} of run {run}")]
    Plugin {
        /// The transport.
        transport: &'static str,
        /// What it was asked, e.g. `send the swap request`.
        action: &'static str,
        /// The run id.
        run: String,
        /// The transport's own error.
        #[source]
        source: TransportFailure,
    },
}

/// `--transport`'s parser: the first-party names (a binary built without one refuses it later,
/// naming the build that has it, [`Transport::check_built_in`]) and the binary's registered
/// plugins; any other name is clap's error listing them all.
#[derive(Clone, Copy)]
pub struct TransportParser {
    plugins: &'static [&'static dyn TransportPlugin],
}

impl TransportParser {
    /// The parser of a binary that registered `plugins`.
    pub const fn new(plugins: &'static [&'static dyn TransportPlugin]) -> TransportParser {
        TransportParser { plugins }
    }

    /// Every name it takes, with its help line.
    fn possible(&self) -> Vec<clap::builder::PossibleValue> {
        let first_party = FIRST_PARTY.iter().map(|(transport, help)| {
            clap::builder::PossibleValue::new(transport.as_str()).help(help)
        });
        let plugins = self
            .plugins
            .iter()
            .map(|p| clap::builder::PossibleValue::new(p.name()).help(p.description()));
        first_party.chain(plugins).collect()
    }

    /// The transport named `name`, if the binary knows it.
    pub fn find(&self, name: &str) -> Option<Transport> {
        FIRST_PARTY
            .iter()
            .map(|(transport, _)| *transport)
            .find(|t| t.as_str() == name)
            .or_else(|| find_plugin(self.plugins, name).map(Transport::Plugin))
    }
}

impl clap::builder::TypedValueParser for TransportParser {
    type Value = Transport;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<Transport, clap::Error> {
        let name =
            clap::builder::PossibleValuesParser::new(self.possible()).parse_ref(cmd, arg, value)?;
        self.find(&name).ok_or_else(|| {
            // PossibleValuesParser took only names that `find` knows.
            clap::Error::new(clap::error::ErrorKind::InvalidValue).with_cmd(cmd)
        })
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(self.possible().into_iter()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_flags_with_another_transport_name_the_first_flag_given() {
        let flags = [
            (false, "--listen"),
            (true, "--remote"),
            (true, "--credentials"),
        ];
        assert!(Transport::Zenoh.refuse_zenoh_flags(&flags).is_ok());
        assert!(
            Transport::Iceoryx2
                .refuse_zenoh_flags(&[(false, "--listen")])
                .is_ok()
        );
        assert!(Transport::Ros2.refuse_network_flags(&flags).is_ok());
        let refusals = [
            (
                Transport::Iceoryx2.refuse_zenoh_flags(&flags),
                "--remote needs --transport zenoh (the transport is iceoryx2)",
            ),
            (
                Transport::Ros2.refuse_zenoh_flags(&flags),
                "--remote needs --transport zenoh (the transport is ros2)",
            ),
            (
                Transport::Iceoryx2.refuse_network_flags(&[(true, "--connect")]),
                "--connect needs --transport zenoh or ros2 (the transport is iceoryx2)",
            ),
            (
                Transport::Zenoh.refuse_ros2_flags(&[(true, "--scan")]),
                "--scan needs --transport ros2 (the transport is zenoh)",
            ),
        ];
        for (refused, message) in refusals {
            assert_eq!(refused.unwrap_err().to_string(), message);
        }
    }

    /// A registered transport for the tests: takes an endpoint, opens nothing.
    struct Pigeon;

    impl TransportPlugin for Pigeon {
        fn name(&self) -> &'static str {
            "pigeon"
        }
        fn description(&self) -> &'static str {
            "carrier pigeons"
        }
        fn endpoint(&self) -> Option<&'static str> {
            Some("a loft")
        }
        fn open_world(
            &self,
            _: &crate::plugin::WorldSite<'_>,
        ) -> Result<Box<dyn crate::link::WorldLink>, WorldLinkError> {
            Err(WorldLinkError::Transport("no loft".into()))
        }
        fn connect_agent(
            &self,
            _: &crate::plugin::AgentSite<'_>,
        ) -> Result<Box<dyn crate::link::AgentLink>, AgentLinkError> {
            Err(AgentLinkError::Transport("no pigeon".into()))
        }
    }

    static PLUGINS: &[&dyn TransportPlugin] = &[&Pigeon];

    #[derive(Debug, clap::Parser)]
    struct Flags {
        #[arg(long, value_parser = TransportParser::new(PLUGINS), default_value_t = Transport::Iceoryx2)]
        transport: Transport,
    }

    #[test]
    fn transport_takes_the_first_party_names_and_the_registered_ones() {
        use clap::Parser;
        let parse = |args: &[&str]| Flags::try_parse_from([&["flags"], args].concat());
        assert_eq!(parse(&[]).unwrap().transport, Transport::Iceoryx2);
        assert_eq!(
            parse(&["--transport", "ros2"]).unwrap().transport,
            Transport::Ros2
        );
        let pigeon = parse(&["--transport", "pigeon"]).unwrap().transport;
        assert_eq!(pigeon.as_str(), "pigeon");
        assert!(pigeon.plugin().is_some() && pigeon.takes_endpoint());
        assert!(pigeon.check_built_in("x", &[Transport::Iceoryx2]).is_ok());
        assert!(pigeon.refuse_network_flags(&[(true, "--listen")]).is_ok());
        assert_eq!(
            pigeon
                .refuse_zenoh_flags(&[(true, "--remote")])
                .unwrap_err()
                .to_string(),
            "--remote needs --transport zenoh (the transport is pigeon)"
        );
        let unknown = parse(&["--transport", "owl"]).unwrap_err().to_string();
        assert!(
            unknown.contains("invalid value 'owl' for '--transport <TRANSPORT>'")
                && unknown.contains("[possible values: iceoryx2, zenoh, ros2, pigeon]"),
            "{unknown}"
        );
    }

    #[test]
    fn a_registered_transports_failure_names_it_and_keeps_its_source() {
        use std::error::Error;
        let source = Pigeon
            .connect_agent(&crate::plugin::AgentSite {
                run: crate::plugin::RunSite {
                    run: &formation_proto::wire::RunId::new("r1").unwrap(),
                    endpoint: None,
                },
                robot: 2,
                pid: 1,
                secret: &crate::auth::LaunchSecret::generate().unwrap(),
                connect_timeout: std::time::Duration::from_secs(1),
            })
            .err()
            .expect("no pigeon");
        let e = TransportError::ConnectAgent {
            transport: Pigeon.name(),
            robot: 2,
            run: "r1".into(),
            source,
        };
        assert_eq!(
            e.to_string(),
            "the pigeon transport could not connect robot 2's agent to run r1"
        );
        assert_eq!(e.source().unwrap().to_string(), "no pigeon");
        let swap = Pigeon
            .request_swap(
                &crate::plugin::RunSite {
                    run: &formation_proto::wire::RunId::new("r1").unwrap(),
                    endpoint: None,
                },
                &formation_proto::wire::SwapRequest {
                    request_id: 1,
                    robot: 0,
                    at_tick: 0,
                    path: "m.onnx".into(),
                },
                std::time::Duration::from_secs(1),
            )
            .unwrap_err();
        assert!(
            swap.to_string().contains("carries no swap requests"),
            "{swap}"
        );
    }

    #[test]
    fn iceoryx2_is_the_default_and_a_missing_transport_names_the_fix() {
        assert_eq!(Transport::default(), Transport::Iceoryx2);
        let e = TransportError::NotBuilt {
            program: "formation-agent".into(),
            transport: Transport::Zenoh,
        }
        .to_string();
        assert!(
            e.contains("formation-agent") && e.contains("zenoh") && e.contains("--features zenoh")
        );
        let demo = [Transport::Iceoryx2];
        assert!(Transport::Iceoryx2.check_built_in("x", &demo).is_ok());
        assert!(Transport::Zenoh.check_built_in("x", &demo).is_err());
        assert!(
            Transport::Ros2
                .check_built_in("x", &[Transport::Iceoryx2, Transport::Ros2])
                .is_ok()
        );
    }
}
