//! What the behaviours need from a transport ([`Rig`], and [`SwapRig`] where swaps travel), and
//! one rig per link: the in-memory bus on threads ([`MemoryRig`]), iceoryx2 in a namespace of
//! the test's own ([`IceoryxRig`]), Zenoh on a free loopback port with the run's credentials
//! ([`ZenohRig`]), and the world as a ROS 2 team with ROS 2 agents ([`Ros2Rig`]).
//!
//! A rig is the launch: it makes the world's link and starts agents (each on a thread, known by
//! the pid the test gives it, since they all live in this process), and says at the end whether
//! the run left anything behind.

use std::path::PathBuf;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use formation_proto::wire::{RunId, SwapReply, SwapRequest};
use formation_runtime::ClockMode;
use formation_runtime::agent::error_chain;
use formation_runtime::link::WorldLink;
use formation_runtime::memory::{MemoryBus, MemoryWorldLink};
use formation_tests::{LaunchSecret, LeakCheck, TempDir, free_tcp_port, unique_run_id};
use formation_transport_iceoryx2::naming::RunNamespace;
use formation_transport_iceoryx2::{IceoryxAgentLink, IceoryxWorldLink};
use formation_transport_zenoh::{Endpoint, Login, WorldAccess, ZenohAgentLink, ZenohWorldLink};

use crate::agent::{Agent, CONNECT_TIMEOUT, loop_agent};
use crate::pilot::Models;

pub use ros2::Ros2Rig;

/// What every rig's launch has: a run id, a launch secret, a team size and the suite's models.
pub struct Launch {
    run: RunId,
    secret: LaunchSecret,
    robots: usize,
    models: Models,
}

impl Launch {
    /// Run `run` of `robots` robots with a fresh secret.
    fn new(run: RunId, robots: usize) -> Launch {
        Launch::with_secret(
            run,
            robots,
            LaunchSecret::generate().expect("a launch secret"),
        )
    }

    /// Run `run` of `robots` robots with `secret`.
    fn with_secret(run: RunId, robots: usize, secret: LaunchSecret) -> Launch {
        Launch {
            run,
            secret,
            robots,
            models: Models::new(),
        }
    }
}

/// A transport as the behaviours use it.
pub trait Rig {
    /// The world's link.
    type World: WorldLink;
    /// Part of the reason the world gives a candidate that proves another launch's secret. Over
    /// ROS 2 the world proves the secret for the first publisher on a robot's `cmd_vel`, so
    /// there a stranger is simply a second driver.
    const STRANGER_REFUSAL: &'static str = "did not prove this launch's secret";
    /// Whether a refused candidate is told (its connection fails with the reason). A ROS 2 node
    /// is never told: the team ignores its Twists.
    const REFUSAL_TOLD: bool = true;
    /// Whether the world's shutdown request stops the agents. A ROS 2 agent belongs to its
    /// robot, not to the run: its launcher stops it.
    const SHUTDOWN_STOPS_AGENTS: bool = true;

    /// A launch of `robots` robots, with a run id (and namespace or port) of its own.
    fn new(robots: usize) -> Self;
    /// Its run id, secret, team size and models.
    fn launch(&self) -> &Launch;
    /// The world's link, for a run under `clock`.
    fn world(&self, clock: ClockMode) -> Self::World;
    /// Starts an agent for `robot`, known as process `pid`, proving `secret`, driving with the
    /// model at `model`.
    fn start(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: PathBuf) -> Agent;
    /// Panics unless the run, its world and agents gone, left nothing behind.
    fn assert_nothing_left(&self);

    /// The run id.
    fn run(&self) -> &RunId {
        &self.launch().run
    }
    /// The launch secret.
    fn secret(&self) -> &LaunchSecret {
        &self.launch().secret
    }
    /// The suite's models.
    fn models(&self) -> &Models {
        &self.launch().models
    }
    /// Starts an agent for `robot`, known as process `pid`, proving `secret`, driving with model
    /// `model` (`slow`, `fast`).
    fn agent(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: &str) -> Agent {
        self.start(robot, pid, secret, self.models().path(model))
    }
}

/// A transport that carries swap requests, as `formation swap` sends them.
pub trait SwapRig: Rig {
    /// Sends `request` from a thread of its own and waits there for the world's reply.
    fn swap(&self, request: SwapRequest) -> JoinHandle<Result<SwapReply, String>>;
}

/// The in-memory bus, with the world and every agent on threads of their own.
pub struct MemoryRig {
    bus: MemoryBus,
    launch: Launch,
}

impl Rig for MemoryRig {
    type World = MemoryWorldLink;

    fn new(robots: usize) -> Self {
        MemoryRig {
            bus: MemoryBus::threaded(robots),
            launch: Launch::new(unique_run_id("mem"), robots),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, _: ClockMode) -> MemoryWorldLink {
        self.bus.world_link()
    }

    fn start(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: PathBuf) -> Agent {
        let (bus, run, secret) = (self.bus.clone(), self.run().clone(), secret.clone());
        Agent::spawn(move |gate, stop| {
            let connect = || bus.connect(robot, pid, (&run, &secret), CONNECT_TIMEOUT);
            let ending = loop_agent(connect, (&model, pid, run.as_str()), gate, &stop);
            // The process is gone: what the operating system would tell the world.
            bus.kill(robot, pid);
            ending
        })
    }

    /// An in-memory run holds nothing outside this process: there is nothing to leave.
    fn assert_nothing_left(&self) {}
}

impl SwapRig for MemoryRig {
    fn swap(&self, request: SwapRequest) -> JoinHandle<Result<SwapReply, String>> {
        let bus = self.bus.clone();
        std::thread::spawn(move || {
            let id = request.request_id;
            bus.request_swap(request);
            bus.await_swap_reply(id, CONNECT_TIMEOUT)
                .ok_or_else(|| format!("no reply to swap request {id}"))
        })
    }
}

/// iceoryx2 in a namespace of the test's own.
pub struct IceoryxRig {
    leaks: LeakCheck,
    launch: Launch,
}

impl IceoryxRig {
    fn namespace(&self) -> &RunNamespace {
        self.leaks.namespace()
    }
}

impl Rig for IceoryxRig {
    type World = IceoryxWorldLink;

    fn new(robots: usize) -> Self {
        let run = unique_run_id("iox");
        IceoryxRig {
            leaks: LeakCheck::new(&run),
            launch: Launch::new(run, robots),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, _: ClockMode) -> IceoryxWorldLink {
        IceoryxWorldLink::create(self.namespace(), self.launch.robots)
            .expect("the world's iceoryx2 link")
    }

    fn start(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: PathBuf) -> Agent {
        let (namespace, secret) = (self.namespace().clone(), secret.clone());
        Agent::spawn(move |gate, stop| {
            let run = namespace.run().to_string();
            let connect =
                || IceoryxAgentLink::connect_as(&namespace, robot, &secret, CONNECT_TIMEOUT, pid);
            loop_agent(connect, (&model, pid, &run), gate, &stop)
        })
    }

    /// Every node closed: iceoryx2 removed every service and port; only its management segment
    /// of the namespace stays (by design, across nodes), which the launcher removes at the end,
    /// as this does.
    fn assert_nothing_left(&self) {
        self.leaks.assert_only_management_left();
        self.namespace()
            .remove_all()
            .expect("removing the run's namespace");
        self.leaks.assert_clean();
    }
}

impl SwapRig for IceoryxRig {
    fn swap(&self, request: SwapRequest) -> JoinHandle<Result<SwapReply, String>> {
        let namespace = self.namespace().clone();
        std::thread::spawn(move || {
            formation_transport_iceoryx2::request_swap(&namespace, &request, CONNECT_TIMEOUT)
                .map_err(|e| error_chain(&e))
        })
    }
}

/// Zenoh on a free loopback port, the world's router checking the run's credentials.
pub struct ZenohRig {
    credentials: TempDir,
    endpoint: Endpoint,
    launch: Launch,
}

impl ZenohRig {
    /// The run's credentials folder.
    fn folder(&self) -> PathBuf {
        self.credentials.path().join("credentials")
    }

    /// The login in the credentials file `file`.
    fn login(&self, file: PathBuf) -> Login {
        formation_transport_zenoh::credentials::read_login(&file).expect("a login of the run")
    }
}

/// `tcp/127.0.0.1:<a free port>`.
fn loopback() -> Endpoint {
    Endpoint::parse(&format!("tcp/127.0.0.1:{}", free_tcp_port())).expect("a loopback endpoint")
}

impl Rig for ZenohRig {
    type World = ZenohWorldLink;

    fn new(robots: usize) -> Self {
        use formation_transport_zenoh::credentials;
        let dir = TempDir::new("zcreds");
        let folder = dir.path().join("credentials");
        credentials::create(&folder, robots).expect("the run's credentials");
        let secret = credentials::read_secret(&folder).expect("the run's launch secret");
        ZenohRig {
            credentials: dir,
            endpoint: loopback(),
            launch: Launch::with_secret(unique_run_id("zen"), robots, secret),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, _: ClockMode) -> ZenohWorldLink {
        let access = WorldAccess {
            dictionary_file: formation_transport_zenoh::credentials::check_passwords(
                &self.folder(),
            )
            .expect("the passwords file"),
            run: self.run().clone(),
            n_robots: self.launch.robots,
        };
        ZenohWorldLink::create(
            self.run(),
            self.launch.robots,
            &self.endpoint,
            Some(&access),
        )
        .expect("the world's Zenoh link")
    }

    fn start(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: PathBuf) -> Agent {
        let robot_file = formation_transport_zenoh::credentials::robot_file(&self.folder(), robot);
        let login = self.login(robot_file);
        let (endpoint, run, secret) = (self.endpoint.clone(), self.run().clone(), secret.clone());
        Agent::spawn(move |gate, stop| {
            let connect = || {
                let to = (&run, robot);
                ZenohAgentLink::connect_as(
                    &endpoint,
                    Some(&login),
                    to,
                    &secret,
                    CONNECT_TIMEOUT,
                    pid,
                )
            };
            loop_agent(connect, (&model, pid, run.as_str()), gate, &stop)
        })
    }

    /// The world's port is free again, and no agent left a folder of models.
    fn assert_nothing_left(&self) {
        assert_port_free(&self.endpoint);
        let prefix = format!("formation-agent-{SUITE_PID_PREFIX}");
        let left: Vec<_> = std::fs::read_dir(std::env::temp_dir())
            .expect("the temporary folder")
            .flatten()
            .map(|entry| entry.file_name().to_string_lossy().into_owned())
            .filter(|name| name.starts_with(&prefix))
            .collect();
        assert!(left.is_empty(), "model folders left behind: {left:?}");
    }
}

impl SwapRig for ZenohRig {
    fn swap(&self, request: SwapRequest) -> JoinHandle<Result<SwapReply, String>> {
        use formation_transport_zenoh::{credentials, swap};
        let operator = self.login(credentials::operator_file(&self.folder()));
        let (endpoint, run) = (self.endpoint.clone(), self.run().clone());
        std::thread::spawn(move || {
            let model = std::fs::read(&request.path).map_err(|e| e.to_string())?;
            swap::request_swap(
                &endpoint,
                Some(&operator),
                &run,
                &request,
                &model,
                CONNECT_TIMEOUT,
            )
            .map_err(|e| error_chain(&e))
        })
    }
}

/// The pids the suite gives its agents begin with these digits (`formation-agent-<pid>-…` names
/// an agent's model folder over Zenoh).
pub const SUITE_PID_PREFIX: u32 = 7770;

/// A pid of the suite: [`SUITE_PID_PREFIX`] followed by `n` (0 to 99).
pub fn suite_pid(n: u32) -> u32 {
    SUITE_PID_PREFIX * 100 + n
}

/// Panics unless nothing listens on `endpoint`'s port within a few seconds of its world going
/// (a router closes its listener on a thread of its own).
fn assert_port_free(endpoint: &Endpoint) {
    let address = endpoint
        .as_str()
        .strip_prefix("tcp/")
        .expect("a TCP endpoint");
    let deadline = Instant::now() + Duration::from_secs(5);
    while std::net::TcpListener::bind(address).is_err() {
        assert!(
            Instant::now() < deadline,
            "{address} is still taken after the world went"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

mod ros2 {
    //! The world as a ROS 2 team, and ROS 2 agents (`formation_transport_ros2::run_agent`) on
    //! the team's topics.

    use super::*;
    use formation_ros2::{Namespace, NodeName, PartialScan, RingContract};
    use formation_transport_ros2::{
        DeciderSettings, GoalValue, OrientationKind, Ros2AgentSettings, Ros2Team, Ros2WorldLink,
        TeamTopics, run_agent,
    };

    use crate::pilot::SuitePilot;
    use crate::world::{BEAMS, MAX_RANGE};

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
                n_robots: self.launch.robots,
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
                let mut pilot = SuitePilot::load(&model, gate).map_err(|e| e.to_string())?;
                run_agent(&settings, &mut pilot, &stop).map_err(|e| error_chain(&e))
            })
        }

        /// The router's port is free again.
        fn assert_nothing_left(&self) {
            assert_port_free(&self.endpoint);
        }
    }
}
