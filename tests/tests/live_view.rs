//! Issue 38's acceptance tests of the live view (`formation run --foxglove HOST:PORT`), with a
//! client that is none of formation's code: `tests/python/foxglove_client.py`, Python's
//! `websockets` speaking Foxglove's WebSocket protocol (subprotocol `foxglove.sdk.v1`) and
//! `mcap-ros2-support` decoding the CDR messages with the schemas the server advertised.
//!
//! * A client that joins a running team late gets every advertised channel of a recording (no
//!   replay channels), and decodes a LaserScan and a `/tf` message stamped after the run began.
//! * A client that stops reading leaves the world's tick timing as it is without a client: the
//!   median and the 90th percentile of the ticks' lateness against the 20 Hz schedule stay
//!   within the noise of the run without one.
//! * In lockstep, the run log is the same bytes with a client watching and without the view.
//!
//! The Python packages come from `tests/python/requirements-record.txt` (`bash .ci/setup-python
//! --test`); without them the tests fail with that fix. Each test uses its own run id (its own
//! iceoryx2 namespace, checked clean afterwards) and its own free TCP port.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_proto::wire::RunId;
use formation_tests::{
    LiveProcess, ProcessTest, await_connected, formation_run, free_tcp_port, printed_json, python,
    repo_root, run,
};

const LIMIT: Duration = Duration::from_secs(300);

/// The independent client, `foxglove_client.py ARGS`, started.
fn client(args: &[&str]) -> LiveProcess {
    let mut command = Command::new(python());
    command
        .arg(repo_root().join("tests/python/foxglove_client.py"))
        .args(args);
    LiveProcess::spawn(command)
}

/// The JSON a finished client printed; fails the test with its words (and the fix, for a
/// missing package).
fn client_result(client: LiveProcess) -> serde_json::Value {
    printed_json(
        &client.finish(Duration::from_secs(120)),
        "the independent Foxglove client",
    )
}

/// How late each tick of run 0 began against the schedule of the world's clock \[ms\], sorted.
fn tick_lateness_ms(out: &Path) -> Vec<f64> {
    let log = formation_schema::read_timing_log(&out.join("timing/run-0000.json"))
        .expect("the run's timing log");
    let dt_ns = log.dt_s * 1e9;
    let mut late: Vec<f64> = log
        .tick_start_ns
        .iter()
        .enumerate()
        .map(|(k, &start)| (start as f64 - k as f64 * dt_ns) / 1e6)
        .collect();
    late.sort_by(f64::total_cmp);
    late
}

/// The `q` quantile of sorted `samples`.
fn quantile(samples: &[f64], q: f64) -> f64 {
    let at = ((samples.len() - 1) as f64 * q).round() as usize;
    samples[at]
}

/// Case 1 over processes with `extra` flags, its output in `out`, started under a run id of
/// `t`'s tagged `tag`.
fn launch(run: &RunId, scenario: &Path, out: &Path, extra: &[&str]) -> LiveProcess {
    LiveProcess::spawn(formation_run(run, scenario, out, extra))
}

/// A client that connects to a realtime team after its run began sees it from then on: every
/// channel of a recording but the replay ones, each with its ROS 2 type, and a LaserScan and a
/// `/tf` message it decodes, stamped after the start.
#[test]
fn a_late_websocket_client_decodes_the_live_scans_and_tf() {
    let t = ProcessTest::start("live_view_watch", LIMIT);
    let scenario = t.case1(15.0);
    let out = t.out();
    let address = format!("127.0.0.1:{}", free_tcp_port());
    let flags = ["--clock", "realtime", "--foxglove", &address];
    let mut team = launch(&t.run, &scenario, &out, &flags);
    await_connected(&mut team);
    std::thread::sleep(Duration::from_secs(2));
    let watched = client_result(client(&["watch", &format!("ws://{address}"), "30"]));
    team.finish(LIMIT).assert_success();
    t.assert_clean();

    let topics: Vec<&str> = watched["topics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    let mut expected = vec![
        "/formation/edges",
        "/formation/goal/distance",
        "/formation/goal/heading",
        "/formation/goal/speed",
        "/tf",
        "/tf_static",
    ];
    for robot in 0..3 {
        for name in ["cmd_vel", "odom", "scan"] {
            expected.push(Box::leak(format!("/robot_{robot}/{name}").into_boxed_str()));
        }
    }
    expected.sort_unstable();
    assert_eq!(topics, expected, "{watched}");
    let types = &watched["types"];
    assert_eq!(
        types["/robot_1/scan"], "sensor_msgs/msg/LaserScan",
        "{watched}"
    );
    assert_eq!(types["/tf"], "tf2_msgs/msg/TFMessage", "{watched}");
    assert_eq!(
        types["/formation/edges"],
        "visualization_msgs/msg/MarkerArray"
    );
    let scan = &watched["scan"];
    assert!(scan["beams"].as_u64().unwrap() > 0, "{watched}");
    assert!(scan["range_max"].as_f64().unwrap() > 0.0, "{watched}");
    assert_eq!(scan["stamp_ns"], scan["log_time_ns"], "{watched}");
    // Joined two seconds into a realtime run: what it sees is stamped after the start.
    assert!(
        scan["stamp_ns"].as_u64().unwrap() >= 1_000_000_000,
        "{watched}"
    );
    let tf = &watched["tf"];
    assert_eq!(tf["parent"], "world", "{watched}");
    assert!(
        tf["child"].as_str().unwrap().ends_with("/base_link"),
        "{watched}"
    );
    assert!(tf["x"].as_f64().unwrap().is_finite(), "{watched}");
}

/// A client that subscribes to everything and then stops reading (its socket fills, the
/// server's queue for it fills) leaves the world's ticks on time: the median and the 90th
/// percentile of their lateness stay within the noise of the same run without a live view
/// (the larger of the baseline's interquartile range and 2 ms). The two teams play at the same
/// time, so that both meet the same load of the machine.
#[test]
fn a_client_that_stops_reading_leaves_the_tick_timing_as_it_is() {
    let t = ProcessTest::start("live_view_stall", LIMIT);
    let scenario = t.case1(20.0);

    let baseline_out = t.path().join("baseline");
    let stalled_out = t.path().join("stalled");
    let address = format!("127.0.0.1:{}", free_tcp_port());
    let (baseline_run, baseline_leaks) = t.another_run("lvbase");
    let mut baseline = launch(
        &baseline_run,
        &scenario,
        &baseline_out,
        &["--clock", "realtime"],
    );
    let flags = ["--clock", "realtime", "--foxglove", &address];
    let mut team = launch(&t.run, &scenario, &stalled_out, &flags);
    await_connected(&mut baseline);
    await_connected(&mut team);
    let stalled = client_result(client(&["stall", &format!("ws://{address}"), "15"]));
    baseline.finish(LIMIT).assert_success();
    team.finish(LIMIT).assert_success();
    baseline_leaks.assert_clean();
    t.assert_clean();
    assert!(
        stalled["received_before_stall"].as_u64().unwrap() > 0,
        "{stalled}"
    );
    let without = tick_lateness_ms(&baseline_out);
    let with = tick_lateness_ms(&stalled_out);

    let noise = (quantile(&without, 0.75) - quantile(&without, 0.25)).max(2.0);
    for q in [0.5, 0.9] {
        let (a, b) = (quantile(&without, q), quantile(&with, q));
        assert!(
            b <= a + noise,
            "lateness at q{q}: {b:.3} ms with a stalled client against {a:.3} ms without a live \
             view (noise {noise:.3} ms)"
        );
    }
}

/// In lockstep the live view changes nothing the run computes: the run log is the same bytes
/// with a client watching as without the view.
#[test]
fn lockstep_results_are_the_same_bytes_with_and_without_a_client() {
    let t = ProcessTest::start("live_view_lockstep", LIMIT);
    let scenario = t.case1(10.0);
    // Paced, so that the client watches while the run plays.
    let lockstep = ["--clock", "lockstep", "--pace-ms", "20"];

    let plain_out = t.path().join("plain");
    let plain = launch(&t.run, &scenario, &plain_out, &lockstep);
    plain.finish(LIMIT).assert_success();
    t.assert_clean();

    let viewed_out = t.path().join("viewed");
    let address = format!("127.0.0.1:{}", free_tcp_port());
    let mut flags = lockstep.to_vec();
    flags.extend(["--foxglove", address.as_str()]);
    let (viewed_run, leaks) = t.another_run("lvviewed");
    let mut team = launch(&viewed_run, &scenario, &viewed_out, &flags);
    let watcher = client(&["watch", &format!("ws://{address}"), "30"]);
    await_connected(&mut team);
    let watched = client_result(watcher);
    team.finish(LIMIT).assert_success();
    leaks.assert_clean();
    assert!(
        watched["received"]["/tf"].as_u64().unwrap() > 0,
        "{watched}"
    );

    let plain_log = std::fs::read(plain_out.join("runs/run-0000.json")).unwrap();
    let viewed_log = std::fs::read(viewed_out.join("runs/run-0000.json")).unwrap();
    assert!(
        plain_log == viewed_log,
        "the lockstep run log differs with a live view client ({} and {} bytes)",
        plain_log.len(),
        viewed_log.len()
    );
}

/// A bad address is refused before anything starts, naming the form it takes.
#[test]
fn a_bad_address_is_refused_with_the_form_it_takes() {
    let t = ProcessTest::start("live_view_address", LIMIT);
    let scenario = t.case1(1.0);
    let finished = run(t.formation_run(&scenario, &["--foxglove", "8765"]), LIMIT);
    finished.assert_failure_mentioning("HOST:PORT");
}
