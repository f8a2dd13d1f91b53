//! `formation-agent --transport ros2`: the flags of the ROS 2 mode, how they become
//! `formation_transport_ros2`'s `Ros2AgentSettings`, and the robot's pilots (`RobotPilot`s of
//! the ONNX agent) that the runtime's agent loop drives over the robot's topics, as it drives the
//! agents of every other transport.
//!
//! Topic defaults: with `--robot I`, the simulated team's (`/robot_I/scan`, `/robot_I/odom` as
//! Odometry, `/robot_I/cmd_vel`, node `/robot_I/formation_agent`); without it, a single robot's
//! (`/scan`, `/odom` as Odometry, `/cmd_vel`, node `/formation_agent`). Each goal component is a
//! fixed value when its flag is given (`--phi-star`, `--d-star`, `--v-star`), else the newest
//! `std_msgs/Float64` on its topic (`/formation/goal/heading`, `/distance`, `/speed` by default).
//!
//! `--profile NAME` (a robot profile the world knows: `pioneer-p3dx`, `turtlebot3-burger`) tells
//! the agent its robot: it expects that robot's LaserScan (beams, range, rate), and a scan that
//! differs is named in one warning; the wheel separation (unless `--wheel-separation`), the top
//! wheel speed (both wheels scaled by one factor into it, keeping the curvature) and the wheel
//! acceleration limit (which shapes a formation-velocity model's output) are the robot's. A
//! profile whose LIDAR is not the model's ring is told at start: its scans are resampled.

use std::sync::atomic::AtomicBool;

use clap::Args;
use formation_robot_agent::decision::PolicyBackend;
use formation_runtime::agent::AgentExit;
use formation_runtime::transport::Transport;
#[cfg(not(feature = "zenoh"))]
use formation_runtime::transport::TransportError;

#[cfg(feature = "zenoh")]
use {
    anyhow::Context,
    formation_proto::LidarSpec,
    formation_robot_agent::pilot::OnnxPilots,
    formation_ros2::{Namespace, NodeName, PartialScan, RingContract, TopicName},
    formation_runtime::agent::{AgentLoop, BoxError, Pilot, PilotMaker},
    formation_runtime::clock::SystemClock,
    formation_transport_ros2::agent::{ExpectedScan, run_agent_expecting},
    formation_transport_ros2::{
        DeciderSettings, GoalValue, OrientationKind, Ros2AgentSettings, TeamTopics,
    },
    formation_transport_zenoh::Endpoint,
    formation_world::scenario::{ProfileSettings, RobotProfile},
    std::path::Path,
    std::sync::Arc,
    std::time::Duration,
};

/// The P3-DX's wheel separation \[m\], the robot the shipped models were trained for.
#[cfg(feature = "zenoh")]
const P3DX_WHEEL_SEPARATION: f64 = 0.331;

/// Which message carries the orientation (mirrors the runtime's, so the flag exists in every
/// build).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OrientationType {
    /// `sensor_msgs/msg/Imu`.
    Imu,
    /// `nav_msgs/msg/Odometry`.
    Odometry,
}

/// Flags of the ROS 2 mode.
#[derive(Debug, Args)]
pub struct Ros2Args {
    /// ROS 2: the ROS domain id (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, env = "ROS_DOMAIN_ID", value_name = "ID",
          value_parser = clap::value_parser!(u32).range(0..=232))]
    ros_domain_id: Option<u32>,
    /// ROS 2: the robot's `sensor_msgs/LaserScan` topic.
    #[arg(long, value_name = "TOPIC")]
    scan: Option<String>,
    /// ROS 2: the robot's orientation topic (its type: --orientation-type).
    #[arg(long, value_name = "TOPIC")]
    orientation: Option<String>,
    /// ROS 2: the orientation topic's type.
    #[arg(long, value_enum, value_name = "TYPE")]
    orientation_type: Option<OrientationType>,
    /// ROS 2: where the `geometry_msgs/Twist` commands go.
    #[arg(long, value_name = "TOPIC")]
    cmd_vel: Option<String>,
    /// ROS 2: a fixed goal heading φ* \[rad\] (else the heading topic's newest value).
    #[arg(long, value_name = "RAD", allow_negative_numbers = true)]
    phi_star: Option<f64>,
    /// ROS 2: a fixed goal distance d* \[m\] (else the distance topic's newest value).
    #[arg(long, value_name = "M")]
    d_star: Option<f64>,
    /// ROS 2: a fixed goal speed v* \[m/s\] (else the speed topic's newest value).
    #[arg(long, value_name = "M/S")]
    v_star: Option<f64>,
    /// ROS 2: the `std_msgs/Float64` topic of the goal heading φ* \[rad\].
    #[arg(long, value_name = "TOPIC")]
    heading_topic: Option<String>,
    /// ROS 2: the `std_msgs/Float64` topic of the goal distance d* \[m\].
    #[arg(long, value_name = "TOPIC")]
    distance_topic: Option<String>,
    /// ROS 2: the `std_msgs/Float64` topic of the goal speed v* \[m/s\].
    #[arg(long, value_name = "TOPIC")]
    speed_topic: Option<String>,
    /// ROS 2: the robot's wheel separation \[m\], to turn wheel speeds into a Twist (default:
    /// the P3-DX's 0.331 m, the robot the shipped models were trained for).
    #[arg(long, value_name = "M")]
    wheel_separation: Option<f64>,
    /// ROS 2: an input older than this brakes the robot \[ms\] (default: 500, the `cmd_vel`
    /// timeout of ROS 2's diff_drive_controller).
    #[arg(long, value_name = "MS")]
    stale_ms: Option<u64>,
    /// ROS 2: accept a LaserScan that does not cover the full circle, reading the bearings it
    /// misses as no return (the model was trained on a full ring: expect worse formations).
    #[arg(long)]
    allow_partial_scan: bool,
    /// ROS 2: the node's name.
    #[arg(long, value_name = "NAME")]
    node_name: Option<String>,
    /// ROS 2: the robot, as a profile the world knows (`pioneer-p3dx`, `turtlebot3-burger`):
    /// its LaserScan is expected (a scan that differs is named once), and its wheel separation,
    /// top wheel speed and wheel acceleration limit are used.
    #[arg(long, value_name = "PROFILE")]
    profile: Option<String>,
    /// ROS 2: the robot's top wheel speed \[m/s\], told to the policy as the world tells its
    /// agents (a formation-velocity policy scales both wheels into it), over the profile's;
    /// `formation run --transport ros2` gives its scenario's.
    #[arg(long, value_name = "M/S", value_parser = positive_number)]
    max_wheel_speed: Option<f64>,
    /// ROS 2: the robot's wheel acceleration limit \[m/s²\], over the profile's.
    #[arg(long, value_name = "M/S2", value_parser = positive_number)]
    max_wheel_accel: Option<f64>,
}

/// The wheels the policy is told: each of `--max-wheel-speed` and `--max-wheel-accel` over the
/// profile's robot's, the profile's over nothing.
#[cfg(feature = "zenoh")]
fn told_wheels(
    flags: &Ros2Args,
    robot: Option<formation_world::RobotParams>,
) -> formation_proto::WheelLimits {
    formation_proto::WheelLimits {
        max_speed: flags.max_wheel_speed.or(robot.map(|r| r.max_wheel_speed)),
        max_accel: flags
            .max_wheel_accel
            .or(robot.and_then(|r| r.max_wheel_accel)),
    }
}

/// Parses a finite number above zero.
fn positive_number(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 => Ok(value),
        _ => Err(format!("expected a finite number above 0, got {text:?}")),
    }
}

impl Ros2Args {
    /// `(given, "--flag")` of every ROS 2 flag, for refusing them with another transport.
    pub fn given(&self) -> [(bool, &'static str); 18] {
        [
            // The environment variable alone is not a flag given by mistake.
            (false, "--ros-domain-id"),
            (self.scan.is_some(), "--scan"),
            (self.orientation.is_some(), "--orientation"),
            (self.orientation_type.is_some(), "--orientation-type"),
            (self.cmd_vel.is_some(), "--cmd-vel"),
            (self.phi_star.is_some(), "--phi-star"),
            (self.d_star.is_some(), "--d-star"),
            (self.v_star.is_some(), "--v-star"),
            (self.heading_topic.is_some(), "--heading-topic"),
            (self.distance_topic.is_some(), "--distance-topic"),
            (self.speed_topic.is_some(), "--speed-topic"),
            (self.wheel_separation.is_some(), "--wheel-separation"),
            (self.stale_ms.is_some(), "--stale-ms"),
            (self.allow_partial_scan, "--allow-partial-scan"),
            (self.node_name.is_some(), "--node-name"),
            (self.profile.is_some(), "--profile"),
            (self.max_wheel_speed.is_some(), "--max-wheel-speed"),
            (self.max_wheel_accel.is_some(), "--max-wheel-accel"),
        ]
    }
}

/// The LIDAR ring the model was trained on, from its metadata.
#[cfg(feature = "zenoh")]
fn model_ring(model: &dyn PolicyBackend, path: &Path) -> anyhow::Result<LidarSpec> {
    let sensor = model.sensor();
    match (sensor.beams, sensor.max_range) {
        (Some(beams), Some(max_range)) => Ok(LidarSpec { beams, max_range }),
        _ => anyhow::bail!(
            "model {} does not record the LIDAR it was trained on (formation.lidar.beams and \
             formation.lidar.max_range), which ROS 2 mode needs to resample the robot's \
             LaserScan; export it with `formation train`",
            path.display()
        ),
    }
}

/// Runs the ROS 2 mode until a signal or `stop`.
#[cfg(feature = "zenoh")]
pub fn run(
    args: &crate::Args,
    model: Box<dyn PolicyBackend>,
    stop: &AtomicBool,
) -> anyhow::Result<AgentExit> {
    let flags = &args.ros2;
    let connect = check_ros2_flags(args)?;
    let profile = flags.profile.as_deref().map(profile_named).transpose()?;
    let lidar = model_ring(model.as_ref(), &args.model)?;
    let robot = profile.map(|p| (p, p.settings()));
    if let Some((profile, settings)) = &robot
        && let Some(told) = profile_lidar_differs(*profile, settings, lidar, model.model_id())
    {
        eprintln!("formation-agent: {told}");
    }
    let wheels = told_wheels(flags, robot.map(|(_, s)| s.robot));
    // A profile's robot also gets every command's wheels scaled together into its top speed;
    // the flags alone tell the policy, as the world tells its agents, and leave the rest to the
    // robot's own controller, as the world clips each wheel.
    let pilots = Arc::new(RobotPilots {
        max_wheel_speed: robot.map(|(_, s)| s.robot.max_wheel_speed),
    });
    let topics = robot_topics(args)?;
    let goal = goal_values(flags)?;
    if let GoalValue::Fixed(d_star) = goal[1] {
        // Refused at once, as an agent refuses a goal outside its model's envelope at episode
        // start.
        formation_robot_agent::decision::check_goal_envelope(model.as_ref(), d_star)
            .with_context(|| format!("--d-star {d_star}"))?;
    }
    let wheel_separation = checked_wheel_separation(flags, robot.map(|(_, s)| s.robot))?;
    let stale_ms = checked_stale_ms(flags)?;
    let namespace = match args.robot {
        Some(robot) => Namespace::new(&format!("/robot_{robot}"))?,
        None => Namespace::root(),
    };
    let node_name = NodeName::new(flags.node_name.as_deref().unwrap_or("formation_agent"))
        .context("--node-name")?;
    let RobotTopics {
        scan,
        orientation,
        cmd_vel,
    } = topics;
    let settings = Ros2AgentSettings {
        connect,
        connect_timeout: Duration::from_millis(args.connect_timeout_ms),
        domain_id: flags.ros_domain_id.unwrap_or(0),
        namespace,
        node_name,
        orientation_kind: match flags.orientation_type {
            Some(OrientationType::Imu) => OrientationKind::Imu,
            Some(OrientationType::Odometry) | None => OrientationKind::Odometry,
        },
        decider: DeciderSettings {
            scan_topic: scan.as_str().to_owned(),
            orientation_topic: orientation.as_str().to_owned(),
            goal,
            contract: RingContract {
                beams: lidar.beams,
                max_range: lidar.max_range,
            },
            partial: if flags.allow_partial_scan {
                PartialScan::AllowAsNoReturn
            } else {
                PartialScan::Refuse
            },
            stale: Duration::from_millis(stale_ms),
            wheel_separation,
        },
        wheels,
        scan,
        orientation,
        cmd_vel,
    };
    let expected = match robot {
        Some((profile, settings)) => expected_scan(profile, &settings),
        None => ExpectedScan::model_ring(settings.decider.contract),
    };
    // The pilot is made for the model's own ring as the link begins the robot's one episode.
    let agent = AgentLoop::new(
        pilots,
        args.model.clone(),
        model,
        None,
        Arc::new(SystemClock),
    );
    Ok(run_agent_expecting(&settings, &expected, agent, stop)?)
}

/// The profile named `name`, or an error listing the ones the world knows.
#[cfg(feature = "zenoh")]
fn profile_named(name: &str) -> anyhow::Result<RobotProfile> {
    Ok(RobotProfile::named_by_flag("--profile", name)?)
}

/// The LaserScan a robot of `profile` publishes: its LIDAR's beams and range, and its scan
/// rate (the world's control rate, 20 Hz, where the profile scans every tick).
#[cfg(feature = "zenoh")]
fn expected_scan(profile: RobotProfile, settings: &ProfileSettings) -> ExpectedScan {
    ExpectedScan {
        source: format!("the {} profile's LIDAR", profile.name()),
        beams: settings.lidar.beams,
        max_range: settings.lidar.max_range,
        rate_hz: Some(
            settings
                .reality
                .lidar
                .scan_rate_hz
                .unwrap_or(1.0 / formation_world::WorldConfig::default().dt),
        ),
    }
}

/// What to tell at start when the profile's LIDAR is not the ring model `model_id` was trained
/// on; `None` when it is.
#[cfg(feature = "zenoh")]
fn profile_lidar_differs(
    profile: RobotProfile,
    settings: &ProfileSettings,
    model: LidarSpec,
    model_id: &str,
) -> Option<String> {
    let lidar = settings.lidar;
    (lidar.beams != model.beams || lidar.max_range != model.max_range).then(|| {
        format!(
            "model {model_id} was trained on a {}-beam, {} m LIDAR; the {} profile's has {} \
             beams and {} m, and its scans are resampled onto the model's ring (expect worse \
             formations than the model's card says; a model trained for this robot drives it \
             better)",
            model.beams,
            model.max_range,
            profile.name(),
            lidar.beams,
            lidar.max_range
        )
    })
}

/// The pilot of a robot with a top wheel speed: both wheels of each command scaled by one
/// factor so that neither exceeds it, which keeps the curvature the decision asked for (as
/// the expert saturates). Without a top speed, the command is the inner pilot's.
#[cfg(feature = "zenoh")]
struct RobotPilot<P> {
    inner: P,
    max_wheel_speed: Option<f64>,
}

/// Makes the ONNX agent's pilots of a robot with a top wheel speed ([`RobotPilot`]s).
#[cfg(feature = "zenoh")]
struct RobotPilots {
    max_wheel_speed: Option<f64>,
}

#[cfg(feature = "zenoh")]
impl PilotMaker for RobotPilots {
    type Model = <OnnxPilots as PilotMaker>::Model;
    type Pilot = RobotPilot<<OnnxPilots as PilotMaker>::Pilot>;

    fn load(&self, path: &Path) -> Result<Self::Model, BoxError> {
        OnnxPilots.load(path)
    }

    fn model_id<'m>(&self, model: &'m Self::Model) -> &'m str {
        OnnxPilots.model_id(model)
    }

    fn pilot(&self, model: Self::Model, lidar: LidarSpec) -> Result<Self::Pilot, BoxError> {
        Ok(RobotPilot::new(
            OnnxPilots.pilot(model, lidar)?,
            self.max_wheel_speed,
        ))
    }
}

#[cfg(feature = "zenoh")]
impl<P: Pilot> RobotPilot<P> {
    fn new(inner: P, max_wheel_speed: Option<f64>) -> RobotPilot<P> {
        RobotPilot {
            inner,
            max_wheel_speed,
        }
    }
}

#[cfg(feature = "zenoh")]
impl<P: Pilot> Pilot for RobotPilot<P> {
    type Model = P::Model;

    fn model_id(&self) -> &str {
        self.inner.model_id()
    }

    fn perceive(&mut self, ranges: &[f32], goal: &formation_proto::Goal) -> Result<(), BoxError> {
        self.inner.perceive(ranges, goal)
    }

    fn decide(
        &mut self,
        heading: f64,
        goal: &formation_proto::Goal,
    ) -> Result<formation_proto::WheelCmd, BoxError> {
        let cmd = self.inner.decide(heading, goal)?;
        Ok(match self.max_wheel_speed {
            Some(limit) => formation_perception::policy_input::saturate_together(cmd, limit),
            None => cmd,
        })
    }

    fn swap(&mut self, model: Self::Model) -> Result<(), BoxError> {
        self.inner.swap(model)
    }

    fn rehearse(&mut self) -> Result<(), BoxError> {
        self.inner.rehearse()
    }

    fn set_wheel_limits(&mut self, wheels: formation_proto::WheelLimits) {
        self.inner.set_wheel_limits(wheels);
    }
}

/// Refuses the flags of the other transports and returns the router to connect to.
#[cfg(feature = "zenoh")]
fn check_ros2_flags(args: &crate::Args) -> anyhow::Result<Endpoint> {
    if args.fault.is_some() {
        anyhow::bail!("--fault is for the iceoryx2 and zenoh transports, not ros2");
    }
    if args.run_id.is_some() {
        anyhow::bail!(
            "--run-id is for the iceoryx2 and zenoh transports; a ROS 2 agent joins the robot's \
             ROS graph, not a run (drop --run-id)"
        );
    }
    formation_transport_zenoh::required_endpoint(
        args.reach.connect.as_deref(),
        "--connect",
        Transport::Ros2,
    )
    .map_err(Into::into)
}

/// The topic `flag` names, else `default`, checked.
#[cfg(feature = "zenoh")]
fn topic_name(flag: &str, given: &Option<String>, default: String) -> anyhow::Result<TopicName> {
    let name = given.clone().unwrap_or(default);
    TopicName::new(&name).with_context(|| format!("{flag} {name:?}"))
}

/// The robot's own topics.
#[cfg(feature = "zenoh")]
struct RobotTopics {
    /// Its `LaserScan`.
    scan: TopicName,
    /// Its orientation.
    orientation: TopicName,
    /// Where its commands go.
    cmd_vel: TopicName,
}

/// The robot's topics: the flags', else the team's robot's (`--robot`) or a single robot's.
#[cfg(feature = "zenoh")]
fn robot_topics(args: &crate::Args) -> anyhow::Result<RobotTopics> {
    let flags = &args.ros2;
    let team = args.robot.map(TeamTopics::robot);
    let default = |pick: fn(&TeamTopics) -> &TopicName, single: &str| match &team {
        Some(topics) => pick(topics).as_str().to_owned(),
        None => single.to_owned(),
    };
    let scan = topic_name("--scan", &flags.scan, default(|t| &t.scan, "/scan"))?;
    let orientation = topic_name(
        "--orientation",
        &flags.orientation,
        default(|t| &t.odometry, "/odom"),
    )?;
    let cmd_vel = topic_name(
        "--cmd-vel",
        &flags.cmd_vel,
        default(|t| &t.cmd_vel, "/cmd_vel"),
    )?;
    Ok(RobotTopics {
        scan,
        orientation,
        cmd_vel,
    })
}

/// One goal component: `fixed` when its flag `flag` is given (finite), else the newest value on
/// the topic `topic_flag` names (or `default`).
#[cfg(feature = "zenoh")]
fn goal_value(
    fixed: Option<f64>,
    flag: &str,
    topic_flag: &str,
    given: &Option<String>,
    default: &TopicName,
) -> anyhow::Result<GoalValue> {
    match fixed {
        Some(value) if value.is_finite() => Ok(GoalValue::Fixed(value)),
        Some(value) => anyhow::bail!("{flag} must be a finite number, got {value}"),
        None => Ok(GoalValue::Topic(topic_name(
            topic_flag,
            given,
            default.as_str().to_owned(),
        )?)),
    }
}

/// The goal's heading, distance and speed.
#[cfg(feature = "zenoh")]
fn goal_values(flags: &Ros2Args) -> anyhow::Result<[GoalValue; 3]> {
    let goal_topics = TeamTopics::goal();
    Ok([
        goal_value(
            flags.phi_star,
            "--phi-star",
            "--heading-topic",
            &flags.heading_topic,
            &goal_topics[0],
        )?,
        goal_value(
            flags.d_star,
            "--d-star",
            "--distance-topic",
            &flags.distance_topic,
            &goal_topics[1],
        )?,
        goal_value(
            flags.v_star,
            "--v-star",
            "--speed-topic",
            &flags.speed_topic,
            &goal_topics[2],
        )?,
    ])
}

/// `--wheel-separation` (default: the profile's robot's, else the P3-DX's), refused outside
/// (0, 10) m.
#[cfg(feature = "zenoh")]
fn checked_wheel_separation(
    flags: &Ros2Args,
    robot: Option<formation_world::RobotParams>,
) -> anyhow::Result<f64> {
    let wheel_separation = flags
        .wheel_separation
        .unwrap_or_else(|| robot.map_or(P3DX_WHEEL_SEPARATION, |robot| robot.wheel_separation));
    if !(wheel_separation.is_finite() && wheel_separation > 0.0 && wheel_separation < 10.0) {
        anyhow::bail!(
            "--wheel-separation must be a length in metres between 0 and 10, got {wheel_separation}"
        );
    }
    Ok(wheel_separation)
}

/// `--stale-ms` (default: the runtime's), refused outside 1..=60000.
#[cfg(feature = "zenoh")]
fn checked_stale_ms(flags: &Ros2Args) -> anyhow::Result<u64> {
    let stale_ms = flags.stale_ms.unwrap_or_else(|| {
        u64::try_from(formation_transport_ros2::decider::DEFAULT_STALE.as_millis())
            .unwrap_or(u64::MAX)
    });
    if stale_ms == 0 || stale_ms > 60_000 {
        anyhow::bail!("--stale-ms must be from 1 to 60000, got {stale_ms}");
    }
    Ok(stale_ms)
}

/// This build has no Zenoh, so no ROS 2.
#[cfg(not(feature = "zenoh"))]
pub fn run(
    _args: &crate::Args,
    _model: Box<dyn PolicyBackend>,
    _stop: &AtomicBool,
) -> anyhow::Result<AgentExit> {
    Err(TransportError::NotBuilt {
        program: "formation-agent".into(),
        transport: Transport::Ros2,
    }
    .into())
}

#[cfg(all(test, feature = "zenoh"))]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_profile_is_refused_naming_the_flag() {
        // The world's `RobotProfile::named_by_flag` lists the known names; the flag is ours.
        let message = profile_named("turtlebot4").unwrap_err().to_string();
        assert!(
            message.starts_with("--profile must name a robot profile"),
            "{message}"
        );
        assert_eq!(
            profile_named("turtlebot3-burger").unwrap(),
            RobotProfile::Turtlebot3Burger
        );
    }

    #[test]
    fn the_burger_expects_its_lds01_scan() {
        let profile = RobotProfile::Turtlebot3Burger;
        let expected = expected_scan(profile, &profile.settings());
        assert_eq!(
            (expected.beams, expected.max_range, expected.rate_hz),
            (360, 3.5, Some(5.0))
        );
        assert_eq!(expected.source, "the turtlebot3-burger profile's LIDAR");
        // The ideal world's LIDAR scans every tick, at the control rate.
        let ideal = expected_scan(RobotProfile::Ideal, &RobotProfile::Ideal.settings());
        assert_eq!((ideal.beams, ideal.rate_hz), (900, Some(20.0)));
    }

    #[test]
    fn a_profile_lidar_unlike_the_models_is_told_at_start() {
        let model = LidarSpec::default();
        let burger = RobotProfile::Turtlebot3Burger;
        let told = profile_lidar_differs(burger, &burger.settings(), model, "policy-x")
            .expect("the burger's LDS-01 is not the model's ring");
        assert!(
            told.starts_with(
                "model policy-x was trained on a 900-beam, 10 m LIDAR; the turtlebot3-burger \
                 profile's has 360 beams and 3.5 m"
            ),
            "{told}"
        );
        let pioneer = RobotProfile::Pioneer3dx;
        assert_eq!(
            profile_lidar_differs(pioneer, &pioneer.settings(), model, "policy-x"),
            None
        );
    }

    #[test]
    fn the_wheel_separation_is_the_profiles_unless_given() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            ros2: Ros2Args,
        }
        let burger = RobotProfile::Turtlebot3Burger.settings().robot;
        let plain = Cli::parse_from(["x"]);
        assert_eq!(checked_wheel_separation(&plain.ros2, None).unwrap(), 0.331);
        assert_eq!(
            checked_wheel_separation(&plain.ros2, Some(burger)).unwrap(),
            0.160
        );
        let given = Cli::parse_from(["x", "--wheel-separation", "0.2", "--profile", "x"]);
        assert_eq!(
            checked_wheel_separation(&given.ros2, Some(burger)).unwrap(),
            0.2
        );
        // The wheels the policy is told: the flags over the profile, the profile over nothing.
        let none = formation_proto::WheelLimits::default();
        assert_eq!(told_wheels(&plain.ros2, None), none);
        assert_eq!(
            told_wheels(&plain.ros2, Some(burger)),
            burger.wheel_limits()
        );
        let told = Cli::parse_from(["x", "--max-wheel-speed", "0.9", "--max-wheel-accel", "1.5"]);
        let wheels = told_wheels(&told.ros2, Some(burger));
        assert_eq!((wheels.max_speed, wheels.max_accel), (Some(0.9), Some(1.5)));
        for bad in ["0", "-1", "nan", "inf", "fast"] {
            assert!(
                Cli::try_parse_from(["x", "--max-wheel-speed", bad]).is_err(),
                "{bad}"
            );
        }
    }
}
