//! Fault injection on real processes: agents SIGKILLed at random ticks in lockstep and in realtime
//! runs, a hung agent, a late agent. The world must keep ticking, brake every orphaned robot, take
//! back every restarted agent, and leave nothing in shared memory.

use std::process::Command;
use std::time::Duration;

use formation_proto::wire::RunId;
use formation_tests::{
    LiveProcess, ProcessTest, RobotLog, agent_pids, await_rejoin, binaries, run, send_signal,
    test_model, the_agent, world_pid,
};
use rand::{Rng, SeedableRng};

/// The watchdog limit of each test: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// Sends SIGKILL to robot `robot`'s current agent and returns its pid.
fn kill_agent(run_id: &RunId, robot: usize, launch: &mut LiveProcess) -> u32 {
    let pid = the_agent(run_id, robot, launch);
    send_signal(pid, "KILL");
    pid
}

/// Issue 5: twenty SIGKILLs of random agents at random ticks of one lockstep run. Every kill is
/// followed by a restart and a rejoin, every orphaned tick is braked, the run completes, and the
/// run's shared memory is gone afterwards.
#[test]
fn twenty_random_sigkills_in_lockstep_each_end_in_a_rejoin() {
    let t = ProcessTest::start("twenty_kills_lockstep", LIMIT);
    let kills = 20;
    // 150 s at >= 20 ms per tick: at least 60 s of run, far more than 20 kill-restart cycles take.
    let mut launch = t.connected_launch(
        150.0,
        &[
            "--timeout-ms",
            "300",
            "--pace-ms",
            "20",
            "--restarts",
            "10",
            "--restart-window-s",
            "3",
        ],
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(20);
    let mut rejoins: [Vec<usize>; 3] = Default::default();
    for _ in 0..kills {
        // A random moment, hence a random tick, then a random robot.
        std::thread::sleep(Duration::from_millis(rng.random_range(100..600)));
        let robot = rng.random_range(0..3);
        let pid = kill_agent(&t.run, robot, &mut launch);
        rejoins[robot].push(await_rejoin(&mut launch, robot, pid));
    }
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has(&format!("{kills} agent restart(s)"));
    let out = t.out();
    let mut orphaned_ticks = 0;
    for (robot, rejoined_at) in rejoins.iter().enumerate() {
        let log = RobotLog::read(&out, robot);
        assert_eq!(log.outcomes.len(), 3000, "the world ticked to the end");
        // Every tick without a usable command of a live agent is a full brake ...
        log.assert_braked_whenever_refused(robot);
        orphaned_ticks += log.outcomes.iter().filter(|o| *o != "fresh").count();
        // ... and every rejoin is the new agent's first fresh command.
        for &tick in rejoined_at {
            assert_eq!(
                log.outcomes[tick],
                "fresh",
                "robot {robot} rejoined at tick {tick}: {:?}",
                log.braked_stretches()
            );
        }
        assert_eq!(
            log.outcomes.last().map(String::as_str),
            Some("fresh"),
            "robot {robot} drives at the end"
        );
    }
    // A kill usually orphans at least the next tick (a kill between an answer and the next
    // tick can be healed while the world waits for another robot, so not always).
    assert!(orphaned_ticks > 0, "no tick was ever braked");
    t.assert_clean();
}

/// Issue 5: a kill in a realtime run: the world never waits for the dead agent, the robot brakes
/// once its newest command is stale, and the restarted agent drives it again.
#[test]
fn a_sigkill_in_a_realtime_run_is_braked_and_rejoined() {
    let t = ProcessTest::start("kill_realtime", LIMIT);
    let mut launch = t.connected_launch(
        12.0,
        // The restart waits 600 ms (12 ticks), so the orphan is seen braking meanwhile.
        &[
            "--clock",
            "realtime",
            "--restarts",
            "2",
            "--restart-delay-ms",
            "600",
        ],
    );
    std::thread::sleep(Duration::from_secs(3));
    let pid = kill_agent(&t.run, 1, &mut launch);
    await_rejoin(&mut launch, 1, pid);
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("1 agent restart(s)");
    let out = t.out();
    let robot1 = RobotLog::read(&out, 1);
    assert_eq!(robot1.outcomes.len(), 240, "12 s at 20 Hz, every tick");
    robot1.assert_braked_whenever_refused(1);
    let stretches = robot1.braked_stretches();
    assert!(
        stretches
            .iter()
            .any(|&(first, last)| first > 0 && last + 1 < 240 && last - first >= 5),
        "a braked stretch of the restart's length in mid-run, then fresh commands: {stretches:?}"
    );
    assert_eq!(robot1.outcomes.last().map(String::as_str), Some("fresh"));
    for robot in [0, 2] {
        let log = RobotLog::read(&out, robot);
        log.assert_braked_whenever_refused(robot);
        let fresh = log.outcomes.iter().filter(|o| *o == "fresh").count();
        assert!(
            fresh > 180,
            "robot {robot}'s live agent kept driving: {fresh} fresh ticks"
        );
    }
    t.assert_clean();
}

/// Issue 5: an agent that hangs is braked from its first missed tick on and the run completes
/// without it; an agent that answers later than the realtime staleness limit is never obeyed.
#[test]
fn hung_and_late_agents_are_braked() {
    let t = ProcessTest::start("hung_and_late", LIMIT);
    let mut command = Command::new(&binaries().cli);
    command
        .args(["run", "--run-id", t.run.as_str(), "--clock", "realtime"])
        .args(["--fault", "1:hang-after=20", "--fault", "2:late-ms=400"])
        .arg("--scenario")
        .arg(t.case1(5.0))
        .arg("--model")
        .arg(test_model())
        .arg("--out")
        .arg(t.out());
    run(command, LIMIT).assert_success();
    let out = t.out();
    let hung = RobotLog::read(&out, 1);
    hung.assert_braked_whenever_refused(1);
    // It answered 20 times (so at least up to tick 19; realtime reuses a command while the scan it
    // answers is under 150 ms old), then never again: braked from then to the end of the run.
    let last_fresh = hung.outcomes.iter().rposition(|o| o == "fresh");
    assert!(
        last_fresh.is_some_and(|t| t >= 19 && t + 40 < hung.outcomes.len()),
        "driven until about tick 20, then braked: {:?}",
        hung.outcomes
    );
    let late = RobotLog::read(&out, 2);
    late.assert_braked_whenever_refused(2);
    assert!(
        late.outcomes.iter().all(|o| o != "fresh"),
        "commands computed from 400 ms old scans are stale: {:?}",
        late.outcomes
    );
    let healthy = RobotLog::read(&out, 0);
    assert!(healthy.outcomes.iter().filter(|o| *o == "fresh").count() > 80);
    t.assert_clean();
}

/// Issue 5: when the world dies, every agent notices on its own (no launcher involved) and exits
/// cleanly with a message naming the cause. (iceoryx2 keeps the dead world's node-management
/// segment until someone removes the run's namespace, which the launcher does: see
/// [`a_killed_world_ends_the_launch_cleanly`].)
#[test]
fn agents_exit_cleanly_when_the_world_dies() {
    use std::time::Instant;
    let t = ProcessTest::start("world_dies", LIMIT);
    let mut world = t.world_by_hand(600.0, &t.out());
    world.args(["--pace-ms", "20"]);
    let secret = formation_tests::launch_secret();
    let mut world = LiveProcess::spawn_with_secret(world, &secret);
    let mut agents: Vec<LiveProcess> = (0..3)
        .map(|robot| {
            let mut agent = Command::new(&t.bins().agent);
            agent
                .args(["--run-id", t.run.as_str(), "--robot", &robot.to_string()])
                .arg("--model")
                .arg(test_model());
            LiveProcess::spawn_with_secret(agent, &secret)
        })
        .collect();
    // The world's own events: wait for all agents (`agent_connected` comes per agent).
    let connected =
        world.wait_for_line(Duration::from_secs(120), |l| l.contains("agents_connected"));
    assert!(connected.is_some(), "{}", world.describe());
    std::thread::sleep(Duration::from_millis(500));

    let killed_at = Instant::now();
    let status = Command::new("kill")
        .args(["-KILL", &world.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let _ = world.finish(LIMIT);
    for (robot, agent) in agents.drain(..).enumerate() {
        let finished = agent.finish(LIMIT);
        finished.assert_success();
        assert!(
            finished.stderr().contains("world process of run")
                && finished.stderr().contains("went away"),
            "robot {robot}: {}",
            finished.describe()
        );
        eprintln!(
            "robot {robot}'s agent exited {:.0} ms after the world was killed",
            killed_at.elapsed().as_secs_f64() * 1e3
        );
    }
    drop(t.leaks); // removes the dead world's leftovers
}

/// Issue 5: a world killed under `formation run` fails the launch with the reason, the agents are
/// stopped, and nothing of the run is left in shared memory.
#[test]
fn a_killed_world_ends_the_launch_cleanly() {
    let t = ProcessTest::start("world_killed_launch", LIMIT);
    let launch = t.connected_launch(600.0, &["--pace-ms", "20"]);
    std::thread::sleep(Duration::from_millis(300));
    let world = world_pid(&t.run).expect("the world process runs");
    let status = Command::new("kill")
        .args(["-KILL", &world.to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let finished = launch.finish(LIMIT);
    finished.assert_failure_mentioning("world process exited (killed by signal 9)");
    for robot in 0..3 {
        assert!(
            agent_pids(&t.run, robot).is_empty(),
            "robot {robot}'s agent still runs"
        );
    }
    t.assert_clean();
}
