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

use std::path::{Path, PathBuf};
use std::time::Duration;

use formation_cli::launch::read_trajectory;
use formation_tests::relay::ResettingRelay;
use formation_tests::{
    Finished, LiveProcess, ProcessTest, assert_bit_identical, await_line, free_tcp_port,
    in_process_run, remote_zenoh_agent, send_signal, zenoh_credentials,
};
use formation_world::Scenario;

const LIMIT: Duration = Duration::from_secs(180);

/// A launch of `scenario` on clock `clock` with robot 1 remote, listening on a free port of
/// 127.0.0.1, with `extra` flags; returns it (waiting for robot 1) and its endpoint.
fn launch(
    t: &ProcessTest,
    scenario: &Path,
    creds: &Path,
    clock: &str,
    extra: &[&str],
) -> (LiveProcess, String) {
    let listen = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let flags = [&["--clock", clock, "--remote-timeout-s", "60"], extra].concat();
    let launch = t.launch_awaiting_remote(scenario, &listen, 1, creds, &flags);
    (launch, listen)
}

/// Waits for `launch` and then `agent` to end, both successfully.
fn finish_both(launch: LiveProcess, agent: LiveProcess) -> (Finished, Finished) {
    let finished = launch.finish(LIMIT);
    let agent = agent.finish(Duration::from_secs(30));
    finished.assert_success();
    agent.assert_success();
    (finished, agent)
}

/// The end of a lockstep run whose robot 1's agent went and came back: both ended successfully,
/// the world's stderr says the agent came back (`came_back`), no agent was counted lost, and the
/// run is bit-identical to in-process.
fn assert_back_and_bit_identical(
    t: &ProcessTest,
    (launch, agent): (LiveProcess, LiveProcess),
    scenario: &Path,
    came_back: impl Fn(&str) -> bool,
) {
    let (finished, agent) = finish_both(launch, agent);
    assert!(
        came_back(&finished.stderr()),
        "the world saw robot 1's agent go and come back\n{}\n{}",
        finished.describe(),
        agent.describe()
    );
    finished.assert_holds(
        !finished.stdout().contains("agent lost"),
        "no agent counted lost",
    );
    let over_zenoh = read_trajectory(&t.out().join("runs/run-0000.json")).expect("the run log");
    let scenario = Scenario::from_path(scenario).expect("scenario");
    assert_bit_identical(&over_zenoh, &in_process_run(&scenario, 0));
    t.assert_clean();
}

/// Robot 1's agent of `t`'s run, connecting to `connect` with its credentials from `creds`.
fn robot1(t: &ProcessTest, connect: &str, creds: &Path) -> LiveProcess {
    let mut agent = remote_zenoh_agent(connect, &t.run, 1);
    agent
        .args(["--connect-timeout-ms", "60000", "--credentials"])
        .arg(creds.join("robot-1.json"));
    LiveProcess::spawn(agent)
}

/// A test's launch of case 1 (see [`launch`]) with robot 1's agent connected, straight to the
/// world or through a [`ResettingRelay`].
struct Team {
    /// The test (its run id, folder and leak check).
    t: ProcessTest,
    /// The team's Zenoh credentials folder.
    creds: PathBuf,
    /// The launched scenario.
    scenario: PathBuf,
    /// The world's `formation run`.
    launch: LiveProcess,
    /// The world's endpoint.
    listen: String,
    /// The relay robot 1's agent connects through, if any.
    relay: Option<ResettingRelay>,
    /// Robot 1's agent.
    agent: LiveProcess,
}

impl Team {
    /// Starts test `name`: `duration_s` s of case 1 on `clock` with `extra` flags, and robot 1's
    /// agent (through a relay when `relayed`); returns once the agents are connected.
    fn start(
        name: &'static str,
        duration_s: f64,
        clock: &str,
        extra: &[&str],
        relayed: bool,
    ) -> Team {
        let t = ProcessTest::start(name, LIMIT);
        let creds = zenoh_credentials(t.path(), 3);
        let scenario = t.case1(duration_s);
        let (mut launch, listen) = launch(&t, &scenario, &creds, clock, extra);
        let relay = relayed.then(|| ResettingRelay::start(listen.trim_start_matches("tcp/")));
        let connect = match &relay {
            Some(relay) => format!("tcp/127.0.0.1:{}", relay.port),
            None => listen.clone(),
        };
        let agent = robot1(&t, &connect, &creds);
        await_line(&mut launch, "agents connected");
        Team {
            t,
            creds,
            scenario,
            launch,
            listen,
            relay,
            agent,
        }
    }
}

/// Issue 36: robot 1's link reset twice mid-run (the relay closes both connections): the agent
/// reconnects, the world takes it back (no agent lost), and the lockstep run is bit-identical to
/// in-process.
#[test]
fn an_agent_whose_link_resets_reconnects_and_lockstep_stays_bit_identical() {
    // Paced, so the resets fall mid-run (201 ticks of at least 30 ms).
    let Team {
        t,
        scenario,
        launch,
        relay,
        agent,
        ..
    } = Team::start("zreset", 10.0, "lockstep", &["--pace-ms", "30"], true);
    let relay = relay.expect("the relay");
    for _ in 0..2 {
        std::thread::sleep(Duration::from_secs(2));
        assert!(relay.reset() >= 1, "the relay carried robot 1's link");
    }
    assert_back_and_bit_identical(&t, (launch, agent), &scenario, |stderr| {
        stderr.matches("robot 1: agent pid").count() >= 2 && stderr.contains("reconnected after")
    });
}

/// Issue 36: robot 1's agent stopped (SIGSTOP) for 12 s, past the 10 s link lease, so the
/// world's router drops its session; continued, it reconnects and the world takes it back. The
/// world holds the tick meanwhile (a command timeout, `--timeout-ms`, longer than the stop), so the lockstep run
/// is still bit-identical to in-process.
#[test]
fn an_agent_stopped_past_the_lease_reconnects_and_lockstep_stays_bit_identical() {
    let Team {
        t,
        scenario,
        launch,
        agent,
        ..
    } = Team::start(
        "zstop",
        6.0,
        "lockstep",
        &["--pace-ms", "20", "--timeout-ms", "60000"],
        false,
    );
    std::thread::sleep(Duration::from_secs(1));
    send_signal(agent.id(), "STOP");
    std::thread::sleep(Duration::from_secs(12));
    send_signal(agent.id(), "CONT");
    assert_back_and_bit_identical(&t, (launch, agent), &scenario, |stderr| {
        stderr.contains("reconnected after")
    });
}

/// Issue 36: robot 1's agent stopped (SIGSTOP) for 17 s, past the 10 s lease and the 5 s the
/// world waits for it, is counted lost (its robot brakes); continued, it reconnects, is told in
/// its lobby that the world counted it gone, and exits with code 2 saying so and to start it
/// again, instead of waiting for scans that never come. The run plays to its end without it
/// (and the launch, whose robot 1 was lost for good, says its results are not the policy's).
#[test]
fn an_agent_back_after_the_grace_is_told_it_was_counted_gone_and_exits() {
    let Team {
        t,
        mut launch,
        agent,
        ..
    } = Team::start("zlate", 30.0, "realtime", &[], false);
    std::thread::sleep(Duration::from_secs(1));
    send_signal(agent.id(), "STOP");
    let lost = launch.wait_for_line(Duration::from_secs(40), |l| {
        l.starts_with("robot 1: agent lost")
    });
    assert!(lost.is_some(), "{}", launch.describe());
    send_signal(agent.id(), "CONT");
    let agent = agent.finish(Duration::from_secs(30));
    agent.assert_exit(2).assert_stderr_has_all(
        &[
            "was unreachable for more than 5 s",
            "start this agent again",
        ],
        "the agent says the world counted it gone and what to do",
    );
    launch
        .finish(LIMIT)
        .assert_failure_mentioning("robots that had lost their agent for good")
        .assert_stdout_has("run 0 done")
        .assert_stderr_has("came back after it was counted gone");
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
    let Team {
        t,
        creds,
        launch,
        listen,
        relay,
        agent,
        ..
    } = Team::start("zswapdrop", 40.0, "realtime", &[], true);
    let relay = relay.expect("the relay");
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
    let (_, agent) = finish_both(launch, agent);
    agent.assert_holds(
        agent.stderr().contains("the world asked for swap"),
        "the agent answered the repeated swap request again",
    );
    t.assert_clean();
}
