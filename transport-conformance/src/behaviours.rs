//! The link behaviours, each written once, generic over the [`Rig`]: the world's exchange on the
//! test's thread, every agent on a thread of its own, real clocks, lockstep wherever the
//! behaviour allows. Each test holds the binary's one-at-a-time lock (its timing must not
//! compete with another test's) and a watchdog that aborts a hung test.

use std::ops::Range;
use std::time::Duration;

use formation_proto::WheelCmd;
use formation_proto::wire::{SwapOutcome, SwapReply, SwapRequest, TickOutcome, WorldEvent};
use formation_runtime::agent::AgentExit;
use formation_runtime::auth::LaunchSecret;
use formation_runtime::{ClockMode, RuntimeSettings};
use formation_test_kit::{Watchdog, one_at_a_time};

use crate::agent::Agent;
use crate::pilot::{FAST, SLOW};
use crate::rig::{Rig, SwapRig, suite_pid};
use crate::world::{World, settings};

/// The watchdog's limit: far beyond any behaviour, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(180);
/// How long a test waits for something the world must see (a candidate, a rejoin, a reply).
const PATIENCE: Duration = Duration::from_secs(30);

/// An agent for each of `robots` robots, of this launch, with the slow model.
fn team<R: Rig>(rig: &R, robots: usize) -> Vec<Agent> {
    (0..robots)
        .map(|robot| rig.agent(robot, suite_pid(robot as u32), rig.secret(), "slow"))
        .collect()
}

/// Panics unless on every tick in `ticks` robot `robot` used its agent's command, `cmd`.
fn assert_drove(world: &World<'_>, robot: usize, ticks: Range<usize>, cmd: WheelCmd) {
    let played = world.played(robot);
    for tick in ticks {
        assert_eq!(
            played[tick],
            (TickOutcome::Fresh, cmd),
            "robot {robot} at tick {tick}: {played:?}"
        );
    }
}

/// Panics unless robot `robot` was braked on every tick in `ticks` without using a command.
fn assert_braked(world: &World<'_>, robot: usize, ticks: Range<usize>) {
    let played = world.played(robot);
    for tick in ticks {
        let (outcome, applied) = played[tick];
        assert!(
            outcome != TickOutcome::Fresh && applied == WheelCmd::BRAKE,
            "robot {robot} at tick {tick} should be braked: {played:?}"
        );
    }
}

/// Waits (ticking) up to [`PATIENCE`] for `done`, failing with `what` otherwise.
fn tick_until(world: &mut World<'_>, what: &str, done: impl FnMut(&World<'_>) -> bool) {
    assert!(
        world.tick_for(PATIENCE, done),
        "{what} within {PATIENCE:?}: events {:?}",
        world.events()
    );
}

/// Plays behaviour `name` on a fresh launch of `R` with two robots under `runtime`: the world's
/// link, its exchange, a team of this launch connected and ready for the first episode, handed
/// to `play`. The world and its link are gone when this returns the rig and what `play` gave.
fn play<R: Rig, T>(
    name: &'static str,
    runtime: RuntimeSettings,
    play: impl FnOnce(&R, &mut World<'_>, Vec<Agent>) -> T,
) -> (R, T) {
    let _one = one_at_a_time();
    let _watchdog = Watchdog::arm(name, LIMIT);
    let rig = R::new(2);
    let mut link = rig.world(runtime.clock);
    let mut world = World::new(&rig, &mut link, runtime);
    let team = team(&rig, 2);
    world.connect();
    let played = play(&rig, &mut world, team);
    (rig, played)
}

/// Lockstep with at least `pace_ms` per tick.
fn paced(pace_ms: u64) -> RuntimeSettings {
    RuntimeSettings {
        pace_ms,
        ..settings(ClockMode::Lockstep)
    }
}

/// Only an agent that proves this launch's secret drives a robot, one agent per robot: a second
/// agent of the launch for a driven robot, and a stranger proving another launch's secret, are
/// refused with the reason (and told, where the link can tell them), and neither ever drives.
pub fn admission<R: Rig>() {
    play::<R, _>("admission", paced(0), |rig, world, _team| {
        admit_only_the_launchs_agents(rig, world);
    });
}

fn admit_only_the_launchs_agents<R: Rig>(rig: &R, world: &mut World<'_>) {
    world.ticks(2);
    // Both candidates drive the fast model, so a command of theirs would show.
    let second = rig.agent(0, suite_pid(10), rig.secret(), "fast");
    let stranger_secret = LaunchSecret::generate().expect("another launch's secret");
    let stranger = rig.agent(1, suite_pid(11), &stranger_secret, "fast");
    tick_until(world, "both candidates refused", |w| {
        w.refusals().len() >= 2
    });
    world.ticks(10);
    let mut refusals = world.refusals();
    refusals.sort();
    assert_eq!(refusals.len(), 2, "{refusals:?}");
    assert_eq!(refusals[0].0, 0);
    assert!(
        refusals[0].1.contains("is already driven by agent pid"),
        "{refusals:?}"
    );
    assert_eq!(refusals[1].0, 1);
    assert!(refusals[1].1.contains(R::STRANGER_REFUSAL), "{refusals:?}");
    for robot in 0..2 {
        assert_drove(world, robot, 0..world.played_ticks(), SLOW);
    }
    for (candidate, reason) in [(second, &refusals[0].1), (stranger, &refusals[1].1)] {
        if R::REFUSAL_TOLD {
            let told = candidate.finish().expect_err("a refused candidate is told");
            assert!(told.contains(reason.as_str()), "{told}");
        } else {
            assert!(!candidate.ended(), "an ignored candidate runs on");
        }
    }
}

/// In lockstep an agent that stops answering is waited for once (the command timeout), braked
/// meanwhile, and drives again as soon as it answers; the rest of the team drives throughout,
/// and nobody reports the agent lost.
pub fn lagging<R: Rig>() {
    let runtime = paced(0);
    play::<R, _>("lagging", runtime, |_, world, team| {
        world.ticks(3);
        team[1].gate().hold();
        let waited = world.ticks(1);
        assert!(
            waited >= runtime.command_timeout(),
            "the first tick robot 1 misses waits the command timeout for it, waited {waited:?}"
        );
        world.ticks(2);
        team[1].gate().release();
        tick_until(world, "robot 1 drives again", |w| {
            w.played(1)
                .last()
                .is_some_and(|p| p.0 == TickOutcome::Fresh)
        });
        let back = world.played_ticks() - 1;
        world.ticks(5);
        let end = world.played_ticks();
        assert_drove(world, 0, 0..end, SLOW);
        assert_drove(world, 1, 0..3, SLOW);
        assert_braked(world, 1, 3..back);
        assert_drove(world, 1, back..end, SLOW);
        let events = world.events();
        assert!(
            !events
                .iter()
                .any(|e| matches!(e, WorldEvent::AgentLost { .. })),
            "a lagging agent is not lost: {events:?}"
        );
    });
}

/// An agent that goes (its process ends) leaves its robot braked; another agent of the launch
/// for that robot is admitted as a new incarnation and drives it again from the first tick it
/// answers, and the world reports the loss and the rejoin.
pub fn rejoin<R: Rig>() {
    play::<R, _>("rejoin", paced(20), |rig, world, mut team| {
        world.ticks(3);
        let gone = team.pop().expect("robot 1's agent");
        assert!(gone.stop().is_ok(), "a stopped agent ends cleanly");
        replace_robot_1s_agent(rig, world);
    });
}

/// Whether the world reported robot 1's agent lost.
fn lost(world: &World<'_>) -> bool {
    world
        .events()
        .iter()
        .any(|e| matches!(e, WorldEvent::AgentLost { robot: 1, .. }))
}

/// The tick from which robot 1's successor drove, once the world reported it.
fn rejoined(world: &World<'_>) -> Option<usize> {
    world.events().iter().find_map(|e| match e {
        WorldEvent::AgentRejoined { robot: 1, tick, .. } => Some(*tick as usize),
        _ => None,
    })
}

/// Starts a successor for robot 1, whose agent went after tick 2, and checks that it drives
/// from the tick the world reports it rejoined, robot 1 braked in between.
fn replace_robot_1s_agent<R: Rig>(rig: &R, world: &mut World<'_>) {
    // A link that sees an agent's end reports it within a few ticks; over iceoryx2 a process
    // that closed its node cleanly is found gone only when its successor greets.
    world.tick_for(Duration::from_secs(2), lost);
    let _successor = rig.agent(1, suite_pid(21), rig.secret(), "slow");
    tick_until(world, "robot 1's successor rejoins", |w| {
        rejoined(w).is_some()
    });
    world.ticks(5);
    let from = rejoined(world).expect("the rejoin");
    assert!(lost(world), "the loss is reported: {:?}", world.events());
    let end = world.played_ticks();
    assert_drove(world, 0, 0..end, SLOW);
    assert_drove(world, 1, 0..3, SLOW);
    assert_braked(world, 1, 3..from);
    assert_drove(world, 1, from..end, SLOW);
}

/// In realtime a command is used only while the scan it answers is within the stale window: an
/// agent whose every answer comes later than that has its commands arrive and never used (its
/// robot braked as stale), while the rest of the team drives.
pub fn stale_command<R: Rig>() {
    let runtime = settings(ClockMode::Realtime);
    play::<R, _>("stale_command", runtime, |_, world, team| {
        team[1]
            .gate()
            .make_late(runtime.stale_after() + Duration::from_millis(600));
        world.ticks(60);
        let played = world.played(1);
        assert!(
            played.contains(&(TickOutcome::Stale, WheelCmd::BRAKE)),
            "robot 1's late commands arrived and were refused as stale: {played:?}"
        );
        assert_braked(world, 1, 0..played.len());
        assert_drove(world, 0, 2..played.len(), SLOW);
    });
}

/// What the world answered a swap request.
fn reply(handle: std::thread::JoinHandle<Result<SwapReply, String>>) -> SwapOutcome {
    handle
        .join()
        .expect("the swap client's thread")
        .expect("a reply to the swap request")
        .outcome
}

/// A swap request is forwarded to the robot's agent, which swaps at a tick boundary no earlier
/// than asked and says so; a model that does not load is refused and the old one keeps driving;
/// a robot that does not exist is refused by the world.
pub fn swap<R: SwapRig>() {
    play::<R, _>("swap", paced(10), |rig, world, _team| {
        world.ticks(2);
        let at = world.next_tick() + 40;
        let request = |request_id, robot, model: &str| SwapRequest {
            request_id,
            robot,
            at_tick: at,
            path: rig.models().path(model),
        };
        let good = rig.swap(request(1, 0, "fast"));
        let bad = rig.swap(request(2, 1, "bad"));
        let nobody = rig.swap(request(3, 7, "fast"));
        tick_until(world, "every swap answered", |_| {
            good.is_finished() && bad.is_finished() && nobody.is_finished()
        });
        world.ticks(3);
        check_swaps(world, at, [reply(good), reply(bad), reply(nobody)]);
    });
}

/// Robot 0's swap to the fast model, asked for tick `at`, was done at a tick boundary; robot
/// 1's to a model that does not load and robot 7's were refused.
fn check_swaps(world: &World<'_>, at: u64, [good, bad, nobody]: [SwapOutcome; 3]) {
    let SwapOutcome::Done { tick, model_id } = good else {
        panic!("robot 0's swap was refused: {good:?}")
    };
    assert!(tick >= at, "swapped at tick {tick}, asked for {at}");
    assert_eq!(model_id, "fast");
    let (tick, end) = (tick as usize, world.played_ticks());
    assert_drove(world, 0, 0..tick, SLOW);
    assert_drove(world, 0, tick..end, FAST);
    let SwapOutcome::Refused { reason } = bad else {
        panic!("a model that does not load was swapped in")
    };
    assert!(
        reason.contains("the old model keeps driving; the new one failed")
            && reason.contains("bad is not a model"),
        "{reason}"
    );
    assert_drove(world, 1, 0..end, SLOW);
    let SwapOutcome::Refused { reason } = nobody else {
        panic!("robot 7 was swapped")
    };
    assert!(reason.contains("robot 7 does not exist"), "{reason}");
    assert_eq!(world.model_ids(), ["fast", "slow"]);
}

/// The world's shutdown reaches every agent, which exits as shut down (a ROS 2 agent, which
/// belongs to its robot rather than to the run, runs on until its launcher stops it), and once
/// the world and the agents are gone nothing of the run is left.
pub fn shutdown<R: Rig>() {
    let (rig, team) = play::<R, _>("shutdown", paced(0), |_, world, team| {
        world.ticks(3);
        world.shut_down();
        if R::SHUTDOWN_STOPS_AGENTS {
            for agent in team {
                assert_eq!(agent.finish(), Ok(AgentExit::Shutdown));
            }
            Vec::new()
        } else {
            team
        }
    });
    // The world and its link are gone.
    for agent in team {
        assert!(!agent.ended(), "the agent outlives the world");
        assert_eq!(
            agent.stop(),
            Ok(AgentExit::Because("the launcher went away".into()))
        );
    }
    rig.assert_nothing_left();
}
