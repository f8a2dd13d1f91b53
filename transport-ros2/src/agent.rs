//! A ROS 2 agent ([`run_agent`]): one robot's decision maker as a ROS 2 node on the robot's
//! rmw_zenoh router, with no ROS installation. It subscribes to the robot's LaserScan, an
//! orientation (`sensor_msgs/Imu` or `nav_msgs/Odometry`) and, where they are not fixed, the
//! goal topics (`std_msgs/Float64`), and publishes `geometry_msgs/Twist` on `cmd_vel`.
//!
//! It runs on the runtime's agent loop ([`AgentLoop`]), as the agents of every other transport
//! do, over [`RobotLink`]: the robot as an [`AgentLink`]. A robot runs free of any world, so the
//! link is the world's stand-in, and this is all that differs:
//! - one episode, begun by the link as the loop starts (the model's ring, the robot's wheel
//!   limits), which lasts until the agent stops; no swap, no shutdown, no world to lose;
//! - each LaserScan becomes the loop's scan once the [`Decider`] has it on the model's ring with
//!   a fresh heading and the goal, and each command the loop answers becomes a Twist stamped
//!   with that scan's stamp; what cannot be decided on brakes the robot with its reason;
//! - the link wakes the loop at least every [`LOOK_EVERY`], to brake when the inputs go stale.
//!
//! It stops on SIGINT/SIGTERM, or when its launcher goes (the `stop` flag), and publishes one
//! zero Twist before it goes. If it dies without one, the robot's own `cmd_vel` timeout brakes it
//! (ros2_controllers' diff_drive_controller: 0.5 s). A router that goes away mid-run is waited
//! for (Zenoh reconnects by itself); meanwhile the scans stop and the robot is braked.
//!
//! The first scans are checked against the scan the agent expects ([`ExpectedScan`]: its robot
//! profile's LIDAR, else the ring its model was trained on): a beam count, a range or a rate
//! that differs is named in one warning ([`ScanCheck`]), and the scans are resampled onto the
//! model's ring as always.

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use formation_proto::wire::{AgentStatus, CmdMsg, CmdStatus, ControlRequest, ScanMsg};
use formation_proto::{LidarSpec, WheelLimits};
use formation_ros2::convert::OrientationError;
use formation_ros2::{
    Float64, Imu, LaserScan, Namespace, NodeName, Odometry, Qos, RingContract, TopicName, Twist,
};

use super::decider::{Answer, Decider, DeciderSettings, GoalValue, Inputs};
use super::node::{
    Delivery, InputError, Node, NodeError, Received, RosPublisher, RosSubscription, system_time_ns,
};
use formation_runtime::agent::{AgentError, AgentExit, AgentLoop, PilotMaker};
use formation_runtime::link::{AgentLink, AgentLinkError, TransportCrateError, Wake};
use formation_transport_zenoh::{Bell, Endpoint, SignalWatch};

/// Which message carries the robot's orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OrientationKind {
    /// `sensor_msgs/msg/Imu` (its orientation must be filled: covariance\[0\] ≠ −1).
    Imu,
    /// `nav_msgs/msg/Odometry` (the pose's orientation).
    Odometry,
}

/// Everything a ROS 2 agent is told.
#[derive(Debug, Clone)]
pub struct Ros2AgentSettings {
    /// The router to connect to.
    pub connect: Endpoint,
    /// How long to wait for it.
    pub connect_timeout: Duration,
    /// ROS domain id.
    pub domain_id: u32,
    /// The node's namespace.
    pub namespace: Namespace,
    /// The node's name.
    pub node_name: NodeName,
    /// Topics.
    pub scan: TopicName,
    /// The orientation topic.
    pub orientation: TopicName,
    /// Its type.
    pub orientation_kind: OrientationKind,
    /// Where the Twists go.
    pub cmd_vel: TopicName,
    /// The decision's settings (goal sources, ring, stale window, wheel separation).
    pub decider: DeciderSettings,
    /// The robot's wheel limits (its profile's top speed and acceleration; none told: the
    /// default), handed to the pilot as its one episode begins.
    pub wheels: WheelLimits,
}

/// Why a ROS 2 agent could not run.
#[derive(Debug, thiserror::Error)]
pub enum Ros2AgentError {
    /// The router could not be reached.
    #[error(
        "cannot reach the ROS 2 router at {endpoint}: {detail}; is the robot's `rmw_zenohd` (or \
         `formation run --transport ros2 --listen {endpoint}`) running, and is that address \
         reachable from this host?"
    )]
    Unreachable {
        /// The endpoint.
        endpoint: String,
        /// Zenoh's error.
        detail: String,
    },
    /// Setting up the node failed.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// Signals could not be watched.
    #[error("cannot watch for termination signals")]
    Signals(#[source] std::io::Error),
    /// The pilot could not be made for the robot (the loop's episode was refused).
    #[error("the model cannot drive this robot: {reason}")]
    Unfit {
        /// Why, as the agent loop told it.
        reason: String,
    },
    /// The agent loop failed (its link's failure is one of the errors above, as its source).
    #[error(transparent)]
    Agent(#[from] AgentError),
}

impl TransportCrateError for Ros2AgentError {}

/// What the subscriptions leave for the loop.
#[derive(Default)]
struct Inbox {
    scan: Option<(Received<LaserScan>, Instant)>,
    /// Scans replaced by a newer one before the loop took them (newest wins).
    superseded: u64,
    /// Why the newest unusable sample on the scan topic was unusable.
    scan_problem: Option<String>,
    inputs: Inputs,
    /// Inputs that were not usable messages, newest last (bounded).
    problems: Vec<String>,
}

const PROBLEMS_KEPT: usize = 16;

fn lock(inbox: &Mutex<Inbox>) -> MutexGuard<'_, Inbox> {
    inbox.lock().unwrap_or_else(|e| e.into_inner())
}

fn note_problem(inbox: &Mutex<Inbox>, problem: String) {
    let mut inbox = lock(inbox);
    if inbox.problems.len() == PROBLEMS_KEPT {
        inbox.problems.remove(0);
    }
    inbox.problems.push(problem);
}

/// How long the robot's link lets the agent loop wait at most, between looks at the stale window
/// and the stop flag.
pub const LOOK_EVERY: Duration = Duration::from_millis(50);

/// Why the agent's loop ends when its `stop` flag is set: a ROS 2 agent belongs to its robot,
/// and whoever started it went away.
pub const LAUNCHER_WENT_AWAY: &str = "the launcher went away";

/// Runs `agent` (its pilot's maker and model) until a signal or `stop`: connects, declares the
/// node, its subscriptions and its publisher, and answers every scan. The scans are expected to
/// be the model's own ring ([`ExpectedScan::model_ring`]); [`run_agent_expecting`] names another.
pub fn run_agent<M: PilotMaker>(
    settings: &Ros2AgentSettings,
    agent: AgentLoop<M>,
    stop: &AtomicBool,
) -> Result<AgentExit, Ros2AgentError> {
    let expected = ExpectedScan::model_ring(settings.decider.contract);
    run_agent_expecting(settings, &expected, agent, stop)
}

/// [`run_agent`] for a robot whose LaserScan is expected to be `expected` (a robot profile's
/// LIDAR): the first scans that differ from it are named in one warning.
pub fn run_agent_expecting<M: PilotMaker>(
    settings: &Ros2AgentSettings,
    expected: &ExpectedScan,
    agent: AgentLoop<M>,
    stop: &AtomicBool,
) -> Result<AgentExit, Ros2AgentError> {
    let session = connect_router(settings)?;
    let node = Node::new(
        Arc::clone(&session),
        settings.domain_id,
        settings.namespace.clone(),
        settings.node_name.clone(),
        1,
    )?;
    let bell = Arc::new(Bell::default());
    let inbox = Arc::new(Mutex::new(Inbox::default()));
    let _signals = SignalWatch::start(Arc::clone(&bell)).map_err(Ros2AgentError::Signals)?;
    let subscriptions = subscribe_inputs(&node, settings, &inbox, &bell)?;

    // The publisher comes last: its token tells the graph (and the simulated team) that this
    // node drives the robot, and by then every subscription is in place. Twists are reliable
    // (one per scan, tiny): a dropped one would leave the robot on its previous command.
    let cmd_vel =
        node.publisher::<Twist>(&settings.cmd_vel, Qos::ROS_DEFAULT, Delivery::Reliable)?;
    let mut link = RobotLink::new(settings, expected.clone(), &bell, &inbox, &cmd_vel);
    // No world checks on a robot: the run's name is never told.
    let exit = agent
        .with_stop_reason(LAUNCHER_WENT_AWAY)
        .run(&mut link, stop, "")
        .map_err(Ros2AgentError::from);
    // Whatever ended the loop (a signal, the launcher, an error), the robot is told to stop.
    brake(&cmd_vel, system_time_ns());
    drop(subscriptions);
    exit
}

/// Opens the agent's session: a Zenoh client of the router at `settings.connect`.
fn connect_router(settings: &Ros2AgentSettings) -> Result<Arc<::zenoh::Session>, Ros2AgentError> {
    let config =
        formation_transport_zenoh::client_config(&settings.connect, settings.connect_timeout, None)
            .map_err(|detail| Ros2AgentError::Unreachable {
                endpoint: settings.connect.to_string(),
                detail,
            })?;
    Ok(Arc::new(formation_transport_zenoh::open(config).map_err(
        |detail| Ros2AgentError::Unreachable {
            endpoint: settings.connect.to_string(),
            detail,
        },
    )?))
}

/// Subscribes `node` to everything the decision reads, in this order: the scan, the orientation
/// and each goal value that comes from a topic. Each fills `inbox` and rings `bell`.
fn subscribe_inputs(
    node: &Node,
    settings: &Ros2AgentSettings,
    inbox: &Arc<Mutex<Inbox>>,
    bell: &Arc<Bell>,
) -> Result<Vec<RosSubscription>, Ros2AgentError> {
    let feed = InputFeed { node, inbox, bell };
    let mut subscriptions: Vec<RosSubscription> = Vec::new();
    subscriptions.push(feed.scan(settings)?);
    subscriptions.push(feed.orientation(settings)?);
    for (index, source) in settings.decider.goal.iter().enumerate() {
        let GoalValue::Topic(topic) = source else {
            continue;
        };
        subscriptions.push(feed.goal(topic, index)?);
    }
    Ok(subscriptions)
}

/// What the decision's subscriptions feed: `node` subscribes, and each sample fills `inbox` and
/// rings `bell`.
struct InputFeed<'a> {
    node: &'a Node,
    inbox: &'a Arc<Mutex<Inbox>>,
    bell: &'a Arc<Bell>,
}

impl InputFeed<'_> {
    /// A callback's own handles on the inbox and the bell.
    fn handles(&self) -> (Arc<Mutex<Inbox>>, Arc<Bell>) {
        (Arc::clone(self.inbox), Arc::clone(self.bell))
    }

    /// Subscribes to the scan topic: the newest scan waits in `inbox` (counting the ones it
    /// replaced); an unusable sample is noted as the scan's problem and as an input problem.
    fn scan(&self, settings: &Ros2AgentSettings) -> Result<RosSubscription, Ros2AgentError> {
        let (inbox, bell) = self.handles();
        Ok(self.node.subscription::<LaserScan>(
            &settings.scan,
            Qos::SENSOR_DATA,
            move |sample| {
                match sample {
                    Ok(scan) => {
                        let mut inbox = lock(&inbox);
                        if inbox.scan.replace((scan, Instant::now())).is_some() {
                            inbox.superseded += 1;
                        }
                    }
                    Err(e) => {
                        let problem = formation_runtime::agent::error_chain(&e);
                        lock(&inbox).scan_problem = Some(problem.clone());
                        note_problem(&inbox, problem);
                    }
                }
                bell.ring();
            },
        )?)
    }

    /// Subscribes to the orientation topic as `settings.orientation_kind` says (Imu or Odometry):
    /// the yaw (or why there is none) goes to `inbox`'s inputs; unusable samples are noted.
    fn orientation(&self, settings: &Ros2AgentSettings) -> Result<RosSubscription, Ros2AgentError> {
        let feed = {
            let (inbox, bell) = self.handles();
            move |sample: Result<Result<f64, OrientationError>, InputError>| {
                match sample {
                    Ok(yaw) => {
                        let yaw = yaw.map_err(|e| e.to_string());
                        lock(&inbox).inputs.orientation = Some((yaw, Instant::now()));
                    }
                    Err(e) => note_problem(&inbox, formation_runtime::agent::error_chain(&e)),
                }
                bell.ring();
            }
        };
        let (node, topic) = (self.node, &settings.orientation);
        Ok(match settings.orientation_kind {
            OrientationKind::Imu => {
                node.subscription::<Imu>(topic, Qos::SENSOR_DATA, move |s| {
                    feed(s.map(|imu| imu.message.yaw()))
                })?
            }
            OrientationKind::Odometry => {
                node.subscription::<Odometry>(topic, Qos::ROS_DEFAULT, move |s| {
                    feed(s.map(|odom| odom.message.yaw()))
                })?
            }
        })
    }

    /// Subscribes to goal value `index`'s `topic`: a finite value goes to `inbox`'s inputs; a
    /// non-finite one or an unusable sample is noted and the previous value kept.
    fn goal(&self, topic: &TopicName, index: usize) -> Result<RosSubscription, Ros2AgentError> {
        let (inbox, bell) = self.handles();
        Ok(self
            .node
            .subscription::<Float64>(topic, Qos::ROS_DEFAULT, move |sample| {
                match sample {
                    Ok(value) if value.message.data.is_finite() => {
                        lock(&inbox).inputs.goal[index] = Some(value.message.data);
                    }
                    Ok(value) => note_problem(
                        &inbox,
                        format!(
                            "{} is {} on its topic; keeping the previous value",
                            super::decider::GOAL_NAMES[index],
                            value.message.data
                        ),
                    ),
                    Err(e) => note_problem(&inbox, formation_runtime::agent::error_chain(&e)),
                }
                bell.ring();
            })?)
    }
}

/// Publishes a zero Twist stamped `stamp` on `cmd_vel`; a failure is only logged.
fn brake(cmd_vel: &RosPublisher<Twist>, stamp: i64) {
    if let Err(e) = cmd_vel.publish(&Twist::default(), stamp) {
        tracing::warn!("could not publish a zero Twist: {e}");
    }
}

/// What the subscriptions left for one turn of the loop, taken from the inbox at once.
struct Taken {
    scan: Option<(Received<LaserScan>, Instant)>,
    inputs: Inputs,
    problems: Vec<String>,
    superseded: u64,
    scan_problem: Option<String>,
}

impl Taken {
    /// Takes the newest scan, a copy of the inputs, the problems noted, the count of scans
    /// superseded so far and the scan's problem from `inbox`.
    fn take_from(inbox: &Mutex<Inbox>) -> Taken {
        let mut inbox = lock(inbox);
        Taken {
            scan: inbox.scan.take(),
            inputs: inbox.inputs.clone(),
            problems: std::mem::take(&mut inbox.problems),
            superseded: inbox.superseded,
            scan_problem: inbox.scan_problem.take(),
        }
    }
}

/// The generation of a ROS 2 agent's one episode.
const ROBOT_EPISODE: u64 = 0;

/// A ROS 2 robot as the agent loop's [`AgentLink`]: the robot's inputs in (each usable scan as
/// the loop's scan), Twists out, and what was told on stderr. It stands in for the world: it
/// begins the one episode, is never gone, and asks for nothing else.
pub struct RobotLink<'a> {
    bell: &'a Bell,
    inbox: &'a Mutex<Inbox>,
    cmd_vel: &'a RosPublisher<Twist>,
    /// The episode to begin, until the loop has taken it.
    episode: Option<ControlRequest>,
    decider: Decider,
    /// When the link began: the scans' simulation time is this host's time since.
    started: Instant,
    /// Scans handed to the loop so far (each one's tick).
    ticks: u64,
    /// The stamp of the scan handed to the loop and not answered yet.
    answering: Option<i64>,
    /// Why the pilot could not decide on that scan, when it could not.
    decision_failure: Option<String>,
    /// The braking reason told last (told again only when it changes).
    told: Option<String>,
    problems_told: ProblemLog,
    superseded_told: u64,
    /// Why the latest sample on the scan topic was unusable, until a usable scan comes.
    scan_unusable: Option<String>,
    /// The first scans against the one expected.
    scan_check: ScanCheck,
}

impl<'a> RobotLink<'a> {
    /// The robot of `settings` on the subscriptions' `inbox` (rung on `bell`) and `cmd_vel`,
    /// its clock started now, expecting scans like `expected`.
    fn new(
        settings: &Ros2AgentSettings,
        expected: ExpectedScan,
        bell: &'a Bell,
        inbox: &'a Mutex<Inbox>,
        cmd_vel: &'a RosPublisher<Twist>,
    ) -> RobotLink<'a> {
        let contract = settings.decider.contract;
        let now = Instant::now();
        RobotLink {
            bell,
            inbox,
            cmd_vel,
            episode: Some(ControlRequest::BeginEpisode {
                generation: ROBOT_EPISODE,
                lidar: LidarSpec {
                    beams: contract.beams,
                    max_range: contract.max_range,
                },
                wheels: settings.wheels,
            }),
            decider: Decider::new(settings.decider.clone(), now),
            started: now,
            ticks: 0,
            answering: None,
            decision_failure: None,
            told: None,
            problems_told: ProblemLog::default(),
            superseded_told: 0,
            scan_unusable: None,
            scan_check: ScanCheck::new(expected, contract, settings.scan.as_str().to_owned()),
        }
    }

    /// Tells the problems and the superseded scans in `taken`, and keeps the scan's problem.
    fn tell_problems(&mut self, taken: &mut Taken, now: Instant) {
        for problem in std::mem::take(&mut taken.problems) {
            self.problems_told.tell(problem, now);
        }
        if taken.superseded > self.superseded_told && self.superseded_told == 0 {
            eprintln!(
                "formation-agent: scans come faster than the agent decides: each decision takes \
                 the newest scan and the older ones go unanswered (the robot acts on the newest)"
            );
        }
        self.superseded_told = taken.superseded;
        if taken.scan_problem.is_some() {
            self.scan_unusable = taken.scan_problem.take();
        }
    }

    /// The loop's scan for `scan`, arrived at `arrived`, if the decider has all it needs;
    /// else the robot is braked with the reason, stamped with the scan's stamp.
    fn ready_scan(
        &mut self,
        scan: &LaserScan,
        inputs: &Inputs,
        arrived: Instant,
    ) -> Option<ScanMsg> {
        self.scan_unusable = None;
        if let Some(warning) = self.scan_check.look(scan) {
            eprintln!("formation-agent: {warning}");
        }
        let stamp = scan.header.stamp.as_nanos();
        let ready = self
            .decider
            .on_scan(scan, inputs, arrived)
            .and_then(|ready| {
                let since_start = arrived.saturating_duration_since(self.started);
                ScanMsg::new(
                    ROBOT_EPISODE,
                    self.ticks + 1,
                    since_start.as_secs_f64(),
                    ready.heading,
                    &ready.goal,
                    &ready.ranges,
                )
                .map_err(|e| format!("the LaserScan on {}: {e}", self.scan_check.topic))
            });
        match ready {
            Ok(msg) => {
                self.ticks += 1;
                self.answering = Some(stamp);
                Some(msg)
            }
            Err(reason) => {
                tell(&mut self.told, &reason);
                brake(self.cmd_vel, stamp);
                None
            }
        }
    }
}

impl AgentLink for RobotLink<'_> {
    /// Waits at most [`LOOK_EVERY`], so that stale inputs brake the robot in time.
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        Ok(Wake::from(self.bell.wait(timeout.min(LOOK_EVERY))))
    }

    /// The one episode, once.
    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        if let Some(episode) = self.episode.take() {
            sink(episode);
        }
        Ok(())
    }

    /// One turn on what the subscriptions left: tells the problems, then hands the loop the
    /// newest scan if it can be decided on (else brakes), or brakes when the inputs went stale.
    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        let mut taken = Taken::take_from(self.inbox);
        let now = Instant::now();
        self.tell_problems(&mut taken, now);
        if let Some((scan, arrived)) = taken.scan {
            return Ok(self.ready_scan(&scan.message, &taken.inputs, arrived));
        }
        if let Some(mut reason) = self.decider.check_stale(now) {
            if let Some(problem) = &self.scan_unusable {
                reason.push_str(&format!("; the samples that came were unusable: {problem}"));
            }
            tell(&mut self.told, &reason);
            brake(self.cmd_vel, system_time_ns());
        }
        Ok(None)
    }

    /// The command as a Twist (or a brake, with the reason) stamped with its scan's stamp. A
    /// Twist that cannot be sent is an error.
    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        let stamp = self.answering.take().unwrap_or_else(system_time_ns);
        let answer = if msg.status().contains(CmdStatus::DECISION_FAILED) {
            let why = self.decision_failure.take().unwrap_or_default();
            self.decider.on_failed_decision(&why)
        } else {
            self.decider.on_wheels(msg.wheels())
        };
        match answer {
            Answer::Drive(twist) => {
                self.told = None;
                self.cmd_vel
                    .publish(&twist, stamp)
                    .map_err(Ros2AgentError::from)?;
            }
            Answer::Brake(reason) => {
                tell(&mut self.told, &reason);
                brake(self.cmd_vel, stamp);
            }
        }
        Ok(())
    }

    /// Nothing to tell a robot, but a refused episode: the pilot cannot be made for it.
    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        match status {
            AgentStatus::Refused { reason, .. } => Err(Ros2AgentError::Unfit {
                reason: reason.clone(),
            }
            .into()),
            _ => Ok(()),
        }
    }

    /// A robot is never gone: its agent runs until stopped.
    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        Ok(true)
    }

    /// Kept for the brake that follows, told with its reason.
    fn decision_failed(&mut self, _tick: u64, why: &str) {
        self.decision_failure = Some(why.to_owned());
    }
}

/// How often the same unusable-input message is repeated at most.
const PROBLEM_REPEAT: Duration = Duration::from_secs(5);

/// Tells unusable inputs on stderr, each distinct message at most once per [`PROBLEM_REPEAT`]
/// (a LIDAR at 40 Hz with the wrong type would otherwise write 40 lines a second).
#[derive(Default)]
struct ProblemLog {
    told_at: std::collections::HashMap<String, (Instant, u64)>,
}

impl ProblemLog {
    fn tell(&mut self, problem: String, now: Instant) {
        if self.told_at.len() > 64 {
            self.told_at.clear();
        }
        let entry = self.told_at.entry(problem.clone()).or_insert((now, 0));
        let (at, unsaid) = entry;
        if *unsaid == 0 || now.saturating_duration_since(*at) >= PROBLEM_REPEAT {
            let repeats = if *unsaid > 1 {
                format!(" ({} more like it since)", *unsaid - 1)
            } else {
                String::new()
            };
            eprintln!("formation-agent: ignoring an input: {problem}{repeats}");
            *at = now;
            *unsaid = 1;
        } else {
            *unsaid += 1;
        }
    }
}

/// Tells why the robot brakes, once per reason in a row.
fn tell(told: &mut Option<String>, reason: &str) {
    if told.as_deref() != Some(reason) {
        eprintln!("formation-agent: braking: {reason}");
        *told = Some(reason.to_owned());
    }
}

/// The LaserScan an agent expects of its robot: its robot profile's LIDAR (`formation-agent
/// --profile`), else the ring its model was trained on (whose metadata declares no rate).
#[derive(Debug, Clone, PartialEq)]
pub struct ExpectedScan {
    /// Whose scan it is, for the warning (`the turtlebot3-burger profile's LIDAR`).
    pub source: String,
    /// Readings per scan (a full circle).
    pub beams: usize,
    /// Largest range \[m\].
    pub max_range: f64,
    /// Scans per second, if expected (`None`: any rate).
    pub rate_hz: Option<f64>,
}

impl ExpectedScan {
    /// The model's own ring: its beams and range, any rate.
    pub fn model_ring(contract: RingContract) -> ExpectedScan {
        ExpectedScan {
            source: "the model's LIDAR".into(),
            beams: contract.beams,
            max_range: contract.max_range,
            rate_hz: None,
        }
    }
}

/// A scan's rate may differ from the expected one by this share before it is named (drivers
/// round `scan_time`, and a LIDAR's motor drifts by a few per cent).
const RATE_TOLERANCE: f64 = 0.2;
/// A scan's `range_max` may differ from the expected range by this share before it is named.
const RANGE_TOLERANCE: f64 = 0.05;

/// What one scan shows of its LIDAR.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SeenScan {
    beams: usize,
    max_range: f64,
    /// From `scan_time`, else from the first two scans' stamps; `None` while unknown.
    rate_hz: Option<f64>,
}

/// Checks the first scans against the [`ExpectedScan`] and names, in one warning, every way
/// they differ (beams, range, rate). It judges once: on the first scan when that scan tells its
/// rate (`scan_time` > 0), when no rate is expected, or when the beams or range differ already;
/// else on the second, whose stamp gives the rate. Later scans are not looked at.
#[derive(Debug, Clone)]
pub struct ScanCheck {
    expected: ExpectedScan,
    model: RingContract,
    topic: String,
    first_stamp_ns: Option<i64>,
    judged: bool,
}

impl ScanCheck {
    /// A check of the scans on `topic` against `expected`, resampled onto the `model`'s ring.
    pub fn new(expected: ExpectedScan, model: RingContract, topic: String) -> ScanCheck {
        ScanCheck {
            expected,
            model,
            topic,
            first_stamp_ns: None,
            judged: false,
        }
    }

    /// Looks at a scan that came: the warning to give, once, if the scans differ from the
    /// expected one.
    pub fn look(&mut self, scan: &LaserScan) -> Option<String> {
        if self.judged {
            return None;
        }
        let stamp = scan.header.stamp.as_nanos();
        let mut seen = SeenScan {
            beams: scan.ranges.len(),
            max_range: f64::from(scan.range_max),
            rate_hz: (scan.scan_time.is_finite() && scan.scan_time > 0.0)
                .then(|| 1.0 / f64::from(scan.scan_time)),
        };
        if let (None, Some(first)) = (seen.rate_hz, self.first_stamp_ns) {
            seen.rate_hz = (stamp > first).then(|| 1e9 / (stamp - first) as f64);
        }
        let differences = self.differences(&seen);
        let waiting_for_rate = seen.rate_hz.is_none()
            && self.expected.rate_hz.is_some()
            && self.first_stamp_ns.is_none()
            && differences.is_empty();
        if waiting_for_rate {
            self.first_stamp_ns = Some(stamp);
            return None;
        }
        self.judged = true;
        if differences.is_empty() {
            return None;
        }
        Some(format!(
            "the LaserScan on {} is not the one expected ({}: {}): {}; every scan is resampled \
             onto the model's ring ({} beams, {} m) as usual, and the formations may be worse \
             than the model's card says (told once)",
            self.topic,
            self.expected.source,
            describe(
                self.expected.beams,
                self.expected.max_range,
                self.expected.rate_hz
            ),
            differences.join(", "),
            self.model.beams,
            self.model.max_range,
        ))
    }

    /// How `seen` differs from the expected scan, one phrase each.
    fn differences(&self, seen: &SeenScan) -> Vec<String> {
        let expected = &self.expected;
        let mut differences = Vec::new();
        if seen.beams != expected.beams {
            differences.push(format!(
                "it has {} beams, not {}",
                seen.beams, expected.beams
            ));
        }
        let range_off =
            (seen.max_range - expected.max_range).abs() > RANGE_TOLERANCE * expected.max_range;
        if !seen.max_range.is_finite() || range_off {
            differences.push(format!(
                "it reaches {} m, not {} m",
                seen.max_range, expected.max_range
            ));
        }
        if let (Some(seen_rate), Some(rate)) = (seen.rate_hz, expected.rate_hz)
            && (seen_rate - rate).abs() > RATE_TOLERANCE * rate
        {
            differences.push(format!("it scans at {seen_rate:.1} Hz, not {rate} Hz"));
        }
        differences
    }
}

/// `360 beams, 3.5 m, 5 Hz`.
fn describe(beams: usize, max_range: f64, rate_hz: Option<f64>) -> String {
    match rate_hz {
        Some(rate) => format!("{beams} beams, {max_range} m, {rate} Hz"),
        None => format!("{beams} beams, {max_range} m"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_ros2::{Header, Time};

    fn scan(beams: usize, range_max: f32, scan_time: f32, stamp_ns: i64) -> LaserScan {
        let increment = std::f32::consts::TAU / beams as f32;
        LaserScan {
            header: Header {
                stamp: Time::from_nanos(stamp_ns),
                frame_id: "base_scan".into(),
            },
            angle_min: 0.0,
            angle_max: increment * (beams - 1) as f32,
            angle_increment: increment,
            time_increment: 0.0,
            scan_time,
            range_min: 0.12,
            range_max,
            ranges: vec![1.0; beams],
            intensities: Vec::new(),
        }
    }

    fn burger() -> ExpectedScan {
        ExpectedScan {
            source: "the turtlebot3-burger profile's LIDAR".into(),
            beams: 360,
            max_range: 3.5,
            rate_hz: Some(5.0),
        }
    }

    fn check(expected: ExpectedScan) -> ScanCheck {
        let model = RingContract {
            beams: 900,
            max_range: 10.0,
        };
        ScanCheck::new(expected, model, "/scan".into())
    }

    #[test]
    fn the_expected_scan_gives_no_warning() {
        let mut check = check(burger());
        assert_eq!(check.look(&scan(360, 3.5, 0.2, 0)), None);
        // Judged on the first scan (it told its rate): later ones are not looked at.
        assert_eq!(check.look(&scan(720, 30.0, 0.05, 1)), None);
    }

    #[test]
    fn a_foreign_scan_is_named_once_with_every_difference() {
        let mut check = check(burger());
        let warning = check.look(&scan(720, 12.0, 0.1, 0)).expect("a warning");
        assert!(
            warning.starts_with(
                "the LaserScan on /scan is not the one expected (the turtlebot3-burger \
                 profile's LIDAR: 360 beams, 3.5 m, 5 Hz): it has 720 beams, not 360, it \
                 reaches 12 m, not 3.5 m, it scans at 10.0 Hz, not 5 Hz; every scan is \
                 resampled onto the model's ring (900 beams, 10 m)"
            ),
            "{warning}"
        );
        for stamp in 1..50 {
            assert_eq!(check.look(&scan(720, 12.0, 0.1, stamp)), None);
        }
    }

    #[test]
    fn without_scan_time_the_rate_comes_from_the_first_two_stamps() {
        let mut check = check(burger());
        // 20 Hz, scan_time unset (0): nothing to say until the second stamp.
        assert_eq!(check.look(&scan(360, 3.5, 0.0, 1_000_000_000)), None);
        let warning = check
            .look(&scan(360, 3.5, 0.0, 1_050_000_000))
            .expect("a warning");
        assert!(
            warning.contains("): it scans at 20.0 Hz, not 5 Hz;"),
            "{warning}"
        );
        assert_eq!(check.look(&scan(360, 3.5, 0.0, 1_100_000_000)), None);

        // Within the tolerance (4.6 Hz against 5): no warning.
        let mut check = check_fresh();
        assert_eq!(check.look(&scan(360, 3.6, 0.0, 0)), None);
        assert_eq!(check.look(&scan(360, 3.6, 0.0, 217_000_000)), None);
    }

    fn check_fresh() -> ScanCheck {
        check(burger())
    }

    #[test]
    fn the_model_ring_expects_no_rate_and_judges_at_once() {
        let model = RingContract {
            beams: 900,
            max_range: 10.0,
        };
        let mut same = check(ExpectedScan::model_ring(model));
        assert_eq!(same.look(&scan(900, 10.0, 0.0, 0)), None);
        assert_eq!(same.look(&scan(360, 3.5, 0.0, 1)), None);
        let mut other = check(ExpectedScan::model_ring(model));
        let warning = other.look(&scan(360, 10.0, 0.0, 0)).expect("a warning");
        assert!(
            warning.contains("(the model's LIDAR: 900 beams, 10 m): it has 360 beams, not 900;"),
            "{warning}"
        );
    }
}
