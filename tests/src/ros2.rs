//! What the ROS 2 tests share: a ROS 2 agent's decision computed in the test's own process, the
//! scans they make up, and the independent client's script and JSON lines.
//!
//! [`InProcessDecision`] is the agent's pipeline without the agent: the LaserScan resampled onto
//! the model's ring (`formation_ros2::resample_scan`), the occupancy image and the policy
//! (`formation_robot_agent::decision::Agent`), so a test compares the Twist a `formation-agent
//! --transport ros2` published with this one bit for bit ([`twist_bits`]).
//! [`range_to_discs`] casts one beam at a set of discs, for the scans the tests send.
//! [`client_script`] is the Python client (`tests/python/ros2_client.py`) the tests drive the
//! agent with; [`parse_event`], [`is_event`] and [`answered_bits`] read its JSON lines.

use std::path::PathBuf;

use formation_proto::{Goal, LidarSpec, WheelCmd};
use formation_robot_agent::decision::Agent;
use formation_robot_agent::pilot::OnnxPilots;
use formation_ros2::{LaserScan, PartialScan, RingContract, Twist, resample_scan};
use formation_runtime::agent::PilotMaker;

use serde_json::Value;

use crate::{repo_root, test_model};

/// The test model's decision in this process, on the scans a ROS 2 agent is sent.
pub struct InProcessDecision {
    agent: Agent,
    contract: RingContract,
}

impl InProcessDecision {
    /// The shipped test model ([`test_model`]) on its own ring, noiseless.
    pub fn new() -> InProcessDecision {
        let model = OnnxPilots
            .load(test_model())
            .expect("loading the test model");
        let contract = RingContract {
            beams: model.sensor().beams.expect("the model's beams"),
            max_range: model.sensor().max_range.expect("the model's range"),
        };
        let lidar = LidarSpec {
            beams: contract.beams,
            max_range: contract.max_range,
        };
        InProcessDecision {
            agent: Agent::new(model, lidar).expect("the in-process agent"),
            contract,
        }
    }

    /// The wheel speeds for `scan` at `heading` under `goal`, the scan resampled as `partial`
    /// says.
    pub fn wheels(
        &mut self,
        scan: &LaserScan,
        heading: f64,
        goal: &Goal,
        partial: PartialScan,
    ) -> WheelCmd {
        let resampled = resample_scan(scan, self.contract, partial).expect("a usable scan");
        self.agent
            .perceive(&resampled.ranges, goal)
            .expect("in-process perception");
        self.agent.decide(heading).expect("in-process decision")
    }
}

impl Default for InProcessDecision {
    fn default() -> Self {
        InProcessDecision::new()
    }
}

/// A Twist's six values as bits, to compare two Twists exactly.
pub fn twist_bits(twist: &Twist) -> [u64; 6] {
    [
        twist.linear.x,
        twist.linear.y,
        twist.linear.z,
        twist.angular.x,
        twist.angular.y,
        twist.angular.z,
    ]
    .map(f64::to_bits)
}

/// The range \[m\] at which a beam from the origin at `angle` \[rad\] first meets one of
/// `discs` (`(x, y, radius)`), or +inf (REP-117's "nothing within range") when none is within
/// `range_max`.
pub fn range_to_discs(angle: f64, discs: &[(f64, f64, f64)], range_max: f32) -> f32 {
    let (dx, dy) = (angle.cos(), angle.sin());
    let hit = discs
        .iter()
        .filter_map(|&(x, y, r)| {
            let along = dx * x + dy * y;
            let disc = along * along - (x * x + y * y) + r * r;
            (disc >= 0.0).then(|| along - disc.sqrt())
        })
        .filter(|&t| t > 0.0)
        .fold(f64::INFINITY, f64::min);
    if hit <= f64::from(range_max) {
        hit as f32
    } else {
        f32::INFINITY
    }
}

/// The independent ROS 2 client the tests drive an agent with.
pub fn client_script() -> PathBuf {
    repo_root().join("tests/python/ros2_client.py")
}

/// One JSON event line of the client (`{"event": ...}`), or `None` for any other line.
pub fn parse_event(line: &str) -> Option<Value> {
    serde_json::from_str::<Value>(line)
        .ok()
        .filter(|v| v.get("event").is_some())
}

/// Whether `line` is a client event named one of `names`.
pub fn is_event(line: &str, names: &[&str]) -> bool {
    parse_event(line)
        .and_then(|v| v["event"].as_str().map(|e| names.contains(&e)))
        .unwrap_or(false)
}

/// The bit patterns of the Twist the client decoded (its answer's `twist_bits`), to compare
/// with [`twist_bits`].
pub fn answered_bits(answer: &Value) -> [u64; 6] {
    let bits: Vec<u64> = answer["twist_bits"]
        .as_array()
        .expect("twist_bits")
        .iter()
        .map(|b| b.as_u64().expect("u64 bits"))
        .collect();
    bits.try_into().expect("six components")
}
