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
use super::node::{Delivery, Node, NodeError, Received, RosSubscription, system_time_ns};
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
    let config = crate::zenoh::client_config(&settings.connect, settings.connect_timeout, None)
        .map_err(|detail| Ros2AgentError::Unreachable {
            endpoint: settings.connect.to_string(),
            detail,
        })?;
    let session =
        Arc::new(
            crate::zenoh::open(config).map_err(|detail| Ros2AgentError::Unreachable {
                endpoint: settings.connect.to_string(),
                detail,
            })?,
        );
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
    let mut subscriptions: Vec<RosSubscription> = Vec::new();
    subscriptions.push({
        let (inbox, bell) = (Arc::clone(&inbox), Arc::clone(&bell));
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
        })?
    });
    subscriptions.push({
        let deliver = {
            let (inbox, bell) = (Arc::clone(&inbox), Arc::clone(&bell));
            move |yaw: Result<f64, String>| {
                lock(&inbox).inputs.orientation = Some((yaw, Instant::now()));
                bell.ring();
            }
        };
        let problem = {
            let (inbox, bell) = (Arc::clone(&inbox), Arc::clone(&bell));
            move |e: super::node::InputError| {
                note_problem(&inbox, crate::agent::error_chain(&e));
                bell.ring();
            }
        };
        match settings.orientation_kind {
            OrientationKind::Imu => node.subscription::<Imu>(
                &settings.orientation,
                Qos::SENSOR_DATA,
                move |s| match s {
                    Ok(imu) => deliver(imu.message.yaw().map_err(|e| e.to_string())),
                    Err(e) => problem(e),
                },
            )?,
            OrientationKind::Odometry => {
                node.subscription::<Odometry>(&settings.orientation, Qos::ROS_DEFAULT, move |s| {
                    match s {
                        Ok(odom) => deliver(odom.message.yaw().map_err(|e| e.to_string())),
                        Err(e) => problem(e),
                    }
                })?
            }
        }
    });
    for (index, source) in settings.decider.goal.iter().enumerate() {
        let GoalValue::Topic(topic) = source else {
            continue;
        };
        let (inbox, bell) = (Arc::clone(&inbox), Arc::clone(&bell));
        subscriptions.push(node.subscription::<Float64>(
            topic,
            Qos::ROS_DEFAULT,
            move |sample| {
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
            },
        )?);
    }

    // The publisher comes last: its token tells the graph (and the simulated team) that this
    // node drives the robot, and by then every subscription is in place. Twists are reliable
    // (one per scan, tiny): a dropped one would leave the robot on its previous command.
    let cmd_vel =
        node.publisher::<Twist>(&settings.cmd_vel, Qos::ROS_DEFAULT, Delivery::Reliable)?;
    let brake = |stamp: i64| {
        if let Err(e) = cmd_vel.publish(&Twist::default(), stamp) {
            tracing::warn!("could not publish a zero Twist: {e}");
        }
    };
    let mut decider = Decider::new(settings.decider.clone(), Instant::now());
    let mut told: Option<String> = None;
    let mut problems_told = ProblemLog::default();
    let mut superseded_told = 0;
    // Why the latest sample on the scan topic was unusable, until a usable scan comes.
    let mut scan_unusable: Option<String> = None;
    let exit = loop {
        if stop.load(Ordering::Relaxed) {
            break Ok(AgentExit::Because("the launcher went away".into()));
        }
        if let Ring::Terminated(signal) = bell.wait(LOOK_EVERY) {
            break Ok(AgentExit::Signal(signal));
        }
        let (scan, inputs, problems, superseded, scan_problem) = {
            let mut inbox = lock(&inbox);
            (
                inbox.scan.take(),
                inbox.inputs.clone(),
                std::mem::take(&mut inbox.problems),
                inbox.superseded,
                inbox.scan_problem.take(),
            )
        };
        let now = Instant::now();
        for problem in problems {
            problems_told.tell(problem, now);
        }
        if superseded > superseded_told && superseded_told == 0 {
            eprintln!(
                "formation-agent: scans come faster than the agent decides: each decision takes \
                 the newest scan and the older ones go unanswered (the robot acts on the newest)"
            );
        }
        superseded_told = superseded;
        if scan_problem.is_some() {
            scan_unusable = scan_problem;
        }
        if let Some((scan, arrived)) = scan {
            scan_unusable = None;
            let stamp = scan.message.header.stamp.as_nanos();
            match decider.on_scan(&scan.message, &inputs, arrived, pilot) {
                Answer::Drive(twist) => {
                    told = None;
                    if let Err(e) = cmd_vel.publish(&twist, stamp) {
                        break Err(Ros2AgentError::from(e));
                    }
                }
                Answer::Brake(reason) => {
                    tell(&mut told, &reason);
                    brake(stamp);
                }
            }
        } else if let Some(mut reason) = decider.check_stale(now) {
            if let Some(problem) = &scan_unusable {
                reason.push_str(&format!("; the samples that came were unusable: {problem}"));
            }
            tell(&mut told, &reason);
            brake(system_time_ns());
        }
    };
    // Whatever ended the loop (a signal, the launcher, an error), the robot is told to stop.
    brake(system_time_ns());
    drop(subscriptions);
    exit
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
