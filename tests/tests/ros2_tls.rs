//! A ROS 2 team over mutual TLS (issue 36): `formation run --transport ros2 --listen tls/…
//! --credentials DIR` makes the world's router listen with the world's certificate and admit only
//! nodes with a certificate of the team's authority, each to its own topics; the launcher's ROS 2
//! agents join with the session configurations written into `DIR/ros2/` (the file rmw_zenoh's
//! `ZENOH_SESSION_CONFIG_URI` names), and the run completes.
//!
//! Independent clients (`tests/python/tls_ros2_reader.py`: `eclipse-zenoh` sessions with TLS
//! settings of their own, `rosbags` decoding) check the rules from outside while the team runs:
//! robot 1's certificate reads `/tf` and its LaserScan, and neither robot 2's scan nor a forged
//! Twist on robot 2's `cmd_vel` gets through (the recorder's certificate, which reads `/tf` and
//! sees robot 2's agent's Twists there, sees none of them); a client without a certificate, or
//! with another team's, reads nothing.
//!
//! `formation record --connect tls/… --transport ros2 --credentials DIR/recorder.json` records
//! such a team from outside with the recorder's certificate, message for message as the world's
//! own `--record`; the recorder's certificate publishes nothing (a raw session with its session
//! configuration puts Twists and records that nobody receives).
//!
//! Each test uses its own run id, free TCP port on 127.0.0.1 and scratch folder, and runs alone
//! within this binary ([`one_at_a_time`](formation_tests::one_at_a_time)).

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_tests::{
    LiveProcess, ProcessTest, binaries, formation_run_with_model, free_tcp_port, python, repo_root,
    run, shipped_model, tls_credentials,
};
use serde_json::Value;

const LIMIT: Duration = Duration::from_secs(240);

/// A free `tls/` endpoint on 127.0.0.1.
fn tls_endpoint() -> String {
    format!("tls/127.0.0.1:{}", free_tcp_port())
}

/// `formation run --transport ros2 --listen LISTEN --credentials CREDS --clock lockstep EXTRA` of
/// `scenario` with the shipped policy, this test's run id and its `out` folder.
fn ros2_tls_team(
    t: &ProcessTest,
    scenario: &Path,
    listen: &str,
    creds: &Path,
    extra: &[&str],
) -> Command {
    let creds = creds.to_string_lossy();
    let flags = [
        ["--transport", "ros2", "--listen", listen].as_slice(),
        &["--credentials", &creds, "--clock", "lockstep"],
        extra,
    ]
    .concat();
    formation_run_with_model(&t.run, scenario, &shipped_model(), &t.out(), &flags)
}

/// A count of the reader's report (0 when absent).
fn count(report: &Value, session: &str, what: &str) -> u64 {
    report[session][what].as_u64().unwrap_or(0)
}

#[test]
fn a_robot_s_certificate_reads_its_tf_and_scan_and_no_certificate_reads_nothing() {
    let t = ProcessTest::start("ros2_tls", LIMIT);
    let creds = tls_credentials(t.path(), "creds", 3);
    let other = tls_credentials(t.path(), "other", 3);
    let scenario = t.case1(20.0);
    let listen = tls_endpoint();
    let team = LiveProcess::spawn(ros2_tls_team(
        &t,
        &scenario,
        &listen,
        &creds,
        &["--pace-ms", "30"],
    ));
    let mut reader = Command::new(python());
    reader
        .arg(repo_root().join("tests/python/tls_ros2_reader.py"))
        .args(["--connect", &listen, "--robot", "1", "--seconds", "6"])
        .arg("--credentials")
        .arg(&creds)
        .arg("--other")
        .arg(&other);
    let read = run(reader, LIMIT);
    read.assert_success();
    let team = team.finish(LIMIT);
    team.assert_success();
    t.assert_clean();

    let report: Value = serde_json::from_str(read.stdout().trim())
        .unwrap_or_else(|e| panic!("the reader's report is not JSON ({e})\n{}", read.describe()));
    let context = format!("{report}\n{}", team.describe());
    for (session, what) in [("robot", "tf"), ("robot", "scan"), ("recorder", "tf")] {
        assert!(
            count(&report, session, what) > 0,
            "the {session} certificate read no {what}: {context}"
        );
    }
    // What must have come through (so the checks of what must not are not vacuous) ...
    let came_through = [
        (
            count(&report, "robot", "beams"),
            "robot 1's LaserScan as decoded has ranges",
        ),
        (
            report["forged_sent"].as_u64().unwrap_or(0),
            "the robot's session put its forged Twists",
        ),
        (
            count(&report, "recorder", "cmd_vel_seen"),
            "the recorder saw robot 2's agent's Twists (so it would see forged ones)",
        ),
    ];
    for (seen, what) in came_through {
        assert!(seen > 0, "{what}: {context}");
    }
    // ... and what must not.
    let kept_out = [
        (
            count(&report, "robot", "other_scan"),
            "robot 1's certificate read robot 2's scan",
        ),
        (
            count(&report, "recorder", "forged_seen"),
            "a Twist robot 1's certificate put on robot 2's cmd_vel got through",
        ),
    ];
    for (seen, what) in kept_out {
        assert_eq!(seen, 0, "{what}: {context}");
    }
    for session in ["bare", "stranger"] {
        assert_eq!(
            count(&report, session, "any"),
            0,
            "the {session} client read the team: {context}"
        );
    }
    // The launcher's agents joined with the session configurations it wrote.
    for robot in 0..3 {
        let config = creds.join("ros2").join(format!("robot-{robot}.json5"));
        assert!(config.is_file(), "{} is missing", config.display());
    }
}

/// A raw Zenoh session (no `formation` code on its path) with `principal`'s ROS 2 session
/// configuration of credentials folder `creds`, joining the router at `listen`.
fn ros2_session(creds: &Path, principal: &str, listen: &str) -> zenoh::Session {
    use formation_transport_ros2::secure::session_config;
    use formation_transport_zenoh::Endpoint;
    use zenoh::Wait;
    let endpoint = Endpoint::parse(listen).expect("a tls/ endpoint");
    let config = session_config(creds, principal, &endpoint).expect("a session configuration");
    let config = zenoh::Config::from_json5(&config.to_string()).expect("a Zenoh configuration");
    zenoh::open(config).wait().expect("the session opens")
}

/// Issue 36: `formation record --connect tls/… --transport ros2 --credentials DIR/recorder.json`
/// records a ROS 2 team on TLS from outside, attached before the first tick, into the very
/// messages the world's own `--record` writes; without `--credentials` it is refused, naming the
/// fix. The recorder's certificate publishes nothing: a raw session with its ROS 2 session
/// configuration puts Twists on robot 0's `cmd_vel` and a record on the run's record channel, and
/// a second such session, which sees the agents' Twists and the world's records, sees none of
/// them (nor does the recorder, which would fail on a record it cannot read).
#[test]
fn the_recorder_s_certificate_records_a_ros2_tls_team_and_publishes_nothing() {
    use formation_tests::{
        AgentGate, assert_recorded_from_the_start, await_recorder_connected, mcap_readers,
    };
    use formation_transport_zenoh::keys::record_live;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use zenoh::Wait;
    const FORGED: &[u8] = b"forged by the recorder's certificate";
    let t = ProcessTest::start("ros2_tls_record", LIMIT);
    let run_id = &t.run;
    let creds = tls_credentials(t.path(), "creds", 3);
    let scenario = t.case1(6.0);
    let own = t.path().join("own.mcap");
    let outside = t.path().join("outside.mcap");
    let listen = tls_endpoint();
    // The agents wait at the gate, so the run waits for them while the recorder connects.
    let gate = AgentGate::new(t.path());
    let team = gate.spawn_recording(ros2_tls_team(&t, &scenario, &listen, &creds, &[]), &own);
    let record = |login: Option<&Path>| {
        let mut command = Command::new(&binaries().cli);
        command
            .args(["record", "--connect", &listen, "--transport", "ros2"])
            .args(["--run-id", run_id.as_str(), "--out"])
            .arg(&outside);
        if let Some(login) = login {
            command.arg("--credentials").arg(login);
        }
        command
    };
    run(record(None), Duration::from_secs(60))
        .assert_failure_mentioning("admits its recorder by the recorder's certificate");
    let mut recorder = LiveProcess::spawn(record(Some(&creds.join("recorder.json"))));
    await_recorder_connected(&mut recorder, run_id);

    let watcher = ros2_session(&creds, "recorder", &listen);
    let count = |key: String| {
        let (all, forged) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let (seen_all, seen_forged) = (Arc::clone(&all), Arc::clone(&forged));
        let subscriber = watcher
            .declare_subscriber(key)
            .callback(move |sample| {
                seen_all.fetch_add(1, Ordering::Relaxed);
                if sample.payload().to_bytes().as_ref() == FORGED {
                    seen_forged.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .expect("a subscriber");
        (subscriber, all, forged)
    };
    let cmd_vel = "0/robot_0/cmd_vel/**".to_string();
    let (_twists, twists, forged_twists) = count(cmd_vel.clone());
    let (_records, records, forged_records) = count(record_live(run_id));
    let forger = ros2_session(&creds, "recorder", &listen);
    // Let the subscriptions reach the router before the run begins.
    std::thread::sleep(Duration::from_secs(1));
    for _ in 0..20 {
        for key in ["0/robot_0/cmd_vel/forged".to_string(), record_live(run_id)] {
            forger
                .put(key, FORGED)
                .wait()
                .expect("the put leaves the session");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    gate.open();
    let team = team.finish(LIMIT);
    team.assert_success();
    assert_recorded_from_the_start(recorder);
    let compared = mcap_readers(&["compare".as_ref(), own.as_os_str(), outside.as_os_str()]);
    // 6 s at 20 Hz: 120 ticks of 3 robots' scan, odometry, command, TF and more.
    assert!(
        compared["messages"].as_u64().unwrap_or(0) > 120 * 3 * 4,
        "{compared}"
    );
    assert_eq!(compared["differing"], 0, "{compared}");
    let context = team.describe();
    assert!(
        twists.load(Ordering::Relaxed) > 0 && records.load(Ordering::Relaxed) > 0,
        "the recorder's certificate reads robot 0's Twists and the record channel: {context}"
    );
    assert_eq!(
        forged_twists.load(Ordering::Relaxed),
        0,
        "a Twist the recorder's certificate put on {cmd_vel} got through: {context}"
    );
    assert_eq!(
        forged_records.load(Ordering::Relaxed),
        0,
        "a record the recorder's certificate put on the record channel got through: {context}"
    );
    drop((forger, watcher));
    t.assert_clean();
}
