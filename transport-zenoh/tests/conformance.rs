//! Zenoh held to the transport conformance suite (`formation-transport-conformance`): the world's
//! router on a free loopback port of each test's own, checking the run's credentials.

use std::path::PathBuf;
use std::thread::JoinHandle;

use formation_proto::wire::{SwapReply, SwapRequest};
use formation_runtime::ClockMode;
use formation_runtime::agent::error_chain;
use formation_runtime::auth::LaunchSecret;
use formation_test_kit::{TempDir, assert_port_free, free_tcp_port, unique_run_id};
use formation_transport_conformance::agent::{Agent, CONNECT_TIMEOUT, loop_agent};
use formation_transport_conformance::rig::{Launch, Rig, SUITE_PID_PREFIX, SwapRig};
use formation_transport_zenoh::{Endpoint, Login, WorldAccess, ZenohAgentLink, ZenohWorldLink};

formation_transport_conformance::conformance_tests!(ZenohRig, swap);

/// `HOST:PORT` of a `tcp/` endpoint.
fn loopback_address(endpoint: &Endpoint) -> &str {
    endpoint
        .as_str()
        .strip_prefix("tcp/")
        .expect("a TCP endpoint")
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
            n_robots: self.robots(),
        };
        ZenohWorldLink::create(self.run(), self.robots(), &self.endpoint, Some(&access))
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
        assert_port_free(loopback_address(&self.endpoint));
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
