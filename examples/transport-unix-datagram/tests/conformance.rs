//! The Unix datagram transport held to the transport conformance suite
//! (`formation-transport-conformance`), each test in a run folder of its own under a scratch
//! folder of its own (the endpoint), which the rig checks is gone after the run.

use std::path::PathBuf;
use std::thread::JoinHandle;

use formation_example_transport_unix_datagram::folder::RunFolder;
use formation_example_transport_unix_datagram::{
    DatagramAgentLink, DatagramWorldLink, UnixDatagram,
};
use formation_proto::wire::{SwapReply, SwapRequest};
use formation_runtime::ClockMode;
use formation_runtime::agent::error_chain;
use formation_runtime::auth::LaunchSecret;
use formation_runtime::plugin::{AgentSite, RunSite, TransportPlugin, WorldSite};
use formation_test_kit::{TempDir, unique_run_id};
use formation_transport_conformance::agent::{Agent, CONNECT_TIMEOUT, loop_agent};
use formation_transport_conformance::rig::{Launch, Rig, SwapRig};

formation_transport_conformance::conformance_tests!(DatagramRig, swap);

/// A run of the transport under a scratch folder of the test's own.
pub struct DatagramRig {
    base: TempDir,
    launch: Launch,
}

impl DatagramRig {
    /// The endpoint: the scratch folder.
    fn endpoint(&self) -> String {
        self.base.path().display().to_string()
    }

    fn folder(&self) -> RunFolder {
        let endpoint = self.endpoint();
        RunFolder::locate(&RunSite {
            run: self.run(),
            endpoint: Some(&endpoint),
        })
        .expect("the run's folder")
    }
}

impl Rig for DatagramRig {
    type World = DatagramWorldLink;

    fn new(robots: usize) -> Self {
        DatagramRig {
            base: TempDir::new("udg"),
            launch: Launch::new(unique_run_id("udg"), robots),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, _: ClockMode) -> DatagramWorldLink {
        let endpoint = self.endpoint();
        DatagramWorldLink::create(&WorldSite {
            run: RunSite {
                run: self.run(),
                endpoint: Some(&endpoint),
            },
            robots: self.robots(),
        })
        .expect("the world's link")
    }

    fn start(&self, robot: usize, pid: u32, secret: &LaunchSecret, model: PathBuf) -> Agent {
        let (run, secret, endpoint) = (self.run().clone(), secret.clone(), self.endpoint());
        Agent::spawn(move |gate, stop| {
            let connect = || {
                DatagramAgentLink::connect(&AgentSite {
                    run: RunSite {
                        run: &run,
                        endpoint: Some(&endpoint),
                    },
                    robot,
                    pid,
                    secret: &secret,
                    connect_timeout: CONNECT_TIMEOUT,
                })
            };
            loop_agent(connect, (&model, pid, run.as_str()), gate, &stop)
        })
    }

    /// The world took the run's folder with it; only the user's empty folder above it stays,
    /// which the scratch folder takes.
    fn assert_nothing_left(&self) {
        let folder = self.folder();
        assert!(
            !folder.dir().exists(),
            "the run left {} behind: {:?}",
            folder.dir().display(),
            std::fs::read_dir(folder.dir())
                .map(|d| d.flatten().map(|e| e.path()).collect::<Vec<_>>())
        );
        let user = folder.dir().parent().expect("the user's folder");
        let others: Vec<_> = std::fs::read_dir(user)
            .expect("the user's folder")
            .flatten()
            .map(|e| e.path())
            .collect();
        assert!(others.is_empty(), "left in {}: {others:?}", user.display());
    }
}

impl SwapRig for DatagramRig {
    fn swap(&self, request: SwapRequest) -> JoinHandle<Result<SwapReply, String>> {
        let (run, endpoint) = (self.run().clone(), self.endpoint());
        std::thread::spawn(move || {
            let site = RunSite {
                run: &run,
                endpoint: Some(&endpoint),
            };
            UnixDatagram
                .request_swap(&site, &request, CONNECT_TIMEOUT)
                .map_err(|e| error_chain(e.as_ref()))
        })
    }
}
