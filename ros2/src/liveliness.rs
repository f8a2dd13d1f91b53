//! Liveliness token key expressions: how rmw_zenoh announces nodes, publishers and subscriptions.
//!
//! `Entity`'s constructor in rmw_zenoh's `liveliness_utils.cpp` joins with `/`:
//!
//! ```text
//! @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node name>
//!          [/<topic name>/<DDS type name>/<type hash>/<QoS>]          (all but nodes)
//! ```
//!
//! where `zid` is the Zenoh session id as text, a node's entity id is its node id
//! (`rmw_node_data.cpp`), enclave, namespace, node name, topic, type and hash are *mangled*
//! (every `/` becomes `%`, so the root namespace is `%` and `/cmd_vel` is `%cmd_vel`), and the QoS
//! is written relative to rmw_zenoh's default profile (`qos.cpp`: reliable, volatile, keep last 42,
//! infinite deadline, lifespan and lease, automatic liveliness), each field left empty where it
//! equals the default:
//!
//! ```text
//! <reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>
//! ```
//!
//! with rmw's enum numbers (reliability 1 reliable, 2 best effort; durability 1 transient local,
//! 2 volatile; history 1 keep last, 2 keep all). A default-QoS rclcpp publisher (keep last 10)
//! writes `::,10:,:,:,,`; a sensor-data one `2::,5:,:,:,,`. `ros2 node list` and
//! `ros2 topic info -v` are built from these tokens.

use std::fmt;
use std::num::ParseIntError;

use thiserror::Error;

use crate::names::{NameError, Namespace, NodeName, TopicName};
use crate::type_hash::{TypeHashError, TypeHashField};

/// The admin space every token lives under.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// `@ros2_lv/<domain>/**`: every token of a domain, for discovery.
pub fn domain_wildcard(domain_id: u32) -> String {
    format!("{ADMIN_SPACE}/{domain_id}/**")
}

/// `/` → `%`, as rmw_zenoh's `mangle_name`.
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// `%` → `/`, as rmw_zenoh's `demangle_name`.
pub fn demangle(name: &str) -> String {
    name.replace('%', "/")
}

/// What a token announces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
    /// A service server (`SS`); parsed, not built here.
    ServiceServer,
    /// A service client (`SC`); parsed, not built here.
    ServiceClient,
}

impl EntityKind {
    /// The two-letter code in the token.
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
            EntityKind::ServiceServer => "SS",
            EntityKind::ServiceClient => "SC",
        }
    }

    fn from_code(code: &str) -> Option<EntityKind> {
        [
            EntityKind::Node,
            EntityKind::Publisher,
            EntityKind::Subscription,
            EntityKind::ServiceServer,
            EntityKind::ServiceClient,
        ]
        .into_iter()
        .find(|k| k.code() == code)
    }
}

/// QoS reliability, numbered as `rmw_qos_reliability_policy_e`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Reliability {
    /// `SYSTEM_DEFAULT`.
    SystemDefault = 0,
    /// `RELIABLE`.
    Reliable = 1,
    /// `BEST_EFFORT`.
    BestEffort = 2,
    /// `UNKNOWN`.
    Unknown = 3,
    /// `BEST_AVAILABLE`.
    BestAvailable = 4,
}

/// QoS durability, numbered as `rmw_qos_durability_policy_e`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Durability {
    /// `SYSTEM_DEFAULT`.
    SystemDefault = 0,
    /// `TRANSIENT_LOCAL`.
    TransientLocal = 1,
    /// `VOLATILE`.
    Volatile = 2,
    /// `UNKNOWN`.
    Unknown = 3,
    /// `BEST_AVAILABLE`.
    BestAvailable = 4,
}

/// QoS history, numbered as `rmw_qos_history_policy_e`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum History {
    /// `SYSTEM_DEFAULT`.
    SystemDefault = 0,
    /// `KEEP_LAST`.
    KeepLast = 1,
    /// `KEEP_ALL`.
    KeepAll = 2,
    /// `UNKNOWN`.
    Unknown = 3,
}

/// The QoS fields a token carries that this crate models. Deadline, lifespan and liveliness
/// are always written as rmw_zenoh's defaults (infinite, automatic); parsing checks their shape
/// and drops them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// History.
    pub history: History,
    /// History depth.
    pub depth: u32,
}

impl Qos {
    /// rmw_zenoh's default profile (`qos.cpp`), against which tokens are written.
    pub const RMW_ZENOH_DEFAULT: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::Volatile,
        history: History::KeepLast,
        depth: 42,
    };

    /// rclcpp's default for publishers and subscriptions: reliable, volatile, keep last 10.
    pub const ROS_DEFAULT: Qos = Qos {
        depth: 10,
        ..Qos::RMW_ZENOH_DEFAULT
    };

    /// `rclcpp::SensorDataQoS`: best effort, volatile, keep last 5 (what LIDAR drivers publish).
    pub const SENSOR_DATA: Qos = Qos {
        reliability: Reliability::BestEffort,
        durability: Durability::Volatile,
        history: History::KeepLast,
        depth: 5,
    };

    /// The QoS segment of a token.
    pub fn to_key(&self) -> String {
        let default = Qos::RMW_ZENOH_DEFAULT;
        let field = |differs: bool, value: u32| {
            if differs {
                value.to_string()
            } else {
                String::new()
            }
        };
        format!(
            "{}:{}:{},{}:,:,:,,",
            field(
                self.reliability != default.reliability,
                self.reliability as u32
            ),
            field(
                self.durability != default.durability,
                self.durability as u32
            ),
            field(self.history != default.history, self.history as u32),
            field(self.depth != default.depth, self.depth),
        )
    }

    /// Parses the QoS segment of a token.
    pub fn parse(text: &str) -> Result<Qos, QosError> {
        let bad = |reason: &'static str| QosError {
            text: text.to_owned(),
            reason,
        };
        let parts: Vec<&str> = text.split(':').collect();
        let [
            reliability,
            durability,
            history,
            deadline,
            lifespan,
            liveliness,
        ] = parts[..]
        else {
            return Err(bad("it does not have 6 `:`-separated fields"));
        };
        let (history, depth) = history
            .split_once(',')
            .ok_or_else(|| bad("history is not `<kind>,<depth>`"))?;
        for (value, commas, reason) in [
            (deadline, 1, "deadline is not `<s>,<ns>`"),
            (lifespan, 1, "lifespan is not `<s>,<ns>`"),
            (liveliness, 2, "liveliness is not `<kind>,<s>,<ns>`"),
        ] {
            let numbers_or_empty = value
                .split(',')
                .all(|n| n.bytes().all(|b| b.is_ascii_digit()));
            if value.matches(',').count() != commas || !numbers_or_empty {
                return Err(bad(reason));
            }
        }
        let default = Qos::RMW_ZENOH_DEFAULT;
        let number = |s: &str, reason| -> Result<Option<u32>, QosError> {
            if s.is_empty() {
                Ok(None)
            } else {
                s.parse().map(Some).map_err(|_| bad(reason))
            }
        };
        let reliability = match number(reliability, "reliability is not a number")? {
            None => default.reliability,
            Some(0) => Reliability::SystemDefault,
            Some(1) => Reliability::Reliable,
            Some(2) => Reliability::BestEffort,
            Some(3) => Reliability::Unknown,
            Some(4) => Reliability::BestAvailable,
            Some(_) => return Err(bad("reliability is not an rmw reliability")),
        };
        let durability = match number(durability, "durability is not a number")? {
            None => default.durability,
            Some(0) => Durability::SystemDefault,
            Some(1) => Durability::TransientLocal,
            Some(2) => Durability::Volatile,
            Some(3) => Durability::Unknown,
            Some(4) => Durability::BestAvailable,
            Some(_) => return Err(bad("durability is not an rmw durability")),
        };
        let history = match number(history, "history is not a number")? {
            None => default.history,
            Some(0) => History::SystemDefault,
            Some(1) => History::KeepLast,
            Some(2) => History::KeepAll,
            Some(3) => History::Unknown,
            Some(_) => return Err(bad("history is not an rmw history")),
        };
        let depth = number(depth, "depth is not a number")?.unwrap_or(default.depth);
        Ok(Qos {
            reliability,
            durability,
            history,
            depth,
        })
    }
}

/// Why a token's QoS segment could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("QoS `{text}` in a liveliness token is malformed: {reason}")]
pub struct QosError {
    /// The segment.
    pub text: String,
    /// What is wrong.
    pub reason: &'static str,
}

/// The node a token belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeIdentity {
    /// ROS domain id.
    pub domain_id: u32,
    /// The Zenoh session id as text (lowercase hexadecimal, as zenoh prints it).
    pub zid: String,
    /// The node's id, unique within the session.
    pub node_id: u64,
    /// The security enclave (`/` by default).
    pub enclave: Namespace,
    /// The node's namespace (`/` for none).
    pub namespace: Namespace,
    /// The node's name.
    pub name: NodeName,
}

/// The topic part of a publisher's or subscription's token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicEndpoint {
    /// The topic (or service) name.
    pub topic: TopicName,
    /// The DDS type name.
    pub type_name: String,
    /// The type hash.
    pub type_hash: TypeHashField,
    /// The QoS.
    pub qos: Qos,
}

/// One liveliness token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LivelinessToken {
    /// What it announces.
    pub kind: EntityKind,
    /// Its node.
    pub node: NodeIdentity,
    /// The entity's id within the session (for a node, its node id).
    pub entity_id: u64,
    /// The topic, for everything but nodes.
    pub endpoint: Option<TopicEndpoint>,
}

/// Why a token could not be built or parsed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LivelinessError {
    /// The zid is not lowercase hexadecimal.
    #[error("Zenoh id `{zid}` is not 1 to 32 lowercase hexadecimal digits")]
    BadZid {
        /// The zid.
        zid: String,
    },
    /// A type name that would break the key expression.
    #[error(
        "type name `{type_name}` cannot go in a key expression (empty, or holds `/`, `%`, `*`, `$`, `?`, `#` or `@`)"
    )]
    BadTypeName {
        /// The type name.
        type_name: String,
    },
    /// Not under `@ros2_lv`, or too few or too many segments for its kind.
    #[error("`{key}` is not an rmw_zenoh liveliness token: {reason}")]
    Malformed {
        /// The key expression.
        key: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// A numeric segment that does not parse.
    #[error("`{key}`: the {segment} is not a number")]
    BadNumber {
        /// The key expression.
        key: String,
        /// Which segment.
        segment: &'static str,
        /// Why.
        #[source]
        source: ParseIntError,
    },
    /// A name segment that is not a valid ROS name.
    #[error("`{key}` carries an invalid name")]
    BadName {
        /// The key expression.
        key: String,
        /// What is wrong with it.
        #[source]
        source: NameError,
    },
    /// A hash segment that does not parse.
    #[error("`{key}` carries an invalid type hash")]
    BadTypeHash {
        /// The key expression.
        key: String,
        /// What is wrong with it.
        #[source]
        source: TypeHashError,
    },
    /// A QoS segment that does not parse.
    #[error("`{key}` carries an invalid QoS")]
    BadQos {
        /// The key expression.
        key: String,
        /// What is wrong with it.
        #[source]
        source: QosError,
    },
}

fn check_zid(zid: &str) -> Result<(), LivelinessError> {
    let ok = (1..=32).contains(&zid.len())
        && zid
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
    if ok {
        Ok(())
    } else {
        Err(LivelinessError::BadZid {
            zid: zid.to_owned(),
        })
    }
}

fn check_type_name(type_name: &str) -> Result<(), LivelinessError> {
    let forbidden = |c: char| "/%*$?#@".contains(c);
    if type_name.is_empty() || type_name.contains(forbidden) {
        Err(LivelinessError::BadTypeName {
            type_name: type_name.to_owned(),
        })
    } else {
        Ok(())
    }
}

impl LivelinessToken {
    /// The token of a node.
    pub fn node(node: NodeIdentity) -> Result<LivelinessToken, LivelinessError> {
        check_zid(&node.zid)?;
        Ok(LivelinessToken {
            kind: EntityKind::Node,
            entity_id: node.node_id,
            node,
            endpoint: None,
        })
    }

    /// The token of a publisher (`MP`) or subscription (`MS`) of `node`.
    pub fn endpoint(
        kind: EntityKind,
        node: NodeIdentity,
        entity_id: u64,
        endpoint: TopicEndpoint,
    ) -> Result<LivelinessToken, LivelinessError> {
        check_zid(&node.zid)?;
        check_type_name(&endpoint.type_name)?;
        Ok(LivelinessToken {
            kind,
            node,
            entity_id,
            endpoint: Some(endpoint),
        })
    }

    /// Parses a token (of any kind, services included).
    pub fn parse(key: &str) -> Result<LivelinessToken, LivelinessError> {
        let malformed = |reason| LivelinessError::Malformed {
            key: key.to_owned(),
            reason,
        };
        let parts: Vec<&str> = key.split('/').collect();
        if parts.len() != 9 && parts.len() != 13 {
            return Err(malformed("it has neither 9 nor 13 `/`-separated segments"));
        }
        if parts.iter().any(|p| p.is_empty()) {
            return Err(malformed("it has an empty segment"));
        }
        if parts[0] != ADMIN_SPACE {
            return Err(malformed("it is not under @ros2_lv"));
        }
        let kind = EntityKind::from_code(parts[5])
            .ok_or_else(|| malformed("its entity kind is not NN, MP, MS, SS or SC"))?;
        if (kind == EntityKind::Node) != (parts.len() == 9) {
            return Err(malformed(
                "a node token has 9 segments, any other 13 (with topic, type, hash and QoS)",
            ));
        }
        let number = |segment: &'static str, text: &str| -> Result<u64, LivelinessError> {
            text.parse().map_err(|source| LivelinessError::BadNumber {
                key: key.to_owned(),
                segment,
                source,
            })
        };
        let name_error = |source| LivelinessError::BadName {
            key: key.to_owned(),
            source,
        };
        let domain_id = u32::try_from(number("domain id", parts[1])?)
            .map_err(|_| malformed("its domain id does not fit 32 bits"))?;
        let node = NodeIdentity {
            domain_id,
            zid: parts[2].to_owned(),
            node_id: number("node id", parts[3])?,
            enclave: Namespace::enclave(&demangle(parts[6])).map_err(name_error)?,
            namespace: Namespace::new(&demangle(parts[7])).map_err(name_error)?,
            name: NodeName::new(&demangle(parts[8])).map_err(name_error)?,
        };
        check_zid(&node.zid)?;
        let entity_id = number("entity id", parts[4])?;
        let endpoint = if parts.len() == 13 {
            let type_name = demangle(parts[10]);
            check_type_name(&type_name)?;
            Some(TopicEndpoint {
                topic: TopicName::new(&demangle(parts[9])).map_err(name_error)?,
                type_name,
                type_hash: TypeHashField::parse(&demangle(parts[11])).map_err(|source| {
                    LivelinessError::BadTypeHash {
                        key: key.to_owned(),
                        source,
                    }
                })?,
                qos: Qos::parse(parts[12]).map_err(|source| LivelinessError::BadQos {
                    key: key.to_owned(),
                    source,
                })?,
            })
        } else {
            None
        };
        Ok(LivelinessToken {
            kind,
            node,
            entity_id,
            endpoint,
        })
    }
}

impl LivelinessToken {
    /// The entity's GID as every rmw_zenoh process computes it from this token: what a publisher
    /// puts in its [attachments](crate::attachment::Attachment::source_gid).
    pub fn gid(&self) -> [u8; crate::attachment::GID_LEN] {
        crate::gid::entity_gid(&self.to_string())
    }
}

impl fmt::Display for LivelinessToken {
    /// The token's key expression.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let node = &self.node;
        write!(
            f,
            "{ADMIN_SPACE}/{}/{}/{}/{}/{}/{}/{}/{}",
            node.domain_id,
            node.zid,
            node.node_id,
            self.entity_id,
            self.kind.code(),
            mangle(node.enclave.as_str()),
            mangle(node.namespace.as_str()),
            mangle(node.name.as_str()),
        )?;
        if let Some(endpoint) = &self.endpoint {
            write!(
                f,
                "/{}/{}/{}/{}",
                mangle(endpoint.topic.as_str()),
                mangle(&endpoint.type_name),
                mangle(&endpoint.type_hash.to_string()),
                endpoint.qos.to_key()
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{RosMessage, Twist};

    const ZID: &str = "7c4e5f0a1b2c3d4e5f60718293a4b5c6";

    fn agent_node() -> NodeIdentity {
        NodeIdentity {
            domain_id: 0,
            zid: ZID.to_owned(),
            node_id: 0,
            enclave: Namespace::root(),
            namespace: Namespace::root(),
            name: NodeName::new("formation_agent").unwrap(),
        }
    }

    fn cmd_vel(qos: Qos) -> TopicEndpoint {
        TopicEndpoint {
            topic: TopicName::new("/cmd_vel").unwrap(),
            type_name: Twist::DDS_TYPE_NAME.to_owned(),
            type_hash: TypeHashField::Rihs01(Twist::type_hash()),
            qos,
        }
    }

    #[test]
    fn node_token_matches_rmw_zenoh_layout() {
        let token = LivelinessToken::node(agent_node()).unwrap();
        assert_eq!(
            token.to_string(),
            format!("@ros2_lv/0/{ZID}/0/0/NN/%/%/formation_agent")
        );
        assert_eq!(LivelinessToken::parse(&token.to_string()), Ok(token));
    }

    #[test]
    fn publisher_token_matches_rmw_zenoh_layout() {
        let mut node = agent_node();
        node.namespace = Namespace::new("/robot_0").unwrap();
        let token =
            LivelinessToken::endpoint(EntityKind::Publisher, node, 3, cmd_vel(Qos::ROS_DEFAULT))
                .unwrap();
        assert_eq!(
            token.to_string(),
            format!(
                "@ros2_lv/0/{ZID}/0/3/MP/%/%robot_0/formation_agent/%cmd_vel/geometry_msgs::msg::dds_::Twist_/{}/::,10:,:,:,,",
                Twist::TYPE_HASH
            )
        );
        assert_eq!(LivelinessToken::parse(&token.to_string()), Ok(token));
    }

    #[test]
    fn qos_is_written_relative_to_rmw_zenoh_defaults() {
        assert_eq!(Qos::RMW_ZENOH_DEFAULT.to_key(), "::,:,:,:,,");
        assert_eq!(Qos::ROS_DEFAULT.to_key(), "::,10:,:,:,,");
        assert_eq!(Qos::SENSOR_DATA.to_key(), "2::,5:,:,:,,");
        let transient_keep_all = Qos {
            reliability: Reliability::Reliable,
            durability: Durability::TransientLocal,
            history: History::KeepAll,
            depth: 42,
        };
        assert_eq!(transient_keep_all.to_key(), ":1:2,:,:,:,,");
        for qos in [Qos::ROS_DEFAULT, Qos::SENSOR_DATA, transient_keep_all] {
            assert_eq!(Qos::parse(&qos.to_key()), Ok(qos));
        }
        // Deadline, lifespan and lease values written by another node are accepted.
        assert_eq!(Qos::parse("2::,5:1,500:3,0:3,10,0"), Ok(Qos::SENSOR_DATA));
    }

    #[test]
    fn malformed_qos_is_refused_with_the_reason() {
        for text in [
            "",
            "::,:,:,:",
            "9::,:,:,:,,",
            "::5:,:,:,,",
            "::,x:,:,:,,",
            "::,:,:,:a,,",
        ] {
            assert!(Qos::parse(text).is_err(), "{text}");
        }
    }

    #[test]
    fn foreign_tokens_parse_including_services() {
        let token = "@ros2_lv/12/0123abcd/5/9/MS/%/%/teleop/%robot_1%cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported/2::,5:,:,:,,";
        let parsed = LivelinessToken::parse(token).unwrap();
        assert_eq!(parsed.kind, EntityKind::Subscription);
        assert_eq!(parsed.node.domain_id, 12);
        assert_eq!(parsed.node.node_id, 5);
        assert_eq!(parsed.entity_id, 9);
        let endpoint = parsed.endpoint.as_ref().unwrap();
        assert_eq!(endpoint.topic.as_str(), "/robot_1/cmd_vel");
        assert_eq!(endpoint.type_hash, TypeHashField::NotSupported);
        assert_eq!(endpoint.qos, Qos::SENSOR_DATA);
        assert_eq!(parsed.to_string(), token);

        let service = "@ros2_lv/0/ab/1/2/SS/%/%/talker/%talker%describe_parameters/rcl_interfaces::srv::dds_::DescribeParameters_/RIHS01_0000000000000000000000000000000000000000000000000000000000000000/::,1:,:,:,,";
        assert_eq!(
            LivelinessToken::parse(service).unwrap().kind,
            EntityKind::ServiceServer
        );
    }

    #[test]
    fn malformed_tokens_are_refused_with_the_reason() {
        let cases = [
            "@ros2_lv/0/ab/1/1/NN/%/%",
            "@other/0/ab/1/1/NN/%/%/talker",
            "@ros2_lv/0/ab/1/1/XX/%/%/talker",
            "@ros2_lv/0/ab/1/1/MP/%/%/talker",
            "@ros2_lv/0/ab//1/NN/%/%/talker",
        ];
        let refusal = |key| LivelinessToken::parse(key).unwrap_err();
        for key in cases {
            assert!(
                matches!(refusal(key), LivelinessError::Malformed { .. }),
                "{key}"
            );
        }
        let bad_domain = refusal("@ros2_lv/x/ab/1/1/NN/%/%/talker");
        assert!(matches!(
            bad_domain,
            LivelinessError::BadNumber {
                segment: "domain id",
                ..
            }
        ));
        let bad_zid = refusal("@ros2_lv/0/AB/1/1/NN/%/%/talker");
        assert!(matches!(bad_zid, LivelinessError::BadZid { .. }));
        let bad_name = refusal("@ros2_lv/0/ab/1/1/NN/%/ns/talker");
        assert!(matches!(bad_name, LivelinessError::BadName { .. }));
    }

    #[test]
    fn building_refuses_bad_zids_and_type_names() {
        let mut node = agent_node();
        node.zid = "not/hex".to_owned();
        assert!(matches!(
            LivelinessToken::node(node),
            Err(LivelinessError::BadZid { .. })
        ));
        let mut endpoint = cmd_vel(Qos::ROS_DEFAULT);
        endpoint.type_name = "geometry_msgs/msg/Twist".to_owned();
        assert!(matches!(
            LivelinessToken::endpoint(EntityKind::Publisher, agent_node(), 1, endpoint),
            Err(LivelinessError::BadTypeName { .. })
        ));
    }

    #[test]
    fn domain_wildcard_covers_the_domain() {
        assert_eq!(domain_wildcard(3), "@ros2_lv/3/**");
    }
}
