//! An agent whose Zenoh session drops comes back (issue 36), with real processes and real Zenoh
//! on 127.0.0.1: the world's `formation run` with robot 1 remote, and robot 1's
//! `formation-agent` connecting through a TCP relay of this test.
//!
//! - The relay resets the agent's link twice mid-run (both TCP connections closed at once, as a
//!   Wi-Fi access point or a NAT does): the world sees the agent's liveliness token go, waits for
//!   it, the agent reconnects on its own, and the lockstep run is bit-identical to in-process,
//!   with no agent reported lost.
//! - The agent process is stopped (SIGSTOP) past the link lease, so the world's router drops its
//!   session, then continued: it reconnects, and the lockstep run (a command timeout longer than
//!   the stop) is still bit-identical to in-process.
//!
//! Without the world's grace for a vanished token the first reset counts the agent dead, its
//! robot brakes for the rest of the run and the trajectories differ.
//!
//! Every test uses its own run id, its own free TCP port and its own scratch folder, and runs
//! alone within this binary ([`one_at_a_time`](formation_tests::one_at_a_time)). The relay is
//! [`ResettingRelay`].

use std::path::Path;
use std::time::Duration;

use formation_cli::launch::read_trajectory;
use formation_robot_agent::decision::PolicyController;
use formation_tests::relay::ResettingRelay;
use formation_tests::{
    LiveProcess, ProcessTest, assert_bit_identical, free_tcp_port, remote_zenoh_agent, send_signal,
    test_model, zenoh_credentials,
};
use formation_world::{Scenario, run_episode};

const LIMIT: Duration = Duration::from_secs(180);

/// Run 0 of the scenario at `scenario` in-process, the test model on every robot.
fn in_process(scenario: &Path) -> formation_world::Trajectory {
    let scenario = Scenario::from_path(scenario).expect("scenario");
    let spec = scenario.run_spec(scenario.seed(), 0);
    let model = test_model();
    let mut controller =
        PolicyController::from_model_paths(&[model, model, model], spec.world.lidar)
            .expect("in-process agents");
    run_episode(&spec, &mut controller, &mut |_, _| {}).expect("in-process run")
}

/// A lockstep launch of `scenario` with robot 1 remote, listening on a free port of
/// 127.0.0.1, with `extra` flags; returns it (waiting for robot 1) and its endpoint.
fn launch(t: &ProcessTest, scenario: &Path, creds: &Path, extra: &[&str]) -> (LiveProcess, String) {
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let creds = creds.to_string_lossy();
    let flags = [
        ["--transport", "zenoh", "--listen", &listen, "--remote", "1"].as_slice(),
        &["--clock", "lockstep", "--remote-timeout-s", "60"],
        &["--credentials", &creds],
        extra,
    ]
    .concat();
    let mut launch = LiveProcess::spawn(formation_tests::formation_run(
        &t.run,
        scenario,
        &t.out(),
        &flags,
    ));
    let waiting = launch.wait_for_line(Duration::from_secs(60), |l| {
        l.contains("waiting for the remote agents of robots [1]")
    });
    assert!(waiting.is_some(), "{}", launch.describe());
    (launch, listen)
}

/// Robot 1's agent of `t`'s run, connecting to `connect` with its credentials from `creds`.
fn robot1(t: &ProcessTest, connect: &str, creds: &Path) -> LiveProcess {
    let mut agent = remote_zenoh_agent(connect, &t.run, 1);
    agent
        .args(["--connect-timeout-ms", "60000", "--credentials"])
        .arg(creds.join("robot-1.json"));
    LiveProcess::spawn(agent)
}

/// Issue 36: robot 1's link reset twice mid-run (the relay closes both connections): the agent
/// reconnects, the world takes it back (no agent lost), and the lockstep run is bit-identical to
/// in-process.
#[test]
fn an_agent_whose_link_resets_reconnects_and_lockstep_stays_bit_identical() {
    let t = ProcessTest::start("zreset", LIMIT);
    let creds = zenoh_credentials(t.path(), 3);
    let scenario = t.case1(10.0);
    // Paced, so the resets fall mid-run (201 ticks of at least 30 ms).
    let (mut launch, listen) = launch(&t, &scenario, &creds, &["--pace-ms", "30"]);
    let relay = ResettingRelay::start(listen.trim_start_matches("tcp/"));
    let agent = robot1(&t, &format!("tcp/127.0.0.1:{}", relay.port), &creds);
    let connected =
        launch.wait_for_line(Duration::from_secs(60), |l| l.contains("agents connected"));
    assert!(connected.is_some(), "{}", launch.describe());
    for _ in 0..2 {
        std::thread::sleep(Duration::from_secs(2));
        assert!(relay.reset() >= 1, "the relay carried robot 1's link");
    }
    let finished = launch.finish(LIMIT);
    let agent = agent.finish(Duration::from_secs(30));
    finished.assert_success();
    assert!(agent.output.status.success(), "{}", agent.describe());
    let stderr = finished.stderr();
    assert!(
        stderr.matches("robot 1: agent pid").count() >= 2 && stderr.contains("reconnected after"),
        "the world saw robot 1's agent go and come back\n{}\n{}",
        finished.describe(),
        agent.describe()
    );
    assert!(
        !finished.stdout().contains("agent lost"),
        "no agent counted lost\n{}",
        finished.describe()
    );
    let over_zenoh = read_trajectory(&t.out().join("runs/run-0000.json")).expect("the run log");
    assert_bit_identical(&over_zenoh, &in_process(&scenario));
    t.assert_clean();
}

/// Issue 36: robot 1's agent stopped (SIGSTOP) for 12 s, past the 10 s link lease, so the
/// world's router drops its session; continued, it reconnects and the world takes it back. The
/// world holds the tick meanwhile (a command timeout, `--timeout-ms`, longer than the stop), so the lockstep run
/// is still bit-identical to in-process.
#[test]
fn an_agent_stopped_past_the_lease_reconnects_and_lockstep_stays_bit_identical() {
    let t = ProcessTest::start("zstop", LIMIT);
    let creds = zenoh_credentials(t.path(), 3);
    let scenario = t.case1(6.0);
    let (mut launch, listen) = launch(
        &t,
        &scenario,
        &creds,
        &["--pace-ms", "20", "--timeout-ms", "60000"],
    );
    let agent = robot1(&t, &listen, &creds);
    let connected =
        launch.wait_for_line(Duration::from_secs(60), |l| l.contains("agents connected"));
    assert!(connected.is_some(), "{}", launch.describe());
    std::thread::sleep(Duration::from_secs(1));
    send_signal(agent.id(), "STOP");
    std::thread::sleep(Duration::from_secs(12));
    send_signal(agent.id(), "CONT");
    let finished = launch.finish(LIMIT);
    let agent = agent.finish(Duration::from_secs(30));
    finished.assert_success();
    assert!(agent.output.status.success(), "{}", agent.describe());
    assert!(
        finished.stderr().contains("reconnected after"),
        "the world saw robot 1's agent go and come back\n{}\n{}",
        finished.describe(),
        agent.describe()
    );
    assert!(
        !finished.stdout().contains("agent lost"),
        "no agent counted lost\n{}",
        finished.describe()
    );
    let over_zenoh = read_trajectory(&t.out().join("runs/run-0000.json")).expect("the run log");
    assert_bit_identical(&over_zenoh, &in_process(&scenario));
    t.assert_clean();
}

/// Issue 36: robot 1's agent stopped (SIGSTOP) for 17 s, past the 10 s lease and the 5 s the
/// world waits for it, is counted lost (its robot brakes); continued, it reconnects, is told in
/// its lobby that the world counted it gone, and exits with code 2 saying so and to start it
/// again, instead of waiting for scans that never come. The run plays to its end without it
/// (and the launch, whose robot 1 was lost for good, says its results are not the policy's).
#[test]
fn an_agent_back_after_the_grace_is_told_it_was_counted_gone_and_exits() {
    let t = ProcessTest::start("zlate", LIMIT);
    let creds = zenoh_credentials(t.path(), 3);
    let scenario = t.case1(30.0);
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let creds_text = creds.to_string_lossy();
    let mut launch = LiveProcess::spawn(formation_tests::formation_run(
        &t.run,
        &scenario,
        &t.out(),
        &[
            "--transport",
            "zenoh",
            "--listen",
            &listen,
            "--remote",
            "1",
            "--clock",
            "realtime",
            "--remote-timeout-s",
            "60",
            "--credentials",
            &creds_text,
        ],
    ));
    let waiting = launch.wait_for_line(Duration::from_secs(60), |l| {
        l.contains("waiting for the remote agents of robots [1]")
    });
    assert!(waiting.is_some(), "{}", launch.describe());
    let agent = robot1(&t, &listen, &creds);
    let connected =
        launch.wait_for_line(Duration::from_secs(60), |l| l.contains("agents connected"));
    assert!(connected.is_some(), "{}", launch.describe());
    std::thread::sleep(Duration::from_secs(1));
    send_signal(agent.id(), "STOP");
    let lost = launch.wait_for_line(Duration::from_secs(40), |l| {
        l.starts_with("robot 1: agent lost")
    });
    assert!(lost.is_some(), "{}", launch.describe());
    send_signal(agent.id(), "CONT");
    let agent = agent.finish(Duration::from_secs(30));
    assert_eq!(agent.output.status.code(), Some(2), "{}", agent.describe());
    assert!(
        agent.stderr().contains("was unreachable for more than 5 s")
            && agent.stderr().contains("start this agent again"),
        "the agent says the world counted it gone and what to do\n{}",
        agent.describe()
    );
    let finished = launch.finish(LIMIT);
    finished.assert_failure_mentioning("robots that had lost their agent for good");
    assert!(
        finished.stdout().contains("run 0 done")
            && finished
                .stderr()
                .contains("came back after it was counted gone"),
        "{}",
        finished.describe()
    );
    t.assert_clean();
}

/// Issue 36: a swap's answer lost in a drop is sent again. In a realtime run, the relay holds
/// what robot 1's agent sends (reads none of it) while `formation swap` sends the agent a model,
/// so the agent's `SwapDone` is stuck in the relay; then the relay resets the link, losing it.
/// The agent reconnects, the world sends its control requests again, the agent answers the
/// repeated swap request with the `SwapDone` it sent (without loading the model twice), and
/// `formation swap` reports the swap done.
#[test]
fn a_swap_answer_lost_in_a_drop_is_sent_again() {
    let t = ProcessTest::start("zswapdrop", LIMIT);
    let creds = zenoh_credentials(t.path(), 3);
    let scenario = t.case1(40.0);
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let creds_text = creds.to_string_lossy();
    let mut launch = LiveProcess::spawn(formation_tests::formation_run(
        &t.run,
        &scenario,
        &t.out(),
        &[
            ["--transport", "zenoh", "--listen", &listen, "--remote", "1"].as_slice(),
            &["--clock", "realtime", "--remote-timeout-s", "60"],
            &["--credentials", &creds_text],
        ]
        .concat(),
    ));
    let relay = ResettingRelay::start(listen.trim_start_matches("tcp/"));
    let agent = robot1(&t, &format!("tcp/127.0.0.1:{}", relay.port), &creds);
    let connected =
        launch.wait_for_line(Duration::from_secs(60), |l| l.contains("agents connected"));
    assert!(connected.is_some(), "{}", launch.describe());
    std::thread::sleep(Duration::from_secs(1));
    relay.hold_toward_world(true);
    let other = t.path().join("other.onnx");
    formation_tests::write_tiny_model(&other, 99);
    let mut swap = std::process::Command::new(&formation_tests::binaries().cli);
    swap.args(["swap", "--transport", "zenoh", "--connect", &listen])
        .args(["--run", t.run.as_str(), "--robot", "1", "--timeout-s", "40"])
        .arg("--model")
        .arg(&other)
        .arg("--credentials")
        .arg(creds.join("operator.json"));
    let swap = LiveProcess::spawn(swap);
    // The request reaches the agent, which swaps at its next scans and answers into the hold.
    // A tiny model loads in milliseconds; 8 s leaves room for cores loaded by other tests.
    std::thread::sleep(Duration::from_secs(8));
    assert!(relay.reset() >= 1, "the relay carried robot 1's link");
    relay.hold_toward_world(false);
    let swapped = swap.finish(LIMIT);
    swapped.assert_success();
    assert!(
        swapped.stdout().contains("drives with model"),
        "{}",
        swapped.describe()
    );
    let finished = launch.finish(LIMIT);
    let agent = agent.finish(Duration::from_secs(30));
    finished.assert_success();
    assert!(agent.output.status.success(), "{}", agent.describe());
    assert!(
        agent.stderr().contains("the world asked for swap"),
        "the agent answered the repeated swap request again\n{}",
        agent.describe()
    );
    t.assert_clean();
}
