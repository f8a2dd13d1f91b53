//! A ROS 2 agent ([`run_agent`]): one robot's decision maker as a ROS 2 node on the robot's
//! rmw_zenoh router, with no ROS installation. It subscribes to the robot's LaserScan, an
//! orientation (`sensor_msgs/Imu` or `nav_msgs/Odometry`) and, where they are not fixed, the
//! goal topics (`std_msgs/Float64`), and publishes `geometry_msgs/Twist` on `cmd_vel`; what it
//! does with each scan is the [`Decider`]'s.
//!
//! It stops on SIGINT/SIGTERM, or when its launcher goes (the `stop` flag), and publishes one
//! zero Twist before it goes. If it dies without one, the robot's own `cmd_vel` timeout brakes it
//! (ros2_controllers' diff_drive_controller: 0.5 s). A router that goes away mid-run is waited
//! for (Zenoh reconnects by itself); meanwhile the scans stop and the robot is braked.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use formation_ros2::{
    Float64, Imu, LaserScan, Namespace, NodeName, Odometry, Qos, TopicName, Twist,
};

use super::decider::{Answer, Decider, DeciderSettings, GoalValue, Inputs};
use super::node::{
    Delivery, Node, NodeError, Received, RosPublisher, RosSubscription, system_time_ns,
};
use crate::agent::{AgentExit, Pilot};
use crate::zenoh::{Bell, Endpoint, Ring, SignalWatch};

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
}

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

/// How long the loop sleeps at most between looks at the stale window and the stop flag.
const LOOK_EVERY: Duration = Duration::from_millis(50);

/// Runs the agent until a signal or `stop`: connects, declares the node, its subscriptions and
/// its publisher, and answers every scan.
pub fn run_agent<P: Pilot>(
    settings: &Ros2AgentSettings,
    pilot: &mut P,
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
    let exit =
        ScanAnswers::new(settings).answer_until_stopped(pilot, stop, &bell, &inbox, &cmd_vel);
    // Whatever ended the loop (a signal, the launcher, an error), the robot is told to stop.
    brake(&cmd_vel, system_time_ns());
    drop(subscriptions);
    exit
}

/// Opens the agent's session: a Zenoh client of the router at `settings.connect`.
fn connect_router(settings: &Ros2AgentSettings) -> Result<Arc<::zenoh::Session>, Ros2AgentError> {
    let config = crate::zenoh::client_config(&settings.connect, settings.connect_timeout, None)
        .map_err(|detail| Ros2AgentError::Unreachable {
            endpoint: settings.connect.to_string(),
            detail,
        })?;
    Ok(Arc::new(crate::zenoh::open(config).map_err(|detail| {
        Ros2AgentError::Unreachable {
            endpoint: settings.connect.to_string(),
            detail,
        }
    })?))
}

/// Subscribes `node` to everything the decision reads, in this order: the scan, the orientation
/// and each goal value that comes from a topic. Each fills `inbox` and rings `bell`.
fn subscribe_inputs(
    node: &Node,
    settings: &Ros2AgentSettings,
    inbox: &Arc<Mutex<Inbox>>,
    bell: &Arc<Bell>,
) -> Result<Vec<RosSubscription>, Ros2AgentError> {
    let mut subscriptions: Vec<RosSubscription> = Vec::new();
    subscriptions.push(subscribe_scan(node, settings, inbox, bell)?);
    subscriptions.push(subscribe_orientation(node, settings, inbox, bell)?);
    for (index, source) in settings.decider.goal.iter().enumerate() {
        let GoalValue::Topic(topic) = source else {
            continue;
        };
        subscriptions.push(subscribe_goal(node, topic, index, inbox, bell)?);
    }
    Ok(subscriptions)
}

/// Subscribes to the scan topic: the newest scan waits in `inbox` (counting the ones it
/// replaced); an unusable sample is noted as the scan's problem and as an input problem.
fn subscribe_scan(
    node: &Node,
    settings: &Ros2AgentSettings,
    inbox: &Arc<Mutex<Inbox>>,
    bell: &Arc<Bell>,
) -> Result<RosSubscription, Ros2AgentError> {
    let (inbox, bell) = (Arc::clone(inbox), Arc::clone(bell));
    Ok(
        node.subscription::<LaserScan>(&settings.scan, Qos::SENSOR_DATA, move |sample| {
            match sample {
                Ok(scan) => {
                    let mut inbox = lock(&inbox);
                    if inbox.scan.replace((scan, Instant::now())).is_some() {
                        inbox.superseded += 1;
                    }
                }
                Err(e) => {
                    let problem = crate::agent::error_chain(&e);
                    lock(&inbox).scan_problem = Some(problem.clone());
                    note_problem(&inbox, problem);
                }
            }
            bell.ring();
        })?,
    )
}

/// Subscribes to the orientation topic as `settings.orientation_kind` says (Imu or Odometry):
/// the yaw (or why there is none) goes to `inbox`'s inputs; unusable samples are noted.
fn subscribe_orientation(
    node: &Node,
    settings: &Ros2AgentSettings,
    inbox: &Arc<Mutex<Inbox>>,
    bell: &Arc<Bell>,
) -> Result<RosSubscription, Ros2AgentError> {
    let deliver = {
        let (inbox, bell) = (Arc::clone(inbox), Arc::clone(bell));
        move |yaw: Result<f64, String>| {
            lock(&inbox).inputs.orientation = Some((yaw, Instant::now()));
            bell.ring();
        }
    };
    let problem = {
        let (inbox, bell) = (Arc::clone(inbox), Arc::clone(bell));
        move |e: super::node::InputError| {
            note_problem(&inbox, crate::agent::error_chain(&e));
            bell.ring();
        }
    };
    Ok(match settings.orientation_kind {
        OrientationKind::Imu => {
            node.subscription::<Imu>(&settings.orientation, Qos::SENSOR_DATA, move |s| match s {
                Ok(imu) => deliver(imu.message.yaw().map_err(|e| e.to_string())),
                Err(e) => problem(e),
            })?
        }
        OrientationKind::Odometry => node.subscription::<Odometry>(
            &settings.orientation,
            Qos::ROS_DEFAULT,
            move |s| match s {
                Ok(odom) => deliver(odom.message.yaw().map_err(|e| e.to_string())),
                Err(e) => problem(e),
            },
        )?,
    })
}

/// Subscribes to goal value `index`'s `topic`: a finite value goes to `inbox`'s inputs; a
/// non-finite one or an unusable sample is noted and the previous value kept.
fn subscribe_goal(
    node: &Node,
    topic: &TopicName,
    index: usize,
    inbox: &Arc<Mutex<Inbox>>,
    bell: &Arc<Bell>,
) -> Result<RosSubscription, Ros2AgentError> {
    let (inbox, bell) = (Arc::clone(inbox), Arc::clone(bell));
    Ok(
        node.subscription::<Float64>(topic, Qos::ROS_DEFAULT, move |sample| {
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
                Err(e) => note_problem(&inbox, crate::agent::error_chain(&e)),
            }
            bell.ring();
        })?,
    )
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

/// The loop's state while it answers scans: the decision and what was told on stderr.
struct ScanAnswers {
    decider: Decider,
    /// The braking reason told last (told again only when it changes).
    told: Option<String>,
    problems_told: ProblemLog,
    superseded_told: u64,
    /// Why the latest sample on the scan topic was unusable, until a usable scan comes.
    scan_unusable: Option<String>,
}

impl ScanAnswers {
    /// A fresh loop state with `settings`' decision, its clock started now.
    fn new(settings: &Ros2AgentSettings) -> ScanAnswers {
        ScanAnswers {
            decider: Decider::new(settings.decider.clone(), Instant::now()),
            told: None,
            problems_told: ProblemLog::default(),
            superseded_told: 0,
            scan_unusable: None,
        }
    }

    /// Answers every scan in `inbox` with a Twist on `cmd_vel` (or a brake) until `stop` is set
    /// or a signal rings `bell`, waking at least every [`LOOK_EVERY`] to brake on stale input.
    fn answer_until_stopped<P: Pilot>(
        mut self,
        pilot: &mut P,
        stop: &AtomicBool,
        bell: &Bell,
        inbox: &Mutex<Inbox>,
        cmd_vel: &RosPublisher<Twist>,
    ) -> Result<AgentExit, Ros2AgentError> {
        loop {
            if stop.load(Ordering::Relaxed) {
                break Ok(AgentExit::Because("the launcher went away".into()));
            }
            if let Ring::Terminated(signal) = bell.wait(LOOK_EVERY) {
                break Ok(AgentExit::Signal(signal));
            }
            let taken = Taken::take_from(inbox);
            if let Err(e) = self.answer(taken, pilot, cmd_vel) {
                break Err(e);
            }
        }
    }

    /// One turn of the loop on what was `taken`: tells the problems, then answers the scan if
    /// one came, or brakes when the inputs went stale. A Twist that cannot be sent is an error.
    fn answer<P: Pilot>(
        &mut self,
        taken: Taken,
        pilot: &mut P,
        cmd_vel: &RosPublisher<Twist>,
    ) -> Result<(), Ros2AgentError> {
        let Taken {
            scan,
            inputs,
            problems,
            superseded,
            scan_problem,
        } = taken;
        let now = Instant::now();
        for problem in problems {
            self.problems_told.tell(problem, now);
        }
        if superseded > self.superseded_told && self.superseded_told == 0 {
            eprintln!(
                "formation-agent: scans come faster than the agent decides: each decision takes \
                 the newest scan and the older ones go unanswered (the robot acts on the newest)"
            );
        }
        self.superseded_told = superseded;
        if scan_problem.is_some() {
            self.scan_unusable = scan_problem;
        }
        if let Some((scan, arrived)) = scan {
            self.scan_unusable = None;
            let stamp = scan.message.header.stamp.as_nanos();
            match self.decider.on_scan(&scan.message, &inputs, arrived, pilot) {
                Answer::Drive(twist) => {
                    self.told = None;
                    cmd_vel.publish(&twist, stamp)?;
                }
                Answer::Brake(reason) => {
                    tell(&mut self.told, &reason);
                    brake(cmd_vel, stamp);
                }
            }
        } else if let Some(mut reason) = self.decider.check_stale(now) {
            if let Some(problem) = &self.scan_unusable {
                reason.push_str(&format!("; the samples that came were unusable: {problem}"));
            }
            tell(&mut self.told, &reason);
            brake(cmd_vel, system_time_ns());
        }
        Ok(())
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
