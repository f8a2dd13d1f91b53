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
//! The test uses its own run id, free TCP port on 127.0.0.1 and scratch folder, and runs alone
//! within this binary ([`one_at_a_time`]).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_tests::{
    LeakCheck, LiveProcess, TempDir, Watchdog, binaries, case1_scenario, formation_run_with_model,
    free_tcp_port, one_at_a_time, python, repo_root, run, unique_run_id,
};
use serde_json::Value;

const LIMIT: Duration = Duration::from_secs(240);

/// `formation credentials --tls --robots N --out DIR/NAME`.
fn tls_credentials(dir: &Path, name: &str, robots: usize) -> PathBuf {
    let creds = dir.join(name);
    let mut command = Command::new(&binaries().cli);
    command
        .args(["credentials", "--tls", "--valid-days", "30"])
        .args(["--robots", &robots.to_string(), "--out"])
        .arg(&creds);
    run(command, Duration::from_secs(120)).assert_success();
    creds
}

/// A count of the reader's report (0 when absent).
fn count(report: &Value, session: &str, what: &str) -> u64 {
    report[session][what].as_u64().unwrap_or(0)
}

#[test]
fn a_robot_s_certificate_reads_its_tf_and_scan_and_no_certificate_reads_nothing() {
    let _one = one_at_a_time();
    let _watchdog = Watchdog::arm("ros2_tls", LIMIT);
    let dir = TempDir::new("r2tls");
    let run_id = unique_run_id("r2tls");
    let leaks = LeakCheck::new(&run_id);
    let creds = tls_credentials(dir.path(), "creds", 3);
    let other = tls_credentials(dir.path(), "other", 3);
    let scenario = case1_scenario(dir.path(), 20.0);
    let out = dir.path().join("out");
    let listen = format!("tls/127.0.0.1:{}", free_tcp_port());
    let creds_text = creds.to_string_lossy();
    let team = LiveProcess::spawn(formation_run_with_model(
        &run_id,
        &scenario,
        &repo_root().join("onnx/models/policy.onnx"),
        &out,
        &[
            "--transport",
            "ros2",
            "--listen",
            &listen,
            "--credentials",
            &creds_text,
            "--clock",
            "lockstep",
            "--pace-ms",
            "30",
        ],
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
    leaks.assert_clean();

    let report: Value = serde_json::from_str(read.stdout().trim())
        .unwrap_or_else(|e| panic!("the reader's report is not JSON ({e})\n{}", read.describe()));
    let context = format!("{report}\n{}", team.describe());
    for (session, what) in [("robot", "tf"), ("robot", "scan"), ("recorder", "tf")] {
        assert!(
            count(&report, session, what) > 0,
            "the {session} certificate read no {what}: {context}"
        );
    }
    assert!(
        count(&report, "robot", "beams") > 0,
        "robot 1's LaserScan as decoded has ranges: {context}"
    );
    assert_eq!(
        count(&report, "robot", "other_scan"),
        0,
        "robot 1's certificate read robot 2's scan: {context}"
    );
    assert!(
        report["forged_sent"].as_u64().unwrap_or(0) > 0,
        "the robot's session put its forged Twists: {context}"
    );
    assert!(
        count(&report, "recorder", "cmd_vel_seen") > 0,
        "the recorder saw robot 2's agent's Twists (so it would see forged ones): {context}"
    );
    assert_eq!(
        count(&report, "recorder", "forged_seen"),
        0,
        "a Twist robot 1's certificate put on robot 2's cmd_vel got through: {context}"
    );
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
