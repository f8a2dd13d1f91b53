//! Issue 26: SIGTERM ends every binary with 143 and SIGINT with 130 (the shell's 128 + the
//! signal), as the guide's exit codes chapter (docs/src/exit-codes.md) says: `formation-agent`
//! over iceoryx2 and over Zenoh, `formation-world` over both, and the `formation` launcher. The
//! launcher restarts an agent whatever its exit code and prints that code, which is how an
//! agent's is read here; a world's
//! is printed by the launcher when it fails.
//!
//! Every test uses its own run id (and port) and runs alone within this binary.

use std::time::{Duration, Instant};

use formation_proto::wire::RunId;
use formation_tests::{
    LeakCheck, LiveProcess, ProcessTest, await_connected, case1_scenario, formation_run,
    send_signal, the_agent, world_pid,
};

const LIMIT: Duration = Duration::from_secs(240);

/// Waits until the launch's stderr mentions `needle`; panics with everything it printed after
/// `limit`.
fn await_stderr(launch: &mut LiveProcess, needle: &str, limit: Duration) {
    let deadline = Instant::now() + limit;
    loop {
        let text = launch.describe();
        let stderr = text.split("--- stderr ---").nth(1).unwrap_or_default();
        if stderr.contains(needle) {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "stderr never mentioned {needle:?}\n{text}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A realtime launch of case 1 (long enough to outlive the test) with `extra` flags, under a run
/// id of its own tagged `tag` (in a folder `tag` of the test's), once its agents are connected.
fn launch(t: &ProcessTest, tag: &str, extra: &[&str]) -> (RunId, LeakCheck, LiveProcess) {
    let dir = t.folder(tag);
    let (run_id, leaks) = t.another_run(tag);
    let scenario = case1_scenario(&dir, 120.0);
    let mut flags = vec!["--clock", "realtime"];
    flags.extend_from_slice(extra);
    let mut launch =
        LiveProcess::spawn(formation_run(&run_id, &scenario, &dir.join("out"), &flags));
    await_connected(&mut launch);
    (run_id, leaks, launch)
}

/// Agents SIGTERMed exit 143 and SIGINTed 130 (each is then restarted); the world SIGTERMed exits
/// 143 (the launcher fails, naming it).
fn agents_then_world(t: &ProcessTest, tag: &str, extra: &[&str]) {
    let (run_id, leaks, mut launch) = launch(t, tag, extra);
    for (robot, signal, code) in [(0, "TERM", 143), (1, "INT", 130)] {
        let agent = the_agent(&run_id, robot, &mut launch);
        send_signal(agent, signal);
        await_stderr(
            &mut launch,
            &format!("agent of robot {robot} exited (exit code {code})"),
            Duration::from_secs(30),
        );
    }
    world_ends_the_launch(&run_id, leaks, launch, ("TERM", 143));
}

/// Sends `signal` to the world of `launch` (run `run_id`): the launch fails naming the world's
/// exit code `code`, and leaves nothing behind.
fn world_ends_the_launch(
    run_id: &RunId,
    leaks: LeakCheck,
    launch: LiveProcess,
    (signal, code): (&str, i32),
) {
    send_signal(world_pid(run_id).expect("the world runs"), signal);
    let finished = launch.finish(LIMIT);
    finished.assert_failure_mentioning(&format!("the world process exited (exit code {code})"));
    leaks.assert_clean();
}

#[test]
fn sigterm_gives_143_and_sigint_130_for_agents_and_the_world_over_iceoryx2() {
    let t = ProcessTest::start("exit_codes_iceoryx", LIMIT);
    agents_then_world(&t, "exitI", &[]);
    // The world on SIGINT.
    let (run_id, leaks, launch) = launch(&t, "exitJ", &[]);
    world_ends_the_launch(&run_id, leaks, launch, ("INT", 130));
}

#[test]
fn sigterm_gives_143_and_sigint_130_for_agents_and_the_world_over_zenoh() {
    let t = ProcessTest::start("exit_codes_zenoh", LIMIT);
    let listen = t.endpoint();
    agents_then_world(&t, "exitZ", &["--transport", "zenoh", "--listen", &listen]);
}

#[test]
fn the_launcher_exits_143_on_sigterm_and_130_on_sigint() {
    let t = ProcessTest::start("exit_codes_launcher", LIMIT);
    for (signal, code) in [("TERM", 143), ("INT", 130)] {
        let (_run_id, leaks, launch) = launch(&t, &format!("exitL{code}"), &[]);
        send_signal(launch.id(), signal);
        let finished = launch.finish(LIMIT);
        assert_eq!(
            finished.output.status.code(),
            Some(code),
            "SIG{signal}\n{}",
            finished.describe()
        );
        leaks.assert_clean();
    }
}
