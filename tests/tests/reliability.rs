//! The runtime against a hostile user and a hostile local process (the reliability issue):
//! harmless signals, stopped and continued processes, a process that was not started by the
//! launch, two launches with one run id, a dead launch's leftovers, private shared memory, an
//! agent that exits on its own, a kill near the end whose restart is still under way, and a
//! 100-kill realtime drill. Every test runs real `formation`, `formation-world` and `formation-agent` processes.

use std::process::Command;
use std::time::{Duration, Instant};

use formation_proto::wire::RunId;
use formation_tests::{
    LaunchSecret, LiveProcess, ProcessTest, RobotLog, TempDir, agent_pids, await_rejoin,
    case1_scenario, formation_run, run, send_signal, the_agent, world_pid,
};
use formation_transport_iceoryx2::naming::RunNamespace;
use rand::{Rng, SeedableRng};

/// The watchdog limit of each test: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(400);

fn run_command(run_id: &RunId, dir: &TempDir, duration_s: f64, extra: &[&str]) -> Command {
    let scenario = case1_scenario(dir.path(), duration_s);
    formation_run(run_id, &scenario, &dir.path().join("out"), extra)
}

fn alive(pid: u32) -> bool {
    std::path::Path::new(&format!("/proc/{pid}")).exists()
}

/// SIGCONT, SIGUSR1 and SIGURG to an agent interrupt its wait and nothing else: the same process
/// keeps driving, nobody restarts it, the run succeeds.
#[test]
fn harmless_signals_to_an_agent_do_not_end_it() {
    let t = ProcessTest::start("harmless_signals", LIMIT);
    let mut launch = t.connected_launch(8.0, &["--clock", "realtime"]);
    std::thread::sleep(Duration::from_millis(1500));
    let agent = the_agent(&t.run, 1, &mut launch);
    for name in ["CONT", "USR1", "URG", "CONT", "USR1"] {
        send_signal(agent, name);
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(alive(agent), "robot 1's agent died of a harmless signal");
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("0 agent restart(s)");
    finished.assert_stderr_lacks("termination signal");
    let out = t.out();
    let robot1 = RobotLog::read(&out, 1).outcomes;
    let fresh = robot1.iter().filter(|o| *o == "fresh").count();
    assert!(
        fresh * 10 >= robot1.len() * 9,
        "robot 1 drove only {fresh} of {} ticks: {robot1:?}",
        robot1.len()
    );
    t.assert_clean();
}

/// SIGSTOP then SIGCONT of the world, and of an agent: both are survived. The stopped agent's robot
/// brakes while it is stopped and drives again afterwards; nothing is restarted.
#[test]
fn stopped_and_continued_processes_are_survived() {
    let t = ProcessTest::start("stop_continue", LIMIT);
    let mut launch = t.connected_launch(14.0, &["--clock", "realtime"]);
    std::thread::sleep(Duration::from_millis(1000));
    let world = world_pid(&t.run).expect("the world's pid");
    send_signal(world, "STOP");
    std::thread::sleep(Duration::from_millis(1000));
    send_signal(world, "CONT");
    std::thread::sleep(Duration::from_millis(1000));
    let agent = the_agent(&t.run, 2, &mut launch);
    send_signal(agent, "STOP");
    std::thread::sleep(Duration::from_millis(1000));
    send_signal(agent, "CONT");
    std::thread::sleep(Duration::from_millis(1000));
    // Ctrl-Z and `fg` on the whole launch: SIGTSTP then SIGCONT to every process of it (one by
    // one, since the launch shares this test's process group).
    let everyone: Vec<u32> = [launch.id(), world]
        .into_iter()
        .chain((0..3).flat_map(|robot| agent_pids(&t.run, robot)))
        .collect();
    for &pid in &everyone {
        send_signal(pid, "TSTP");
    }
    std::thread::sleep(Duration::from_millis(700));
    for &pid in &everyone {
        send_signal(pid, "CONT");
    }
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("0 agent restart(s)");
    let log = RobotLog::read(&t.out(), 2);
    let robot2 = &log.outcomes;
    let braked = robot2.iter().filter(|o| *o != "fresh").count();
    assert!(
        braked >= 10,
        "robot 2 should brake while its agent is stopped (1 s = 20 ticks): {robot2:?}"
    );
    for (k, outcome) in robot2.iter().enumerate() {
        if outcome != "fresh" {
            assert_eq!(log.commands[k], (0.0, 0.0), "tick {k} was braked");
        }
    }
    assert!(
        robot2.iter().rev().take(20).all(|o| o == "fresh"),
        "robot 2 drives again after SIGCONT: {robot2:?}"
    );
    t.assert_clean();
}

/// An agent that exits on its own mid-run (here SIGTERM, exit code 130) is restarted and rejoins.
#[test]
fn an_agent_that_exits_mid_run_is_restarted() {
    let t = ProcessTest::start("exit_restart", LIMIT);
    let mut launch = t.connected_launch(8.0, &["--clock", "realtime"]);
    std::thread::sleep(Duration::from_millis(1000));
    let old = the_agent(&t.run, 0, &mut launch);
    send_signal(old, "TERM");
    await_rejoin(&mut launch, 0, old);
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("1 agent restart(s)");
    t.assert_clean();
}

/// Issue 26: a kill in the last seconds whose restart is still under way (here inside a 5 s
/// backoff) when the run ends counts as a restart, not as a robot that lost its agent for good:
/// `formation run` succeeds, and `summary.json` and `profile.json` count the ticks braked for the
/// dead agent under their own reason, `agent_down`.
#[test]
fn a_kill_near_the_end_whose_restart_is_under_way_does_not_fail_the_run() {
    let t = ProcessTest::start("restart_under_way", LIMIT);
    // 100 ticks; robot 1 crashes after 90 and is restarted only after 5 s, past the end.
    let command = run_command(
        &t.run,
        &t.dir,
        5.0,
        &[
            "--fault",
            "1:crash-after=90",
            "--restart-delay-ms",
            "5000",
            "--timeout-ms",
            "300",
        ],
    );
    let finished = run(command, LIMIT);
    finished.assert_success();
    finished.assert_stdout_has("run 0: robot 1's agent (lost at tick 90) was being restarted");
    finished.assert_stdout_has("1 agent restart(s)");
    let summary: serde_json::Value = serde_json::from_slice(
        &std::fs::read(t.path().join("out/summary.json")).expect("summary.json"),
    )
    .expect("summary JSON");
    let braked = &summary["braked_ticks"];
    let robot1 = braked[1].as_object().expect("robot 1's braked ticks");
    let total: u64 = robot1.values().filter_map(serde_json::Value::as_u64).sum();
    assert_eq!(total, 10, "ticks 90..100 braked: {braked}");
    assert_eq!(
        robot1.get("agent_down").and_then(serde_json::Value::as_u64),
        Some(10),
        "every tick after the crash was braked because no agent drove robot 1: {braked}"
    );
    assert_eq!(braked[0].as_object().map(|m| m.len()), Some(0), "{braked}");
    let profile: serde_json::Value = serde_json::from_slice(
        &std::fs::read(t.path().join("out/profile.json")).expect("profile.json"),
    )
    .expect("profile JSON");
    assert_eq!(
        profile["braked_per_robot"][1]["agent_down"], 10,
        "{profile:#}"
    );
    t.assert_clean();
}

/// Two launches started at the same instant with one run id: exactly one wins, the other is
/// refused without touching the winner's files, and the winner completes.
#[test]
fn two_launches_with_one_run_id_exactly_one_wins() {
    let t = ProcessTest::start("same_run_id", LIMIT);
    for attempt in 0..3 {
        let (run_id, leaks) = t.another_run("twin");
        let dirs = [TempDir::new("twin-a"), TempDir::new("twin-b")];
        let commands: Vec<Command> = dirs
            .iter()
            .map(|dir| run_command(&run_id, dir, 3.0, &["--pace-ms", "25"]))
            .collect();
        let children: Vec<LiveProcess> = commands.into_iter().map(LiveProcess::spawn).collect();
        let finished: Vec<_> = children.into_iter().map(|c| c.finish(LIMIT)).collect();
        let winners: Vec<usize> = (0..2)
            .filter(|&i| finished[i].output.status.success())
            .collect();
        assert_eq!(
            winners.len(),
            1,
            "attempt {attempt}: exactly one launch wins\n{}\n{}",
            finished[0].describe(),
            finished[1].describe()
        );
        let loser = &finished[1 - winners[0]];
        loser.assert_stderr_has("in use by another live launch");
        let winner_out = dirs[winners[0]].path().join("out");
        assert_eq!(RobotLog::read(&winner_out, 0).outcomes.len(), 60);
        assert!(winner_out.join("summary.json").is_file());
        leaks.assert_clean();
    }
}

/// Every file of a running launch is private to its user (0600 files, 0700 folders), including
/// iceoryx2's node-management segment, which iceoryx2 itself makes world-writable.
#[test]
fn the_runs_shared_memory_is_private_to_its_user() {
    use std::os::unix::fs::PermissionsExt;
    let t = ProcessTest::start("file_modes", LIMIT);
    let launch = t.connected_launch(10.0, &["--pace-ms", "20"]);
    std::thread::sleep(Duration::from_millis(300));
    let namespace = RunNamespace::new(&t.run);
    let files = namespace.leftovers();
    assert!(
        files
            .iter()
            .any(|p| p.to_string_lossy().ends_with(".global_mgmt")),
        "the run's management segment exists: {files:#?}"
    );
    let shared = namespace.shared_entries();
    assert!(
        shared.is_empty(),
        "files of the run readable or writable by others: {shared:#?}"
    );
    let base = std::fs::metadata(namespace.base_dir()).expect("base folder");
    assert_eq!(
        base.permissions().mode() & 0o077,
        0,
        "base folder is private"
    );
    launch.finish(LIMIT).assert_success();
    t.assert_clean();
}

/// A launcher SIGKILLed mid-run leaves iceoryx2 files behind; the next launch of the same run id
/// removes them (none of the dead launch's processes lives) and says so.
#[test]
fn a_dead_launchs_leftovers_are_removed_by_the_next_launch() {
    let t = ProcessTest::start("leftovers", LIMIT);
    let first = t.connected_launch(60.0, &["--pace-ms", "20"]);
    let world = world_pid(&t.run).expect("the world's pid");
    send_signal(first.id(), "KILL");
    let _ = first.finish(LIMIT);
    // The children see their input close and exit on their own.
    let deadline = Instant::now() + Duration::from_secs(30);
    while (alive(world) || !agent_pids(&t.run, 0).is_empty()) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(!alive(world), "the orphaned world exited");
    assert!(
        !t.leaks.leftovers().is_empty(),
        "a killed launcher leaves its files (else this test proves nothing)"
    );
    let again = TempDir::new("dead-2");
    let second = run(run_command(&t.run, &again, 2.0, &[]), LIMIT);
    second.assert_success();
    second.assert_stderr_has("that a dead launch of run");
    t.assert_clean();
}

/// Files of a run id whose processes are alive, though no launch holds the run's lock (a world
/// started by hand), are not touched: the launch is refused naming the live process.
#[test]
fn leftovers_with_live_processes_are_not_touched() {
    let t = ProcessTest::start("live_leftovers", LIMIT);
    let mut world = t.world_by_hand(5.0, &t.path().join("world-out"));
    world
        .arg("--exit-on-stdin-close")
        .args(["--startup-timeout-ms", "600000"]);
    let mut world = LiveProcess::spawn_with_secret(world, &LaunchSecret::generate().unwrap());
    let listening = world.wait_for_line(Duration::from_secs(60), |l| l.contains("listening"));
    assert!(listening.is_some(), "{}", world.describe());
    let before = t.leaks.leftovers();
    let refused = run(run_command(&t.run, &t.dir, 2.0, &[]), LIMIT);
    refused.assert_failure_mentioning("has live processes (formation-world");
    assert_eq!(
        t.leaks.leftovers(),
        before,
        "the live run's files are untouched"
    );
    assert!(alive(world.id()), "the live world still runs");
    world.close_input();
    let _ = world.finish(LIMIT);
    drop(t.leaks);
}

/// The realtime drill: 100 SIGKILLs of random agents at random moments, the restart budget raised
/// to match. Every kill is followed by a rejoin; every braked tick applied (0, 0); no command was
/// used beyond the stale window; nothing is left in /dev/shm or the iceoryx2 root.
#[test]
fn a_hundred_sigkills_in_realtime_each_end_in_a_rejoin() {
    let t = ProcessTest::start("hundred_kills", Duration::from_secs(900));
    const KILLS: usize = 100;
    const STALE_MS: u64 = 150;
    let stale = STALE_MS.to_string();
    let mut launch = t.connected_launch(
        // 100 kills took 39 s on a 2-core machine; the run lasts long enough for them.
        100.0,
        &[
            "--clock",
            "realtime",
            "--stale-ms",
            &stale,
            "--restarts",
            "200",
            "--restart-window-s",
            "2",
            "--restart-delay-ms",
            "20",
        ],
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(100);
    let started = Instant::now();
    for _ in 0..KILLS {
        std::thread::sleep(Duration::from_millis(rng.random_range(0..300)));
        let robot = rng.random_range(0..3);
        let old = the_agent(&t.run, robot, &mut launch);
        send_signal(old, "KILL");
        await_rejoin(&mut launch, robot, old);
    }
    eprintln!(
        "{KILLS} kills and rejoins in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    finished.assert_stdout_has(&format!("{KILLS} agent restart(s)"));
    let out = t.out();
    let timing: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("timing/run-0000.json")).unwrap()).unwrap();
    let dt_ms = timing["dt_s"].as_f64().unwrap() * 1e3;
    let mut braked = 0;
    for robot in 0..3 {
        let log = RobotLog::read(&out, robot);
        let lags = &timing["robots"][robot]["lag_ticks"];
        for (k, outcome) in log.outcomes.iter().enumerate() {
            if outcome == "fresh" {
                let lag = lags[k].as_u64().expect("lag_ticks per tick");
                assert!(
                    lag as f64 * dt_ms <= STALE_MS as f64,
                    "robot {robot} tick {k}: a command {lag} ticks old was used"
                );
            } else {
                braked += 1;
                assert_eq!(log.commands[k], (0.0, 0.0), "robot {robot} tick {k}");
            }
        }
    }
    assert!(
        braked >= KILLS,
        "each kill brakes at least one tick: {braked}"
    );
    t.assert_clean();
}
