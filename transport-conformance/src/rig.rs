//! What the behaviours need from a transport ([`Rig`], and [`SwapRig`] where swaps travel), and
//! the in-memory bus on threads ([`MemoryRig`]), the reference every transport is held to. Each
//! transport crate has its own rig in its `tests/conformance.rs`.
//!
//! A rig is the launch: it makes the world's link and starts agents (each on a thread, known by
//! the pid the test gives it, since they all live in this process), and says at the end whether
//! the run left anything behind.

use std::path::PathBuf;
use std::thread::JoinHandle;

use formation_proto::wire::{RunId, SwapReply, SwapRequest};
use formation_runtime::ClockMode;
use formation_runtime::auth::LaunchSecret;
use formation_runtime::link::WorldLink;
use formation_runtime::memory::{MemoryBus, MemoryWorldLink};
use formation_test_kit::unique_run_id;

use crate::agent::{Agent, CONNECT_TIMEOUT, loop_agent};
use crate::pilot::Models;

/// What every rig's launch has: a run id, a launch secret, a team size and the suite's models.
pub struct Launch {
    run: RunId,
    secret: LaunchSecret,
    robots: usize,
    models: Models,
}

impl Launch {
    /// Run `run` of `robots` robots with a fresh secret.
    pub fn new(run: RunId, robots: usize) -> Launch {
        Launch::with_secret(
            run,
            robots,
            LaunchSecret::generate().expect("a launch secret"),
        )
    }

    /// Run `run` of `robots` robots with `secret`.
    pub fn with_secret(run: RunId, robots: usize, secret: LaunchSecret) -> Launch {
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
    /// How many robots the run has.
    fn robots(&self) -> usize {
        self.launch().robots
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

/// The pids the suite gives its agents begin with these digits (`formation-agent-<pid>-…` names
/// an agent's model folder over Zenoh).
pub const SUITE_PID_PREFIX: u32 = 7770;

/// A pid of the suite: [`SUITE_PID_PREFIX`] followed by `n` (0 to 99).
pub fn suite_pid(n: u32) -> u32 {
    SUITE_PID_PREFIX * 100 + n
}
