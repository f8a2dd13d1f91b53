//! iceoryx2 held to the transport conformance suite (`formation-transport-conformance`), in a
//! namespace of each test's own that the rig checks is empty before and after.

use std::path::PathBuf;
use std::thread::JoinHandle;

use formation_proto::wire::{SwapReply, SwapRequest};
use formation_runtime::ClockMode;
use formation_runtime::agent::error_chain;
use formation_runtime::auth::LaunchSecret;
use formation_test_kit::unique_run_id;
use formation_transport_conformance::agent::{Agent, CONNECT_TIMEOUT, loop_agent};
use formation_transport_conformance::rig::{Launch, Rig, SwapRig};
use formation_transport_iceoryx2::naming::RunNamespace;
use formation_transport_iceoryx2::{IceoryxAgentLink, IceoryxWorldLink};

formation_transport_conformance::conformance_tests!(IceoryxRig, swap);

/// iceoryx2 in a namespace of the test's own.
pub struct IceoryxRig {
    namespace: RunNamespace,
    launch: Launch,
}

impl IceoryxRig {
    fn namespace(&self) -> &RunNamespace {
        &self.namespace
    }
}

impl Drop for IceoryxRig {
    fn drop(&mut self) {
        // Never leak into other tests, even when this one failed.
        let _ = self.namespace.remove_all();
    }
}

impl Rig for IceoryxRig {
    type World = IceoryxWorldLink;

    fn new(robots: usize) -> Self {
        let run = unique_run_id("iox");
        let namespace = RunNamespace::new(&run);
        let before = namespace.leftovers();
        assert!(
            before.is_empty(),
            "run {run} has files before it started: {before:?}"
        );
        IceoryxRig {
            namespace,
            launch: Launch::new(run, robots),
        }
    }

    fn launch(&self) -> &Launch {
        &self.launch
    }

    fn world(&self, _: ClockMode) -> IceoryxWorldLink {
        IceoryxWorldLink::create(self.namespace(), self.robots())
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
        let shm = self.namespace.shared_memory_but_management();
        assert!(
            shm.is_empty(),
            "shared memory left after a clean exit: {shm:#?}"
        );
        self.namespace
            .remove_all()
            .expect("removing the run's namespace");
        let mut left = self.namespace.leftovers();
        let lock = self.namespace.lock_path();
        if lock.exists() {
            left.push(lock);
        }
        assert!(left.is_empty(), "the run left files behind: {left:#?}");
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
