//! A ROS 2 agent whose link to the world's router drops comes back (issue 36), with real
//! processes and real Zenoh on 127.0.0.1: `formation run --transport ros2` in lockstep, robot
//! 1's `formation-agent --transport ros2` connecting through a TCP relay of this test
//! ([`ResettingRelay`]) that resets its link mid-run, as a Wi-Fi access point or a NAT does. The
//! agent's session reconnects by itself; the run must play as the same launch without resets
//! does, bit for bit, with no agent counted lost.
//!
//! Every test uses its own run ids, free TCP ports and scratch folder.

use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_cli::launch::read_trajectory;
use formation_tests::relay::ResettingRelay;
use formation_tests::{
    LeakCheck, LiveProcess, ProcessTest, assert_bit_identical, binaries, formation_run_with_model,
    free_tcp_port, shipped_model,
};

const LIMIT: Duration = Duration::from_secs(240);

/// An agent executable (a shell script in `dir`) that starts the real `formation-agent`, with
/// robot `robot`'s `--connect` endpoint replaced by `through`: how a test puts a relay between
/// one agent of a ROS 2 launch and the world's router.
fn detour(dir: &Path, robot: usize, through: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let script = dir.join("detoured-agent.sh");
    let text = format!(
        "#!/bin/sh\nrobot=''\nprevious=''\nfor a in \"$@\"; do\n  \
         [ \"$previous\" = --robot ] && robot=\"$a\"\n  previous=\"$a\"\ndone\n\
         if [ \"$robot\" = {robot} ]; then\n  n=$#\n  previous=''\n  for a in \"$@\"; do\n    \
         [ \"$previous\" = --connect ] && a='{through}'\n    set -- \"$@\" \"$a\"\n    \
         previous=\"$a\"\n  done\n  shift \"$n\"\nfi\nexec '{}' \"$@\"\n",
        binaries().agent.display()
    );
    std::fs::write(&script, text).expect("writing the detoured agent's script");
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755))
        .expect("making the detoured agent's script executable");
    script
}

/// A lockstep ROS 2 launch of `scenario` paced at `pace_ms`, into `out`, on `listen`, its agents
/// started as `agent` says (the real one when `None`), under a run id of `t`'s.
fn ros2_team(
    t: &ProcessTest,
    scenario: &Path,
    out: &Path,
    listen: &str,
    pace_ms: &str,
    agent: Option<&Path>,
) -> (LiveProcess, LeakCheck) {
    let (run_id, leaks) = t.another_run("r2drop");
    let mut command = formation_run_with_model(
        &run_id,
        scenario,
        &shipped_model(),
        out,
        &[
            "--transport",
            "ros2",
            "--listen",
            listen,
            "--clock",
            "lockstep",
            "--pace-ms",
            pace_ms,
        ],
    );
    if let Some(agent) = agent {
        command.env("FORMATION_AGENT_BIN", agent);
    }
    (LiveProcess::spawn(command), leaks)
}

/// Issue 36: robot 1's ROS 2 link reset twice mid-run (the relay closes both connections at
/// once): its session reconnects, the world takes it back (no agent lost), and the lockstep run
/// is bit-identical to the same launch without resets.
#[test]
fn a_ros2_agent_whose_link_resets_comes_back_and_lockstep_plays_as_without() {
    let t = ProcessTest::start("ros2_reconnect", LIMIT);
    let scenario = t.case1(10.0);

    let plain_out = t.path().join("plain");
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let (plain, leaks) = ros2_team(&t, &scenario, &plain_out, &listen, "0", None);
    plain.finish(LIMIT).assert_success();
    leaks.assert_clean();

    let out = t.path().join("reset");
    let port = free_tcp_port();
    let relay = ResettingRelay::start(&format!("127.0.0.1:{port}"));
    let agent = detour(t.path(), 1, &format!("tcp/127.0.0.1:{}", relay.port));
    // Paced, so the resets fall mid-run (201 ticks of at least 30 ms).
    let listen = format!("tcp/127.0.0.1:{port}");
    let (mut launch, leaks) = ros2_team(&t, &scenario, &out, &listen, "30", Some(&agent));
    let connected =
        launch.wait_for_line(Duration::from_secs(60), |l| l.contains("agents connected"));
    assert!(connected.is_some(), "{}", launch.describe());
    for _ in 0..2 {
        std::thread::sleep(Duration::from_secs(2));
        assert!(relay.reset() >= 1, "the relay carried robot 1's link");
    }
    let finished = launch.finish(LIMIT);
    finished.assert_success();
    leaks.assert_clean();
    let stderr = finished.stderr();
    finished.assert_holds(
        stderr.matches("is unreachable").count() >= 2 && stderr.contains("reconnected after"),
        "the world saw robot 1's ROS 2 node go and come back",
    );
    finished.assert_holds(
        !finished.stdout().contains("agent lost"),
        "no agent counted lost",
    );
    let plain = read_trajectory(&plain_out.join("runs/run-0000.json")).expect("the run log");
    let reset = read_trajectory(&out.join("runs/run-0000.json")).expect("the run log");
    assert_bit_identical(&reset, &plain);
}
