//! Issue 26: the figures a run reports stay true under a slow link, and a degraded link is told
//! while the run goes on. With real processes in realtime: an agent made late on purpose
//! (`--fault 1:late-ms=120`) shows a round trip of at least its lateness in `profile.json`, and
//! the launcher prints a degraded-link line for it; across the `delay-relay` of this package (a
//! remote Zenoh agent on 127.0.0.1 whose traffic is held 70 ± 30 ms each way), the p50 round trip
//! is the sum of both directions' delays to within a tick, and the degraded-link line names the
//! robot. The exit code stays 0: the runs completed.
//!
//! Every test uses its own run id, port and scratch folder, and runs alone within this binary.

use std::process::Command;
use std::time::Duration;

use formation_tests::{
    LiveProcess, ProcessTest, free_tcp_port, read_json, run, start_relay, test_model,
    zenoh_credentials,
};

const LIMIT: Duration = Duration::from_secs(240);

/// One tick of the 20 Hz schedule \[µs\].
const TICK_US: f64 = 50_000.0;

/// Robot `robot`'s p50 round trip in `profile.json` \[µs\].
fn round_trip_p50_us(profile: &serde_json::Value, robot: usize) -> f64 {
    profile["per_agent"][robot]["round_trip"]["p50_us"]
        .as_f64()
        .unwrap_or_else(|| panic!("robot {robot}'s round trip in {profile:#}"))
}

/// An agent that publishes every command 120 ms late (between one 50 ms tick and the 150 ms stale
/// window) shows a round trip of at least 120 ms for its robot, however soon after a later
/// tick's scan its command arrives; its robot brakes often enough that the launcher reports the
/// degraded link, and the run still exits 0.
#[test]
fn a_late_agent_shows_its_lateness_in_the_round_trip_and_a_degraded_link_is_told() {
    let t = ProcessTest::start("late_agent_round_trip", LIMIT);
    let scenario = t.case1(8.0);
    let out = t.out();
    let command = t.formation_run(
        &scenario,
        &["--clock", "realtime", "--fault", "1:late-ms=120"],
    );
    let finished = run(command, LIMIT);
    finished.assert_success();
    let profile = read_json(&out.join("profile.json"));
    let late = round_trip_p50_us(&profile, 1);
    eprintln!("an agent 120 ms late: round trip p50 {late} us");
    finished.assert_holds(
        late >= 120_000.0,
        &format!(
            "robot 1's agent answers 120 ms late, so its round trip is at least that: p50 {late} us"
        ),
    );
    let max = profile["per_agent"][1]["round_trip"]["max_us"]
        .as_f64()
        .unwrap_or_default();
    assert!(
        max < 150_000.0 + TICK_US,
        "a used command answers a scan within the stale window: max {max} us"
    );
    let punctual = round_trip_p50_us(&profile, 0);
    assert!(
        punctual < TICK_US,
        "robot 0's agent is not late: p50 {punctual} us"
    );
    finished.assert_holds(
        finished.stderr().contains("robot 1: degraded link"),
        "the launcher tells the degraded link while the run goes on",
    );
    finished.assert_stderr_lacks("robot 0: degraded link");
    let summary = read_json(&out.join("summary.json"));
    let braked = summary["braked_ticks"][1]
        .as_object()
        .unwrap_or_else(|| panic!("robot 1's braked ticks in {summary:#}"));
    assert!(
        braked.get("stale").and_then(serde_json::Value::as_u64) > Some(8),
        "summary.json gives the totals by reason: {braked:?}"
    );
    t.assert_clean();
}

/// Across the delaying relay (70 ± 30 ms each way; a remote Zenoh agent on 127.0.0.1), robot 1's
/// p50 round trip is the sum of both directions' delays (140 ms) to within a tick, and the
/// robot's link, which loses every command whose round trip outlasts the 150 ms stale window
/// (about a third of them), is reported degraded while the run goes on; the run exits 0.
#[test]
fn across_a_delaying_relay_the_round_trip_is_both_delays_and_the_degraded_link_is_told() {
    let t = ProcessTest::start("relay_round_trip", LIMIT);
    let scenario = t.case1(10.0);
    let out = t.out();
    let creds = zenoh_credentials(t.path(), 3);
    let world_port = free_tcp_port();
    let listen = format!("tcp/127.0.0.1:{world_port}");
    let relay_port = free_tcp_port();
    let mut relay = Command::new(env!("CARGO_BIN_EXE_delay-relay"));
    relay.args([
        &format!("127.0.0.1:{relay_port}"),
        &format!("127.0.0.1:{world_port}"),
        "70",
        "30",
        "26",
    ]);
    let mut relay = start_relay(relay);
    let launch = t.launch_awaiting_remote(&scenario, &listen, 1, &creds, &["--clock", "realtime"]);
    let mut agent = Command::new(&t.bins().agent);
    agent
        .args(["--transport", "zenoh", "--connect"])
        .arg(format!("tcp/127.0.0.1:{relay_port}"))
        .args(["--run-id", t.run.as_str(), "--robot", "1", "--model"])
        .arg(test_model())
        .arg("--credentials")
        .arg(creds.join("robot-1.json"));
    let remote = LiveProcess::spawn_with_input(agent, None);
    let finished = launch.finish(LIMIT);
    let remote = remote.finish(Duration::from_secs(60));
    relay.close_input();
    finished.assert_success();
    remote.assert_success();
    let profile = read_json(&out.join("profile.json"));
    let delayed = round_trip_p50_us(&profile, 1);
    let summary = read_json(&out.join("summary.json"));
    eprintln!(
        "70 ± 30 ms each way: round trip p50 {delayed} us; braked ticks {}",
        summary["braked_ticks"]
    );
    finished.assert_holds(
        (delayed - 140_000.0).abs() <= TICK_US,
        &format!("p50 round trip {delayed} us across 70 + 70 ms of delay"),
    );
    finished.assert_holds(
        finished.stderr().contains("robot 1: degraded link"),
        "the launcher tells the degraded link while the run goes on",
    );
    t.assert_clean();
}
