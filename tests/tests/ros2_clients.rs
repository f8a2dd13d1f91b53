//! Issue 14's acceptance tests of `formation-agent --transport ros2` against independent ROS 2
//! clients: `tests/python/ros2_client.py` drives the agent with `eclipse-zenoh` (it is the Zenoh
//! router the agent connects to, as a robot's `rmw_zenohd` would be), `rosbags` (CDR of
//! LaserScan, Imu, Float64 and Twist, and the RIHS01 type hashes) and `zenoh-ros2-sdk`
//! (discovery through liveliness tokens, and a Float64 publisher of its own), none of them
//! written here. The Twists the agent answers with are checked bit for bit against the same
//! decision computed in this process; bad input must be reported on the agent's stderr and brake
//! the robot (a zero Twist); an unreachable router must end the agent with a clear error.
//!
//! The scans, orientations and goals are made here and handed to the client in a JSON plan, as
//! IEEE-754 bit patterns, so that both sides use exactly the same numbers.
//!
//! The Python packages come from `tests/python/requirements-ros2.txt` (`bash .ci/setup-python --test`
//! installs them into `.venv`). Without them the tests that need them fail with that fix.
//!
//! Every test uses its own free TCP port and scratch folder, runs alone within this binary
//! ([`one_at_a_time`]), and stops every process it started.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use formation_proto::Goal;
use formation_ros2::msg::Quaternion;
use formation_ros2::{
    Header, LaserScan, PartialScan, Time, Twist, twist_from_wheels, yaw_from_quaternion,
};
use formation_tests::ros2::{
    CMD_VEL_TOPIC, GOAL_TOPICS, IMU_TOPIC, InProcessDecision, Outcome, SCAN_TOPIC, answered_bits,
    clients, plan, range_to_discs, session, topic_flags, twist_bits,
};
use formation_tests::{ProcessTest, binaries, run, test_model};
use rand::{Rng, SeedableRng};
use serde_json::{Value, json};

const LIMIT: Duration = Duration::from_secs(300);
/// The agent's default wheel separation (the P3-DX's), which these tests do not override.
const WHEEL_SEPARATION: f64 = 0.331;

// ---------------------------------------------------------------------------------------------
// Scans, orientations and goals, and the decision in this process

/// A LaserScan as both sides see it.
#[derive(Debug, Clone)]
struct Scan {
    stamp_ns: i64,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: Vec<f32>,
}

impl Scan {
    fn angle_max(&self) -> f32 {
        self.angle_min + self.angle_increment * (self.ranges.len() - 1) as f32
    }

    fn message(&self) -> LaserScan {
        LaserScan {
            header: Header {
                stamp: Time::from_nanos(self.stamp_ns),
                frame_id: "laser".into(),
            },
            angle_min: self.angle_min,
            angle_max: self.angle_max(),
            angle_increment: self.angle_increment,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: self.range_min,
            range_max: self.range_max,
            ranges: self.ranges.clone(),
            intensities: Vec::new(),
        }
    }

    fn to_json(&self) -> Value {
        json!({
            "stamp_ns": self.stamp_ns,
            "angle_min_bits": self.angle_min.to_bits(),
            "angle_max_bits": self.angle_max().to_bits(),
            "angle_increment_bits": self.angle_increment.to_bits(),
            "range_min_bits": self.range_min.to_bits(),
            "range_max_bits": self.range_max.to_bits(),
            "ranges_bits": self.ranges.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
        })
    }

    fn with_stamp(&self, stamp_ns: i64) -> Scan {
        Scan {
            stamp_ns,
            ..self.clone()
        }
    }
}

/// Circular obstacles `(x, y, radius)` around the robot, from `seed`: four to seven within the
/// occupancy window of the test model (±2.5 m), so that they shape its decision.
fn obstacles(seed: u64) -> Vec<(f64, f64, f64)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let count = rng.random_range(4..8);
    (0..count)
        .map(|_| {
            let distance: f64 = rng.random_range(0.6..2.3);
            let bearing: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let radius: f64 = rng.random_range(0.1..0.4);
            (distance * bearing.cos(), distance * bearing.sin(), radius)
        })
        .collect()
}

/// A real-looking scan of `obstacles`: `readings` readings from `angle_min` every `increment`
/// \[rad\], limits 0.05–8 m, readings beyond the maximum as +inf (REP-117), and a few dropouts:
/// every 37th reading NaN and every 53rd below the minimum range.
fn cast_scan(
    stamp_ns: i64,
    angle_min: f32,
    increment: f32,
    readings: usize,
    obstacles: &[(f64, f64, f64)],
) -> Scan {
    let (range_min, range_max) = (0.05f32, 8.0f32);
    let ranges = (0..readings)
        .map(|i| {
            if i % 37 == 5 {
                return f32::NAN;
            }
            if i % 53 == 7 {
                return 0.01;
            }
            let angle = f64::from(angle_min) + i as f64 * f64::from(increment);
            range_to_discs(angle, obstacles, range_max)
        })
        .collect();
    Scan {
        stamp_ns,
        angle_min,
        angle_increment: increment,
        range_min,
        range_max,
        ranges,
    }
}

/// A full-circle scan of 720 readings (0.5°, not the model's 0.4°: resampling is exercised).
fn full_scan(stamp_ns: i64, seed: u64, angle_min: f32, counter_clockwise: bool) -> Scan {
    let step = (std::f64::consts::TAU / 720.0) as f32;
    let increment = if counter_clockwise { step } else { -step };
    cast_scan(stamp_ns, angle_min, increment, 720, &obstacles(seed))
}

/// An Imu orientation: a heading with a little roll and pitch (a robot on a ramp).
#[derive(Debug, Clone, Copy)]
struct Orientation {
    stamp_ns: i64,
    quaternion: [f64; 4],
}

impl Orientation {
    fn new(stamp_ns: i64, roll: f64, pitch: f64, yaw: f64) -> Orientation {
        let (sr, cr) = (roll / 2.0).sin_cos();
        let (sp, cp) = (pitch / 2.0).sin_cos();
        let (sy, cy) = (yaw / 2.0).sin_cos();
        Orientation {
            stamp_ns,
            quaternion: [
                sr * cp * cy - cr * sp * sy,
                cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy,
                cr * cp * cy + sr * sp * sy,
            ],
        }
    }

    /// The heading the agent must read from it.
    fn heading(&self) -> f64 {
        let [x, y, z, w] = self.quaternion;
        yaw_from_quaternion(&Quaternion { x, y, z, w }).expect("a heading")
    }

    fn to_json(self) -> Value {
        json!({
            "stamp_ns": self.stamp_ns,
            "quaternion_bits": self.quaternion.map(f64::to_bits),
        })
    }
}

/// One step of a plan: an orientation (if any) then a scan, answered by one Twist.
fn step(orientation: Option<Orientation>, scan: &Scan) -> Value {
    json!({ "imu": orientation.map(Orientation::to_json), "scan": scan.to_json() })
}

/// The goal of every test: φ* 0.3 rad, d* 1.2 m, v* 0.5 m/s.
const GOAL: Goal = Goal {
    phi_star: 0.3,
    d_star: 1.2,
    v_star: 0.5,
};

/// The Twist of the agent's decision computed in this process
/// ([`InProcessDecision`]), made with the robot's wheel separation.
fn in_process_twist(
    reference: &mut InProcessDecision,
    scan: &Scan,
    heading: f64,
    partial: PartialScan,
) -> Twist {
    let wheels = reference.wheels(&scan.message(), heading, &GOAL, partial);
    twist_from_wheels(wheels.left, wheels.right, WHEEL_SEPARATION).expect("a Twist")
}

fn is_zero(answer: &Value) -> bool {
    answer["zero"] == json!(true)
}

/// Panics unless `answer` answers `scan` (by the attachment's source timestamp).
fn assert_answers(outcome: &Outcome, answer: &Value, scan: &Scan) {
    assert_eq!(
        answer["stamp_ns"].as_i64(),
        Some(scan.stamp_ns),
        "{}",
        outcome.describe()
    );
}

/// Panics unless `answer` drives exactly as `expected`, bit for bit.
fn assert_drives_as(outcome: &Outcome, answer: &Value, expected: &Twist, what: &str) {
    outcome.assert_holds(!is_zero(answer), &format!("{what}: the agent braked"));
    assert_eq!(
        answered_bits(answer),
        twist_bits(expected),
        "{what}: the agent's Twist {} differs from the in-process {expected:?}\n{}",
        answer["twist"],
        outcome.describe()
    );
}

fn stamp(i: i64) -> i64 {
    // 2023-11-14T22:13:20Z plus 50 ms per scan: a robot's clock, far from this host's.
    1_700_000_000_000_000_000 + i * 50_000_000
}

// ---------------------------------------------------------------------------------------------
// The tests

/// The agent answers each LaserScan (720 readings over 360°, at three different starting angles
/// and both directions, obstacles from a fixed seed, readings beyond the maximum as +inf, a few
/// NaN and too-short readings) with exactly the Twist that the same decision gives in this
/// process: the scan resampled onto the model's 900-beam ring, the heading of the `sensor_msgs/Imu`
/// quaternion, the goal received on three `std_msgs/Float64` topics, `twist_from_wheels`. The
/// client serialises everything with rosbags and matches each Twist to its scan by the
/// attachment's source timestamp; the Twists are compared bit for bit (the agent runs the same
/// code on the same f32/f64 values, so nothing may differ).
#[test]
fn twists_answer_laser_scans_and_imu_as_the_in_process_decision_does() {
    let t = ProcessTest::start("ros2_twists_as_in_process", LIMIT);
    let python = clients();
    let half_turn = std::f32::consts::PI;
    let cases = [
        (
            full_scan(stamp(0), 1, 0.0, true),
            Orientation::new(stamp(0), 0.02, -0.01, 0.4),
        ),
        (
            full_scan(stamp(1), 2, -half_turn, true),
            Orientation::new(stamp(1), -0.03, 0.02, -2.0),
        ),
        (
            full_scan(stamp(2), 3, half_turn, false),
            Orientation::new(stamp(2), 0.0, 0.0, 3.0),
        ),
    ];
    let steps = cases
        .iter()
        .map(|(scan, imu)| step(Some(*imu), scan))
        .collect();
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "5000"]);
    let outcome = session(python, t.path(), "decide", &plan(&GOAL, steps), &flags);

    let mut reference = InProcessDecision::new();
    let answers = outcome.answers();
    assert_eq!(answers.len(), cases.len(), "{}", outcome.describe());
    let mut expected_twists = Vec::new();
    for (i, ((scan, imu), answer)) in cases.iter().zip(&answers).enumerate() {
        assert_answers(&outcome, answer, scan);
        let expected = in_process_twist(&mut reference, scan, imu.heading(), PartialScan::Refuse);
        assert_drives_as(&outcome, answer, &expected, &format!("scan {i}"));
        expected_twists.push(twist_bits(&expected));
    }
    // The three inputs give three decisions: the comparison above is not of constants.
    expected_twists.dedup();
    assert_eq!(expected_twists.len(), cases.len(), "{}", outcome.describe());
    outcome.assert_clean_wire_and_exit();
}

/// `zenoh-ros2-sdk` finds the agent through its liveliness tokens, as `ros2 topic list -t` and
/// `ros2 topic info -v` would: its subscriptions to the scan (`sensor_msgs/msg/LaserScan`), the
/// orientation (`sensor_msgs/msg/Imu`) and the goal topics (`std_msgs/msg/Float64`), and its
/// `cmd_vel` publisher (`geometry_msgs/msg/Twist`), all of node `--node-name` in `/`, with the
/// RIHS01 hashes rosbags computes; the node list (`NN` tokens, read with eclipse-zenoh's
/// liveliness query: the SDK has no node listing) shows the node once, on the session of its
/// publisher token. The goal comes from the SDK's own `ROS2Publisher`, whose type hash (computed
/// by the SDK from the explicitly given `float64 data`) equals rosbags', and the agent drives on
/// it exactly as in process.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one scripted scenario against an independent client: its steps read in order"
)]
fn zenoh_ros2_sdk_discovers_the_agents_node_and_topics_through_liveliness() {
    let t = ProcessTest::start("ros2_discovery", LIMIT);
    let python = clients();
    let node = "ros2_clients_agent";
    let scan = full_scan(stamp(0), 4, 0.0, true);
    let imu = Orientation::new(stamp(0), 0.0, 0.0, 1.0);
    let mut plan = plan(&GOAL, vec![step(Some(imu), &scan)]);
    plan["goal_via_sdk"] = json!(true);
    plan["discover"] = json!(true);
    let mut flags = topic_flags();
    flags.extend(["--node-name", node, "--stale-ms", "5000"]);
    let outcome = session(python, t.path(), "discover", &plan, &flags);

    let answers = outcome.answers();
    assert_eq!(answers.len(), 1, "{}", outcome.describe());
    let expected = in_process_twist(
        &mut InProcessDecision::new(),
        &scan,
        imu.heading(),
        PartialScan::Refuse,
    );
    assert_drives_as(
        &outcome,
        answers[0],
        &expected,
        "the scan after the SDK's goals",
    );

    let discovery = outcome.one("discovery");
    let hashes = &discovery["rosbags_hashes"];
    let sdk_hashes = &outcome.one("sdk_goal_publishers")["type_hashes"];
    assert_eq!(
        sdk_hashes,
        &Value::Array(vec![hashes["std_msgs/msg/Float64"].clone(); 3]),
        "{}",
        outcome.describe()
    );
    let listed: Vec<(String, Vec<String>)> =
        serde_json::from_value(discovery["topics"].clone()).expect("topic list");
    let mut wanted = vec![
        (SCAN_TOPIC, "sensor_msgs/msg/LaserScan"),
        (IMU_TOPIC, "sensor_msgs/msg/Imu"),
        (CMD_VEL_TOPIC, "geometry_msgs/msg/Twist"),
    ];
    wanted.extend(GOAL_TOPICS.map(|t| (t, "std_msgs/msg/Float64")));
    for (topic, ros_type) in &wanted {
        outcome.assert_holds(
            listed.contains(&(topic.to_string(), vec![ros_type.to_string()])),
            &format!("`ros2 topic list -t` should show {topic} [{ros_type}]: {listed:?}"),
        );
    }
    let endpoint = |topic: &str, side: &str, ros_type: &str| {
        let info = &discovery["info"][topic];
        let entries = info[side]
            .as_array()
            .unwrap_or_else(|| panic!("{topic}: no info\n{}", outcome.describe()));
        assert_eq!(
            entries.len(),
            1,
            "{topic}: one {side} entry\n{}",
            outcome.describe()
        );
        let entry = &entries[0];
        assert_eq!(entry["node_name"], node, "{}", outcome.describe());
        assert_eq!(entry["node_namespace"], "/", "{}", outcome.describe());
        assert_eq!(entry["topic_type"], ros_type, "{}", outcome.describe());
        assert_eq!(
            entry["type_hash"],
            hashes[ros_type],
            "{topic}: the type hash rosbags computes\n{}",
            outcome.describe()
        );
    };
    endpoint(SCAN_TOPIC, "subscribers", "sensor_msgs/msg/LaserScan");
    endpoint(IMU_TOPIC, "subscribers", "sensor_msgs/msg/Imu");
    endpoint(CMD_VEL_TOPIC, "publishers", "geometry_msgs/msg/Twist");
    for topic in GOAL_TOPICS {
        // The SDK's goal publisher is on these topics too; the agent is their one subscriber.
        endpoint(topic, "subscribers", "std_msgs/msg/Float64");
    }
    for topic in [SCAN_TOPIC, IMU_TOPIC] {
        assert_eq!(
            discovery["info"][topic]["publishers"],
            json!([]),
            "the agent publishes nothing on {topic}\n{}",
            outcome.describe()
        );
    }
    assert_eq!(
        discovery["info"][CMD_VEL_TOPIC]["subscribers"],
        json!([]),
        "{}",
        outcome.describe()
    );

    let nodes: Vec<&Value> = discovery["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .filter(|n| n["name"] == node)
        .collect();
    assert_eq!(nodes.len(), 1, "one node {node}\n{}", outcome.describe());
    assert_eq!(nodes[0]["namespace"], "/", "{}", outcome.describe());
    let publisher_token = outcome.one("agent")["token"]
        .as_str()
        .expect("token")
        .to_owned();
    let publisher_zid = publisher_token.split('/').nth(2).expect("a zid");
    assert_eq!(
        nodes[0]["zid"],
        publisher_zid,
        "the node and its publisher live on one session\n{}",
        outcome.describe()
    );
    outcome.assert_clean_wire_and_exit();
}

/// A LaserScan published on a key with another type's RIHS01 hash (a publisher whose message
/// definition differs) is reported on stderr, naming the topic and both hashes, and never decided
/// on; with only such scans arriving, the robot brakes (a zero Twist) when the stale window
/// passes, telling why.
#[test]
fn a_laser_scan_with_another_type_hash_is_reported_and_the_robot_brakes() {
    let t = ProcessTest::start("ros2_wrong_hash", LIMIT);
    let python = clients();
    let outcome = bad_stream(python, t.path(), "wrong_hash");
    let other_hash = outcome.one("stream")["other_hash"]
        .as_str()
        .expect("the hash used")
        .to_owned();
    outcome.assert_agent_said("formation-agent: ignoring an input: /scan carries");
    outcome.assert_agent_said(&format!("with type hash {other_hash}"));
    outcome.assert_clean_wire_and_exit();
}

/// A LaserScan whose CDR is cut in half is reported on stderr as not a valid LaserScan and never
/// decided on; with only such scans arriving, the robot brakes when the stale window passes.
#[test]
fn a_truncated_laser_scan_is_reported_and_the_robot_brakes() {
    let t = ProcessTest::start("ros2_truncated", LIMIT);
    let python = clients();
    let outcome = bad_stream(python, t.path(), "truncated");
    outcome.assert_agent_said(
        "formation-agent: ignoring an input: a sample on /scan is not a valid \
         sensor_msgs/msg/LaserScan (CDR)",
    );
    outcome.assert_clean_wire_and_exit();
}

/// Drives once on a good scan, then streams `bad` scans (every 50 ms, stale window 500 ms) until
/// the agent publishes a zero Twist; checks that it drove first, answered none of the bad scans
/// and braked after, saying no LaserScan came.
fn bad_stream(python: &Path, dir: &Path, bad: &str) -> Outcome {
    let good = full_scan(stamp(0), 5, 0.0, true);
    let imu = Orientation::new(stamp(0), 0.0, 0.0, -0.7);
    let mut plan = plan(&GOAL, vec![step(Some(imu), &good)]);
    plan["stream"] = json!({
        "bad": bad,
        "scan": full_scan(stamp(100), 6, 0.0, true).to_json(),
        "period_ms": 50,
        "limit_s": 60,
    });
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "500"]);
    let outcome = session(python, dir, bad, &plan, &flags);
    let answers = outcome.answers();
    assert_eq!(answers.len(), 1, "{}", outcome.describe());
    assert_answers(&outcome, answers[0], &good);
    outcome.assert_holds(!is_zero(answers[0]), "the robot drove before the bad input");
    let brake = outcome.one("brake");
    assert!(is_zero(brake), "{}", outcome.describe());
    assert_eq!(
        brake["streamed_answered"],
        json!(0),
        "{}",
        outcome.describe()
    );
    outcome.assert_agent_said("formation-agent: braking: no LaserScan on /scan for");
    outcome
}

/// A LaserScan whose readings are mostly NaN (erroneous measurements, REP-117) is answered with a
/// zero Twist, and the agent says how many readings were NaN; the next good scan drives again.
#[test]
fn a_scan_of_mostly_nan_readings_brakes_the_robot_with_the_reason() {
    let t = ProcessTest::start("ros2_nan", LIMIT);
    let python = clients();
    let good = full_scan(stamp(0), 7, 0.0, true);
    let mut nan = full_scan(stamp(1), 8, 0.0, true);
    for (i, r) in nan.ranges.iter_mut().enumerate() {
        if i % 4 != 0 {
            *r = f32::NAN;
        }
    }
    let nans = nan.ranges.iter().filter(|r| r.is_nan()).count();
    let again = good.with_stamp(stamp(2));
    let imu = |i| Orientation::new(stamp(i), 0.0, 0.0, 0.9);
    let steps = vec![
        step(Some(imu(0)), &good),
        step(Some(imu(1)), &nan),
        step(Some(imu(2)), &again),
    ];
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "5000"]);
    let outcome = session(python, t.path(), "nan", &plan(&GOAL, steps), &flags);
    let answers = outcome.answers();
    assert_eq!(answers.len(), 3, "{}", outcome.describe());
    for (answer, scan) in answers.iter().zip([&good, &nan, &again]) {
        assert_answers(&outcome, answer, scan);
    }
    assert!(!is_zero(answers[0]), "{}", outcome.describe());
    outcome.assert_holds(is_zero(answers[1]), "a NaN scan brakes");
    outcome.assert_holds(!is_zero(answers[2]), "a good scan drives again");
    outcome.assert_agent_said(&format!(
        "formation-agent: braking: the LaserScan on /scan has {nans} NaN readings of {}",
        nan.ranges.len()
    ));
    outcome.assert_clean_wire_and_exit();
}

/// A scan of the front half circle (360 readings from −90° to +90°) is refused with a zero
/// Twist and a message saying that the model needs the full 360°; with `--allow-partial-scan`
/// the same scan drives, with the Twist of the in-process decision on it (missing bearings as
/// no return).
#[test]
fn a_partial_circle_scan_brakes_unless_allowed_and_then_drives_as_in_process() {
    let t = ProcessTest::start("ros2_partial", LIMIT);
    let python = clients();
    let good = full_scan(stamp(0), 9, 0.0, true);
    let step_angle = (std::f64::consts::TAU / 720.0) as f32;
    let half = cast_scan(
        stamp(1),
        -std::f32::consts::FRAC_PI_2,
        step_angle,
        360,
        &obstacles(10),
    );
    let imu = |i| Orientation::new(stamp(i), 0.0, 0.0, 1.3);
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "5000"]);

    let steps = vec![step(Some(imu(0)), &good), step(Some(imu(1)), &half)];
    let refused = session(python, t.path(), "refused", &plan(&GOAL, steps), &flags);
    let answers = refused.answers();
    assert_eq!(answers.len(), 2, "{}", refused.describe());
    assert_answers(&refused, answers[0], &good);
    assert_answers(&refused, answers[1], &half);
    assert!(!is_zero(answers[0]), "{}", refused.describe());
    refused.assert_holds(is_zero(answers[1]), "a partial scan brakes");
    refused.assert_agent_said(
        "formation-agent: braking: the LaserScan on /scan: the LaserScan covers 180.0°",
    );
    refused.assert_agent_said("but the model needs the full 360°");
    refused.assert_clean_wire_and_exit();

    flags.push("--allow-partial-scan");
    let steps = vec![step(Some(imu(1)), &half)];
    let allowed = session(python, t.path(), "allowed", &plan(&GOAL, steps), &flags);
    let answers = allowed.answers();
    assert_eq!(answers.len(), 1, "{}", allowed.describe());
    assert_answers(&allowed, answers[0], &half);
    let expected = in_process_twist(
        &mut InProcessDecision::new(),
        &half,
        imu(1).heading(),
        PartialScan::AllowAsNoReturn,
    );
    assert_drives_as(&allowed, answers[0], &expected, "the allowed partial scan");
    allowed.assert_clean_wire_and_exit();
}

/// A silent orientation topic brakes the robot with the reason: scans before any Imu are
/// answered with zero Twists ("no orientation received"); once the Imu has spoken the robot
/// drives; when the Imu stops while scans go on, the scans are answered with a zero Twist as soon
/// as the newest orientation is older than the stale window (500 ms).
#[test]
fn a_silent_orientation_topic_brakes_the_robot() {
    let t = ProcessTest::start("ros2_silent_orientation", LIMIT);
    let python = clients();
    let blind = full_scan(stamp(0), 11, 0.0, true);
    let good = full_scan(stamp(1), 12, 0.0, true);
    let imu = Orientation::new(stamp(1), 0.0, 0.0, 2.2);
    let mut plan = plan(&GOAL, vec![step(None, &blind), step(Some(imu), &good)]);
    plan["stream"] = json!({
        "bad": "no_orientation",
        "scan": good.with_stamp(stamp(100)).to_json(),
        "period_ms": 50,
        "limit_s": 60,
    });
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "500"]);
    let outcome = session(python, t.path(), "silent", &plan, &flags);
    let answers = outcome.answers();
    assert_eq!(answers.len(), 2, "{}", outcome.describe());
    assert_answers(&outcome, answers[0], &blind);
    assert_answers(&outcome, answers[1], &good);
    outcome.assert_holds(is_zero(answers[0]), "no orientation yet: brake");
    assert!(!is_zero(answers[1]), "{}", outcome.describe());
    let brake = outcome.one("brake");
    assert!(is_zero(brake), "{}", outcome.describe());
    assert_eq!(
        brake["answers_a_streamed_scan"],
        json!(true),
        "the brake answers a scan that came after the Imu fell silent\n{}",
        outcome.describe()
    );
    outcome.assert_agent_said("formation-agent: braking: no orientation received on /imu yet");
    outcome.assert_agent_said("formation-agent: braking: the newest orientation on /imu is");
    outcome.assert_agent_said("(the stale window is 0.50 s); is its publisher alive?");
    outcome.assert_clean_wire_and_exit();
}

/// On SIGTERM the agent publishes one zero Twist, and nothing after it, before it exits (with
/// status 130); the stray signals sent before it (SIGUSR1, SIGUSR2, SIGCONT, SIGALRM) change
/// nothing. The stale window is a minute, so no other brake can come meanwhile.
#[test]
fn on_sigterm_the_agent_publishes_one_zero_twist_before_exiting() {
    let t = ProcessTest::start("ros2_sigterm", LIMIT);
    let python = clients();
    let scan = full_scan(stamp(0), 13, 0.0, true);
    let imu = Orientation::new(stamp(0), 0.0, 0.0, -1.1);
    let mut plan = plan(&GOAL, vec![step(Some(imu), &scan)]);
    plan["hold"] = json!(true);
    let mut flags = topic_flags();
    flags.extend(["--stale-ms", "60000"]);
    let outcome = session(python, t.path(), "term", &plan, &flags);
    let answers = outcome.answers();
    assert_eq!(answers.len(), 1, "{}", outcome.describe());
    assert!(!is_zero(answers[0]), "{}", outcome.describe());
    let before = outcome.one("driving")["twists_so_far"]
        .as_u64()
        .expect("count") as usize;
    let summary = outcome.one("summary");
    let twists = summary["twists"].as_array().expect("twists");
    let after = &twists[before..];
    assert_eq!(
        after.len(),
        1,
        "exactly one Twist after SIGTERM\n{}",
        outcome.describe()
    );
    assert!(is_zero(&after[0]), "{}", outcome.describe());
    assert_eq!(
        twists.iter().filter(|t| is_zero(t)).count(),
        1,
        "no other brake\n{}",
        outcome.describe()
    );
    outcome.assert_clean_wire_and_exit();
}

/// Without a router at `--connect`, the agent fails with exit status 2 and a message naming the
/// endpoint and `rmw_zenohd`.
#[test]
fn an_unreachable_router_fails_with_status_2_naming_the_endpoint_and_rmw_zenohd() {
    let t = ProcessTest::start("ros2_unreachable", LIMIT);
    let nowhere = t.endpoint();
    let mut agent = Command::new(&binaries().agent);
    agent
        .args(["--transport", "ros2", "--connect", &nowhere])
        .args(["--connect-timeout-ms", "1500", "--model"])
        .arg(test_model());
    let finished = run(agent, LIMIT);
    finished.assert_failure_mentioning(&format!("cannot reach the ROS 2 router at {nowhere}"));
    finished.assert_failure_mentioning("rmw_zenohd");
    finished.assert_exit(2);
}
