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
    LeakCheck, LiveProcess, ProcessTest, TempDir, agent_pids, await_connected, case1_scenario,
    formation_run, send_signal, unique_run_id, world_pid,
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

fn the_agent(run_id: &RunId, robot: usize, launch: &mut LiveProcess) -> u32 {
    let pids = agent_pids(run_id, robot);
    assert_eq!(pids.len(), 1, "{pids:?}\n{}", launch.describe());
    pids[0]
}

/// A realtime launch of case 1 (long enough to outlive the test) with `extra` flags.
fn launch(tag: &str, extra: &[&str]) -> (TempDir, RunId, LeakCheck, LiveProcess) {
    let dir = TempDir::new(tag);
    let run_id = unique_run_id(tag);
    let leaks = LeakCheck::new(&run_id);
    let scenario = case1_scenario(dir.path(), 120.0);
    let mut flags = vec!["--clock", "realtime"];
    flags.extend_from_slice(extra);
    let mut launch = LiveProcess::spawn(formation_run(
        &run_id,
        &scenario,
        &dir.path().join("out"),
        &flags,
    ));
    await_connected(&mut launch);
    (dir, run_id, leaks, launch)
}

/// Agents SIGTERMed exit 143 and SIGINTed 130 (each is then restarted); the world SIGTERMed exits
/// 143 (the launcher fails, naming it).
fn agents_then_world(tag: &str, extra: &[&str]) {
    let (_dir, run_id, leaks, mut launch) = launch(tag, extra);
    let agent = the_agent(&run_id, 0, &mut launch);
    send_signal(agent, "TERM");
    await_stderr(
        &mut launch,
        "agent of robot 0 exited (exit code 143)",
        Duration::from_secs(30),
    );
    let agent = the_agent(&run_id, 1, &mut launch);
    send_signal(agent, "INT");
    await_stderr(
        &mut launch,
        "agent of robot 1 exited (exit code 130)",
        Duration::from_secs(30),
    );
    let world = world_pid(&run_id).expect("the world runs");
    send_signal(world, "TERM");
    let finished = launch.finish(LIMIT);
    finished.assert_failure_mentioning("the world process exited (exit code 143)");
    leaks.assert_clean();
}

#[test]
fn sigterm_gives_143_and_sigint_130_for_agents_and_the_world_over_iceoryx2() {
    let _t = ProcessTest::start("exit_codes_iceoryx", LIMIT);
    agents_then_world("exitI", &[]);
    // The world on SIGINT.
    let (_dir, run_id, leaks, launch) = launch("exitJ", &[]);
    send_signal(world_pid(&run_id).expect("the world runs"), "INT");
    let finished = launch.finish(LIMIT);
    finished.assert_failure_mentioning("the world process exited (exit code 130)");
    leaks.assert_clean();
}

#[test]
fn sigterm_gives_143_and_sigint_130_for_agents_and_the_world_over_zenoh() {
    let t = ProcessTest::start("exit_codes_zenoh", LIMIT);
    let listen = t.endpoint();
    agents_then_world("exitZ", &["--transport", "zenoh", "--listen", &listen]);
}

#[test]
fn the_launcher_exits_143_on_sigterm_and_130_on_sigint() {
    let _t = ProcessTest::start("exit_codes_launcher", LIMIT);
    for (signal, code) in [("TERM", 143), ("INT", 130)] {
        let (_dir, _run_id, leaks, launch) = launch(&format!("exitL{code}"), &[]);
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
