//! Issue 37 item 5: `formation-agent --transport ros2 --profile PROFILE` knows its robot. Against
//! an independent ROS 2 client (`tests/python/ros2_client.py`: eclipse-zenoh as the robot's
//! router, rosbags for the CDR), a TurtleBot3 Burger agent fed a foreign LaserScan (720
//! readings to 8 m, not the LDS-01's 360 to 3.5 m) names the difference in one warning, still
//! answers every scan, and drives exactly as the same decision in this process: the scan
//! resampled onto the model's ring, both wheels scaled into the Burger's 0.22 m/s, the Twist
//! made with its 0.160 m wheel separation. An unknown profile is refused with the known names.
//!
//! The Python packages come from `tests/python/requirements-ros2.txt` (`bash .ci/setup-python
//! --test`); without them the session test fails with that fix. Each test runs alone within this
//! binary ([`one_at_a_time`]), on its own free TCP port and scratch folder, and stops every
//! process it started.

use std::process::Command;
use std::time::Duration;

use formation_perception::policy_input::saturate_together;
use formation_proto::Goal;
use formation_ros2::msg::Quaternion;
use formation_ros2::{
    Header, LaserScan, PartialScan, Time, Twist, twist_from_wheels, yaw_from_quaternion,
};
use formation_tests::ros2::{
    InProcessDecision, answered_bits, clients, plan, range_to_discs, session, topic_flags,
    twist_bits,
};
use formation_tests::{ProcessTest, binaries, free_tcp_port, test_model};
use serde_json::{Value, json};

const LIMIT: Duration = Duration::from_secs(300);
/// The TurtleBot3 Burger's top wheel speed \[m/s\] and wheel separation \[m\] (its profile's).
const BURGER_TOP_SPEED: f64 = 0.22;
const BURGER_WHEEL_SEPARATION: f64 = 0.160;
/// The foreign LIDAR: readings per full circle and range.
const FOREIGN_BEAMS: usize = 720;
const FOREIGN_RANGE: f32 = 8.0;
/// The goal: φ* 0.3 rad, d* 1.2 m, v* 0.2 m/s (within the Burger's envelope).
const GOAL: Goal = Goal {
    phi_star: 0.3,
    d_star: 1.2,
    v_star: 0.2,
};

/// A full-circle scan of `FOREIGN_BEAMS` readings of circular obstacles, beyond the range as
/// +inf (REP-117); `seed` moves the obstacles.
fn foreign_scan(stamp_ns: i64, seed: u64) -> LaserScan {
    let increment = (std::f64::consts::TAU / FOREIGN_BEAMS as f64) as f32;
    let shift = seed as f64 * 0.7;
    let obstacles: Vec<(f64, f64, f64)> = (0..5)
        .map(|k| {
            let bearing = shift + k as f64 * 1.3;
            let distance = 0.7 + 0.35 * k as f64;
            (distance * bearing.cos(), distance * bearing.sin(), 0.2)
        })
        .collect();
    let ranges = (0..FOREIGN_BEAMS)
        .map(|i| range_to_discs(i as f64 * f64::from(increment), &obstacles, FOREIGN_RANGE))
        .collect::<Vec<f32>>();
    LaserScan {
        header: Header {
            stamp: Time::from_nanos(stamp_ns),
            frame_id: "laser".into(),
        },
        angle_min: 0.0,
        angle_max: increment * (FOREIGN_BEAMS - 1) as f32,
        angle_increment: increment,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: 0.05,
        range_max: FOREIGN_RANGE,
        ranges,
        intensities: Vec::new(),
    }
}

/// The scan as the client's plan carries it (IEEE-754 bit patterns).
fn scan_json(scan: &LaserScan) -> Value {
    json!({
        "stamp_ns": scan.header.stamp.as_nanos(),
        "angle_min_bits": scan.angle_min.to_bits(),
        "angle_max_bits": scan.angle_max.to_bits(),
        "angle_increment_bits": scan.angle_increment.to_bits(),
        "range_min_bits": scan.range_min.to_bits(),
        "range_max_bits": scan.range_max.to_bits(),
        "ranges_bits": scan.ranges.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
    })
}

/// A flat robot's Imu quaternion for heading `yaw`.
fn quaternion(yaw: f64) -> [f64; 4] {
    let (s, c) = (yaw / 2.0).sin_cos();
    [0.0, 0.0, s, c]
}

/// The client's plan steps: each an Imu then a scan.
fn plan_steps(steps: &[(LaserScan, f64)]) -> Vec<Value> {
    steps
        .iter()
        .map(|(scan, yaw)| {
            let stamp = scan.header.stamp.as_nanos();
            json!({
                "imu": {
                    "stamp_ns": stamp,
                    "quaternion_bits": quaternion(*yaw).map(f64::to_bits),
                },
                "scan": scan_json(scan),
            })
        })
        .collect()
}

/// The same decision in this process: the scan resampled onto the model's ring, the policy,
/// both wheels scaled by one factor into the Burger's top speed, the Burger's Twist.
fn in_process_twists(steps: &[(LaserScan, f64)]) -> Vec<Twist> {
    let mut reference = InProcessDecision::new();
    steps
        .iter()
        .map(|(scan, yaw)| {
            let heading = yaw_from_quaternion(&{
                let [x, y, z, w] = quaternion(*yaw);
                Quaternion { x, y, z, w }
            })
            .expect("a heading");
            let wheels = saturate_together(
                reference.wheels(scan, heading, &GOAL, PartialScan::Refuse),
                BURGER_TOP_SPEED,
            );
            twist_from_wheels(wheels.left, wheels.right, BURGER_WHEEL_SEPARATION).expect("a Twist")
        })
        .collect()
}

/// A TurtleBot3 Burger agent on a 720-beam, 8 m LaserScan: one warning names the beams and the
/// range (not the LDS-01's 360 and 3.5 m), said once over every scan; a line at start says the
/// Burger's LIDAR is not the model's ring; and every scan is answered with the Twist of the same
/// decision in this process, the wheels within the Burger's 0.22 m/s and the Twist made with its
/// 0.160 m wheel separation, bit for bit. (The small test model asks less than 0.22 m/s of its
/// wheels, so the scaling into the top speed is checked by the agent's unit tests.)
#[test]
fn a_burger_agent_names_a_foreign_scan_once_and_still_drives_within_its_wheels() {
    let t = ProcessTest::start("ros2_profile_foreign_scan", LIMIT);
    let python = clients();
    let base = 1_700_000_000_000_000_000_i64;
    let steps: Vec<(LaserScan, f64)> = (0..4)
        .map(|i| {
            (
                foreign_scan(base + i * 200_000_000, i as u64),
                0.4 - 0.9 * i as f64,
            )
        })
        .collect();
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "5000", "--profile", "turtlebot3-burger"]);
    let plan = plan(&GOAL, plan_steps(&steps));
    let outcome = session(python, t.path(), "plan", &plan, &flags);
    let describe = outcome.describe();

    let stderr = outcome.agent_stderr();
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("is not the one expected"))
        .collect();
    assert_eq!(warnings.len(), 1, "one warning\n{describe}");
    assert!(
        warnings[0].contains(
            "formation-agent: the LaserScan on /scan is not the one expected (the \
             turtlebot3-burger profile's LIDAR: 360 beams, 3.5 m, 5 Hz): it has 720 beams, not \
             360, it reaches 8 m, not 3.5 m; every scan is resampled onto the model's ring"
        ),
        "{describe}"
    );
    assert!(
        stderr.contains("the turtlebot3-burger profile's has 360 beams and 3.5 m"),
        "the start names the Burger's LIDAR against the model's\n{describe}"
    );

    let answers = outcome.answers();
    assert_eq!(answers.len(), steps.len(), "one answer a scan\n{describe}");
    assert_drives_as_in_process(&answers, &steps, &describe);
}

/// Panics unless each answer answers its step's scan (by stamp) with the in-process Twist, bit
/// for bit, its wheels within the Burger's top speed.
fn assert_drives_as_in_process(answers: &[&Value], steps: &[(LaserScan, f64)], describe: &str) {
    let expected = in_process_twists(steps);
    for ((answer, twist), (scan, _)) in answers.iter().zip(&expected).zip(steps) {
        assert_eq!(
            answer["stamp_ns"].as_i64(),
            Some(scan.header.stamp.as_nanos()),
            "{describe}"
        );
        assert_ne!(answer["zero"], json!(true), "the agent braked\n{describe}");
        assert_eq!(
            answered_bits(answer),
            twist_bits(twist),
            "the agent's Twist {} differs from the in-process {twist:?}\n{describe}",
            answer["twist"]
        );
        // Each wheel within the Burger's top speed.
        let half = BURGER_WHEEL_SEPARATION / 2.0 * twist.angular.z;
        let (left, right) = (twist.linear.x - half, twist.linear.x + half);
        assert!(
            left.abs().max(right.abs()) <= BURGER_TOP_SPEED + 1e-12,
            "{twist:?}"
        );
    }
}

/// An unknown `--profile` is refused before the agent connects, naming the profiles known.
#[test]
fn an_unknown_profile_is_refused_with_the_known_names() {
    let _t = ProcessTest::start("ros2_profile_unknown", LIMIT);
    let port = free_tcp_port();
    let output = Command::new(&binaries().agent)
        .args(["--transport", "ros2", "--connect"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .arg("--model")
        .arg(test_model())
        .args(["--profile", "turtlebot4"])
        .output()
        .expect("running formation-agent");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains(
            "--profile must name a robot profile, one of \"ideal\", \"pioneer-p3dx\", \
             \"turtlebot3-burger\" (got \"turtlebot4\")"
        ),
        "{stderr}"
    );
}
