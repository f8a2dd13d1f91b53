//! Both links over channels in one process ([`MemoryBus`]), for tests of the exchange and the
//! agent loop without processes or shared memory.
//!
//! A [`MemoryBus`] holds every queue of one run: per robot a lobby (hellos, welcomes) and the
//! channels of its current incarnation, and the swap channel. [`MemoryBus::world_link`] is the
//! world's end ([`WorldLink`]), [`MemoryBus::agent_link`] an agent's end on the incarnation its
//! accepted greeting named ([`AgentLink`]). As over iceoryx2, what an agent of a closed
//! incarnation sends reaches nobody, and the world's messages reach only the current one.
//!
//! The bus also plays the operating system: [`MemoryBus::kill`] makes an agent process dead (the
//! world learns it from [`WorldLink::agent_alive`] and once from [`WorldLink::dead_agents`]),
//! [`MemoryBus::terminate_world`] a termination signal, [`MemoryBus::end_world`] the world's exit.
//!
//! A bus made with [`MemoryBus::new`] never blocks on other threads: a wait with nothing queued
//! first runs the world link's wait hook ([`MemoryWorldLink::on_wait`], where a test runs its
//! agents), then lets the timeout pass on the bus's [`Clock`], which for a
//! [`FakeClock`](crate::clock::FakeClock) is instant. So a whole run is one deterministic thread.
//! A bus made with [`MemoryBus::threaded`] is a transport like the others for a world and agents
//! on threads of their own: its waits block until something arrives, and [`MemoryBus::connect`]
//! greets and waits for the welcome as an agent's link does (the conformance suite,
//! `formation-transport-conformance`, runs on it as its reference).

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use crate::auth::LaunchSecret;
use formation_proto::exit::TerminationSignal;
use formation_proto::wire::{
    AgentStatus, CmdMsg, ControlRequest, RunId, ScanMsg, SwapReply, SwapRequest, Welcome,
};

use crate::clock::{Clock, SystemClock};
use crate::link::{AgentLink, AgentLinkError, Hello, Wake, WorldLink, WorldLinkError, WorldResult};

/// The queues of one incarnation of a robot.
#[derive(Debug, Default)]
struct Incarnation {
    id: u64,
    scans: VecDeque<ScanMsg>,
    control: VecDeque<ControlRequest>,
    cmds: VecDeque<CmdMsg>,
    statuses: VecDeque<AgentStatus>,
}

#[derive(Debug, Default)]
struct Lobby {
    hellos: VecDeque<Hello>,
    welcomes: HashMap<u64, Welcome>,
}

#[derive(Debug)]
struct BusState {
    lobbies: Vec<Lobby>,
    robots: Vec<Option<Incarnation>>,
    swap_requests: VecDeque<SwapRequest>,
    swap_replies: Vec<SwapReply>,
    /// Agent processes that died and the world has not been told of yet.
    unreported_dead: Vec<(usize, u32)>,
    /// Every agent process that died.
    dead: HashSet<(usize, u32)>,
    /// How many times the world asked which agents died.
    liveness_asks: usize,
    world_alive: bool,
    terminate_world: Option<TerminationSignal>,
    /// Per robot: a termination signal its agent received, seen at its next wait.
    terminate_agents: Vec<Option<TerminationSignal>>,
    next_nonce: u64,
}

impl BusState {
    fn incarnation(&mut self, robot: usize, id: u64) -> Option<&mut Incarnation> {
        self.robots
            .get_mut(robot)?
            .as_mut()
            .filter(|incarnation| incarnation.id == id)
    }

    fn world_has_mail(&self) -> bool {
        self.lobbies.iter().any(|l| !l.hellos.is_empty())
            || !self.swap_requests.is_empty()
            || self
                .robots
                .iter()
                .flatten()
                .any(|i| !i.cmds.is_empty() || !i.statuses.is_empty())
    }
}

/// The bus's state and the condition variable every change rings.
struct Shared {
    state: Mutex<BusState>,
    changed: Condvar,
}

/// Every queue of one in-memory run, shared by the world's link and the agents' links.
#[derive(Clone)]
pub struct MemoryBus {
    shared: Arc<Shared>,
    clock: Arc<dyn Clock>,
    /// Whether waits block until something changes ([`MemoryBus::threaded`]) instead of letting
    /// the timeout pass on the clock at once.
    blocking: bool,
}

impl MemoryBus {
    /// A bus for `n_robots` robots whose waits let time pass on `clock`.
    pub fn new(n_robots: usize, clock: Arc<dyn Clock>) -> MemoryBus {
        let state = BusState {
            lobbies: (0..n_robots).map(|_| Lobby::default()).collect(),
            robots: (0..n_robots).map(|_| None).collect(),
            swap_requests: VecDeque::new(),
            swap_replies: Vec::new(),
            unreported_dead: Vec::new(),
            dead: HashSet::new(),
            liveness_asks: 0,
            world_alive: true,
            terminate_world: None,
            terminate_agents: vec![None; n_robots],
            next_nonce: 1,
        };
        MemoryBus {
            shared: Arc::new(Shared {
                state: Mutex::new(state),
                changed: Condvar::new(),
            }),
            clock,
            blocking: false,
        }
    }

    /// A bus for `n_robots` robots whose world and agents run on threads of their own, on the
    /// system clock: a wait blocks until something it waits for arrives, or its timeout passes.
    pub fn threaded(n_robots: usize) -> MemoryBus {
        MemoryBus {
            blocking: true,
            ..MemoryBus::new(n_robots, Arc::new(SystemClock))
        }
    }

    fn lock(&self) -> MutexGuard<'_, BusState> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Changes the bus's state with `change` and wakes every waiter.
    fn update<R>(&self, change: impl FnOnce(&mut BusState) -> R) -> R {
        let result = change(&mut self.lock());
        self.ring();
        result
    }

    /// Wakes every waiter: something changed.
    fn ring(&self) {
        self.shared.changed.notify_all();
    }

    /// Waits until `ready` holds or `timeout` passes: on a threaded bus by blocking, else by
    /// letting the timeout pass on the clock (instant for a fake clock).
    fn wait_for(&self, timeout: Duration, ready: impl Fn(&BusState) -> bool) {
        if !self.blocking {
            self.clock.sleep(timeout);
            return;
        }
        let guard = self.lock();
        let _unused = self
            .shared
            .changed
            .wait_timeout_while(guard, timeout, |state| !ready(state));
    }

    /// Connects an agent process `pid` to robot `robot` of run `run` as a transport's agent link
    /// does: greets proving `secret`, waits up to `timeout` for the world's answer, and returns
    /// its end of the incarnation the world opened; a refusal is an error at once.
    pub fn connect(
        &self,
        robot: usize,
        pid: u32,
        (run, secret): (&RunId, &LaunchSecret),
        timeout: Duration,
    ) -> Result<MemoryAgentLink, AgentLinkError> {
        let started = self.clock.now();
        let nonce = self.greet(robot, pid, run, secret);
        loop {
            match self.welcome(robot, nonce) {
                Some(Welcome::Accepted) => return Ok(self.agent_link(robot, nonce)),
                Some(Welcome::Refused(reason)) => {
                    return Err(AgentLinkError::Refused { robot, reason });
                }
                None => {}
            }
            let waited = self.clock.now().saturating_duration_since(started);
            if waited >= timeout {
                return Err(AgentLinkError::NoWelcome {
                    robot,
                    run: run.to_string(),
                    waited_s: waited.as_secs_f64(),
                });
            }
            self.wait_for(timeout - waited, |state| {
                state
                    .lobbies
                    .get(robot)
                    .is_some_and(|lobby| lobby.welcomes.contains_key(&nonce))
            });
        }
    }

    /// The world's end.
    pub fn world_link(&self) -> MemoryWorldLink {
        MemoryWorldLink {
            bus: self.clone(),
            n_robots: self.lock().lobbies.len(),
            hook: None,
        }
    }

    /// Sends a hello in robot `robot`'s lobby as it is (a test may forge one).
    pub fn send_hello(&self, robot: usize, hello: Hello) {
        self.update(|state| {
            if let Some(lobby) = state.lobbies.get_mut(robot) {
                lobby.hellos.push_back(hello);
            }
        });
    }

    /// Asks to drive robot `robot` of run `run` as process `pid`, proving `secret` with a fresh
    /// nonce; returns the nonce, which names the incarnation if the world accepts.
    pub fn greet(&self, robot: usize, pid: u32, run: &RunId, secret: &LaunchSecret) -> u64 {
        let nonce = {
            let mut state = self.lock();
            state.next_nonce += 1;
            state.next_nonce
        };
        self.send_hello(
            robot,
            Hello {
                pid,
                nonce,
                proof: secret.prove(run, robot, pid, nonce),
            },
        );
        nonce
    }

    /// The world's answer to the hello with `nonce` in robot `robot`'s lobby, once it gave one.
    pub fn welcome(&self, robot: usize, nonce: u64) -> Option<Welcome> {
        self.lock().lobbies.get_mut(robot)?.welcomes.remove(&nonce)
    }

    /// An agent's end on robot `robot`'s incarnation `nonce` (its accepted greeting's nonce).
    pub fn agent_link(&self, robot: usize, nonce: u64) -> MemoryAgentLink {
        MemoryAgentLink {
            bus: self.clone(),
            robot,
            incarnation: nonce,
        }
    }

    /// Agent process `pid` of robot `robot` dies.
    pub fn kill(&self, robot: usize, pid: u32) {
        self.update(|state| {
            if state.dead.insert((robot, pid)) {
                state.unreported_dead.push((robot, pid));
            }
        });
    }

    /// How many times the world asked which agents died ([`WorldLink::dead_agents`]).
    pub fn liveness_asks(&self) -> usize {
        self.lock().liveness_asks
    }

    /// The world receives a termination signal: its next wait ends with
    /// [`WorldLinkError::Terminated`].
    pub fn terminate_world(&self, signal: TerminationSignal) {
        self.update(|state| state.terminate_world = Some(signal));
    }

    /// Robot `robot`'s agent receives a termination signal: its next wait ends with
    /// [`Wake::Terminated`].
    pub fn terminate_agent(&self, robot: usize, signal: TerminationSignal) {
        self.update(|state| {
            if let Some(slot) = state.terminate_agents.get_mut(robot) {
                *slot = Some(signal);
            }
        });
    }

    /// The world process is gone: agents see it in [`AgentLink::world_alive`].
    pub fn end_world(&self) {
        self.update(|state| state.world_alive = false);
    }

    /// A user's swap request (what `formation swap` sends).
    pub fn request_swap(&self, request: SwapRequest) {
        self.update(|state| state.swap_requests.push_back(request));
    }

    /// Waits up to `timeout` for the world's reply to swap request `request_id` and takes it
    /// (what `formation swap` does).
    pub fn await_swap_reply(&self, request_id: u64, timeout: Duration) -> Option<SwapReply> {
        let started = self.clock.now();
        loop {
            {
                let mut state = self.lock();
                let found = state
                    .swap_replies
                    .iter()
                    .position(|r| r.request_id == request_id);
                if let Some(index) = found {
                    return Some(state.swap_replies.remove(index));
                }
            }
            let waited = self.clock.now().saturating_duration_since(started);
            if waited >= timeout {
                return None;
            }
            self.wait_for(timeout - waited, |state| {
                state
                    .swap_replies
                    .iter()
                    .any(|r| r.request_id == request_id)
            });
        }
    }

    /// The swap replies the world sent since the last call.
    pub fn take_swap_replies(&self) -> Vec<SwapReply> {
        std::mem::take(&mut self.lock().swap_replies)
    }
}

/// The world's end of a [`MemoryBus`].
pub struct MemoryWorldLink {
    bus: MemoryBus,
    n_robots: usize,
    hook: Option<Box<dyn FnMut()>>,
}

impl MemoryWorldLink {
    /// The error for a robot index past this bus's team.
    fn no_such_robot(&self, robot: usize) -> WorldLinkError {
        WorldLinkError::NoSuchRobot {
            robot,
            robots: self.n_robots,
        }
    }

    /// Runs `f` under the bus lock on robot `robot`'s open incarnation, if it has one (else
    /// gives `T::default()`); a robot the bus does not have is an error.
    fn with_incarnation<T: Default>(
        &self,
        robot: usize,
        f: impl FnOnce(&mut Incarnation) -> T,
    ) -> WorldResult<T> {
        let mut state = self.bus.lock();
        let slot = state
            .robots
            .get_mut(robot)
            .ok_or_else(|| self.no_such_robot(robot))?;
        Ok(slot.as_mut().map(f).unwrap_or_default())
    }

    /// Runs `hook` whenever the world would wait with nothing queued, before time passes: a
    /// test runs its agents there, so one thread plays the whole launch.
    pub fn on_wait(&mut self, hook: impl FnMut() + 'static) {
        self.hook = Some(Box::new(hook));
    }
}

impl WorldLink for MemoryWorldLink {
    fn n_robots(&self) -> usize {
        self.bus.lock().lobbies.len()
    }

    fn drain_hellos(&mut self, robot: usize, sink: &mut dyn FnMut(Hello)) -> WorldResult {
        let hellos: Vec<Hello> = {
            let mut state = self.bus.lock();
            let lobby = state
                .lobbies
                .get_mut(robot)
                .ok_or_else(|| self.no_such_robot(robot))?;
            lobby.hellos.drain(..).collect()
        };
        hellos.into_iter().for_each(sink);
        Ok(())
    }

    fn answer_hello(&mut self, robot: usize, nonce: u64, welcome: &Welcome) -> WorldResult {
        let mut state = self.bus.lock();
        let lobby = state
            .lobbies
            .get_mut(robot)
            .ok_or_else(|| self.no_such_robot(robot))?;
        lobby.welcomes.insert(nonce, welcome.clone());
        drop(state);
        self.bus.ring();
        Ok(())
    }

    fn open_incarnation(&mut self, robot: usize, incarnation: u64) -> WorldResult {
        let mut state = self.bus.lock();
        let slot = state
            .robots
            .get_mut(robot)
            .ok_or_else(|| self.no_such_robot(robot))?;
        *slot = Some(Incarnation {
            id: incarnation,
            ..Incarnation::default()
        });
        drop(state);
        self.bus.ring();
        Ok(())
    }

    fn close_incarnation(&mut self, robot: usize) {
        if let Some(slot) = self.bus.lock().robots.get_mut(robot) {
            *slot = None;
        }
    }

    fn publish_scan(&mut self, robot: usize, msg: &ScanMsg) -> WorldResult {
        self.with_incarnation(robot, |incarnation| incarnation.scans.push_back(*msg))?;
        self.bus.ring();
        Ok(())
    }

    fn send_control(&mut self, robot: usize, request: &ControlRequest) -> WorldResult {
        self.with_incarnation(robot, |incarnation| {
            incarnation.control.push_back(request.clone())
        })?;
        self.bus.ring();
        Ok(())
    }

    fn wait(&mut self, timeout: Duration) -> WorldResult {
        let ready = |bus: &MemoryBus| -> WorldResult<bool> {
            let state = bus.lock();
            if let Some(signal) = state.terminate_world {
                return Err(WorldLinkError::Terminated(signal));
            }
            Ok(state.world_has_mail())
        };
        if ready(&self.bus)? {
            return Ok(());
        }
        if let Some(hook) = &mut self.hook {
            hook();
            if ready(&self.bus)? {
                return Ok(());
            }
        }
        self.bus.wait_for(timeout, |state| {
            state.terminate_world.is_some() || state.world_has_mail()
        });
        ready(&self.bus).map(|_| ())
    }

    fn drain_commands(&mut self, robot: usize, sink: &mut dyn FnMut(CmdMsg)) -> WorldResult {
        let cmds: Vec<CmdMsg> =
            self.with_incarnation(robot, |incarnation| incarnation.cmds.drain(..).collect())?;
        cmds.into_iter().for_each(sink);
        Ok(())
    }

    fn drain_statuses(&mut self, robot: usize, sink: &mut dyn FnMut(AgentStatus)) -> WorldResult {
        let statuses: Vec<AgentStatus> = self.with_incarnation(robot, |incarnation| {
            incarnation.statuses.drain(..).collect()
        })?;
        statuses.into_iter().for_each(sink);
        Ok(())
    }

    fn agent_alive(&mut self, robot: usize, pid: u32) -> WorldResult<bool> {
        Ok(!self.bus.lock().dead.contains(&(robot, pid)))
    }

    fn dead_agents(&mut self) -> Result<Vec<(usize, u32)>, WorldLinkError> {
        let mut state = self.bus.lock();
        state.liveness_asks += 1;
        let mut dead = std::mem::take(&mut state.unreported_dead);
        drop(state);
        dead.sort_unstable();
        dead.dedup();
        Ok(dead)
    }

    fn drain_swap_requests(&mut self, sink: &mut dyn FnMut(SwapRequest)) -> WorldResult {
        let requests: Vec<SwapRequest> = self.bus.lock().swap_requests.drain(..).collect();
        requests.into_iter().for_each(sink);
        Ok(())
    }

    fn publish_swap_reply(&mut self, reply: &SwapReply) -> WorldResult {
        self.bus
            .update(|state| state.swap_replies.push(reply.clone()));
        Ok(())
    }
}

/// An agent's end of a [`MemoryBus`]: its robot's incarnation named by its accepted greeting.
pub struct MemoryAgentLink {
    bus: MemoryBus,
    robot: usize,
    incarnation: u64,
}

impl MemoryAgentLink {
    fn has_mail(&self) -> bool {
        let mut state = self.bus.lock();
        state
            .incarnation(self.robot, self.incarnation)
            .is_some_and(|i| !i.scans.is_empty() || !i.control.is_empty())
    }
}

impl AgentLink for MemoryAgentLink {
    fn wait(&mut self, timeout: Duration) -> Result<Wake, AgentLinkError> {
        let signal = self
            .bus
            .lock()
            .terminate_agents
            .get(self.robot)
            .copied()
            .flatten();
        if let Some(signal) = signal {
            return Ok(Wake::Terminated(signal));
        }
        if self.has_mail() {
            return Ok(Wake::Activity);
        }
        let (robot, incarnation) = (self.robot, self.incarnation);
        self.bus.wait_for(timeout, |state| {
            state
                .robots
                .get(robot)
                .and_then(Option::as_ref)
                .filter(|i| i.id == incarnation)
                .is_some_and(|i| !i.scans.is_empty() || !i.control.is_empty())
        });
        Ok(if self.has_mail() {
            Wake::Activity
        } else {
            Wake::Idle
        })
    }

    fn drain_control(
        &mut self,
        sink: &mut dyn FnMut(ControlRequest),
    ) -> Result<(), AgentLinkError> {
        let requests: Vec<ControlRequest> = {
            let mut state = self.bus.lock();
            state
                .incarnation(self.robot, self.incarnation)
                .map(|i| i.control.drain(..).collect())
                .unwrap_or_default()
        };
        requests.into_iter().for_each(sink);
        Ok(())
    }

    fn newest_scan(&mut self) -> Result<Option<ScanMsg>, AgentLinkError> {
        let mut state = self.bus.lock();
        Ok(state
            .incarnation(self.robot, self.incarnation)
            .and_then(|i| {
                let newest = i.scans.pop_back();
                i.scans.clear();
                newest
            }))
    }

    fn publish_command(&mut self, msg: &CmdMsg) -> Result<(), AgentLinkError> {
        self.bus.update(|state| {
            if let Some(i) = state.incarnation(self.robot, self.incarnation) {
                i.cmds.push_back(*msg);
            }
        });
        Ok(())
    }

    fn publish_status(&mut self, status: &AgentStatus) -> Result<(), AgentLinkError> {
        self.bus.update(|state| {
            if let Some(i) = state.incarnation(self.robot, self.incarnation) {
                i.statuses.push_back(status.clone());
            }
        });
        Ok(())
    }

    fn world_alive(&mut self) -> Result<bool, AgentLinkError> {
        Ok(self.bus.lock().world_alive)
    }
}
