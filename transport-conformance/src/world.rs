//! The world's side of a suite run: the runtime's exchange ([`AgentsController`]) over a rig's
//! link, stepped tick by tick by the test on its own thread, with every event, outcome and
//! command it chose kept for the assertions.

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use formation_proto::control::{Controller, Observation};
use formation_proto::wire::{TickOutcome, WorldEvent};
use formation_proto::{Goal, LidarSpec, Pose, WheelCmd};
use formation_runtime::clock::SystemClock;
use formation_runtime::exchange::{AgentsController, ExchangeSettings};
use formation_runtime::{ClockMode, RuntimeSettings};

use crate::rig::Rig;

/// Beams of the suite's LIDAR.
pub const BEAMS: usize = 90;
/// Its range \[m\].
pub const MAX_RANGE: f64 = 10.0;
/// The tick \[s\].
const DT: f64 = 0.05;
/// The team's goal.
const GOAL: Goal = Goal {
    phi_star: 0.0,
    d_star: 1.0,
    v_star: 0.1,
};

/// The runtime settings of a suite run under `clock`: a command timeout and a stale window far
/// beyond what an agent that keeps up needs on a busy machine, so that only the agents a test
/// holds back are braked.
pub fn settings(clock: ClockMode) -> RuntimeSettings {
    RuntimeSettings {
        clock,
        command_timeout_ms: 1500,
        stale_ms: 400,
        ..RuntimeSettings::DEFAULT
    }
}

/// The exchange over a rig's link, and what it did.
pub struct World<'l> {
    exchange: AgentsController<'l>,
    events: Rc<RefCell<Vec<WorldEvent>>>,
    robots: usize,
    next_tick: u64,
    /// Per tick, per robot: the watchdog's outcome and the command applied.
    played: Vec<Vec<(TickOutcome, WheelCmd)>>,
}

fn lidar() -> LidarSpec {
    LidarSpec {
        beams: BEAMS,
        max_range: MAX_RANGE,
    }
}

impl<'l> World<'l> {
    /// The exchange of `rig`'s launch over `link`, under `runtime`.
    pub fn new<R: Rig>(rig: &R, link: &'l mut R::World, runtime: RuntimeSettings) -> World<'l> {
        let robots = formation_runtime::link::WorldLink::n_robots(link);
        let settings = ExchangeSettings {
            runtime,
            stop: Arc::new(AtomicBool::new(false)),
            run: rig.run().clone(),
            secret: rig.secret().clone(),
        };
        let events = Rc::new(RefCell::new(Vec::new()));
        let sink = Rc::clone(&events);
        let exchange = AgentsController::new(
            link,
            settings,
            lidar(),
            Arc::new(SystemClock),
            Box::new(move |e| sink.borrow_mut().push(e.clone())),
        );
        World {
            exchange,
            events,
            robots,
            next_tick: 0,
            played: Vec::new(),
        }
    }

    /// Waits for every robot's agent and begins the first episode.
    pub fn connect(&mut self) {
        self.exchange
            .await_agents(Duration::from_secs(60))
            .expect("every agent connects");
        self.exchange
            .begin_episode(DT, lidar(), formation_proto::WheelLimits::default())
            .expect("every agent is ready");
    }

    /// Plays the next tick and returns the commands applied.
    pub fn tick(&mut self) -> Vec<WheelCmd> {
        let tick = self.next_tick;
        // Every robot at the origin, seeing a wall 5 m away all round.
        let origin = Pose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        let (poses, scans): (Vec<Pose>, Vec<Vec<f32>>) =
            (0..self.robots).map(|_| (origin, vec![5.0; BEAMS])).unzip();
        let obs = Observation {
            tick,
            time: tick as f64 * DT,
            goal: GOAL,
            poses: &poses,
            wheel_speeds: &[],
            scans: &scans,
        };
        let mut out = vec![WheelCmd::BRAKE; self.robots];
        self.exchange
            .commands(&obs, &mut out)
            .unwrap_or_else(|e| panic!("tick {tick}: {e}"));
        let outcomes = self
            .exchange
            .take_timings()
            .into_iter()
            .map(|t| *t.outcome.last().expect("one outcome per tick"));
        self.played
            .push(outcomes.zip(out.iter().copied()).collect());
        self.next_tick += 1;
        out
    }

    /// Plays ticks until `done` holds or `patience` has passed; false if it never held.
    pub fn tick_for(
        &mut self,
        patience: Duration,
        mut done: impl FnMut(&World<'_>) -> bool,
    ) -> bool {
        let started = Instant::now();
        while started.elapsed() < patience {
            if done(self) {
                return true;
            }
            self.tick();
        }
        done(self)
    }

    /// Plays `n` ticks; returns how long they took.
    pub fn ticks(&mut self, n: usize) -> Duration {
        let started = Instant::now();
        for _ in 0..n {
            self.tick();
        }
        started.elapsed()
    }

    /// The next tick to be played.
    pub fn next_tick(&self) -> u64 {
        self.next_tick
    }

    /// Robot `robot`'s outcome and command at every tick played.
    pub fn played(&self, robot: usize) -> Vec<(TickOutcome, WheelCmd)> {
        self.played.iter().map(|tick| tick[robot]).collect()
    }

    /// How many ticks were played.
    pub fn played_ticks(&self) -> usize {
        self.played.len()
    }

    /// Every event so far.
    pub fn events(&self) -> Vec<WorldEvent> {
        self.events.borrow().clone()
    }

    /// The refusals so far: robot and reason.
    pub fn refusals(&self) -> Vec<(usize, String)> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                WorldEvent::AgentRefused { robot, reason, .. } => Some((robot, reason)),
                _ => None,
            })
            .collect()
    }

    /// Asks every agent to exit, as the world does at its end.
    pub fn shut_down(&mut self) {
        self.exchange.shutdown_agents();
    }

    /// The model each robot's agent last reported.
    pub fn model_ids(&self) -> Vec<String> {
        self.exchange.model_ids().to_vec()
    }
}
