//! A team through the ROS 2 path (issue 14): `formation run --transport ros2` makes the world a
//! team of ROS 2 robots (`/robot_<i>/scan`, `/robot_<i>/odom`, `/robot_<i>/cmd_vel`, the goal on
//! `/formation/goal/*`) on a Zenoh router, and starts one `formation-agent --transport ros2` per
//! robot, which sees nothing of the run but those topics.
//!
//! In lockstep the Table I JSON equals in-process evaluation's: the success flags, convergence
//! times and collisions exactly, the continuous figures to 1e-9 relative. Bit-identity is not
//! promised: a Twist carries v and ω, not the wheel speeds, and turning one into the other and
//! back is exact only up to rounding (about 1e-17 m/s). In realtime case 1 converges.
//!
//! Every test uses its own run id, port and folder.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_cli::launch::read_trajectory;
use formation_tests::{
    ProcessTest, binaries, formation_run_with_model, free_tcp_port, image_model, policy_eval,
    python, read_json, repo_root, run, shipped_model, test_model,
};

const LIMIT: Duration = Duration::from_secs(300);

fn endpoint(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// Equal, with numbers that are not integers compared to `1e-9` relative.
fn assert_json_close(over: &serde_json::Value, reference: &serde_json::Value, at: &str) {
    use serde_json::Value;
    match (over, reference) {
        (Value::Number(a), Value::Number(b)) if a.is_f64() || b.is_f64() => {
            let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            assert!(
                (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0),
                "{at}: {a} over ROS 2, {b} in-process"
            );
        }
        (Value::Array(a), Value::Array(b)) => {
            assert_eq!(a.len(), b.len(), "{at}: lengths");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert_json_close(x, y, &format!("{at}[{i}]"));
            }
        }
        (Value::Object(a), Value::Object(b)) => {
            for (key, y) in b {
                let x = a
                    .get(key)
                    .unwrap_or_else(|| panic!("{at}.{key} is missing over ROS 2"));
                assert_json_close(x, y, &format!("{at}.{key}"));
            }
        }
        _ => assert_eq!(over, reference, "{at}"),
    }
}

/// `formation eval` in-process of `scenario`'s first run with `model`, its summary JSON.
fn in_process_summary(dir: &Path, scenario: &Path, model: &Path) -> serde_json::Value {
    let path = dir.join("in-process.json");
    let eval = policy_eval(scenario, model, &path);
    run(eval, LIMIT).assert_success();
    read_json(&path)
}

/// What one launch of a ROS 2 team left: its scenario, output and the finished launcher, after
/// the leak check passed.
struct TeamRun {
    scenario: std::path::PathBuf,
    out: std::path::PathBuf,
    finished: formation_tests::Finished,
}

/// `formation run --transport ros2` of case 1 (25 s) with `clock` and the shipped model, on a
/// free port; the launch must succeed and leave nothing behind.
fn run_team(t: &ProcessTest, clock: &str) -> TeamRun {
    run_team_with(t, clock, &shipped_model())
}

/// [`run_team`] with `model`.
fn run_team_with(t: &ProcessTest, clock: &str, model: &Path) -> TeamRun {
    let scenario = t.case1(25.0);
    let out = t.out();
    let listen = endpoint(free_tcp_port());
    let finished = run(
        formation_run_with_model(
            &t.run,
            &scenario,
            model,
            &out,
            &["--transport", "ros2", "--listen", &listen, "--clock", clock],
        ),
        LIMIT,
    );
    finished.assert_success();
    t.assert_clean();
    TeamRun {
        scenario,
        out,
        finished,
    }
}

/// Issue 14 acceptance: lockstep case 1 through the ROS 2 path (the world as a ROS 2 team, three
/// ROS 2 agents) converges and gives in-process evaluation's Table I JSON.
#[test]
fn lockstep_case1_through_ros2_gives_the_in_process_table() {
    let t = ProcessTest::start("ros2_team_lockstep", LIMIT);
    assert_lockstep_case1_gives_the_in_process_table(&t, &shipped_model());
}

/// A model that takes the image alone and answers wheel speeds (the default until issue 34)
/// drives a ROS 2 team as the shipped pair network does, to in-process evaluation's Table I JSON.
#[test]
fn an_image_network_drives_a_ros2_team_to_the_in_process_table() {
    let t = ProcessTest::start("ros2_team_image", LIMIT);
    assert_lockstep_case1_gives_the_in_process_table(&t, &image_model());
}

/// Lockstep case 1 with `model` through the ROS 2 path converges, gives in-process evaluation's
/// Table I JSON and answers every tick.
fn assert_lockstep_case1_gives_the_in_process_table(t: &ProcessTest, model: &Path) {
    let TeamRun {
        scenario,
        out,
        finished,
    } = run_team_with(t, "lockstep", model);
    let over_ros2 = read_json(&out.join("summary.json"));
    let reference = in_process_summary(t.path(), &scenario, model);
    assert_eq!(
        reference["per_run"][0]["success_10"],
        serde_json::Value::Bool(true),
        "case 1 converges in-process: {reference}"
    );
    let keys = reference.as_object().expect("eval JSON is an object");
    assert!(keys.contains_key("per_run") && keys.contains_key("success_rate_5"));
    for (key, value) in keys {
        if key == "models" {
            // In-process names the ONNX model; over ROS 2 the world knows only its drivers.
            continue;
        }
        assert_json_close(&over_ros2[key], value, key);
    }
    // Every tick of every robot was answered: nothing braked.
    let log = read_trajectory(&out.join("runs/run-0000.json")).expect("the run log");
    assert_eq!(log.poses.len(), 501, "25 s at 20 Hz");
    assert_eq!(
        over_ros2["braked_ticks"],
        serde_json::json!([{}, {}, {}]),
        "{}",
        finished.describe()
    );
}

/// `formation eval --processes --transport ros2 --listen E` evaluates through the ROS 2 path too:
/// its `--json` equals in-process evaluation's, key for key (to 1e-9 for continuous figures).
#[test]
fn eval_through_ros2_writes_the_in_process_json() {
    let t = ProcessTest::start("ros2_eval_json", LIMIT);
    let scenario = t.case1(10.0);
    let reference = in_process_summary(t.path(), &scenario, &shipped_model());
    let over_path = t.path().join("ros2.json");
    let listen = t.endpoint();
    let mut eval = policy_eval(&scenario, &shipped_model(), &over_path);
    eval.args(["--processes", "--transport", "ros2", "--listen", &listen]);
    let finished = run(eval, LIMIT);
    finished.assert_success();
    let over_ros2 = read_json(&over_path);
    let keys = reference.as_object().expect("eval JSON is an object");
    assert!(keys.contains_key("per_run") && keys.contains_key("success_rate_5"));
    for (key, value) in keys {
        assert_json_close(
            &over_ros2[key],
            value,
            &format!("{key}\n{}", finished.describe()),
        );
    }
}

/// Issue 14 acceptance: realtime case 1 through the ROS 2 path converges.
#[test]
fn realtime_case1_through_ros2_converges() {
    let t = ProcessTest::start("ros2_team_realtime", LIMIT);
    let TeamRun { out, finished, .. } = run_team(&t, "realtime");
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(
        summary["per_run"][0]["success_10"],
        serde_json::Value::Bool(true),
        "{summary}\n{}",
        finished.describe()
    );
    assert_eq!(summary["per_run"][0]["collisions"], serde_json::json!(0));
}

/// Flags that make no sense for a ROS 2 team are refused with the reason.
#[test]
fn bad_ros2_launches_are_refused_with_the_reason() {
    let t = ProcessTest::start("r2bad", LIMIT);
    let scenario = t.case1(5.0);
    let out = t.out();
    let cases: [(&[&str], &str); 4] = [
        (
            &["--transport", "ros2"],
            "--transport ros2 needs --listen tcp/HOST:PORT",
        ),
        (
            &[
                "--transport",
                "ros2",
                "--listen",
                "tcp/127.0.0.1:7447",
                "--fault",
                "0:crash-after=3",
            ],
            "a ROS 2 agent takes none",
        ),
        (
            &[
                "--transport",
                "ros2",
                "--listen",
                "tcp/127.0.0.1:7447",
                "--remote",
                "1",
            ],
            "--remote needs --transport zenoh (the transport is ros2)",
        ),
        (
            &["--ros-domain-id", "3"],
            "--ros-domain-id needs --transport ros2 (the transport is iceoryx2)",
        ),
    ];
    for (extra, message) in cases {
        run(
            formation_run_with_model(&t.run, &scenario, &shipped_model(), &out, extra),
            LIMIT,
        )
        .assert_failure_mentioning(message);
    }
    let mut swap = Command::new(&binaries().cli);
    swap.args(["swap", "--transport", "ros2", "--run", "r", "--robot", "0"])
        .arg("--model")
        .arg(test_model());
    run(swap, LIMIT).assert_failure_mentioning("a ROS 2 agent cannot be swapped");
}

/// A live ROS 2 team's `/tf` and `/tf_static`, read by an independent client (`eclipse-zenoh`
/// subscribing on rmw_zenoh's keys, `rosbags` decoding `tf2_msgs/TFMessage`): every robot is
/// placed in `world` at every tick it was seen, at exactly the pose of the run log, and each has
/// its static `odom` and `laser` frames.
#[test]
fn a_live_teams_tf_is_read_by_an_independent_client() {
    let t = ProcessTest::start("ros2_team_tf", LIMIT);
    let scenario = t.case1(6.0);
    let out = t.out();
    let port = free_tcp_port();
    let team = formation_tests::LiveProcess::spawn(formation_run_with_model(
        &t.run,
        &scenario,
        &shipped_model(),
        &out,
        &[
            "--transport",
            "ros2",
            "--listen",
            &endpoint(port),
            "--clock",
            "lockstep",
            "--pace-ms",
            "30",
        ],
    ));
    let mut listener = Command::new(python());
    listener
        .arg(repo_root().join("tests/python/tf_listener.py"))
        .args(["--connect", &endpoint(port), "--quiet-s", "3"]);
    let heard = run(listener, LIMIT);
    heard.assert_success();
    team.finish(LIMIT).assert_success();
    t.assert_clean();

    let log = read_trajectory(&out.join("runs/run-0000.json")).expect("the run log");
    let robots = log.n_robots();
    let mut ticks_seen = vec![0usize; robots];
    let mut static_children = std::collections::BTreeSet::new();
    for line in heard.stdout().lines() {
        let edge: serde_json::Value = serde_json::from_str(line).expect("a JSON line");
        let child = edge["child"].as_str().expect("child").to_owned();
        if edge["topic"] == "/tf_static" {
            static_children.insert(child);
            continue;
        }
        assert_eq!(edge["parent"], "world", "{line}");
        let robot: usize = child
            .strip_prefix("robot_")
            .and_then(|rest| rest.strip_suffix("/base_link"))
            .and_then(|i| i.parse().ok())
            .unwrap_or_else(|| panic!("a robot's base_link: {line}"));
        let stamp_ns =
            edge["sec"].as_i64().unwrap() * 1_000_000_000 + edge["nanosec"].as_i64().unwrap();
        let tick = usize::try_from((stamp_ns as f64 / (log.dt * 1e9)).round() as i64).unwrap();
        let pose = log.poses[tick][robot];
        let value = |key: &str| edge[key].as_f64().unwrap();
        assert!(
            (value("x") - pose.x).abs() <= 1e-6 && (value("y") - pose.y).abs() <= 1e-6,
            "robot {robot} at tick {tick}: /tf {line}, run log {pose:?}"
        );
        let yaw = 2.0 * value("qz").atan2(value("qw"));
        let turn = (yaw - pose.theta).rem_euclid(std::f64::consts::TAU);
        assert!(
            turn.min(std::f64::consts::TAU - turn) <= 1e-6,
            "robot {robot} at tick {tick}: yaw {yaw}, run log {}",
            pose.theta
        );
        ticks_seen[robot] += 1;
    }
    // The run is 120 ticks; the client connects while the team is starting, so it may miss the
    // first ones, never most of them.
    heard.assert_holds(
        ticks_seen.iter().all(|&n| n >= 60),
        &format!("/tf samples per robot: {ticks_seen:?}"),
    );
    for robot in 0..robots {
        for frame in ["odom", "laser"] {
            assert!(
                static_children.contains(&format!("robot_{robot}/{frame}")),
                "/tf_static lacks robot_{robot}/{frame}: {static_children:?}"
            );
        }
    }
}
