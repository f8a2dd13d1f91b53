//! Unit tests of the exchange and the agent loop together, with no process and no shared memory:
//! one thread plays a whole launch over the in-memory link ([`crate::memory`]) on a fake clock.
//! The world's wait hook runs the agents, so every outcome below is deterministic.

use std::cell::RefCell;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::auth::LaunchSecret;
use formation_proto::control::{Controller, Observation};
use formation_proto::exit::TerminationSignal;
use formation_proto::wire::{
    RunId, SwapOutcome, SwapReply, SwapRequest, TickOutcome, Welcome, WorldEvent,
};
use formation_proto::{Goal, LidarSpec, Pose, WheelCmd, WheelLimits};

use crate::agent::{AgentExit, AgentLoop, BoxError, Pilot, PilotMaker};
use crate::clock::{Clock, FakeClock};
use crate::exchange::{AgentsController, ExchangeSettings, StopReason};
use crate::faults::Fault;
use crate::memory::{MemoryAgentLink, MemoryBus, MemoryWorldLink};
use crate::settings::{ClockMode, RuntimeSettings};

const BEAMS: usize = 8;
const DT: Duration = Duration::from_millis(50);

/// A model of the test pilots: its file name is its id; `fast*` drives at 0.5, others at 0.1,
/// and `bad*` does not load.
#[derive(Debug, Clone)]
struct TestModel {
    id: String,
    speed: f64,
}

struct TestPilots;

struct TestPilot {
    model: TestModel,
    /// The wheel limits of the episode: the test pilot caps its speed at the acceleration
    /// limit, so a test sees that the limits reached the agent.
    wheels: WheelLimits,
}

impl PilotMaker for TestPilots {
    type Model = TestModel;
    type Pilot = TestPilot;

    fn load(&self, path: &Path) -> Result<TestModel, BoxError> {
        let id = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        if id.starts_with("bad") {
            return Err("not a model".into());
        }
        let speed = if id.starts_with("fast") { 0.5 } else { 0.1 };
        Ok(TestModel { id, speed })
    }

    fn model_id<'m>(&self, model: &'m TestModel) -> &'m str {
        &model.id
    }

    fn pilot(&self, model: TestModel, _: LidarSpec) -> Result<TestPilot, BoxError> {
        Ok(TestPilot {
            model,
            wheels: WheelLimits::default(),
        })
    }
}

impl Pilot for TestPilot {
    type Model = TestModel;

    fn model_id(&self) -> &str {
        &self.model.id
    }

    fn perceive(&mut self, ranges: &[f32], _goal: &Goal) -> Result<(), BoxError> {
        if ranges.len() == BEAMS {
            Ok(())
        } else {
            Err("wrong scan".into())
        }
    }

    fn decide(&mut self, _: f64, _: &Goal) -> Result<WheelCmd, BoxError> {
        let speed = self
            .wheels
            .max_accel
            .map_or(self.model.speed, |cap| self.model.speed.min(cap));
        Ok(WheelCmd {
            left: speed,
            right: speed,
        })
    }

    fn swap(&mut self, model: TestModel) -> Result<(), BoxError> {
        self.model = model;
        Ok(())
    }

    fn set_wheel_limits(&mut self, wheels: WheelLimits) {
        self.wheels = wheels;
    }
}

/// One simulated agent process.
struct SimAgent {
    pid: u32,
    link: MemoryAgentLink,
    agent: AgentLoop<TestPilots>,
    exit: Option<AgentExit>,
}

/// The agent processes of a simulated launch.
#[derive(Default)]
struct Agents {
    /// Greetings sent and not answered yet: robot, pid, nonce, fault.
    greeting: Vec<(usize, u32, u64, Option<Fault>)>,
    running: Vec<SimAgent>,
    /// Stopped processes (SIGSTOP, or a hang): alive, doing nothing.
    paused: HashSet<u32>,
    /// Refused greetings: robot, pid, reason.
    refused: Vec<(usize, u32, String)>,
}

/// A launch in one thread: the bus, the agents, the world's events.
struct Sim {
    clock: Arc<FakeClock>,
    bus: MemoryBus,
    run: RunId,
    secret: LaunchSecret,
    agents: Rc<RefCell<Agents>>,
    events: Rc<RefCell<Vec<WorldEvent>>>,
    stop: Arc<AtomicBool>,
    n_robots: usize,
}

fn lidar() -> LidarSpec {
    LidarSpec {
        beams: BEAMS,
        max_range: 10.0,
    }
}

/// Lets every running, unpaused agent handle what arrived, and finishes answered greetings.
fn run_agents(agents: &RefCell<Agents>, bus: &MemoryBus, clock: &Arc<FakeClock>) {
    let mut agents = agents.borrow_mut();
    let greeting = std::mem::take(&mut agents.greeting);
    for (robot, pid, nonce, fault) in greeting {
        match bus.welcome(robot, nonce) {
            None => agents.greeting.push((robot, pid, nonce, fault)),
            Some(Welcome::Refused(reason)) => agents.refused.push((robot, pid, reason)),
            Some(Welcome::Accepted) => {
                let path = PathBuf::from("slow-model");
                let pilots = Arc::new(TestPilots);
                let model = pilots.load(&path).expect("test model");
                let clock: Arc<dyn Clock> = clock.clone();
                let mut agent = AgentLoop::new(pilots, path, model, fault, clock)
                    .with_spin(Duration::from_millis(5));
                let mut link = bus.agent_link(robot, nonce);
                agent.greet(&mut link, pid).expect("hello");
                agents.running.push(SimAgent {
                    pid,
                    link,
                    agent,
                    exit: None,
                });
            }
        }
    }
    let Agents {
        running, paused, ..
    } = &mut *agents;
    for sim in running.iter_mut() {
        if sim.exit.is_none() && !paused.contains(&sim.pid) {
            sim.exit = sim.agent.handle(&mut sim.link).expect("agent step");
        }
    }
}

impl Sim {
    fn new(n_robots: usize) -> Sim {
        let fake = Arc::new(FakeClock::new());
        let shared: Arc<dyn Clock> = fake.clone();
        Sim {
            bus: MemoryBus::new(n_robots, shared),
            clock: fake,
            run: RunId::new("unit").unwrap(),
            secret: LaunchSecret::generate().unwrap(),
            agents: Rc::default(),
            events: Rc::default(),
            stop: Arc::new(AtomicBool::new(false)),
            n_robots,
        }
    }

    /// A simulation of `n_robots` agents (processes 10, 11, ...) connected to the exchange in
    /// `clock` mode.
    fn connected(n_robots: usize, clock: ClockMode) -> (Sim, AgentsController<'static>) {
        Sim::connected_with(n_robots, settings(clock), &[])
    }

    /// A simulation of `n_robots` agents (processes 10, 11, ..., the robots in `faults` with
    /// those faults) connected to the exchange with `runtime`. The world's link lives as long as
    /// the test.
    fn connected_with(
        n_robots: usize,
        runtime: RuntimeSettings,
        faults: &[(usize, Fault)],
    ) -> (Sim, AgentsController<'static>) {
        let sim = Sim::new(n_robots);
        let link = Box::leak(Box::new(sim.world_link()));
        let world = connected_with(&sim, link, runtime, faults);
        (sim, world)
    }

    /// Starts agent process `pid` for `robot` with this launch's secret.
    fn start(&self, robot: usize, pid: u32, fault: Option<Fault>) {
        let nonce = self.bus.greet(robot, pid, &self.run, &self.secret);
        self.agents
            .borrow_mut()
            .greeting
            .push((robot, pid, nonce, fault));
    }

    /// Starts process `pid` for `robot` proving another secret: an impostor.
    fn start_impostor(&self, robot: usize, pid: u32) {
        let stranger = LaunchSecret::generate().unwrap();
        let nonce = self.bus.greet(robot, pid, &self.run, &stranger);
        self.agents
            .borrow_mut()
            .greeting
            .push((robot, pid, nonce, None));
    }

    fn pause(&self, pid: u32) {
        self.agents.borrow_mut().paused.insert(pid);
    }

    fn resume(&self, pid: u32) {
        self.agents.borrow_mut().paused.remove(&pid);
    }

    /// Agent process `pid` of `robot` dies.
    fn kill(&self, robot: usize, pid: u32) {
        self.agents.borrow_mut().running.retain(|a| a.pid != pid);
        self.bus.kill(robot, pid);
    }

    /// The world's link, with the agents run in its waits.
    fn world_link(&self) -> MemoryWorldLink {
        let mut link = self.bus.world_link();
        let (agents, bus, clock) = (
            Rc::clone(&self.agents),
            self.bus.clone(),
            self.clock.clone(),
        );
        link.on_wait(move || run_agents(&agents, &bus, &clock));
        link
    }

    /// The exchange over `link` with these settings.
    fn world<'l>(
        &self,
        link: &'l mut MemoryWorldLink,
        runtime: RuntimeSettings,
    ) -> AgentsController<'l> {
        let settings = ExchangeSettings {
            runtime,
            stop: Arc::clone(&self.stop),
            run: self.run.clone(),
            secret: self.secret.clone(),
        };
        let events = Rc::clone(&self.events);
        let clock: Arc<dyn Clock> = self.clock.clone();
        AgentsController::new(
            link,
            settings,
            lidar(),
            clock,
            Box::new(move |e| events.borrow_mut().push(e.clone())),
        )
    }

    /// Plays tick `tick` and returns the commands the exchange chose.
    fn tick(&self, world: &mut AgentsController<'_>, tick: u64) -> Vec<WheelCmd> {
        let scans = vec![vec![5.0f32; BEAMS]; self.n_robots];
        let poses = vec![Pose::new(0.0, 0.0, 0.0); self.n_robots];
        let obs = observation(tick, &poses, &scans);
        let mut out = vec![WheelCmd::BRAKE; self.n_robots];
        world.commands(&obs, &mut out).expect("a tick");
        out
    }

    fn events(&self) -> Vec<WorldEvent> {
        self.events.borrow().clone()
    }

    fn exit_of(&self, pid: u32) -> Option<AgentExit> {
        let agents = self.agents.borrow();
        agents.running.iter().find(|a| a.pid == pid)?.exit.clone()
    }

    fn now(&self) -> Duration {
        self.clock.elapsed()
    }
}

fn settings(clock: ClockMode) -> RuntimeSettings {
    RuntimeSettings {
        clock,
        ..RuntimeSettings::DEFAULT
    }
}

/// Plays tick `tick` of three robots whose second agent (11) is paused: it brakes, and the tick
/// waits the whole 2 s command timeout for it (`why`).
fn assert_tick_waits_the_command_timeout(
    sim: &Sim,
    world: &mut AgentsController<'_>,
    tick: u64,
    why: &str,
) {
    let before = sim.now();
    assert_eq!(sim.tick(world, tick), vec![SLOW, WheelCmd::BRAKE, SLOW]);
    assert_eq!(sim.now() - before, Duration::from_millis(2000), "{why}");
}

/// A team of `n` agents (pids 10, 11, ...) connected and ready for episode 1.
fn connected_with<'l>(
    sim: &Sim,
    link: &'l mut MemoryWorldLink,
    runtime: RuntimeSettings,
    faults: &[(usize, Fault)],
) -> AgentsController<'l> {
    for robot in 0..sim.n_robots {
        let fault = faults.iter().find(|(r, _)| *r == robot).map(|(_, f)| *f);
        sim.start(robot, 10 + robot as u32, fault);
    }
    let mut world = sim.world(link, runtime);
    world
        .await_agents(Duration::from_secs(1))
        .expect("agents connect");
    world
        .begin_episode(DT.as_secs_f64(), lidar(), WheelLimits::default())
        .expect("agents ready");
    world
}

fn outcomes(world: &mut AgentsController<'_>, robot: usize) -> Vec<TickOutcome> {
    world.take_timings()[robot].outcome.clone()
}

const SLOW: WheelCmd = WheelCmd {
    left: 0.1,
    right: 0.1,
};

#[test]
fn lockstep_waits_for_a_late_agent_once_then_stops_waiting_until_it_answers_again() {
    use TickOutcome::{Fresh, Stale};
    let (sim, mut world) = Sim::connected(3, ClockMode::Lockstep);
    let start = sim.now();
    for tick in 0..2 {
        assert_eq!(sim.tick(&mut world, tick), vec![SLOW; 3]);
    }
    assert_eq!(sim.now(), start, "agents that answer at once cost no time");
    sim.pause(11);
    assert_tick_waits_the_command_timeout(
        &sim,
        &mut world,
        2,
        "the first missed tick waits the whole command timeout",
    );
    let before = sim.now();
    assert_eq!(sim.tick(&mut world, 3), vec![SLOW, WheelCmd::BRAKE, SLOW]);
    assert_eq!(sim.now(), before, "a lagging agent is not waited for");
    sim.resume(11);
    assert_eq!(sim.tick(&mut world, 4), vec![SLOW; 3]);
    assert_eq!(
        outcomes(&mut world, 1),
        // Stale: its newest command answers an older tick.
        [Fresh, Fresh, Stale, Stale, Fresh]
    );
    assert!(
        sim.events()
            .iter()
            .all(|e| !matches!(e, WorldEvent::AgentLost { .. }))
    );
    let readiness: Vec<usize> = sim
        .events()
        .iter()
        .filter_map(|e| match e {
            WorldEvent::AgentConnected {
                connected, robots, ..
            } => {
                assert_eq!(*robots, 3);
                Some(*connected)
            }
            _ => None,
        })
        .collect();
    assert_eq!(
        readiness,
        vec![1, 2, 3],
        "readiness counts every agent's hello once"
    );
}

#[test]
fn each_episode_tells_every_agent_its_robots_wheel_acceleration_limit() {
    let (sim, mut world) = Sim::connected(2, ClockMode::Lockstep);
    assert_eq!(sim.tick(&mut world, 0), vec![SLOW; 2]);
    // The test pilot caps its speed at the limit it was told.
    world
        .begin_episode(
            DT.as_secs_f64(),
            lidar(),
            WheelLimits {
                max_speed: Some(0.9),
                max_accel: Some(0.05),
            },
        )
        .expect("agents ready");
    let capped = WheelCmd {
        left: 0.05,
        right: 0.05,
    };
    assert_eq!(sim.tick(&mut world, 0), vec![capped; 2]);
    world
        .begin_episode(DT.as_secs_f64(), lidar(), WheelLimits::default())
        .expect("agents ready");
    assert_eq!(sim.tick(&mut world, 0), vec![SLOW; 2]);
}

#[test]
fn realtime_brakes_commands_past_the_stale_window_and_non_finite_ones() {
    use TickOutcome::{Fresh, NonFinite, Stale};
    let (sim, mut world) =
        Sim::connected_with(3, settings(ClockMode::Realtime), &[(2, Fault::NanAfter(2))]);
    sim.tick(&mut world, 0);
    // Robot 1 stops after answering tick 0: its tick-0 command stays usable while tick 0's scan
    // is at most 150 ms old (decided at 100 and 150 ms), then brakes.
    sim.pause(11);
    for tick in 1..5 {
        let cmds = sim.tick(&mut world, tick);
        assert_eq!(cmds[0], SLOW);
    }
    assert_eq!(sim.now(), DT * 5, "realtime ticks keep the 20 Hz schedule");
    let timings = world.take_timings();
    assert_eq!(timings[0].outcome, [Fresh; 5]);
    assert_eq!(timings[1].outcome, [Fresh, Fresh, Fresh, Stale, Stale]);
    assert_eq!(timings[1].lag_ticks[..3], [0, 1, 2]);
    assert_eq!(
        timings[2].outcome,
        [Fresh, Fresh, NonFinite, NonFinite, NonFinite]
    );
}

#[test]
fn a_late_agent_in_realtime_is_stale_however_soon_its_command_arrives_after() {
    let late = Fault::LateBy(Duration::from_millis(200));
    let (sim, mut world) = Sim::connected_with(1, settings(ClockMode::Realtime), &[(0, late)]);
    for tick in 0..3 {
        assert_eq!(sim.tick(&mut world, tick), vec![WheelCmd::BRAKE]);
    }
    assert_eq!(outcomes(&mut world, 0), [TickOutcome::Stale; 3]);
}

fn swap(sim: &Sim, request_id: u64, robot: usize, at_tick: u64, model: &str) {
    sim.bus.request_swap(SwapRequest {
        request_id,
        robot,
        at_tick,
        path: PathBuf::from(model),
    });
}

#[test]
fn a_swap_is_done_at_its_tick_and_a_model_that_fails_is_refused() {
    let (sim, mut world) = Sim::connected(2, ClockMode::Lockstep);
    swap(&sim, 1, 0, 3, "fast-model");
    swap(&sim, 2, 1, 2, "bad-model");
    swap(&sim, 3, 7, 0, "fast-model");
    let fast = WheelCmd {
        left: 0.5,
        right: 0.5,
    };
    let mut replies: Vec<SwapReply> = Vec::new();
    for tick in 0..5 {
        let cmds = sim.tick(&mut world, tick);
        assert_eq!(cmds[0], if tick >= 3 { fast } else { SLOW }, "tick {tick}");
        assert_eq!(
            cmds[1], SLOW,
            "the refused swap leaves the old model driving"
        );
        replies.extend(sim.bus.take_swap_replies());
    }
    replies.sort_by_key(|r| r.request_id);
    assert_eq!(replies.len(), 3, "{replies:?}");
    assert_eq!(
        replies[0].outcome,
        SwapOutcome::Done {
            tick: 3,
            model_id: "fast-model".into()
        }
    );
    let SwapOutcome::Refused { reason } = &replies[1].outcome else {
        panic!("{replies:?}");
    };
    assert_eq!(
        reason,
        "the old model keeps driving; the new one failed: loading model bad-model: not a model"
    );
    let SwapOutcome::Refused { reason } = &replies[2].outcome else {
        panic!("{replies:?}");
    };
    assert!(reason.contains("robot 7 does not exist"), "{reason}");
    assert_eq!(world.model_ids(), ["fast-model", "slow-model"]);
    // The swap done is kept once, with the file its request named, for a recording.
    let done = world.take_swaps_done();
    assert_eq!(
        done,
        [crate::exchange::SwapDone {
            robot: 0,
            request_id: 1,
            tick: 3,
            model_id: "fast-model".into(),
            path: Some(PathBuf::from("fast-model")),
            model: None,
        }]
    );
    assert!(world.take_swaps_done().is_empty());
}

#[test]
fn a_restarted_agent_rejoins_as_a_new_incarnation_and_an_impostor_is_refused() {
    let (sim, mut world) = Sim::connected(3, ClockMode::Lockstep);
    sim.tick(&mut world, 0);
    sim.start_impostor(2, 99);
    sim.start(0, 98, None);
    sim.tick(&mut world, 1);
    // Robot 1's agent dies and its successor greets before the world noticed the death.
    sim.kill(1, 11);
    sim.start(1, 21, None);
    let cmds = sim.tick(&mut world, 2);
    assert_eq!(
        cmds[1],
        WheelCmd::BRAKE,
        "the successor cannot answer a scan it never saw"
    );
    for tick in 3..5 {
        assert_eq!(sim.tick(&mut world, tick), vec![SLOW; 3]);
    }
    let outcomes = outcomes(&mut world, 1);
    assert_eq!(outcomes[..2], [TickOutcome::Fresh; 2]);
    assert_eq!(
        outcomes[2],
        TickOutcome::Stale,
        "the predecessor's last command is old"
    );
    assert_eq!(outcomes[3..], [TickOutcome::Fresh; 2]);
    let events = sim.events();
    assert!(
        events.contains(&WorldEvent::AgentRejoined {
            robot: 1,
            pid: 21,
            tick: 3
        }),
        "{events:?}"
    );
    let refused: Vec<_> = sim.agents.borrow().refused.clone();
    assert_eq!(refused.len(), 2, "{refused:?}");
    let reason_of = |pid| &refused.iter().find(|r| r.1 == pid).unwrap().2;
    assert!(reason_of(99).contains("did not prove this launch's secret"));
    assert!(reason_of(98).contains("already driven by agent pid 10"));
    let refusals = events
        .iter()
        .filter(|e| matches!(e, WorldEvent::AgentRefused { .. }))
        .count();
    assert_eq!(refusals, 2);
}

#[test]
fn an_agent_lost_for_good_is_reported_and_its_robot_brakes() {
    let (sim, mut world) = Sim::connected(2, ClockMode::Lockstep);
    sim.tick(&mut world, 0);
    sim.kill(1, 11);
    let before = sim.now();
    assert_eq!(sim.tick(&mut world, 1), vec![SLOW, WheelCmd::BRAKE]);
    assert_eq!(
        sim.now() - before,
        Duration::from_millis(2000),
        "the tick of the loss waits the command timeout for a successor"
    );
    let before = sim.now();
    assert_eq!(sim.tick(&mut world, 2), vec![SLOW, WheelCmd::BRAKE]);
    assert_eq!(sim.now(), before, "an absent robot is not waited for");
    assert!(sim.events().contains(&WorldEvent::AgentLost {
        robot: 1,
        tick: 1,
        last_fresh_tick: Some(0)
    }));
    assert_eq!(
        outcomes(&mut world, 1),
        [
            TickOutcome::Fresh,
            TickOutcome::AgentDown,
            TickOutcome::AgentDown
        ],
        "ticks braked for a dead agent have a reason of their own"
    );
}

#[test]
fn a_signal_ends_an_agent_that_polls_for_its_scans() {
    let (sim, mut world) = Sim::connected(1, ClockMode::Lockstep);
    // Two scans answered at once: the next one is expected within the spin.
    sim.tick(&mut world, 0);
    sim.tick(&mut world, 1);
    sim.bus.terminate_agent(0, TerminationSignal::Terminate);
    let mut agents = sim.agents.borrow_mut();
    let SimAgent { agent, link, .. } = &mut agents.running[0];
    let stop = AtomicBool::new(false);
    assert_eq!(
        agent.spin_for_next_scan(link, &stop).expect("a spin"),
        Some(AgentExit::Signal(TerminationSignal::Terminate)),
        "seen before the spin runs out, not only at the next blocking wait"
    );
}

#[test]
fn the_world_asks_which_agents_died_only_when_one_went_quiet() {
    let (sim, mut world) = Sim::connected(3, ClockMode::Realtime);
    sim.tick(&mut world, 0);
    let asked = sim.bus.liveness_asks();
    // 2 s of realtime ticks (20 liveness periods) with every agent answering each one.
    for tick in 1..41 {
        sim.tick(&mut world, tick);
    }
    assert_eq!(
        sim.bus.liveness_asks(),
        asked,
        "agents that answer are not listed"
    );
    sim.kill(1, 11);
    // Noticed within two periods (200 ms, four ticks).
    for tick in 41..45 {
        sim.tick(&mut world, tick);
    }
    assert!(sim.bus.liveness_asks() > asked);
    assert!(
        sim.events()
            .iter()
            .any(|e| matches!(e, WorldEvent::AgentLost { robot: 1, .. })),
        "{:?}",
        sim.events()
    );
}

#[test]
fn a_command_that_answers_an_older_scan_is_timed_from_that_scan() {
    let (sim, mut world) = Sim::connected(1, ClockMode::Realtime);
    // Tick 0's scan goes out; the agent takes it only 30 ms after tick 0 ended, so its answer
    // arrives during tick 1, after tick 1's scan was published.
    sim.pause(10);
    sim.tick(&mut world, 0);
    sim.clock.advance(Duration::from_millis(30));
    sim.resume(10);
    run_agents(&sim.agents, &sim.bus, &sim.clock);
    sim.pause(10);
    assert_eq!(
        sim.tick(&mut world, 1),
        vec![SLOW],
        "within the stale window"
    );
    let timing = &world.take_timings()[0];
    assert_eq!(timing.outcome, [TickOutcome::Missing, TickOutcome::Fresh]);
    assert_eq!(timing.lag_ticks[1], 1, "the command answered tick 0");
    assert_eq!(
        Duration::from_nanos(timing.round_trip_ns[1]),
        Duration::from_millis(80),
        "from tick 0's scan (published at 0 ms) to the answer's arrival (80 ms), not from \
         tick 1's scan"
    );
    assert!(
        timing.uplink_ns[1] > 0,
        "tick 0's scan was published before the agent took it; tick 1's only after: {:?}",
        timing.uplink_ns
    );
}

#[test]
fn a_degraded_link_is_reported_while_the_run_goes_on() {
    // One robot: in this one-threaded simulation a late agent's delay holds up every agent.
    let late = Fault::LateBy(Duration::from_millis(200));
    let (sim, mut world) = Sim::connected_with(1, settings(ClockMode::Realtime), &[(0, late)]);
    for tick in 0..8 {
        sim.tick(&mut world, tick);
    }
    let reports: Vec<WorldEvent> = sim
        .events()
        .into_iter()
        .filter(|e| matches!(e, WorldEvent::LinkDegraded { .. }))
        .collect();
    let [
        WorldEvent::LinkDegraded {
            robot,
            tick,
            window_ms,
            braked,
            reasons,
            round_trip_us,
            ..
        },
    ] = reports.as_slice()
    else {
        panic!("one report (at most one a second): {reports:?}");
    };
    assert_eq!((*robot, *tick, *window_ms), (0, 5, 5000));
    assert_eq!(*braked, 6, "more than 5 % of a 100-tick window");
    assert_eq!(
        reasons,
        &std::collections::BTreeMap::from([("stale".to_owned(), 6)])
    );
    assert_eq!(*round_trip_us, None, "no command was used");
}

#[test]
fn shutdown_stops_the_agents_and_a_closed_input_or_a_signal_stops_the_world() {
    let (sim, mut world) = Sim::connected(2, ClockMode::Lockstep);
    sim.tick(&mut world, 0);
    sim.stop.store(true, Ordering::Relaxed);
    let scans = vec![vec![5.0f32; BEAMS]; 2];
    let poses = vec![Pose::new(0.0, 0.0, 0.0); 2];
    let obs = observation(1, &poses, &scans);
    let mut out = vec![WheelCmd::BRAKE; 2];
    let error = world.commands(&obs, &mut out).unwrap_err();
    assert!(error.message.contains("launcher closed"), "{error}");
    assert_eq!(world.stopped(), Some(StopReason::ParentGone));
    world.shutdown_agents();
    run_agents(&sim.agents, &sim.bus, &sim.clock);
    assert_eq!(sim.exit_of(10), Some(AgentExit::Shutdown));
    assert_eq!(sim.exit_of(11), Some(AgentExit::Shutdown));

    let (sim, mut world) = Sim::connected(1, ClockMode::Lockstep);
    sim.bus.terminate_world(TerminationSignal::Terminate);
    sim.pause(10);
    assert!(world.commands(&obs_for(1), &mut [WheelCmd::BRAKE]).is_err());
    assert_eq!(
        world.stopped(),
        Some(StopReason::Signal(TerminationSignal::Terminate)),
        "the world knows which signal stopped it"
    );
}

/// The observation of tick `tick` (at `tick` periods of [`DT`]) of robots at `poses` that see
/// `scans`, with the tests' goal.
fn observation<'a>(tick: u64, poses: &'a [Pose], scans: &'a [Vec<f32>]) -> Observation<'a> {
    Observation {
        tick,
        time: tick as f64 * DT.as_secs_f64(),
        goal: Goal {
            phi_star: 0.0,
            d_star: 1.0,
            v_star: 0.1,
        },
        poses,
        wheel_speeds: &[],
        scans,
    }
}

fn obs_for(n: usize) -> Observation<'static> {
    let scans: &'static [Vec<f32>] = Box::leak(vec![vec![5.0f32; BEAMS]; n].into_boxed_slice());
    let poses: &'static [Pose] = Box::leak(vec![Pose::new(0.0, 0.0, 0.0); n].into_boxed_slice());
    observation(0, poses, scans)
}

#[test]
fn an_agent_exits_when_its_world_goes_away_or_its_input_closes() {
    let clock = Arc::new(FakeClock::new());
    let bus = MemoryBus::new(1, clock.clone());
    let pilots = Arc::new(TestPilots);
    let path = PathBuf::from("slow-model");
    let model = pilots.load(&path).unwrap();
    let mut agent = AgentLoop::new(pilots, path, model, None, clock.clone());
    let mut link = bus.agent_link(0, 1);
    let stop = AtomicBool::new(true);
    assert_eq!(
        agent.run(&mut link, &stop, "r").unwrap(),
        AgentExit::Because("the launcher closed our input".into())
    );
    stop.store(false, Ordering::Relaxed);
    bus.end_world();
    let AgentExit::Because(reason) = agent.run(&mut link, &stop, "r").unwrap() else {
        panic!("the agent should say why it exits");
    };
    assert!(
        reason.contains("world process of run r went away")
            && reason.contains("start this agent again, with the same command"),
        "{reason}"
    );
    assert_eq!(
        clock.elapsed(),
        crate::agent::IDLE_CHECK,
        "noticed at the first idle check"
    );
}

#[test]
fn a_stopped_realtime_world_restarts_its_schedule_instead_of_rushing() {
    let (sim, mut world) = Sim::connected(1, ClockMode::Realtime);
    for tick in 0..4 {
        sim.tick(&mut world, tick);
    }
    // SIGSTOP, then SIGCONT a second later.
    sim.clock.advance(Duration::from_secs(1));
    for tick in 4..6 {
        sim.tick(&mut world, tick);
    }
    // A short hiccup (under 4 periods) is caught up instead: ticks 6 and 7 end at once.
    sim.clock.advance(Duration::from_millis(100));
    for tick in 6..9 {
        sim.tick(&mut world, tick);
    }
    let ms: Vec<u64> = world
        .take_tick_starts()
        .into_iter()
        .map(|ns| ns / 1_000_000)
        .collect();
    assert_eq!(ms, [0, 50, 100, 150, 1200, 1250, 1400, 1400, 1400]);
    assert_eq!(
        sim.now(),
        Duration::from_millis(1450),
        "tick 8 is back on schedule"
    );
}

#[test]
fn a_lockstep_spin_before_blocking_changes_no_outcome() {
    let spinning = RuntimeSettings {
        spin_us: 300,
        ..settings(ClockMode::Lockstep)
    };
    let (sim, mut world) = Sim::connected_with(3, spinning, &[]);
    for tick in 0..3 {
        assert_eq!(sim.tick(&mut world, tick), vec![SLOW; 3]);
    }
    sim.pause(11);
    assert_tick_waits_the_command_timeout(
        &sim,
        &mut world,
        3,
        "a spin does not shorten the command timeout",
    );
}

#[test]
fn an_absurd_spin_setting_is_bounded_and_does_not_overflow() {
    let spinning = RuntimeSettings {
        spin_us: u64::MAX,
        command_timeout_ms: 50,
        ..settings(ClockMode::Lockstep)
    };
    let (sim, mut world) = Sim::connected_with(3, spinning, &[]);
    for tick in 0..3 {
        assert_eq!(sim.tick(&mut world, tick), vec![SLOW; 3]);
    }
}

#[test]
fn a_rehearsal_is_due_ahead_of_the_next_scan_only_once_the_period_is_known() {
    use crate::agent::rehearsal_due;
    let now = std::time::Instant::now();
    let ahead = Duration::from_millis(2);
    assert_eq!(rehearsal_due(None, 0.05, now, ahead), None, "no period yet");
    assert_eq!(
        rehearsal_due(Some((0.05, now)), 0.10, now, ahead),
        Some(now + Duration::from_millis(48)),
        "one 50 ms period from now, 2 ms early"
    );
    for (previous, time) in [(0.10, 0.10), (0.10, 0.05), (0.0, 1.0), (0.0, f64::NAN)] {
        assert_eq!(
            rehearsal_due(Some((previous, now)), time, now, ahead),
            None,
            "period {}",
            time - previous
        );
    }
}
