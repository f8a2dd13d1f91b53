//! A ROS 2 team over mutual TLS (feature `tls`): the world's router and every ROS 2 node use the
//! certificates of the team's `formation credentials --tls` folder (the Zenoh team's, see
//! [`formation_transport_zenoh::tls`]), and the router's access rules name each node by its certificate's
//! common name, so that a robot's certificate reaches only that robot's topics.
//!
//! The configurations are shaped as rmw_zenoh's `zenoh_security_tools` writes them from an SROS2
//! keystore: a session's `transport.link` takes `tls` as its only protocol, with
//! `enable_mtls`, `verify_name_on_connect: false`, the authority as `root_ca_certificate` and the
//! principal's key and certificate as both its connect and listen pair; access rules are per
//! principal over the data keys `<domain>/<topic>/**` (`put` and `declare_subscriber`, each in the
//! direction it flows) plus the ROS graph's liveliness tokens under `@ros2_lv/<domain>/**`.
//! Unlike the security tools, which put each enclave's rules in that node's own session, the
//! rules here live in the world's router, which every node reaches in client mode: a node cannot
//! switch them off, and no node meets another directly.
//!
//! | certificate | may publish | receives |
//! |---|---|---|
//! | `robot-<i>` | `/robot_<i>/cmd_vel` | `/robot_<i>/scan`, `/robot_<i>/odom`, `/tf`, `/tf_static`, `/formation/goal/*` |
//! | `recorder` | nothing | every topic of the domain, the run's record channel |
//! | none, or another team's | (refused by the TLS handshake) | nothing |
//!
//! Every principal may declare and watch liveliness tokens of the domain (the ROS graph), as
//! rmw_zenoh's generated rules allow: a robot's token on another robot's `cmd_vel` makes it a
//! candidate driver there, whose Twists the router still drops.
//!
//! [`session_config`] is the configuration a ROS 2 node (`ros2 run`, with
//! `ZENOH_SESSION_CONFIG_URI` naming the file, or `formation-agent --transport ros2`) uses to join
//! the world's router with its certificate; [`write_session_configs`] writes one per principal.

use std::path::{Path, PathBuf};

use formation_proto::wire::RunId;
use formation_runtime::link::PathIoError;
use serde_json::{Value, json};

use super::TeamTopics;
use formation_transport_zenoh::Endpoint;
use formation_transport_zenoh::access::{RECORDER_USER, allow, deny_by_default, robot_user};
use formation_transport_zenoh::keys;
use formation_transport_zenoh::tls::{self, TlsIdentity};

pub use formation_transport_zenoh::SESSION_CONFIG_ENV;

/// The folder of a credentials folder that holds the ROS 2 session configurations.
pub const SESSION_CONFIG_DIR: &str = "ros2";

/// Why a ROS 2 TLS configuration could not be made or read.
#[derive(Debug, thiserror::Error)]
pub enum Ros2SecurityError {
    /// A certificate file is missing or unusable.
    #[error(transparent)]
    Tls(#[from] tls::TlsError),
    /// A path Zenoh's configuration cannot hold.
    #[error("{path} is not a UTF-8 path; move the credentials folder to a path that is")]
    NotUtf8 {
        /// The path.
        path: PathBuf,
    },
    /// Zenoh refused a setting.
    #[error("zenoh refused the setting {key}: {detail}")]
    Setting {
        /// The key.
        key: String,
        /// Zenoh's error.
        detail: String,
    },
    /// A session configuration could not be written or read.
    #[error(transparent)]
    Io(#[from] PathIoError),
}

/// The ROS 2 team's side of TLS: the credentials folder, the team and the run whose record channel
/// the recorder reads.
#[derive(Debug, Clone)]
pub struct Ros2Access {
    /// The credentials folder written by `formation credentials --tls`.
    pub folder: PathBuf,
    /// The run (its record channel and world token are under `formation/<run>/`).
    pub run: RunId,
    /// Robots `0..n_robots` get a rule set each.
    pub n_robots: usize,
    /// The ROS domain id (the first chunk of every data key).
    pub domain_id: u32,
}

/// Data keys of `topics` in domain `domain`: `<domain>/<topic without its leading slash>/**`, as
/// rmw_zenoh's security tools name a topic's every type and hash.
fn data_keys(domain: u32, topics: &[String]) -> Vec<String> {
    topics
        .iter()
        .map(|topic| format!("{domain}/{}/**", topic.trim_start_matches('/')))
        .collect()
}

impl Ros2Access {
    /// The `access_control` section of the world's router: deny by default; per principal, its
    /// topics in the direction they flow; the ROS graph's tokens for all.
    pub fn rules(&self) -> Value {
        let domain = self.domain_id;
        let graph = format!("@ros2_lv/{domain}/**");
        let mut rules = vec![json!({
            "id": "ros2-graph",
            "messages": [
                "liveliness_token",
                "liveliness_query",
                "declare_liveliness_subscriber",
                "reply"
            ],
            "flows": ["ingress", "egress"],
            "permission": "allow",
            "key_exprs": [graph],
        })];
        let mut subjects = Vec::new();
        let mut policies = Vec::new();
        let mut principal = |name: String, publishes: Vec<String>, receives: Vec<String>| {
            let mut ids = vec!["ros2-graph".to_string()];
            let mut rule = |suffix: &str, messages: &[&str], flow: &str, keys: &[String]| {
                allow(
                    &mut rules,
                    &mut ids,
                    format!("{name}-{suffix}"),
                    messages,
                    flow,
                    keys,
                );
            };
            rule("incoming-publications", &["put"], "ingress", &publishes);
            rule(
                "outgoing-subscriptions",
                &["declare_subscriber"],
                "egress",
                &publishes,
            );
            rule("outgoing-publications", &["put"], "egress", &receives);
            rule(
                "incoming-subscriptions",
                &["declare_subscriber"],
                "ingress",
                &receives,
            );
            subjects.push(json!({ "id": name, "cert_common_names": [name] }));
            policies.push(json!({ "rules": ids, "subjects": [name] }));
        };
        let goal: Vec<String> = TeamTopics::goal()
            .iter()
            .map(|t| t.as_str().to_owned())
            .collect();
        for robot in 0..self.n_robots {
            let topics = TeamTopics::robot(robot);
            let mut receives = vec![
                topics.scan.as_str().to_owned(),
                topics.odometry.as_str().to_owned(),
                "/tf".to_owned(),
                "/tf_static".to_owned(),
            ];
            receives.extend(goal.iter().cloned());
            principal(
                robot_user(robot),
                data_keys(domain, &[topics.cmd_vel.as_str().to_owned()]),
                data_keys(domain, &receives),
            );
        }
        principal(
            RECORDER_USER.to_string(),
            Vec::new(),
            vec![format!("{domain}/**")],
        );
        // The recorder also reads the run's record channel, outside rmw_zenoh's keys
        // (`formation record --connect --transport ros2`).
        let run = &self.run;
        let (live, setup, world) = (
            [keys::record_live(run)],
            [keys::record_setup(run)],
            [keys::world_token(run)],
        );
        let record: [(&str, &[&str], &str, &[String]); 6] = [
            ("record-channel", &["put"], "egress", &live),
            (
                "record-subscription",
                &["declare_subscriber"],
                "ingress",
                &live,
            ),
            ("ask-setup", &["query"], "ingress", &setup),
            ("get-setup", &["reply"], "egress", &setup),
            (
                "watch-world",
                &["declare_liveliness_subscriber", "liveliness_query"],
                "ingress",
                &world,
            ),
            (
                "see-world",
                &["liveliness_token", "reply"],
                "egress",
                &world,
            ),
        ];
        let mut record_ids = Vec::new();
        for (suffix, messages, flow, keys) in record {
            let id = format!("{RECORDER_USER}-{suffix}");
            allow(&mut rules, &mut record_ids, id, messages, flow, keys);
        }
        policies.push(json!({ "rules": record_ids, "subjects": [RECORDER_USER] }));
        deny_by_default(rules, subjects, policies)
    }

    /// Adds to `config` (the world's router, listening on `listen`) the world's certificate,
    /// checked first, the team's authority as the only one trusted for nodes, and the rules.
    pub(crate) fn apply(&self, config: &mut ::zenoh::Config) -> Result<(), Ros2SecurityError> {
        let identity = TlsIdentity::in_folder(&self.folder, tls::WORLD_PRINCIPAL);
        identity.load_checked(std::time::SystemTime::now())?;
        let section = tls_section(&identity)?;
        set(config, "transport/link/protocols", &json!(["tls"]))?;
        set(config, "transport/link/tls", &section)?;
        set(config, "access_control", &self.rules())
    }
}

fn utf8(path: &Path) -> Result<&str, Ros2SecurityError> {
    path.to_str().ok_or_else(|| Ros2SecurityError::NotUtf8 {
        path: path.to_path_buf(),
    })
}

/// `transport.link.tls` as rmw_zenoh's security tools write it: the principal's key and
/// certificate for both connecting and listening, mutual TLS, the team's authority alone.
fn tls_section(identity: &TlsIdentity) -> Result<Value, Ros2SecurityError> {
    let (ca, certificate, key) = (
        utf8(&identity.ca)?,
        utf8(&identity.certificate)?,
        utf8(&identity.key)?,
    );
    Ok(json!({
        "root_ca_certificate": ca,
        "listen_certificate": certificate,
        "listen_private_key": key,
        "connect_certificate": certificate,
        "connect_private_key": key,
        "enable_mtls": true,
        "verify_name_on_connect": false,
        "close_link_on_expiration": true,
    }))
}

fn set(config: &mut ::zenoh::Config, key: &str, value: &Value) -> Result<(), Ros2SecurityError> {
    config
        .insert_json5(key, &value.to_string())
        .map_err(|e| Ros2SecurityError::Setting {
            key: key.to_owned(),
            detail: e.to_string(),
        })
}

/// The session configuration of ROS 2 node principal `principal` (`robot-<i>`, `recorder`) of
/// credentials folder `folder`, joining the world's router at `connect` (`tls/HOST:PORT`): client
/// mode, no scouting, TLS only, with its certificate.
pub fn session_config(
    folder: &Path,
    principal: &str,
    connect: &Endpoint,
) -> Result<Value, Ros2SecurityError> {
    let identity = TlsIdentity::in_folder(folder, principal);
    Ok(json!({
        "mode": "client",
        "connect": { "endpoints": [connect.as_str()] },
        "scouting": {
            "multicast": { "enabled": false },
            "gossip": { "enabled": false },
        },
        "transport": {
            "link": {
                "protocols": ["tls"],
                "tls": tls_section(&identity)?,
            },
        },
    }))
}

/// The file [`write_session_configs`] writes for `principal` in credentials folder `folder`.
pub fn session_config_file(folder: &Path, principal: &str) -> PathBuf {
    folder
        .join(SESSION_CONFIG_DIR)
        .join(format!("{principal}.json5"))
}

/// Writes [`session_config`] of each robot `0..n_robots` and of the recorder into
/// `folder/ros2/<principal>.json5` (owner-only), with absolute paths to the certificates; returns
/// the files. A node on another host needs its principal's files there and the paths changed.
pub fn write_session_configs(
    folder: &Path,
    connect: &Endpoint,
    n_robots: usize,
) -> Result<Vec<PathBuf>, Ros2SecurityError> {
    let folder = std::path::absolute(folder)
        .map_err(PathIoError::of("finding the absolute path of", folder))?;
    let dir = folder.join(SESSION_CONFIG_DIR);
    std::fs::create_dir_all(&dir).map_err(PathIoError::of("creating", &dir))?;
    let principals = (0..n_robots)
        .map(robot_user)
        .chain(std::iter::once(RECORDER_USER.to_string()));
    let mut written = Vec::new();
    for principal in principals {
        let config = session_config(&folder, &principal, connect)?;
        let path = session_config_file(&folder, &principal);
        let text = serde_json::to_string_pretty(&config).unwrap_or_default() + "\n";
        write_private(&path, text.as_bytes())?;
        written.push(path);
    }
    Ok(written)
}

fn write_private(path: &Path, bytes: &[u8]) -> Result<(), Ros2SecurityError> {
    use std::io::Write as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let io = |source| Ros2SecurityError::from(PathIoError::of("writing", path)(source));
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .map_err(io)?;
    file.write_all(bytes).map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn access() -> Ros2Access {
        Ros2Access {
            folder: PathBuf::from("/c"),
            run: RunId::new("r").expect("a run id"),
            n_robots: 2,
            domain_id: 7,
        }
    }

    fn keys_of(rules: &Value, id: &str) -> Vec<String> {
        rules["rules"]
            .as_array()
            .expect("rules")
            .iter()
            .find(|r| r["id"] == id)
            .unwrap_or_else(|| panic!("no rule {id}"))["key_exprs"]
            .as_array()
            .expect("keys")
            .iter()
            .map(|k| k.as_str().expect("a key").to_owned())
            .collect()
    }

    #[test]
    fn a_robot_publishes_its_cmd_vel_only_and_reads_its_sensors_and_the_team_s_tf() {
        let rules = access().rules();
        assert_eq!(
            keys_of(&rules, "robot-1-incoming-publications"),
            ["7/robot_1/cmd_vel/**"]
        );
        let reads = keys_of(&rules, "robot-1-outgoing-publications");
        for key in ["7/robot_1/scan/**", "7/robot_1/odom/**", "7/tf/**"] {
            assert!(reads.contains(&key.to_owned()), "{reads:?}");
        }
        assert!(!reads.iter().any(|k| k.contains("robot_0")), "{reads:?}");
        assert_eq!(rules["default_permission"], "deny");
        let subjects = rules["subjects"].as_array().expect("subjects");
        assert!(
            subjects
                .iter()
                .any(|s| s["id"] == "robot-1" && s["cert_common_names"] == json!(["robot-1"]))
        );
    }

    #[test]
    fn the_recorder_reads_the_domain_and_publishes_nothing() {
        let rules = access().rules();
        assert_eq!(keys_of(&rules, "recorder-outgoing-publications"), ["7/**"]);
        let ingress_puts = rules["rules"]
            .as_array()
            .expect("rules")
            .iter()
            .filter(|r| {
                r["id"]
                    .as_str()
                    .is_some_and(|id| id.starts_with("recorder"))
            })
            .filter(|r| r["messages"] == json!(["put"]) && r["flows"] == json!(["ingress"]))
            .count();
        assert_eq!(ingress_puts, 0);
    }

    #[test]
    fn zenoh_takes_the_router_rules_and_a_node_s_session_configuration() {
        let mut config = ::zenoh::Config::default();
        set(&mut config, "access_control", &access().rules()).expect("the rules");
        let endpoint = Endpoint::parse("tls/127.0.0.1:7447").expect("an endpoint");
        let session = session_config(Path::new("/c"), "robot-0", &endpoint).expect("a config");
        assert_eq!(session["transport"]["link"]["protocols"], json!(["tls"]));
        assert_eq!(
            session["transport"]["link"]["tls"]["connect_certificate"],
            "/c/robot-0.pem"
        );
        ::zenoh::Config::from_json5(&session.to_string()).expect("zenoh reads it");
    }
}
