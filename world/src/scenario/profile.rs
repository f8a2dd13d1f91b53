//! Robot profiles: `[robot] profile = "..."` sets every robot, LIDAR, compass and reality key of a
//! scenario to one robot's values at once; each key the file gives overrides its profile's value.
//!
//! The numbers and their sources (datasheets, manuals, and the estimates where none publishes a
//! figure) are listed in `scenarios/README.md`.

use formation_proto::LidarSpec;
use serde::Serialize;

use crate::reality::{CompassModel, LidarModel, MotorModel, RealityModels};
use crate::robot::RobotParams;

/// A robot whose values a scenario can start from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RobotProfile {
    /// Today's world: the paper's P3-DX geometry at 0.9 m/s, a 900-beam 10 m noiseless ring
    /// scanning every tick, an exact compass, ideal wheels, no latency.
    #[default]
    Ideal,
    /// A Pioneer 3-DX (the paper's robot) with the same LIDAR ring as the ideal world, so that
    /// the shipped models can drive it, and the P3-DX's own top speed, motors and delays.
    Pioneer3dx,
    /// A ROBOTIS TurtleBot3 Burger with its LDS-01 LIDAR.
    Turtlebot3Burger,
}

/// Every value a profile sets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileSettings {
    /// The `[robot]` geometry and limits.
    pub robot: RobotParams,
    /// The `[lidar]` beams, range and range noise.
    pub lidar: LidarSpec,
    /// The reality models (`[robot]` motors, latency and spread; `[lidar]` timing and geometry;
    /// `[compass]`).
    pub reality: RealityModels,
}

impl RobotProfile {
    /// Every profile, in the order error messages list them.
    pub const ALL: [RobotProfile; 3] = [
        RobotProfile::Ideal,
        RobotProfile::Pioneer3dx,
        RobotProfile::Turtlebot3Burger,
    ];

    /// The name a scenario gives it.
    pub fn name(self) -> &'static str {
        match self {
            RobotProfile::Ideal => "ideal",
            RobotProfile::Pioneer3dx => "pioneer-p3dx",
            RobotProfile::Turtlebot3Burger => "turtlebot3-burger",
        }
    }

    /// The profile named `name`, if there is one.
    pub fn from_name(name: &str) -> Option<RobotProfile> {
        RobotProfile::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Whether this is the ideal world's profile.
    pub fn is_ideal(&self) -> bool {
        *self == RobotProfile::Ideal
    }

    /// The values this profile sets.
    pub fn settings(self) -> ProfileSettings {
        match self {
            RobotProfile::Ideal => ProfileSettings {
                robot: RobotParams::default(),
                lidar: LidarSpec::default(),
                reality: RealityModels::IDEAL,
            },
            RobotProfile::Pioneer3dx => ProfileSettings {
                robot: RobotParams {
                    max_wheel_speed: 1.2,
                    ..RobotParams::default()
                },
                lidar: LidarSpec {
                    noise_std: 0.01,
                    ..LidarSpec::default()
                },
                reality: RealityModels {
                    motors: MotorModel {
                        tau_s: 0.15,
                        speed_noise_std: 0.01,
                        gain_asymmetry: 0.02,
                    },
                    lidar: LidarModel {
                        scan_rate_hz: Some(10.0),
                        fov_deg: 360.0,
                        min_range: 0.0,
                        dropout: 0.005,
                    },
                    compass: CompassModel {
                        noise_std_deg: 1.0,
                        bias_deg: 1.0,
                    },
                    command_latency_ticks: 1,
                    spread: 0.05,
                },
            },
            RobotProfile::Turtlebot3Burger => ProfileSettings {
                robot: RobotParams {
                    wheel_separation: 0.160,
                    wheel_radius: 0.033,
                    body_radius: 0.105,
                    max_wheel_speed: 0.22,
                    max_wheel_accel: None,
                },
                lidar: LidarSpec {
                    beams: 360,
                    max_range: 3.5,
                    noise_std: 0.015,
                },
                reality: RealityModels {
                    motors: MotorModel {
                        tau_s: 0.1,
                        speed_noise_std: 0.005,
                        gain_asymmetry: 0.02,
                    },
                    lidar: LidarModel {
                        scan_rate_hz: Some(5.0),
                        fov_deg: 360.0,
                        min_range: 0.12,
                        dropout: 0.01,
                    },
                    compass: CompassModel {
                        noise_std_deg: 1.0,
                        bias_deg: 2.0,
                    },
                    command_latency_ticks: 1,
                    spread: 0.05,
                },
            },
        }
    }
}
