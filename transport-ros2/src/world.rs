//! The world as a team of ROS 2 robots ([`Ros2WorldLink`]): each simulated robot publishes its
//! LaserScan and Odometry and takes Twists on its `cmd_vel`, exactly as a real robot's driver
//! does, so that ROS 2 agents (`formation-agent --transport ros2`) and any ROS 2 tool can drive
//! and watch the team. The world is the Zenoh router they connect to.
//!
//! Behind the [`WorldLink`] seam the exchange still runs its protocol: admission, episodes,
//! lockstep. This link translates it from what the ROS graph says:
//! - **Who drives robot i** is the node whose publisher on `/robot_<i>/cmd_vel` appears in the
//!   graph (its `MP` liveliness token). The link greets for it (with a proof of the launch
//!   secret, which it holds), so the exchange admits one driver per robot as for other
//!   transports; Twists from any other publisher on that topic (told apart by the GID in their
//!   attachments) are ignored. When the token goes, the driver is *unreachable*: its session
//!   may have dropped (a link reset, a lease that ran out), and Zenoh reconnects it by itself,
//!   declaring the same token again. The link waits [`RECONNECT_GRACE`] (5 s, as for the Zenoh
//!   transport) for it, and lockstep holds the tick meanwhile
//!   ([`WorldLink::agent_reconnecting`]); a driver that comes back gets the last tick's odometry
//!   and scan again (the drop may have lost them, or its Twist) and answers as it would have,
//!   and one that does not is reported dead when the grace ends.
//! - **Episodes:** ROS 2 agents need no episode handshake (their decision keeps no state across
//!   scans), so a begin-episode request is answered "ready" at once; a swap is refused (restart
//!   the agent with another model instead).
//! - **Which tick a Twist answers:** every tick's scans carry a stamp on a simulated clock that
//!   never goes back (each episode starts a second after the last stamp of the previous one),
//!   and a ROS 2 agent stamps each Twist's attachment with the stamp of the scan it answers.
//!   A Twist whose stamp is no tick's of the current episode (e.g. an agent's brake on stale
//!   input) is not a command for any tick; the exchange's watchdog brakes robots without one.
//! - **The goal** is published on the team's goal topics before each tick's sensors
//!   ([`super::TeamTopics`]). Every message is express and of one priority, so an agent receives
//!   a tick's goal and odometry before its scan.
//!
//! - **Odometry** is what a real base's driver reports from its wheel encoders: the pose, and a
//!   twist from the wheel speeds of the last step (`odometry_message`). No TF is published:
//!   the odometry's frames name it (`robot_<i>/odom` to `robot_<i>/base_link`).
//!
//! - **Recording from outside** (`formation record --connect --transport ros2`): the world's
//!   session also carries the run's record channel and liveliness token under `formation/<run>/`
//!   ([`Ros2WorldLink::record_feed`], the Zenoh team's [`formation_transport_zenoh::ZenohRecordFeed`]), keys
//!   outside rmw_zenoh's layout that ROS 2 tools do not see. The ROS 2 topics alone could not
//!   give the file `--record` writes: a Twist is not the wheel speeds bit for bit, and the
//!   replay channel's inputs, watchdog outcomes and the run's metadata are on no topic. A ROS 2
//!   team has no logins (as ROS 2 without SROS2), so the recorder needs none; on a `tls/`
//!   endpoint it shows the recorder's certificate, which reads and publishes nothing
//!   ([`super::secure`]).
//!
//! A Twist becomes wheel speeds as `diff_drive_controller` makes them
//! ([`formation_ros2::wheels_from_twist`]), which is the inverse of the agent's conversion only up
//! to rounding: a ROS 2 team's trajectories match in-process ones to about 1e-15 m per step, not
//! bit for bit (a Twist carries v and ω, not the wheel speeds).

use std::collections::{HashMap, VecDeque};
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken as RunToken;
use ::zenoh::pubsub::Subscriber;
use ::zenoh::sample::SampleKind;
use formation_proto::wire::{
    AgentStatus, AgentTimings, CmdMsg, CmdStatus, ControlRequest, RunId, ScanMsg, SwapReply,
    SwapRequest, Welcome,
};
use formation_proto::{Pose, WheelCmd};
use formation_ros2::liveliness::domain_wildcard;
use formation_ros2::team;
use formation_ros2::{
    EntityKind, Float64, LaserScan, LivelinessToken, Namespace, NodeName, Odometry, Qos, TfMessage,
    Time, TopicName, Twist, wheels_from_twist,
};
use formation_runtime::auth::LaunchSecret;

use super::node::{Delivery, Node, NodeError, RosPublisher, RosSubscription};
use super::{Ros2Team, TeamTopics};
use formation_runtime::link::{
    Hello, PublishesOdometry, WorldLink, WorldLinkError, WorldResult, check_robot_index,
};
use formation_runtime::reconnect::ReconnectGrace;
use formation_transport_zenoh::ZenohError;
use formation_transport_zenoh::{Bell, Endpoint, RECONNECT_GRACE, SignalWatch};

/// Stamps of the current episode's ticks kept per robot, to match Twists to ticks.
const STAMPS_KEPT: usize = 64;
/// Twists queued per robot: far more than a tick produces.
const TWIST_QUEUE: usize = 64;
/// The model id the exchange logs for a ROS 2 agent's commands.
const ROS2_MODEL_ID: &str = "ros2";
/// The fixed frame every robot is placed in on `/tf`.
pub use formation_ros2::team::WORLD_FRAME;
/// How often `/tf_static` is sent again \[ns of the simulated clock\]: this link does not
/// implement transient-local durability, so a viewer that joins later gets the static frames
/// within a second instead of at once.
const TF_STATIC_PERIOD_NS: i64 = 1_000_000_000;

fn node_error(e: NodeError) -> WorldLinkError {
    ZenohError::Refused {
        action: "set up the ROS 2 team".into(),
        detail: formation_runtime::agent::error_chain(&e),
    }
    .into()
}

/// A driver of a robot as the ROS graph shows it: the node publishing on its `cmd_vel`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Driver {
    /// Stands in for the pid in the exchange's bookkeeping (ROS 2 does not tell pids).
    pid: u32,
    /// The publisher's GID: only its Twists count.
    gid: [u8; 16],
    /// `<namespace>/<name>` of its node, for the logs.
    node: String,
}

/// A Twist as it arrived.
#[derive(Debug, Clone, Copy)]
struct ReceivedTwist {
    /// The source timestamp of its attachment: the stamp of the scan it answers.
    stamp: i64,
    /// Its publisher's GID.
    gid: [u8; 16],
    twist: Twist,
    /// When it arrived ([`formation_proto::wire::wall_clock_ns`]).
    arrived_ns: u64,
}

/// What the liveliness subscriber and the Twist subscribers fill.
#[derive(Debug)]
struct Graph {
    /// Live `cmd_vel` publishers per robot, by token key.
    drivers: Vec<HashMap<String, Driver>>,
    /// Drivers that appeared and were not greeted for yet.
    new_drivers: Vec<VecDeque<Driver>>,
    /// `(robot, pid)` of drivers whose token went and did not come back within
    /// [`RECONNECT_GRACE`], not yet reported.
    gone: Vec<(usize, u32)>,
    /// Drivers whose token went, by token key, with their robot: unreachable (their session
    /// dropped, and Zenoh reconnects it by itself), back when the same token comes again,
    /// counted gone once [`RECONNECT_GRACE`] has passed.
    vanished: ReconnectGrace<String, (usize, Driver)>,
    /// Robots whose driver came back within the grace, whose last tick's odometry and scan are
    /// not yet sent again.
    returned: Vec<usize>,
    /// Twists received per robot.
    twists: Vec<VecDeque<ReceivedTwist>>,
    next_pid: u32,
}

/// One simulated robot's ROS 2 side.
struct RobotPorts {
    _node: Node,
    scan: RosPublisher<LaserScan>,
    odom: RosPublisher<Odometry>,
    tf: RosPublisher<TfMessage>,
    tf_static: RosPublisher<TfMessage>,
    /// Stamp of the last `/tf_static` sent.
    tf_static_sent: Option<i64>,
    _cmd_vel: RosSubscription,
    /// The pose and wheel speeds to publish with the next scan (given by
    /// [`PublishesOdometry::publish_odometry`]).
    odometry: Option<(Pose, WheelCmd)>,
    /// Stamp (ns) → (generation, tick) of this episode's latest ticks.
    stamps: VecDeque<(i64, u64, u64)>,
    /// The last tick's stamp, odometry (if one went with it) and scan, sent again to a driver
    /// that comes back from a drop (which may have lost them).
    last_sent: Option<(i64, Option<Odometry>, LaserScan)>,
}

/// The world's ROS 2 link: a Zenoh router, one node per simulated robot, the team's goal topics.
pub struct Ros2WorldLink {
    session: Arc<::zenoh::Session>,
    run: RunId,
    secret: LaunchSecret,
    team: Ros2Team,
    bell: Arc<Bell>,
    graph: Arc<Mutex<Graph>>,
    robots: Vec<RobotPorts>,
    _goal_node: Node,
    goal: [RosPublisher<Float64>; 3],
    /// (generation, tick) whose goal was published last.
    goal_published: Option<(u64, u64)>,
    /// Admitted driver per robot (by the hello's nonce until the incarnation opens).
    admitted: Vec<Option<Driver>>,
    pending: Vec<HashMap<u64, Driver>>,
    statuses: Vec<VecDeque<AgentStatus>>,
    /// The simulated clock: stamp of tick 0 of the current episode, and the generation.
    episode: Option<(u64, i64)>,
    last_stamp: i64,
    _graph_watch: Subscriber<()>,
    /// The world's liveliness token (`formation/<run>/world`), which a remote recorder watches.
    _token: RunToken,
    _signals: SignalWatch,
}

fn lock(graph: &Mutex<Graph>) -> MutexGuard<'_, Graph> {
    graph.lock().unwrap_or_else(|e| e.into_inner())
}

/// Opens the world's session: a Zenoh router listening on `listen`; on a `tls/` endpoint with
/// the certificates and rules of credentials folder `credentials` ([`super::secure`]).
fn open_router(
    listen: &Endpoint,
    run: &RunId,
    team: &Ros2Team,
    credentials: Option<&Path>,
) -> Result<Arc<::zenoh::Session>, WorldLinkError> {
    let configure = |detail| ZenohError::Refused {
        action: format!("configure a router on {listen}"),
        detail,
    };
    let config = if listen.is_tls() {
        secure_router_config(listen, run, team, credentials).map_err(configure)?
    } else {
        formation_transport_zenoh::world_config(listen, None).map_err(configure)?
    };
    Ok(Arc::new(formation_transport_zenoh::open(config).map_err(
        |detail| ZenohError::Refused {
            action: format!("listen on {listen} (is the port free?)"),
            detail,
        },
    )?))
}

/// The router's configuration on a `tls/` endpoint: the world's certificate, and rules that name
/// each node by its certificate ([`super::secure::Ros2Access`]).
#[cfg(feature = "tls")]
fn secure_router_config(
    listen: &Endpoint,
    run: &RunId,
    team: &Ros2Team,
    credentials: Option<&Path>,
) -> Result<::zenoh::Config, String> {
    let folder = credentials.ok_or_else(|| {
        format!(
            "{listen} needs the team's certificates: pass --credentials DIR, a folder written by \
             `formation credentials --tls`"
        )
    })?;
    let mut config = formation_transport_zenoh::base_config("router")?;
    config
        .insert_json5("listen/endpoints", &format!("[{:?}]", listen.as_str()))
        .map_err(|e| format!("listening on {listen}: {e}"))?;
    let access = super::secure::Ros2Access {
        folder: folder.to_path_buf(),
        run: run.clone(),
        n_robots: team.n_robots,
        domain_id: team.domain_id,
    };
    access.apply(&mut config).map_err(|e| e.to_string())?;
    Ok(config)
}

/// No TLS in this build ([`Endpoint::parse`] refuses `tls/` already).
#[cfg(not(feature = "tls"))]
fn secure_router_config(
    _listen: &Endpoint,
    _run: &RunId,
    _team: &Ros2Team,
    _credentials: Option<&Path>,
) -> Result<::zenoh::Config, String> {
    Err("this build has no TLS: build with `--features tls`".into())
}

impl RobotPorts {
    /// Declares simulated robot `robot`'s node in `team`'s domain with its publishers (scan and
    /// odometry delivered as `sensors`, `/tf`, `/tf_static`) and its `cmd_vel` subscription,
    /// whose Twists go to `graph` and ring `bell`.
    fn declare(
        session: &Arc<::zenoh::Session>,
        team: &Ros2Team,
        robot: usize,
        sensors: Delivery,
        graph: &Arc<Mutex<Graph>>,
        bell: &Arc<Bell>,
    ) -> WorldResult<RobotPorts> {
        let topics = TeamTopics::robot(robot);
        let namespace =
            Namespace::new(&format!("/robot_{robot}")).map_err(|e| ZenohError::Refused {
                action: "name the robot's namespace".into(),
                detail: e.to_string(),
            })?;
        let node = Node::new(
            Arc::clone(session),
            team.domain_id,
            namespace,
            NodeName::new("formation_sim").expect("a valid node name"),
            robot as u64 + 1,
        )
        .map_err(node_error)?;
        let scan = node
            .publisher::<LaserScan>(&topics.scan, Qos::SENSOR_DATA, sensors)
            .map_err(node_error)?;
        let odom = node
            .publisher::<Odometry>(&topics.odometry, Qos::ROS_DEFAULT, sensors)
            .map_err(node_error)?;
        let tf = node
            .publisher::<TfMessage>(&tf_topic("/tf"), Qos::ROS_DEFAULT, sensors)
            .map_err(node_error)?;
        let tf_static = node
            .publisher::<TfMessage>(
                &tf_topic("/tf_static"),
                Qos::ROS_DEFAULT,
                Delivery::Reliable,
            )
            .map_err(node_error)?;
        let cmd_vel = subscribe_cmd_vel(&node, &topics.cmd_vel, robot, graph, bell)?;
        Ok(RobotPorts {
            _node: node,
            scan,
            odom,
            tf,
            tf_static,
            tf_static_sent: None,
            _cmd_vel: cmd_vel,
            odometry: None,
            stamps: VecDeque::with_capacity(STAMPS_KEPT),
            last_sent: None,
        })
    }
}

/// Subscribes `node` to robot `robot`'s `cmd_vel` `topic`: each Twist is queued in `graph`
/// (at most [`TWIST_QUEUE`], the oldest goes) with its stamp, publisher and arrival, and rings
/// `bell`; unusable samples are logged.
fn subscribe_cmd_vel(
    node: &Node,
    topic: &TopicName,
    robot: usize,
    graph: &Arc<Mutex<Graph>>,
    bell: &Arc<Bell>,
) -> WorldResult<RosSubscription> {
    let graph = Arc::clone(graph);
    let bell = Arc::clone(bell);
    node.subscription::<Twist>(topic, Qos::ROS_DEFAULT, move |sample| match sample {
        Ok(received) => {
            let mut graph = lock(&graph);
            let queue = &mut graph.twists[robot];
            if queue.len() == TWIST_QUEUE {
                queue.pop_front();
            }
            queue.push_back(ReceivedTwist {
                stamp: received.attachment.source_timestamp_ns,
                gid: received.attachment.source_gid,
                twist: received.message,
                arrived_ns: formation_proto::wire::wall_clock_ns(),
            });
            drop(graph);
            bell.ring();
        }
        Err(e) => tracing::warn!("robot {robot}: ignoring a cmd_vel sample: {e}"),
    })
    .map_err(node_error)
}

/// Declares the team's goal node in ROS domain `domain_id` and its three goal publishers
/// ([`TeamTopics::goal`]).
fn declare_goal(
    session: &Arc<::zenoh::Session>,
    domain_id: u32,
) -> Result<(Node, [RosPublisher<Float64>; 3]), WorldLinkError> {
    let goal_node = Node::new(
        Arc::clone(session),
        domain_id,
        Namespace::new("/formation").expect("a valid namespace"),
        NodeName::new("goal").expect("a valid node name"),
        0,
    )
    .map_err(node_error)?;
    let goal_topics = TeamTopics::goal();
    let goal_publisher = |topic| {
        goal_node
            .publisher::<Float64>(topic, Qos::ROS_DEFAULT, Delivery::Reliable)
            .map_err(node_error)
    };
    let goal = [
        goal_publisher(&goal_topics[0])?,
        goal_publisher(&goal_topics[1])?,
        goal_publisher(&goal_topics[2])?,
    ];
    Ok((goal_node, goal))
}

/// Notes in `graph` what liveliness token `key` (parsed as `token`, announcing a `cmd_vel`
/// publisher of robot `robot`) says: a new driver when it comes, a gone one when it goes.
/// Returns false when nothing changed (a token already known came again).
fn note_driver_token(
    graph: &mut Graph,
    robot: usize,
    key: &str,
    token: &LivelinessToken,
    kind: SampleKind,
) -> bool {
    match kind {
        SampleKind::Put => {
            if graph.drivers[robot].contains_key(key) {
                return false;
            }
            if let Some((_, driver)) = graph.vanished.came_back(&key.to_owned(), Instant::now()) {
                graph.drivers[robot].insert(key.to_owned(), driver);
                graph.returned.push(robot);
                return true;
            }
            graph.next_pid = graph.next_pid.wrapping_add(1).max(1);
            let driver = Driver {
                pid: graph.next_pid,
                gid: token.gid(),
                node: format!(
                    "{}/{}",
                    token.node.namespace.as_str().trim_end_matches('/'),
                    token.node.name.as_str()
                ),
            };
            graph.drivers[robot].insert(key.to_owned(), driver.clone());
            graph.new_drivers[robot].push_back(driver);
        }
        SampleKind::Delete => {
            if let Some(driver) = graph.drivers[robot].remove(key) {
                let who = format!("robot {robot}: ROS 2 node {}", driver.node);
                graph.vanished.went(
                    key.to_owned(),
                    (robot, driver),
                    who,
                    "its cmd_vel publisher's token went",
                    Instant::now(),
                );
            }
        }
    }
    true
}

/// Watches the ROS graph of domain `domain_id` (with history) for the drivers of the team's
/// `n` robots: each change is noted in `graph` ([`note_driver_token`]) and rings `bell`.
fn watch_graph(
    session: &::zenoh::Session,
    domain_id: u32,
    n: usize,
    graph: &Arc<Mutex<Graph>>,
    bell: &Arc<Bell>,
) -> Result<Subscriber<()>, WorldLinkError> {
    let graph = Arc::clone(graph);
    let bell = Arc::clone(bell);
    formation_transport_zenoh::watch_liveliness(
        session,
        domain_wildcard(domain_id),
        move |sample| {
            let key = sample.key_expr().as_str();
            let Ok(token) = LivelinessToken::parse(key) else {
                return;
            };
            let Some(robot) = driven_robot(&token, n) else {
                return;
            };
            let mut graph = lock(&graph);
            if !note_driver_token(&mut graph, robot, key, &token, sample.kind()) {
                return;
            }
            drop(graph);
            bell.ring();
        },
    )
    .map_err(|e| {
        ZenohError::Refused {
            action: "watch the ROS graph".into(),
            detail: e.to_string(),
        }
        .into()
    })
}

impl Ros2WorldLink {
    /// Listens on `listen` as a Zenoh router and sets up `team`'s robots for run `run`.
    pub fn create(
        run: &RunId,
        team: Ros2Team,
        listen: &Endpoint,
        secret: LaunchSecret,
    ) -> WorldResult<Ros2WorldLink> {
        Self::create_with_credentials(run, team, listen, secret, None)
    }

    /// [`Ros2WorldLink::create`]; a `tls/` endpoint takes the certificates of credentials
    /// folder `credentials` (`formation credentials --tls`), and admits only nodes with a
    /// certificate of its authority, each to its own topics ([`super::secure`]).
    pub fn create_with_credentials(
        run: &RunId,
        team: Ros2Team,
        listen: &Endpoint,
        secret: LaunchSecret,
        credentials: Option<&Path>,
    ) -> WorldResult<Ros2WorldLink> {
        let session = open_router(listen, run, &team, credentials)?;
        let bell = Arc::new(Bell::default());
        let n = team.n_robots;
        let graph = Arc::new(Mutex::new(Graph {
            drivers: vec![HashMap::new(); n],
            new_drivers: vec![VecDeque::new(); n],
            gone: Vec::new(),
            vanished: ReconnectGrace::new(RECONNECT_GRACE),
            returned: Vec::new(),
            twists: vec![VecDeque::new(); n],
            next_pid: 0,
        }));
        let sensors = if team.lossless {
            Delivery::Reliable
        } else {
            Delivery::Realtime
        };
        let mut robots = Vec::with_capacity(n);
        for robot in 0..n {
            robots.push(RobotPorts::declare(
                &session, &team, robot, sensors, &graph, &bell,
            )?);
        }
        let (goal_node, goal) = declare_goal(&session, team.domain_id)?;
        let graph_watch = watch_graph(&session, team.domain_id, n, &graph, &bell)?;
        let signals = SignalWatch::start(Arc::clone(&bell)).map_err(|e| ZenohError::Refused {
            action: "watch for termination signals".into(),
            detail: e.to_string(),
        })?;
        let token = session
            .liveliness()
            .declare_token(formation_transport_zenoh::keys::world_token(run))
            .wait()
            .map_err(|e| ZenohError::Refused {
                action: "declare the world's liveliness token".into(),
                detail: e.to_string(),
            })?;
        Ok(Ros2WorldLink {
            session,
            run: run.clone(),
            secret,
            bell,
            graph,
            robots,
            _goal_node: goal_node,
            goal,
            goal_published: None,
            admitted: vec![None; n],
            pending: vec![HashMap::new(); n],
            statuses: vec![VecDeque::new(); n],
            episode: None,
            last_stamp: 0,
            team,
            _graph_watch: graph_watch,
            _token: token,
            _signals: signals,
        })
    }

    /// The run's record channel for remote recorders (`formation record --connect --transport
    /// ros2`), on this world's session: the Zenoh team's, keys and format alike.
    pub fn record_feed(&self) -> WorldResult<formation_transport_zenoh::ZenohRecordFeed> {
        formation_transport_zenoh::ZenohRecordFeed::declare(&self.session, &self.run)
    }

    /// The stamp \[ns\] of `msg`'s tick on the team's simulated clock, starting an episode's
    /// clock a second after the last stamp when its generation is new.
    fn stamp(&mut self, msg: &ScanMsg) -> i64 {
        let base = match self.episode {
            Some((generation, base)) if generation == msg.generation => base,
            _ => {
                let base = if self.last_stamp == 0 {
                    0
                } else {
                    (self.last_stamp / 1_000_000_000 + 1) * 1_000_000_000
                };
                self.episode = Some((msg.generation, base));
                for robot in &mut self.robots {
                    robot.stamps.clear();
                }
                base
            }
        };
        let stamp = base.saturating_add((msg.sim_time * 1e9).round() as i64);
        self.last_stamp = self.last_stamp.max(stamp);
        stamp
    }

    /// Sends the last tick's odometry and scan again to each robot whose driver came back from a
    /// drop, which may have lost them: in lockstep the tick is held for it, and it answers the
    /// scan (with the same stamp) as it would have.
    fn send_again_to_returned(&mut self) -> WorldResult {
        let returned = std::mem::take(&mut lock(&self.graph).returned);
        for robot in returned {
            let ports = &self.robots[robot];
            let Some((stamp, odometry, scan)) = &ports.last_sent else {
                continue;
            };
            if let Some(odometry) = odometry {
                ports.odom.publish(odometry, *stamp).map_err(node_error)?;
            }
            ports.scan.publish(scan, *stamp).map_err(node_error)?;
        }
        Ok(())
    }

    fn publish_goal(&mut self, msg: &ScanMsg, stamp: i64) -> WorldResult {
        if self.goal_published == Some((msg.generation, msg.tick)) {
            return Ok(());
        }
        for (publisher, data) in self.goal.iter().zip([msg.phi_star, msg.d_star, msg.v_star]) {
            publisher
                .publish(&Float64 { data }, stamp)
                .map_err(node_error)?;
        }
        self.goal_published = Some((msg.generation, msg.tick));
        Ok(())
    }
}

/// The robot whose `cmd_vel` a publisher token announces, if it is one of the team's.
fn driven_robot(token: &LivelinessToken, n_robots: usize) -> Option<usize> {
    if token.kind != EntityKind::Publisher {
        return None;
    }
    let endpoint = token.endpoint.as_ref()?;
    if endpoint.type_name != <Twist as formation_ros2::RosMessage>::DDS_TYPE_NAME {
        return None;
    }
    (0..n_robots).find(|&robot| TeamTopics::robot(robot).cmd_vel == endpoint.topic)
}

impl PublishesOdometry for Ros2WorldLink {
    fn publish_odometry(&mut self, robot: usize, pose: &Pose, wheels: WheelCmd) -> WorldResult {
        check_robot_index(robot, self.robots.len())?;
        self.robots[robot].odometry = Some((*pose, wheels));
        Ok(())
    }
}

impl WorldLink for Ros2WorldLink {
    fn n_robots(&self) -> usize {
        self.team.n_robots
    }

    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult {
        let drivers: Vec<Driver> = lock(&self.graph).new_drivers[robot].drain(..).collect();
        for driver in drivers {
            let nonce =
                formation_runtime::auth::fresh_nonce().map_err(|e| ZenohError::Refused {
                    action: "draw a nonce".into(),
                    detail: e.to_string(),
                })?;
            tracing::info!(
                "robot {robot}: ROS 2 node {} publishes on its cmd_vel",
                driver.node
            );
            let proof = self.secret.prove(&self.run, robot, driver.pid, nonce);
            let pid = driver.pid;
            self.pending[robot].insert(nonce, driver);
            sink(Hello { pid, nonce, proof });
        }
        Ok(())
    }

    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult {
        let driver = self.pending[robot].remove(&nonce);
        if let (Welcome::Refused(reason), Some(driver)) = (welcome, driver) {
            eprintln!(
                "formation-world: robot {robot}: ignoring the Twists of ROS 2 node {}: {reason}",
                driver.node
            );
        }
        Ok(())
    }

    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult {
        let Some(driver) = self.pending[robot].get(&incarnation).cloned() else {
            return Ok(());
        };
        lock(&self.graph).twists[robot].clear();
        self.statuses[robot].push_back(AgentStatus::Hello {
            pid: driver.pid,
            model_id: format!("{ROS2_MODEL_ID}:{}", driver.node),
        });
        self.admitted[robot] = Some(driver);
        self.bell.ring();
        Ok(())
    }

    fn close_incarnation(&mut self, robot: usize) {
        self.admitted[robot] = None;
        self.statuses[robot].clear();
    }

    fn odometry(&mut self) -> Option<&mut dyn PublishesOdometry> {
        Some(self)
    }

    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult {
        let stamp = self.stamp(msg);
        self.publish_goal(msg, stamp)?;
        let ports = &mut self.robots[robot];
        let mut sent_odometry = None;
        if let Some((pose, wheels)) = ports.odometry.take() {
            let odometry = odometry_message(
                robot,
                Time::from_nanos(stamp),
                &pose,
                msg.heading,
                wheels,
                self.team.wheel_separation,
            );
            ports.odom.publish(&odometry, stamp).map_err(node_error)?;
            sent_odometry = Some(odometry);
            ports
                .tf
                .publish(&tf_message(robot, Time::from_nanos(stamp), &pose), stamp)
                .map_err(node_error)?;
            let due = ports.tf_static_sent.is_none_or(|sent| {
                stamp < sent || stamp.saturating_sub(sent) >= TF_STATIC_PERIOD_NS
            });
            if due {
                ports
                    .tf_static
                    .publish(&static_tf_message(robot, Time::from_nanos(stamp)), stamp)
                    .map_err(node_error)?;
                ports.tf_static_sent = Some(stamp);
            }
        }
        let beams = msg.n_beams as usize;
        let scan = team::laser_scan_message(
            robot,
            Time::from_nanos(stamp),
            &msg.ranges[..beams],
            self.team.max_range,
        );
        ports.scan.publish(&scan, stamp).map_err(node_error)?;
        ports.last_sent = Some((stamp, sent_odometry, scan));
        if ports.stamps.len() == STAMPS_KEPT {
            ports.stamps.pop_front();
        }
        ports.stamps.push_back((stamp, msg.generation, msg.tick));
        Ok(())
    }

    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult {
        if self.admitted[robot].is_none() {
            return Ok(());
        }
        match request {
            ControlRequest::BeginEpisode { generation, .. } => {
                self.statuses[robot].push_back(AgentStatus::Ready {
                    generation: *generation,
                    model_id: ROS2_MODEL_ID.into(),
                });
            }
            ControlRequest::SwapModel { request_id, .. } => {
                self.statuses[robot].push_back(AgentStatus::SwapRefused {
                    request_id: *request_id,
                    reason: "a ROS 2 agent cannot be swapped through the world; restart it with \
                             the other --model"
                        .into(),
                });
            }
            ControlRequest::Shutdown => {}
        }
        self.bell.ring();
        Ok(())
    }

    fn wait(&mut self, timeout: Duration) -> WorldResult {
        self.bell.world_wait(timeout)
    }

    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult {
        let twists: Vec<_> = lock(&self.graph).twists[robot].drain(..).collect();
        let Some(driver) = &self.admitted[robot] else {
            return Ok(());
        };
        let ports = &self.robots[robot];
        for ReceivedTwist {
            stamp,
            gid,
            twist,
            arrived_ns,
        } in twists
        {
            if gid != driver.gid {
                continue;
            }
            let Some(&(_, generation, tick)) = ports.stamps.iter().find(|(s, ..)| *s == stamp)
            else {
                continue;
            };
            let (left, right) = wheels_from_twist(&twist, self.team.wheel_separation);
            let timings = AgentTimings {
                received_wall_ns: arrived_ns,
                ..AgentTimings::default()
            };
            let cmd = CmdMsg::new(
                generation,
                tick,
                WheelCmd { left, right },
                ROS2_MODEL_ID,
                timings,
                CmdStatus::OK,
            )?;
            sink(CmdMsg {
                published_wall_ns: arrived_ns,
                ..cmd
            });
        }
        Ok(())
    }

    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult {
        for status in self.statuses[robot].drain(..) {
            sink(status);
        }
        Ok(())
    }

    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        Ok(lock(&self.graph).drivers[robot]
            .values()
            .any(|d| d.pid == pid))
    }

    fn agent_reconnecting(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        Ok(lock(&self.graph)
            .vanished
            .any(|_, (r, driver)| *r == robot && driver.pid == pid))
    }

    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError> {
        self.send_again_to_returned()?;
        let mut graph = lock(&self.graph);
        for (_, (robot, driver)) in graph.vanished.expire(Instant::now()) {
            graph.gone.push((robot, driver.pid));
        }
        Ok(std::mem::take(&mut graph.gone))
    }

    fn drain_swap_requests(&mut self, _sink: &mut dyn FnMut(SwapRequest)) -> WorldResult {
        Ok(())
    }

    fn publish_swap_reply(&mut self, _reply: &SwapReply) -> WorldResult {
        Ok(())
    }
}

impl Drop for Ros2WorldLink {
    fn drop(&mut self) {
        // Undeclare everything before the session goes, so agents see the team leave.
        self.robots.clear();
        let _ = self.session.close().wait();
    }
}

/// `/tf` and `/tf_static` (absolute: one TF tree for the whole team, as ROS 2 tools expect).
fn tf_topic(name: &str) -> TopicName {
    TopicName::new(name).expect("a valid ROS topic name")
}

/// Robot `robot`'s `/tf` at `stamp` ([`formation_ros2::team::tf_message`]).
fn tf_message(robot: usize, stamp: Time, pose: &Pose) -> TfMessage {
    team::tf_message(robot, stamp, pose.x, pose.y, pose.theta)
}

/// Robot `robot`'s `/tf_static` ([`formation_ros2::team::static_tf_message`]).
fn static_tf_message(robot: usize, stamp: Time) -> TfMessage {
    team::static_tf_message(robot, stamp)
}

/// Robot `robot`'s Odometry at `stamp` ([`formation_ros2::team::odometry_message`]): its pose
/// (`heading` as the orientation, what its compass reads) and the twist of the wheel speeds it ran
/// over the last step, as wheel encoders give it.
fn odometry_message(
    robot: usize,
    stamp: Time,
    pose: &Pose,
    heading: f64,
    wheels: WheelCmd,
    wheel_separation: f64,
) -> Odometry {
    let wheels = team::Wheels {
        left: wheels.left,
        right: wheels.right,
        separation: wheel_separation,
    };
    team::odometry_message(robot, stamp, (pose.x, pose.y), heading, wheels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_ros2::yaw_from_quaternion;

    #[test]
    fn tf_places_each_robot_in_the_world_and_its_laser_on_it() {
        let pose = Pose {
            x: 1.5,
            y: -2.0,
            theta: 2.5,
        };
        let stamp = Time::from_nanos(1_250_000_000);
        let tf = tf_message(3, stamp, &pose);
        assert_eq!(tf.transforms.len(), 1);
        let edge = &tf.transforms[0];
        assert_eq!(
            (edge.header.frame_id.as_str(), edge.child_frame_id.as_str()),
            ("world", "robot_3/base_link")
        );
        assert_eq!(edge.header.stamp, stamp);
        let t = edge.transform;
        assert_eq!(
            (t.translation.x, t.translation.y, t.translation.z),
            (1.5, -2.0, 0.0)
        );
        let yaw = yaw_from_quaternion(&t.rotation).unwrap();
        assert!((yaw - 2.5).abs() < 1e-12, "{yaw}");
        let frames: Vec<(String, String)> = static_tf_message(3, stamp)
            .transforms
            .into_iter()
            .map(|e| (e.header.frame_id, e.child_frame_id))
            .collect();
        assert_eq!(
            frames,
            [
                ("world".to_owned(), "robot_3/odom".to_owned()),
                ("robot_3/base_link".to_owned(), "robot_3/laser".to_owned())
            ]
        );
    }

    #[test]
    fn odometry_twist_is_the_wheel_encoders_and_the_pose_is_the_robots() {
        let pose = Pose {
            x: 1.5,
            y: -2.0,
            theta: 0.3,
        };
        let wheels = WheelCmd {
            left: 0.4,
            right: 0.6,
        };
        let odometry =
            odometry_message(7, Time::from_nanos(2_050_000_000), &pose, 0.3, wheels, 0.4);
        assert_eq!(odometry.header.frame_id, "robot_7/odom");
        assert_eq!(odometry.child_frame_id, "robot_7/base_link");
        assert_eq!(odometry.header.stamp, Time::from_nanos(2_050_000_000));
        assert_eq!(
            (odometry.pose.position.x, odometry.pose.position.y),
            (1.5, -2.0)
        );
        assert!(
            (yaw_from_quaternion(&odometry.pose.orientation).expect("a unit quaternion") - 0.3)
                .abs()
                < 1e-12
        );
        // v = (right + left) / 2, omega = (right - left) / separation, as the agent's inverse.
        assert!((odometry.twist.linear.x - 0.5).abs() < 1e-12);
        assert!((odometry.twist.angular.z - 0.5).abs() < 1e-12);
        let (left, right) = wheels_from_twist(&odometry.twist, 0.4);
        assert!((left - 0.4).abs() < 1e-12 && (right - 0.6).abs() < 1e-12);
        let still = odometry_message(0, Time::from_nanos(0), &pose, 0.3, WheelCmd::BRAKE, 0.4);
        assert_eq!((still.twist.linear.x, still.twist.angular.z), (0.0, 0.0));
    }
}
