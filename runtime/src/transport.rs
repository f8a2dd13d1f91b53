//! Which transport joins the world and its agents ([`Transport`]): iceoryx2 shared memory on one
//! host (the default), Zenoh over TCP for agents on other hosts, or ROS 2 over rmw_zenoh (agents
//! that drive ROS 2 robots, the world as a ROS 2 team). Each is a crate of its own; a binary's
//! package links the ones its build asks for (the `zenoh` cargo feature adds Zenoh and ROS 2,
//! off in the demo's build) and says which with [`Transport::check_built_in`].

use std::fmt;

/// The transport between the world and its agents.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Transport {
    /// iceoryx2 shared memory: every process on this host.
    #[default]
    #[value(name = "iceoryx2")]
    Iceoryx2,
    /// Zenoh over TCP: the world listens (`--listen`), agents connect (`--connect`), from this
    /// host or others.
    #[value(name = "zenoh")]
    Zenoh,
    /// ROS 2 over rmw_zenoh: LaserScan and orientation in, Twist out, through a Zenoh router
    /// (the robot's `rmw_zenohd`, or the world's `--listen`).
    #[value(name = "ros2")]
    Ros2,
}

impl Transport {
    /// The name the flags use.
    pub fn as_str(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Zenoh => "zenoh",
            Transport::Ros2 => "ros2",
        }
    }

    /// `Ok` when `built` (the transports the calling binary links) holds this one, else the
    /// error naming it and how to build it.
    pub fn check_built_in(self, program: &str, built: &[Transport]) -> Result<(), TransportError> {
        if built.contains(&self) {
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

    /// `Ok` unless one of the network flags (`--listen`, `--connect`) was given with a transport
    /// that is not over Zenoh.
    pub fn refuse_network_flags(
        self,
        flags: &[(bool, &'static str)],
    ) -> Result<(), TransportError> {
        self.refuse_flags_unless(self.over_zenoh(), "zenoh or ros2", flags)
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
        let refused = Transport::Iceoryx2.refuse_zenoh_flags(&flags).unwrap_err();
        assert_eq!(
            refused.to_string(),
            "--remote needs --transport zenoh (the transport is iceoryx2)"
        );
        let refused = Transport::Ros2.refuse_zenoh_flags(&flags).unwrap_err();
        assert_eq!(
            refused.to_string(),
            "--remote needs --transport zenoh (the transport is ros2)"
        );
        assert!(Transport::Ros2.refuse_network_flags(&flags).is_ok());
        let refused = Transport::Iceoryx2
            .refuse_network_flags(&[(true, "--connect")])
            .unwrap_err();
        assert_eq!(
            refused.to_string(),
            "--connect needs --transport zenoh or ros2 (the transport is iceoryx2)"
        );
        let refused = Transport::Zenoh
            .refuse_ros2_flags(&[(true, "--scan")])
            .unwrap_err();
        assert_eq!(
            refused.to_string(),
            "--scan needs --transport ros2 (the transport is zenoh)"
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
