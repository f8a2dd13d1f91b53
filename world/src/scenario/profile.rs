//! Robot profiles: `[robot] profile = "..."` sets every robot, LIDAR, compass and reality key of a
//! scenario to one robot's values at once; each key the file gives overrides its profile's value.
//!
//! The numbers and their sources (datasheets, manuals, and the estimates where none publishes a
//! figure) are listed in `scenarios/README.md`.

use formation_proto::{LidarNoise, LidarSpec};
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
    /// The `[lidar]` beams and range: the sensor contract.
    pub lidar: LidarSpec,
    /// The `[lidar]` range noise the world adds.
    pub lidar_noise: LidarNoise,
    /// The reality models (`[robot]` motors, latency and spread; `[lidar]` timing and geometry;
    /// `[compass]`).
    pub reality: RealityModels,
}

/// A command-line flag named no robot profile.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{flag} must name a robot profile, one of {} (got \"{name}\")",
    RobotProfile::ALL.map(|p| format!("\"{}\"", p.name())).join(", ")
)]
pub struct UnknownProfile {
    /// The flag, e.g. `--profile`.
    pub flag: &'static str,
    /// The name given.
    pub name: String,
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

    /// The profile a command-line `flag` names, or an error listing the names.
    pub fn named_by_flag(flag: &'static str, name: &str) -> Result<RobotProfile, UnknownProfile> {
        RobotProfile::from_name(name).ok_or_else(|| UnknownProfile {
            flag,
            name: name.to_owned(),
        })
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
                lidar_noise: LidarNoise::NONE,
                reality: RealityModels::IDEAL,
            },
            RobotProfile::Pioneer3dx => ProfileSettings {
                robot: RobotParams {
                    max_wheel_speed: 1.2,
                    ..RobotParams::default()
                },
                lidar: LidarSpec::default(),
                lidar_noise: LidarNoise { noise_std: 0.01 },
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
                },
                lidar_noise: LidarNoise { noise_std: 0.015 },
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

/// One rung of a profile's reality ladder: the effects added so far, as scenario keys.
#[derive(Debug, Clone, PartialEq)]
pub struct LadderRung {
    /// The effect this rung adds (`"ideal"` for the base scenario itself).
    pub name: &'static str,
    /// The keys this rung adds to the previous one's (dotted, e.g. `robot.motor_tau`).
    pub added: Vec<&'static str>,
    /// Every key set so far with the profile's value, for
    /// [`Scenario::from_path_overridden`](crate::Scenario::from_path_overridden).
    pub overrides: Vec<(String, toml::Value)>,
}

impl RobotProfile {
    /// The reality ladder of this profile: the base scenario (`ideal`), then the profile's
    /// effects added one at a time, cumulatively, in this order: geometry and speed, motors,
    /// LIDAR timing, LIDAR geometry (with its range noise), compass, latency, spread. The last
    /// rung sets every key the profile sets.
    ///
    /// A value the profile leaves absent (no acceleration limit, a scan every tick) is not set,
    /// so the base scenario's stays: a profile cannot remove a key through overrides.
    pub fn ladder(self) -> Vec<LadderRung> {
        let ProfileSettings {
            robot,
            lidar,
            lidar_noise,
            reality,
        } = self.settings();
        let float = toml::Value::Float;
        let optional = |value: Option<f64>| value.map(toml::Value::Float);
        // An effect's name and its keys; a key whose value is `None` is left to the base scenario.
        type Effect = (&'static str, Vec<(&'static str, Option<toml::Value>)>);
        let effects: [Effect; 7] = [
            (
                "geometry and speed",
                vec![
                    (
                        "robot.wheel_separation",
                        Some(float(robot.wheel_separation)),
                    ),
                    ("robot.wheel_radius", Some(float(robot.wheel_radius))),
                    ("robot.body_radius", Some(float(robot.body_radius))),
                    ("robot.max_wheel_speed", Some(float(robot.max_wheel_speed))),
                    ("robot.max_wheel_accel", optional(robot.max_wheel_accel)),
                ],
            ),
            (
                "motors",
                vec![
                    ("robot.motor_tau", Some(float(reality.motors.tau_s))),
                    (
                        "robot.wheel_speed_noise",
                        Some(float(reality.motors.speed_noise_std)),
                    ),
                    (
                        "robot.wheel_gain_asymmetry",
                        Some(float(reality.motors.gain_asymmetry)),
                    ),
                ],
            ),
            (
                "lidar timing",
                vec![("lidar.scan_rate_hz", optional(reality.lidar.scan_rate_hz))],
            ),
            (
                "lidar geometry",
                vec![
                    (
                        "lidar.beams",
                        Some(toml::Value::Integer(lidar.beams as i64)),
                    ),
                    ("lidar.fov_deg", Some(float(reality.lidar.fov_deg))),
                    ("lidar.min_range", Some(float(reality.lidar.min_range))),
                    ("lidar.max_range", Some(float(lidar.max_range))),
                    ("lidar.dropout", Some(float(reality.lidar.dropout))),
                    ("lidar.noise_std", Some(float(lidar_noise.noise_std))),
                ],
            ),
            (
                "compass",
                vec![
                    (
                        "compass.noise_std_deg",
                        Some(float(reality.compass.noise_std_deg)),
                    ),
                    ("compass.bias_deg", Some(float(reality.compass.bias_deg))),
                ],
            ),
            (
                "latency",
                vec![(
                    "robot.command_latency",
                    Some(toml::Value::Integer(i64::from(
                        reality.command_latency_ticks,
                    ))),
                )],
            ),
            (
                "spread",
                vec![("robot.spread", Some(float(reality.spread)))],
            ),
        ];
        let mut rungs = vec![LadderRung {
            name: "ideal",
            added: Vec::new(),
            overrides: Vec::new(),
        }];
        let mut overrides: Vec<(String, toml::Value)> = Vec::new();
        for (name, keys) in effects {
            let mut added = Vec::new();
            for (key, value) in keys {
                if let Some(value) = value {
                    added.push(key);
                    overrides.push((key.to_owned(), value));
                }
            }
            rungs.push(LadderRung {
                name,
                added,
                overrides: overrides.clone(),
            });
        }
        rungs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{Scenario, ScenarioError};

    /// A scenario slow enough for every profile, with `tables` appended.
    fn scenario(tables: &str) -> Result<Scenario, ScenarioError> {
        let text = format!(
            "name = \"p\"\nrobots = 3\nduration_s = 2.0\nseed = 3\n[goal]\nv_star = 0.1\n\
             d_star = 1.0\n[heading]\nschedule = \"random\"\n{tables}"
        );
        Scenario::from_toml_str(&text, "scenarios/p.toml")
    }

    fn error(tables: &str) -> String {
        match scenario(tables) {
            Ok(s) => panic!("expected an error, got {:?}", s.world_config()),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn no_profile_is_the_ideal_world_of_before() {
        let plain = scenario("").unwrap();
        assert_eq!(plain.profile(), RobotProfile::Ideal);
        assert_eq!(*plain.world_config(), crate::WorldConfig::default());
        let named = scenario("[robot]\nprofile = \"ideal\"\n").unwrap();
        assert_eq!(named.world_config(), plain.world_config());
        // Neither the scenario nor its runs serialize anything new.
        let json = serde_json::to_string(&named).unwrap();
        assert!(
            !json.contains("reality") && !json.contains("profile"),
            "{json}"
        );
    }

    #[test]
    fn a_profile_sets_every_key_and_each_key_overrides_it() {
        let burger = scenario("[robot]\nprofile = \"turtlebot3-burger\"\n").unwrap();
        let config = burger.world_config();
        let settings = RobotProfile::Turtlebot3Burger.settings();
        assert_eq!(
            (
                config.robot,
                config.lidar,
                config.lidar_noise,
                config.reality
            ),
            (
                settings.robot,
                settings.lidar,
                settings.lidar_noise,
                settings.reality
            )
        );
        assert_eq!(config.robot.max_wheel_speed, 0.22);
        assert_eq!((config.lidar.beams, config.lidar.max_range), (360, 3.5));
        assert_eq!(config.reality.lidar.scan_rate_hz, Some(5.0));
        assert_eq!(config.reality.lidar.min_range, 0.12);
        assert_eq!(config.reality.command_latency_ticks, 1);
        assert!(config.reality.motors.tau_s >= 0.1);
        assert!(config.reality.compass.noise_std_deg >= 1.0);
        assert!(config.reality.lidar.dropout >= 0.01);

        let tuned = scenario(
            "[robot]\nprofile = \"turtlebot3-burger\"\nmotor_tau = 0.3\ncommand_latency = 0\n\
             [lidar]\nscan_rate_hz = 20.0\nbeams = 180\n[compass]\nbias_deg = -4.0\n",
        )
        .unwrap();
        let tuned = tuned.world_config();
        assert_eq!(tuned.reality.motors.tau_s, 0.3);
        assert_eq!(tuned.reality.command_latency_ticks, 0);
        assert_eq!(tuned.reality.lidar.scan_period_ticks(tuned.dt), 1);
        assert_eq!(tuned.lidar.beams, 180);
        assert_eq!(tuned.reality.compass.bias_deg, -4.0);
        // Everything not overridden is the profile's.
        assert_eq!(tuned.robot, settings.robot);
        assert_eq!(tuned.reality.lidar.dropout, settings.reality.lidar.dropout);

        let pioneer = scenario("[robot]\nprofile = \"pioneer-p3dx\"\n").unwrap();
        let pioneer = pioneer.world_config();
        assert_eq!((pioneer.lidar.beams, pioneer.lidar.max_range), (900, 10.0));
        assert_eq!(pioneer.robot.max_wheel_speed, 1.2);
        assert!(pioneer.reality.motors.tau_s > 0.0);
    }

    #[test]
    fn a_key_that_turns_one_model_on_needs_no_profile() {
        let lagged = scenario("[robot]\nmotor_tau = 0.2\n").unwrap();
        let reality = lagged.world_config().reality;
        assert_eq!(reality.motors.tau_s, 0.2);
        assert_eq!(
            crate::reality::RealityModels {
                motors: crate::reality::MotorModel::IDEAL,
                ..reality
            },
            crate::reality::RealityModels::IDEAL
        );
    }

    #[test]
    fn an_unknown_profile_is_named_with_the_known_ones() {
        assert_eq!(
            error("[robot]\nprofile = \"turtlebot4\"\n"),
            "scenarios/p.toml: robot.profile must be one of \"ideal\", \"pioneer-p3dx\", \
             \"turtlebot3-burger\" (got \"turtlebot4\")"
        );
    }

    #[test]
    fn a_key_out_of_bounds_is_named_with_its_range() {
        let cases = [
            (
                "[robot]\nmotor_tau = 5.0\n",
                "robot.motor_tau must be in [0, 2] s (got 5)",
            ),
            (
                "[robot]\nprofile = \"turtlebot3-burger\"\nspread = 0.9\n",
                "robot.spread must be in [0, 0.5] (got 0.9)",
            ),
            (
                "[robot]\ncommand_latency = -1\n",
                "robot.command_latency must be in [0, 20] ticks (got -1)",
            ),
            (
                "[robot]\nwheel_gain_asymmetry = nan\n",
                "robot.wheel_gain_asymmetry must be a finite number in [-0.5, 0.5]",
            ),
            (
                "[robot]\nwheel_speed_noise = 2.0\n",
                "robot.wheel_speed_noise must be in [0, 1] m/s (got 2)",
            ),
            (
                "[lidar]\nfov_deg = 0.5\n",
                "lidar.fov_deg must be in [1, 360] deg (got 0.5)",
            ),
            (
                "[lidar]\ndropout = 1.0\n",
                "lidar.dropout must be in [0, 0.9] (got 1)",
            ),
            (
                "[robot]\nprofile = \"turtlebot3-burger\"\n[lidar]\nmin_range = 4.0\n",
                "lidar.min_range must be below lidar.max_range (3.5)",
            ),
            (
                "[lidar]\nscan_rate_hz = 40.0\n",
                "lidar.scan_rate_hz must be at most the control rate 1 / dt (20) Hz",
            ),
            (
                "[lidar]\nscan_rate_hz = 7.0\n",
                "lidar.scan_rate_hz must divide the control rate 1 / dt (20 Hz) into whole \
                 ticks per scan, such as 10 or 6.666666666666667 Hz (got 7",
            ),
            (
                "[compass]\nnoise_std_deg = -1.0\n",
                "compass.noise_std_deg must be in [0, 90] deg (got -1)",
            ),
            (
                "[compass]\nbias_deg = 200.0\n",
                "compass.bias_deg must be in [-180, 180] deg (got 200)",
            ),
        ];
        for (tables, expected) in cases {
            let message = error(tables);
            assert!(
                message.starts_with("scenarios/p.toml: ") && message.contains(expected),
                "{tables:?}: {message}"
            );
        }
        let unknown = error("[compass]\ndrift = 1.0\n");
        assert!(unknown.contains("drift"), "{unknown}");
    }

    #[test]
    fn a_goal_faster_than_the_profile_names_the_profile() {
        let text = "name = \"p\"\nrobots = 3\nduration_s = 2.0\nseed = 3\n[goal]\nv_star = 0.7\n\
                    d_star = 1.0\n[heading]\nschedule = \"random\"\n[robot]\n\
                    profile = \"turtlebot3-burger\"\n";
        let message = Scenario::from_toml_str(text, "x").unwrap_err().to_string();
        assert!(
            message.contains(
                "goal.v_star must be <= robot.max_wheel_speed (0.22, the \
                              \"turtlebot3-burger\" profile's"
            ),
            "{message}"
        );
    }

    #[test]
    fn a_run_spec_with_every_model_on_survives_the_launchers_json() {
        // The launcher hands the world process its runs as JSON: every model must come back
        // bit for bit.
        for profile in RobotProfile::ALL {
            let tables = format!(
                "[robot]\nprofile = \"{}\"\n[lidar]\nfov_deg = 300.0\n",
                profile.name()
            );
            let spec = scenario(&tables).unwrap().run_spec(3, 1);
            let json = serde_json::to_vec(&spec).unwrap();
            let back: crate::RunSpec = serde_json::from_slice(&json).unwrap();
            assert_eq!(back, spec, "{}", profile.name());
        }
    }

    #[test]
    fn a_ladder_adds_each_effect_in_order_and_ends_at_the_full_profile() {
        let names: Vec<&str> = RobotProfile::Turtlebot3Burger
            .ladder()
            .iter()
            .map(|r| r.name)
            .collect();
        assert_eq!(
            names,
            [
                "ideal",
                "geometry and speed",
                "motors",
                "lidar timing",
                "lidar geometry",
                "compass",
                "latency",
                "spread"
            ]
        );
        for profile in RobotProfile::ALL {
            let ladder = profile.ladder();
            assert!(ladder[0].overrides.is_empty() && ladder[0].added.is_empty());
            for pair in ladder.windows(2) {
                let (before, after) = (&pair[0], &pair[1]);
                // Cumulative: each rung keeps every key before it and adds its own.
                assert_eq!(
                    after.overrides[..before.overrides.len()],
                    before.overrides[..]
                );
                let new_keys: Vec<&str> = after.overrides[before.overrides.len()..]
                    .iter()
                    .map(|(k, _)| k.as_str())
                    .collect();
                assert_eq!(new_keys, after.added, "{}: {}", profile.name(), after.name);
            }
            // The last rung is the profile itself.
            let last = ladder.last().unwrap();
            let text = "name = \"p\"\nrobots = 3\nduration_s = 2.0\nseed = 3\n[goal]\n\
                        v_star = 0.1\nd_star = 1.0\n[heading]\nschedule = \"random\"\n";
            let dir = std::env::temp_dir().join(format!(
                "formation-ladder-{}-{}",
                std::process::id(),
                profile.name()
            ));
            std::fs::create_dir_all(&dir).unwrap();
            let path = dir.join("p.toml");
            std::fs::write(&path, text).unwrap();
            let laddered = Scenario::from_path_overridden(&path, &last.overrides).unwrap();
            std::fs::remove_dir_all(&dir).unwrap();
            let named = scenario(&format!("[robot]\nprofile = \"{}\"\n", profile.name())).unwrap();
            assert_eq!(
                laddered.world_config(),
                named.world_config(),
                "{}",
                profile.name()
            );
        }
        // The turtlebot's rungs set what the issue names, at the rung that names it.
        let burger = RobotProfile::Turtlebot3Burger.ladder();
        assert!(burger[1].added.contains(&"robot.max_wheel_speed"));
        assert_eq!(burger[3].added, ["lidar.scan_rate_hz"]);
        assert_eq!(burger[6].added, ["robot.command_latency"]);
    }
}
