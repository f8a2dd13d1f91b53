//! ROS 2 held to the transport conformance suite (`formation-transport-conformance`): the world
//! as a ROS 2 team on a free loopback port of each test's own, and ROS 2 agents
//! (`formation_transport_ros2::run_agent`, the runtime's agent loop over the robot's topics) on
//! the team's topics. A ROS 2 world carries no swap
//! request, so ROS 2 runs no swap test.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use formation_runtime::ClockMode;
use formation_runtime::agent::{AgentLoop, PilotMaker, error_chain};
use formation_runtime::auth::LaunchSecret;
use formation_runtime::clock::SystemClock;
use formation_test_kit::{assert_port_free, free_tcp_port, unique_run_id};
use formation_transport_conformance::agent::{Agent, CONNECT_TIMEOUT};
use formation_transport_conformance::rig::{Launch, Rig};
use formation_transport_zenoh::Endpoint;

formation_transport_conformance::conformance_tests!(Ros2Rig);

/// `tcp/127.0.0.1:<a free port>`.
fn loopback() -> Endpoint {
    Endpoint::parse(&format!("tcp/127.0.0.1:{}", free_tcp_port())).expect("a loopback endpoint")
}

use formation_ros2::{Namespace, NodeName, PartialScan, RingContract};
use formation_transport_ros2::{
    DeciderSettings, GoalValue, OrientationKind, Ros2AgentSettings, Ros2Team, Ros2WorldLink,
    TeamTopics, run_agent,
};

use formation_transport_conformance::pilot::SuitePilots;
use formation_transport_conformance::world::{BEAMS, MAX_RANGE};

/// The robots' wheel separation \[m\].
const WHEEL_SEPARATION: f64 = 0.4;

/// The team on a free loopback port.
pub struct Ros2Rig {
    endpoint: Endpoint,
    launch: Launch,
}

/// Robot `robot`'s ROS 2 agent at `endpoint`, its node named after `pid`. Its own stale
/// window is long: what the suite tests is the world's.
fn settings(endpoint: &Endpoint, robot: usize, pid: u32) -> Ros2AgentSettings {
    let topics = TeamTopics::robot(robot);
    Ros2AgentSettings {
        connect: endpoint.clone(),
        connect_timeout: CONNECT_TIMEOUT,
        domain_id: 0,
        namespace: Namespace::new(&format!("/robot_{robot}")).expect("a namespace"),
        node_name: NodeName::new(&format!("agent_{pid}")).expect("a node name"),
        orientation_kind: OrientationKind::Odometry,
        decider: DeciderSettings {
            scan_topic: topics.scan.as_str().to_owned(),
            orientation_topic: topics.odometry.as_str().to_owned(),
            goal: TeamTopics::goal().map(GoalValue::Topic),
            contract: RingContract {
                beams: BEAMS,
                max_range: MAX_RANGE,
            },
            partial: PartialScan::Refuse,
            stale: Duration::from_secs(30),
            wheel_separation: WHEEL_SEPARATION,
        },
        wheels: formation_proto::WheelLimits::default(),
        scan: topics.scan,
        orientation: topics.odometry,
        cmd_vel: topics.cmd_vel,
    }
}

impl Rig for Ros2Rig {
    type World = Ros2WorldLink;
    const STRANGER_REFUSAL: &'static str = "is already driven by agent pid";
    const REFUSAL_TOLD: bool = false;
    const SHUTDOWN_STOPS_AGENTS: bool = false;

    fn new(robots: usize) -> Self {
        Ros2Rig {
            endpoint: loopback(),
            launch: Launch::new(unique_run_id("ros"), robots),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, clock: ClockMode) -> Ros2WorldLink {
        let team = Ros2Team {
            n_robots: self.robots(),
            domain_id: 0,
            wheel_separation: WHEEL_SEPARATION,
            max_range: MAX_RANGE,
            lossless: clock == ClockMode::Lockstep,
        };
        Ros2WorldLink::create(self.run(), team, &self.endpoint, self.secret().clone())
            .expect("the world's ROS 2 team")
    }

    /// A ROS 2 agent proves nothing: `secret` is not used.
    fn start(&self, robot: usize, pid: u32, _secret: &LaunchSecret, model: PathBuf) -> Agent {
        let settings = settings(&self.endpoint, robot, pid);
        Agent::spawn(move |gate, stop| {
            let pilots = Arc::new(SuitePilots { gate });
            let loaded = pilots.load(&model).map_err(|e| e.to_string())?;
            let agent = AgentLoop::new(pilots, model, loaded, None, Arc::new(SystemClock));
            run_agent(&settings, agent, &stop).map_err(|e| error_chain(&e))
        })
    }

    /// The router's port is free again.
    fn assert_nothing_left(&self) {
        assert_port_free(
            self.endpoint
                .as_str()
                .strip_prefix("tcp/")
                .expect("a TCP endpoint"),
        );
    }
}
