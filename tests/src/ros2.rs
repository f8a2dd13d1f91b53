//! What the ROS 2 tests share: a ROS 2 agent's decision computed in the test's own process, the
//! scans they make up, and the independent client's script and JSON lines.
//!
//! [`InProcessDecision`] is the agent's pipeline without the agent: the LaserScan resampled onto
//! the model's ring (`formation_ros2::resample_scan`), the occupancy image and the policy
//! (`formation_robot_agent::decision::Agent`), so a test compares the Twist a `formation-agent
//! --transport ros2` published with this one bit for bit ([`twist_bits`]).
//! [`range_to_discs`] casts one beam at a set of discs, for the scans the tests send.
//! [`client_script`] is the Python client (`tests/python/ros2_client.py`) the tests drive the
//! agent with, [`clients`] the interpreter with its packages; [`parse_event`], [`is_event`] and
//! [`answered_bits`] read its JSON lines. [`plan`] is a client's plan over the usual topics (the
//! agent's [`topic_flags`]), and [`session`] runs one plan against one agent, the [`Outcome`]
//! holding what both did.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use formation_proto::{Goal, LidarSpec, WheelCmd};
use formation_robot_agent::decision::Agent;
use formation_robot_agent::pilot::OnnxPilots;
use formation_ros2::{LaserScan, PartialScan, RingContract, Twist, resample_scan};
use formation_runtime::agent::PilotMaker;

use serde_json::{Value, json};

use crate::{
    Finished, LiveProcess, PYTHON_MISSING_PACKAGE, binaries, free_tcp_port, python, repo_root,
    send_signal, test_model,
};

/// How long the client may take to come up, or to run its plan.
pub const CLIENT_WAIT: Duration = Duration::from_secs(120);

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

/// The interpreter with the client's packages. A missing package or interpreter fails the tests
/// that need it with the fix (no test passes by skipping), as does any other failure of
/// `ros2_client.py check` (a broken script).
pub fn clients() -> &'static Path {
    static FOUND: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let found = FOUND.get_or_init(|| {
        let python = python();
        let output = Command::new(&python)
            .arg(client_script())
            .arg("check")
            .output();
        let missing = match output {
            Ok(out) if out.status.success() => return Ok(python),
            Ok(out) if out.status.code() == Some(PYTHON_MISSING_PACKAGE) => {
                String::from_utf8_lossy(&out.stderr).trim().to_owned()
            }
            Ok(out) => panic!(
                "{} {} check failed ({}):\n{}{}",
                python.display(),
                client_script().display(),
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            ),
            Err(e) => format!("cannot run {}: {e}", python.display()),
        };
        Err(format!(
            "the independent ROS 2 clients are not installed for {} ({missing}); install them \
             with `bash .ci/setup-python --test` (tests/python/requirements-ros2.txt)",
            python.display()
        ))
    });
    match found {
        Ok(python) => python,
        Err(why) => panic!("{why}"),
    }
}

/// The topic of the scans a plan sends.
pub const SCAN_TOPIC: &str = "/scan";
/// The topic of the orientations (`sensor_msgs/Imu`) a plan sends.
pub const IMU_TOPIC: &str = "/imu";
/// The topic the agent publishes its Twists on.
pub const CMD_VEL_TOPIC: &str = "/cmd_vel";
/// The goal's topics: heading, distance, speed.
pub const GOAL_TOPICS: [&str; 3] = [
    "/team/goal/heading",
    "/team/goal/distance",
    "/team/goal/speed",
];

/// The agent's flags for the topics above, with the goal on its three topics.
pub fn topic_flags() -> Vec<&'static str> {
    vec![
        "--scan",
        SCAN_TOPIC,
        "--orientation",
        IMU_TOPIC,
        "--orientation-type",
        "imu",
        "--cmd-vel",
        CMD_VEL_TOPIC,
        "--heading-topic",
        GOAL_TOPICS[0],
        "--distance-topic",
        GOAL_TOPICS[1],
        "--speed-topic",
        GOAL_TOPICS[2],
    ]
}

/// A plan of `steps` over the topics above with `goal` published on its topics; the plan's
/// other parts (`goal_via_sdk`, `stream`, `hold`, `discover`) off, for a test to turn on.
pub fn plan(goal: &Goal, steps: Vec<Value>) -> Value {
    json!({
        "domain_id": 0,
        "scan_topic": SCAN_TOPIC,
        "orientation_topic": IMU_TOPIC,
        "cmd_vel_topic": CMD_VEL_TOPIC,
        "goal_topics": GOAL_TOPICS,
        "goal_bits": [goal.phi_star.to_bits(), goal.d_star.to_bits(), goal.v_star.to_bits()],
        "goal_via_sdk": false,
        "steps": steps,
        "stream": null,
        "hold": false,
        "discover": false,
    })
}

/// What a client and an agent did in one [`session`].
pub struct Outcome {
    events: Vec<Value>,
    client: Finished,
    agent: Finished,
}

impl Outcome {
    /// The client's events named `name`, in order.
    pub fn all(&self, name: &str) -> Vec<&Value> {
        self.events.iter().filter(|e| e["event"] == name).collect()
    }

    /// The client's one event named `name`; panics unless there is exactly one.
    pub fn one(&self, name: &str) -> &Value {
        let found = self.all(name);
        assert_eq!(found.len(), 1, "one {name} event\n{}", self.describe());
        found[0]
    }

    /// The answers to the plan's steps, in order.
    pub fn answers(&self) -> Vec<&Value> {
        self.all("answer")
    }

    /// The agent's stderr as text.
    pub fn agent_stderr(&self) -> String {
        self.agent.stderr()
    }

    /// Everything needed to understand a failure: the client's and the agent's results.
    pub fn describe(&self) -> String {
        format!(
            "=== client ===\n{}\n=== agent ===\n{}",
            self.client.describe(),
            self.agent.describe()
        )
    }

    /// Panics with `why` and [`Outcome::describe`] unless `holds`: a check of what they did.
    #[track_caller]
    pub fn assert_holds(&self, holds: bool, why: &str) {
        assert!(holds, "{why}\n{}", self.describe());
    }

    /// Panics unless the agent's stderr contains `needle`.
    pub fn assert_agent_said(&self, needle: &str) {
        self.assert_holds(
            self.agent_stderr().contains(needle),
            &format!("the agent's stderr should say {needle:?}"),
        );
    }

    /// The checks every session ends with: the client found nothing wrong with any sample on
    /// `cmd_vel` (key with rosbags' hash, 33-byte attachment with a 16-byte GID, CDR header),
    /// the agent's sequence numbers increase under one GID, and the agent left on SIGTERM.
    pub fn assert_clean_wire_and_exit(&self) {
        let summary = self.one("summary");
        assert_eq!(summary["problems"], json!([]), "{}", self.describe());
        assert_eq!(
            summary["sequences_increase"],
            json!(true),
            "{}",
            self.describe()
        );
        let gids = summary["gids"].as_array().expect("gids");
        assert_eq!(gids.len(), 1, "one publisher GID\n{}", self.describe());
        assert_eq!(
            self.agent.output.status.code(),
            Some(143),
            "the agent exits with 143 on SIGTERM\n{}",
            self.describe()
        );
        self.assert_agent_said("exiting: termination signal (SIGTERM)");
    }
}

/// Runs one session: the client (the router, with `python`) with `plan`, written to
/// `NAME.json` in `dir`, then `formation-agent --transport ros2` of the test model connected to
/// it with `flags`; waits for the client's plan to end (sending the agent SIGTERM when the
/// client says it is driving, for a plan that holds), then stops the agent with SIGTERM and lets
/// the client print its summary. Panics unless the client completed its plan.
pub fn session(python: &Path, dir: &Path, name: &str, plan: &Value, flags: &[&str]) -> Outcome {
    // Built (on first use) before the client starts its clock.
    let agent_binary = &binaries().agent;
    let plan_path = dir.join(format!("{name}.json"));
    std::fs::write(&plan_path, serde_json::to_vec(plan).expect("plan JSON")).expect("plan file");
    let endpoint = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let mut client = Command::new(python);
    client
        .arg(client_script())
        .arg("run")
        .arg(&plan_path)
        .args(["--listen", &endpoint]);
    let mut client = LiveProcess::spawn_with_input(client, Some(""));
    if client
        .wait_for_line(CLIENT_WAIT, |l| is_event(l, &["listening"]))
        .is_none()
    {
        panic!("the client did not listen\n{}", client.describe());
    }
    let mut agent = Command::new(agent_binary);
    agent
        .args(["--transport", "ros2", "--connect", &endpoint])
        .args(["--connect-timeout-ms", "30000", "--model"])
        .arg(test_model())
        .args(flags);
    let agent = LiveProcess::spawn(agent);
    let holds = plan["hold"] == json!(true);
    let wanted: &[&str] = if holds {
        &["driving", "error"]
    } else {
        &["done", "error"]
    };
    let mut line = client.wait_for_line(CLIENT_WAIT, |l| is_event(l, wanted));
    let mut terminated = false;
    if holds && line.as_deref().is_some_and(|l| is_event(l, &["driving"])) {
        // Stray signals first: they interrupt nothing and end nothing (the agent must still be
        // there for SIGTERM, and exit 130 on it).
        for stray in ["USR1", "USR2", "CONT", "ALRM"] {
            send_signal(agent.id(), stray);
        }
        send_signal(agent.id(), "TERM");
        terminated = true;
        line = client.wait_for_line(CLIENT_WAIT, |l| is_event(l, &["done", "error"]));
    }
    let ok = line.as_deref().is_some_and(|l| is_event(l, &["done"]));
    if !terminated {
        // Tolerates an agent that is gone already: its status tells.
        let _ = Command::new("kill")
            .args(["-TERM", &agent.id().to_string()])
            .status();
    }
    let agent = agent.finish(Duration::from_secs(60));
    client.close_input();
    let client = client.finish(Duration::from_secs(60));
    let events = client.stdout().lines().filter_map(parse_event).collect();
    let outcome = Outcome {
        events,
        client,
        agent,
    };
    assert!(
        ok,
        "the client did not complete its plan\n{}",
        outcome.describe()
    );
    outcome
}
