//! The second phase: every parsed value checked against its documented range
//! ([`super::limits`]), with errors that name the file, the field, the allowed range and the value
//! found; the result is a [`Scenario`].

use super::*;

/// Builds [`ScenarioError::Invalid`] values that name the origin.
pub(super) struct Checker<'a> {
    pub(super) origin: &'a str,
}

impl Checker<'_> {
    pub(super) fn invalid(
        &self,
        field: impl fmt::Display,
        problem: impl fmt::Display,
    ) -> ScenarioError {
        ScenarioError::Invalid {
            origin: self.origin.to_string(),
            field: field.to_string(),
            problem: problem.to_string(),
        }
    }

    /// `value`, if it is a finite number within `bounds`.
    pub(super) fn bounded(
        &self,
        field: &str,
        value: f64,
        bounds: Bounds,
    ) -> Result<f64, ScenarioError> {
        if !value.is_finite() {
            return Err(self.invalid(
                field,
                format_args!("must be a finite number in {bounds} (got {})", Num(value)),
            ));
        }
        if !(bounds.min..=bounds.max).contains(&value) {
            return Err(self.invalid(
                field,
                format_args!("must be in {bounds} (got {})", Num(value)),
            ));
        }
        Ok(value)
    }

    /// `value`, if it is a whole number in `min..=max`; `why` explains the bounds.
    pub(super) fn count(
        &self,
        field: &str,
        value: usize,
        min: usize,
        max: usize,
        why: &str,
    ) -> Result<usize, ScenarioError> {
        if (min..=max).contains(&value) {
            Ok(value)
        } else {
            Err(self.invalid(
                field,
                format_args!("must be in [{min}, {max}]{why} (got {value})"),
            ))
        }
    }
}

impl ScenarioToml {
    /// The validated [`Scenario`], each value checked in the order the file format lists them,
    /// so the first error a file has is the one reported.
    pub(super) fn validate(self, check: &Checker<'_>) -> Result<Scenario, ScenarioError> {
        let name = validate_name(check, self.name)?;
        let robots = check.count(
            "robots",
            self.robots,
            limits::MIN_ROBOTS,
            limits::MAX_ROBOTS,
            ", a formation needs at least one pair",
        )?;
        let (duration_s, dt, steps) = validate_timing(check, self.duration_s, self.dt)?;
        check_robot_ticks(check, robots, steps.round() as u64, dt)?;
        let runs = check.count("runs", self.runs, 1, limits::MAX_RUNS, "")?;

        let hardware = validate_hardware(check, &self.robot, &self.lidar, &self.compass, dt)?;
        let (profile, robot, lidar, reality) = hardware;
        let SimulatedLidar {
            spec: lidar,
            noise: lidar_noise,
        } = lidar;

        let (v_star, d_star) = validate_goal(check, self.goal, &robot, profile)?;

        let heading = validate_heading(check, &self.heading)?;
        let world = WorldConfig {
            robot,
            lidar,
            lidar_noise,
            dt,
            reality,
        };
        let neighbours = validate_formation(check, &self.formation, robots, &world)?;
        let init = validate_init(
            check,
            self.init,
            robots,
            &robot,
            sensing_range(&neighbours, &world),
        )?;

        let agents = validate_agents(check, self.agent, robots)?;
        if self
            .model
            .as_ref()
            .is_some_and(|model| model.as_os_str().is_empty())
        {
            return Err(check.invalid(
                "model",
                "must not be empty: name the team's ONNX model, or drop the key for the shipped default",
            ));
        }

        Ok(Scenario {
            name,
            n_robots: robots,
            duration_s,
            seed: self.seed,
            runs,
            v_star,
            d_star,
            heading,
            init,
            neighbours,
            world,
            profile,
            agents,
            model: self.model,
            given: Given {
                disc_radius: self.init.disc_radius,
                min_spacing: self.init.min_spacing,
                formation: self.formation,
                origin: check.origin.to_string(),
            },
        })
    }
}

/// `duration_s` and `dt`, each in range, `dt` at most `duration_s` and dividing it into whole
/// steps; returns both and the number of steps.
pub(super) fn validate_timing(
    check: &Checker<'_>,
    duration_s: f64,
    dt: f64,
) -> Result<(f64, f64, f64), ScenarioError> {
    let duration_s = check.bounded("duration_s", duration_s, limits::DURATION_S)?;
    let dt = check.bounded("dt", dt, limits::DT)?;
    if dt > duration_s {
        return Err(check.invalid(
            "dt",
            format_args!(
                "must be <= duration_s ({duration_s}) so a run has at least one tick (got {dt})"
            ),
        ));
    }
    let steps = duration_s / dt;
    if (steps - steps.round()).abs() > 1e-6 {
        return Err(check.invalid(
            "dt",
            format_args!(
                "must divide duration_s ({duration_s}) into whole steps (got {dt}: {steps:.3} steps)"
            ),
        ));
    }
    Ok((duration_s, dt, steps))
}

/// The `[lidar]` table as a [`SimulatedLidar`] (the contract and its noise) and the LIDAR's
/// [`LidarModel`], each key the table
/// gives in range and each it omits taken from `profile` (in range by construction).
pub(super) fn validate_lidar(
    check: &Checker<'_>,
    lidar: &LidarToml,
    profile: &ProfileSettings,
    dt: f64,
) -> Result<(SimulatedLidar, LidarModel), ScenarioError> {
    let spec = LidarSpec {
        beams: check.count(
            "lidar.beams",
            lidar.beams.unwrap_or(profile.lidar.beams),
            limits::MIN_BEAMS,
            limits::MAX_BEAMS,
            " (a scan message carries at most 900 ranges)",
        )?,
        max_range: check.bounded(
            "lidar.max_range",
            lidar.max_range.unwrap_or(profile.lidar.max_range),
            limits::MAX_RANGE,
        )?,
    };
    let noise = LidarNoise {
        noise_std: check.bounded(
            "lidar.noise_std",
            lidar.noise_std.unwrap_or(profile.lidar_noise.noise_std),
            limits::NOISE_STD,
        )?,
    };
    let nominal = profile.reality.lidar;
    let scan_rate_hz = match lidar.scan_rate_hz.or(nominal.scan_rate_hz) {
        None => None,
        Some(rate) => Some(validate_scan_rate(check, rate, dt)?),
    };
    let fov_deg = check.bounded(
        "lidar.fov_deg",
        lidar.fov_deg.unwrap_or(nominal.fov_deg),
        limits::FOV,
    )?;
    let min_range = check.bounded(
        "lidar.min_range",
        lidar.min_range.unwrap_or(nominal.min_range),
        limits::MIN_RANGE,
    )?;
    if min_range >= spec.max_range {
        return Err(check.invalid(
            "lidar.min_range",
            format_args!(
                "must be below lidar.max_range ({}) or no beam can return anything (got {min_range})",
                spec.max_range
            ),
        ));
    }
    let dropout = check.bounded(
        "lidar.dropout",
        lidar.dropout.unwrap_or(nominal.dropout),
        limits::DROPOUT,
    )?;
    let model = LidarModel {
        scan_rate_hz,
        fov_deg,
        min_range,
        dropout,
    };
    Ok((SimulatedLidar { spec, noise }, model))
}

/// `lidar.scan_rate_hz`: in range, at most the control rate `1 / dt`, and a whole number of
/// control ticks per scan.
fn validate_scan_rate(check: &Checker<'_>, rate: f64, dt: f64) -> Result<f64, ScenarioError> {
    let rate = check.bounded("lidar.scan_rate_hz", rate, limits::SCAN_RATE)?;
    let ticks_per_scan = 1.0 / (rate * dt);
    let control_rate = 1.0 / dt;
    if ticks_per_scan < 1.0 - 1e-9 {
        return Err(check.invalid(
            "lidar.scan_rate_hz",
            format_args!(
                "must be at most the control rate 1 / dt ({}) Hz: a scan is taken at a control \
                 tick (got {rate})",
                Num(control_rate)
            ),
        ));
    }
    if (ticks_per_scan - ticks_per_scan.round()).abs() > 1e-6 {
        return Err(check.invalid(
            "lidar.scan_rate_hz",
            format_args!(
                "must divide the control rate 1 / dt ({} Hz) into whole ticks per scan, such as \
                 {} or {} Hz (got {rate}: {ticks_per_scan:.3} ticks per scan)",
                Num(control_rate),
                Num(control_rate / ticks_per_scan.floor().max(1.0)),
                Num(control_rate / ticks_per_scan.ceil()),
            ),
        ));
    }
    Ok(rate)
}

/// Exactly one of `goal.v_star` and `goal.v_star_range` (reachable by the wheels), and exactly
/// one of `goal.d_star`, `goal.d_star_choices` and `goal.d_star_range`, each in range.
pub(super) fn validate_goal(
    check: &Checker<'_>,
    goal: GoalToml,
    robot: &RobotParams,
    profile: RobotProfile,
) -> Result<(VStarPlan, DStarPlan), ScenarioError> {
    let v_star = validate_v_star(check, &goal, robot, profile)?;
    let d_star = validate_d_star(check, goal)?;
    Ok((v_star, d_star))
}

/// Exactly one of `goal.v_star` and `goal.v_star_range`, each speed in `[0, max_wheel_speed]`.
fn validate_v_star(
    check: &Checker<'_>,
    goal: &GoalToml,
    robot: &RobotParams,
    profile: RobotProfile,
) -> Result<VStarPlan, ScenarioError> {
    let reachable = |field: &str, v: f64| -> Result<f64, ScenarioError> {
        let v = check.bounded(
            field,
            v,
            Bounds {
                min: 0.0,
                ..limits::MAX_WHEEL_SPEED
            },
        )?;
        if v > robot.max_wheel_speed {
            let from_profile = if profile.is_ideal() {
                String::new()
            } else {
                format!(
                    ", the {:?} profile's unless [robot] sets it",
                    profile.name()
                )
            };
            return Err(check.invalid(
                field,
                format_args!(
                    "must be <= robot.max_wheel_speed ({}{from_profile}) or the robots cannot \
                     reach it (got {v})",
                    robot.max_wheel_speed
                ),
            ));
        }
        Ok(v)
    };
    const ONE_SPEED: &str = "give exactly one of goal.v_star (fixed) and goal.v_star_range \
                             (uniform per run)";
    let v_star = match (goal.v_star, goal.v_star_range) {
        (Some(_), Some(_)) => {
            return Err(check.invalid(
                "goal.v_star",
                format_args!("is given both ways; {ONE_SPEED}"),
            ));
        }
        (Some(v), None) => VStarPlan::Fixed(reachable("goal.v_star", v)?),
        (None, Some([min, max])) => {
            let min = reachable("goal.v_star_range[0]", min)?;
            let max = reachable("goal.v_star_range[1]", max)?;
            if min > max {
                return Err(check.invalid(
                    "goal.v_star_range",
                    format_args!(
                        "must be [slowest, fastest] with slowest <= fastest (got [{min}, {max}])"
                    ),
                ));
            }
            VStarPlan::Range { min, max }
        }
        (None, None) => {
            return Err(check.invalid("goal.v_star", format_args!("is missing; {ONE_SPEED}")));
        }
    };
    Ok(v_star)
}

/// Exactly one of `goal.d_star`, `goal.d_star_choices` and `goal.d_star_range`, each in range.
fn validate_d_star(check: &Checker<'_>, goal: GoalToml) -> Result<DStarPlan, ScenarioError> {
    const ONE_OF: &str = "give exactly one of goal.d_star (fixed), goal.d_star_choices (one \
                          of a list per run) and goal.d_star_range (uniform per run)";
    let given = [
        goal.d_star.is_some(),
        goal.d_star_choices.is_some(),
        goal.d_star_range.is_some(),
    ];
    let d_star = match (goal.d_star, goal.d_star_choices, goal.d_star_range) {
        _ if given.iter().filter(|&&g| g).count() > 1 => {
            return Err(check.invalid(
                "goal.d_star",
                format_args!("is given more than one way; {ONE_OF}"),
            ));
        }
        (Some(d), None, None) => {
            DStarPlan::Fixed(check.bounded("goal.d_star", d, limits::D_STAR)?)
        }
        (None, Some(choices), None) => {
            if choices.is_empty() {
                return Err(check.invalid("goal.d_star_choices", "must not be empty"));
            }
            if choices.len() > limits::MAX_D_STAR_CHOICES {
                return Err(check.invalid(
                    "goal.d_star_choices",
                    format_args!(
                        "has {} entries, more than the {} allowed",
                        choices.len(),
                        limits::MAX_D_STAR_CHOICES
                    ),
                ));
            }
            for (k, &d) in choices.iter().enumerate() {
                check.bounded(&format!("goal.d_star_choices[{k}]"), d, limits::D_STAR)?;
            }
            DStarPlan::Choices(choices)
        }
        (None, None, Some([min, max])) => {
            let min = check.bounded("goal.d_star_range[0]", min, limits::D_STAR)?;
            let max = check.bounded("goal.d_star_range[1]", max, limits::D_STAR)?;
            if min >= max {
                return Err(check.invalid(
                    "goal.d_star_range",
                    format_args!(
                        "must be [smallest, largest] with smallest < largest (got [{min}, \
                         {max}]); for one distance use goal.d_star"
                    ),
                ));
            }
            DStarPlan::Range { min, max }
        }
        _ => {
            return Err(check.invalid("goal.d_star", format_args!("is missing; {ONE_OF}")));
        }
    };
    Ok(d_star)
}

/// The `[[agent]]` entries: each names a robot of the team, at most once, and a model.
pub(super) fn validate_agents(
    check: &Checker<'_>,
    agents: Vec<AgentModel>,
    robots: usize,
) -> Result<Vec<AgentModel>, ScenarioError> {
    let mut agents = agents;
    let mut seen = vec![false; robots];
    for (k, agent) in agents.iter_mut().enumerate() {
        if agent.robot >= robots {
            return Err(check.invalid(
                format_args!("agent[{k}].robot"),
                format_args!("must be < robots ({robots}) (got {})", agent.robot),
            ));
        }
        if std::mem::replace(&mut seen[agent.robot], true) {
            return Err(check.invalid(
                format_args!("agent[{k}].robot"),
                format_args!("gives robot {} a model a second time", agent.robot),
            ));
        }
        if agent.model.as_os_str().is_empty() {
            return Err(check.invalid(format_args!("agent[{k}].model"), "must not be empty"));
        }
    }
    Ok(agents)
}

/// The name, if it is 1 to [`limits::MAX_NAME_CHARS`] characters without control characters.
pub(super) fn validate_name(check: &Checker<'_>, name: String) -> Result<String, ScenarioError> {
    if name.trim().is_empty() {
        return Err(check.invalid("name", "must not be empty"));
    }
    let chars = name.chars().count();
    if chars > limits::MAX_NAME_CHARS {
        return Err(check.invalid(
            "name",
            format_args!(
                "must be at most {} characters (got {chars}); it is echoed into logs and reports",
                limits::MAX_NAME_CHARS
            ),
        ));
    }
    if let Some(bad) = name.chars().find(|c| c.is_control()) {
        return Err(check.invalid(
            "name",
            format_args!(
                "must be printable, without control characters (found {:?})",
                bad
            ),
        ));
    }
    Ok(name)
}

/// The robot's profile, geometry, LIDAR and reality models from the `[robot]`, `[lidar]` and
/// `[compass]` tables: the profile's values, each key a table gives overriding its own.
pub(super) fn validate_hardware(
    check: &Checker<'_>,
    robot: &RobotToml,
    lidar: &LidarToml,
    compass: &CompassToml,
    dt: f64,
) -> Result<(RobotProfile, RobotParams, SimulatedLidar, RealityModels), ScenarioError> {
    let profile = match robot.profile.as_deref() {
        None => RobotProfile::Ideal,
        Some(name) => RobotProfile::from_name(name).ok_or_else(|| {
            let names: Vec<String> = RobotProfile::ALL
                .iter()
                .map(|p| format!("{:?}", p.name()))
                .collect();
            check.invalid(
                "robot.profile",
                format_args!("must be one of {} (got {name:?})", names.join(", ")),
            )
        })?,
    };
    let settings = profile.settings();
    let params = validate_robot(check, robot, &settings.robot)?;
    let (spec, lidar_model) = validate_lidar(check, lidar, &settings, dt)?;
    let nominal = settings.reality;
    let or = |given: Option<f64>, default: f64| given.unwrap_or(default);
    let motors = MotorModel {
        tau_s: check.bounded(
            "robot.motor_tau",
            or(robot.motor_tau, nominal.motors.tau_s),
            limits::MOTOR_TAU,
        )?,
        speed_noise_std: check.bounded(
            "robot.wheel_speed_noise",
            or(robot.wheel_speed_noise, nominal.motors.speed_noise_std),
            limits::WHEEL_SPEED_NOISE,
        )?,
        gain_asymmetry: check.bounded(
            "robot.wheel_gain_asymmetry",
            or(robot.wheel_gain_asymmetry, nominal.motors.gain_asymmetry),
            limits::WHEEL_GAIN_ASYMMETRY,
        )?,
    };
    let latency = robot
        .command_latency
        .unwrap_or(i64::from(nominal.command_latency_ticks));
    let max_latency = limits::MAX_COMMAND_LATENCY;
    let command_latency_ticks = u32::try_from(latency)
        .ok()
        .filter(|&ticks| ticks as usize <= max_latency)
        .ok_or_else(|| {
            check.invalid(
                "robot.command_latency",
                format_args!("must be in [0, {max_latency}] ticks (got {latency})"),
            )
        })?;
    let spread = check.bounded(
        "robot.spread",
        or(robot.spread, nominal.spread),
        limits::SPREAD,
    )?;
    let compass = CompassModel {
        noise_std_deg: check.bounded(
            "compass.noise_std_deg",
            or(compass.noise_std_deg, nominal.compass.noise_std_deg),
            limits::COMPASS_NOISE,
        )?,
        bias_deg: check.bounded(
            "compass.bias_deg",
            or(compass.bias_deg, nominal.compass.bias_deg),
            limits::COMPASS_BIAS,
        )?,
    };
    let reality = RealityModels {
        motors,
        lidar: lidar_model,
        compass,
        command_latency_ticks,
        spread,
    };
    Ok((profile, params, spec, reality))
}

/// The `[robot]` geometry and limits: each key the table gives in range, each it omits the
/// profile's.
fn validate_robot(
    check: &Checker<'_>,
    robot: &RobotToml,
    profile: &RobotParams,
) -> Result<RobotParams, ScenarioError> {
    let max_wheel_accel = match robot.max_wheel_accel.or(profile.max_wheel_accel) {
        Some(accel) => {
            Some(check.bounded("robot.max_wheel_accel", accel, limits::MAX_WHEEL_ACCEL)?)
        }
        None => None,
    };
    Ok(RobotParams {
        wheel_separation: check.bounded(
            "robot.wheel_separation",
            robot.wheel_separation.unwrap_or(profile.wheel_separation),
            limits::WHEEL_SEPARATION,
        )?,
        wheel_radius: check.bounded(
            "robot.wheel_radius",
            robot.wheel_radius.unwrap_or(profile.wheel_radius),
            limits::WHEEL_RADIUS,
        )?,
        body_radius: check.bounded(
            "robot.body_radius",
            robot.body_radius.unwrap_or(profile.body_radius),
            limits::BODY_RADIUS,
        )?,
        max_wheel_speed: check.bounded(
            "robot.max_wheel_speed",
            robot.max_wheel_speed.unwrap_or(profile.max_wheel_speed),
            limits::MAX_WHEEL_SPEED,
        )?,
        max_wheel_accel,
    })
}

pub(super) fn validate_heading(
    check: &Checker<'_>,
    heading: &HeadingToml,
) -> Result<HeadingPlan, ScenarioError> {
    let kind = heading.schedule;
    let params = [
        (
            "phi",
            heading.phi,
            kind == ScheduleKind::Constant,
            limits::ANGLE,
        ),
        (
            "omega",
            heading.omega,
            matches!(kind, ScheduleKind::Ramp | ScheduleKind::Sine),
            limits::HEADING_RATE,
        ),
        (
            "amplitude",
            heading.amplitude,
            kind == ScheduleKind::Sine,
            limits::ANGLE,
        ),
        (
            "phi0",
            heading.phi0,
            matches!(kind, ScheduleKind::Ramp | ScheduleKind::Sine),
            limits::ANGLE,
        ),
    ];
    for (name, value, used, bounds) in params {
        match value {
            Some(_) if !used => {
                return Err(check.invalid(
                    format_args!("heading.{name}"),
                    format_args!(
                        "is not a parameter of schedule \"{}\"; remove it",
                        kind.as_str()
                    ),
                ));
            }
            Some(v) => {
                check.bounded(&format!("heading.{name}"), v, bounds)?;
            }
            None => {}
        }
    }
    let required = |name: &str, value: Option<f64>| {
        value.ok_or_else(|| {
            check.invalid(
                format_args!("heading.{name}"),
                format_args!("is required by schedule \"{}\"", kind.as_str()),
            )
        })
    };
    Ok(match kind {
        ScheduleKind::Constant => HeadingPlan::Fixed(HeadingSchedule::Constant {
            phi: required("phi", heading.phi)?,
        }),
        ScheduleKind::Random => HeadingPlan::RandomConstant,
        ScheduleKind::Ramp => HeadingPlan::Fixed(HeadingSchedule::Ramp {
            omega: required("omega", heading.omega)?,
            phi0: heading.phi0.unwrap_or(0.0),
        }),
        ScheduleKind::Sine => HeadingPlan::Fixed(HeadingSchedule::Sine {
            omega: required("omega", heading.omega)?,
            amplitude: heading.amplitude.unwrap_or(1.0),
            phi0: heading.phi0.unwrap_or(0.0),
        }),
    })
}

/// Refuses a run whose trajectory would not fit in memory.
pub(super) fn check_robot_ticks(
    check: &Checker<'_>,
    robots: usize,
    ticks: u64,
    dt: f64,
) -> Result<(), ScenarioError> {
    // Both factors are bounded above, so the product cannot overflow.
    let robot_ticks = ticks * robots as u64;
    if robot_ticks > limits::MAX_ROBOT_TICKS {
        return Err(check.invalid(
            "duration_s",
            format_args!(
                "with dt = {dt} gives {ticks} ticks, and robots x ticks = {robot_ticks} is over the \
                 limit of {} (a run's trajectory is held in memory); shorten duration_s, \
                 enlarge dt or use fewer robots",
                limits::MAX_ROBOT_TICKS
            ),
        ));
    }
    Ok(())
}

/// The neighbour rule the `[formation]` table asks for, with its team-size defaults.
pub(super) fn validate_formation(
    check: &Checker<'_>,
    formation: &FormationToml,
    robots: usize,
    world: &WorldConfig,
) -> Result<NeighbourRule, ScenarioError> {
    let default = NeighbourRule::default_for(robots, world.lidar.max_range);
    let name = formation.neighbours.as_deref().unwrap_or(default.name());
    let gabriel_keys = [
        ("formation.sensing_range", formation.sensing_range.is_some()),
        ("formation.nearest", formation.nearest.is_some()),
        ("formation.threshold", formation.threshold.is_some()),
        ("formation.hysteresis", formation.hysteresis.is_some()),
    ];
    match name {
        "all_pairs" => {
            if let Some((key, _)) = gabriel_keys.iter().find(|(_, given)| *given) {
                return Err(check.invalid(
                    key,
                    "applies only to neighbours = \"gabriel\"; remove it or choose the gabriel rule",
                ));
            }
            Ok(NeighbourRule::AllPairs)
        }
        "gabriel" => {
            let max_range = world.lidar.max_range;
            let sensing_range = match formation.sensing_range {
                None => max_range,
                Some(r) => check.bounded(
                    "formation.sensing_range",
                    r,
                    Bounds {
                        max: max_range,
                        ..limits::MAX_RANGE
                    },
                )?,
            };
            let nearest = check.count(
                "formation.nearest",
                formation.nearest.unwrap_or(GabrielRule::DEFAULT_NEAREST),
                0,
                limits::MAX_NEAREST,
                "",
            )?;
            let threshold = check.bounded(
                "formation.threshold",
                formation
                    .threshold
                    .unwrap_or(GabrielRule::DEFAULT_THRESHOLD),
                limits::GABRIEL_THRESHOLD,
            )?;
            let hysteresis = check.bounded(
                "formation.hysteresis",
                formation
                    .hysteresis
                    .unwrap_or(GabrielRule::DEFAULT_HYSTERESIS),
                Bounds {
                    min: 0.0,
                    max: threshold - 0.01,
                    unit: "",
                },
            )?;
            Ok(NeighbourRule::Gabriel(GabrielRule {
                sensing_range,
                nearest,
                threshold,
                hysteresis,
            }))
        }
        other => Err(check.invalid(
            "formation.neighbours",
            format_args!(
                "must be one of {} (got {other:?})",
                NeighbourRule::NAMES
                    .iter()
                    .map(|n| format!("\"{n}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

pub(super) fn validate_init(
    check: &Checker<'_>,
    init: InitToml,
    robots: usize,
    robot: &RobotParams,
    sensing_range: f64,
) -> Result<InitialConditions, ScenarioError> {
    let disc_radius = check.bounded(
        "init.disc_radius",
        init.disc_radius
            .unwrap_or_else(|| default_disc_radius(robots)),
        limits::DISC_RADIUS,
    )?;
    let min_spacing = check.bounded(
        "init.min_spacing",
        init.min_spacing.unwrap_or(DEFAULT_MIN_SPACING),
        limits::MIN_SPACING,
    )?;
    if min_spacing > sensing_range {
        return Err(check.invalid(
            "init.min_spacing",
            format_args!(
                "must be <= the sensing range ({sensing_range} m) or the team cannot start \
                 connected; reduce init.min_spacing or raise lidar.max_range (got {min_spacing})"
            ),
        ));
    }
    let body_diameter = 2.0 * robot.body_radius;
    if min_spacing < body_diameter {
        return Err(check.invalid(
            "init.min_spacing",
            format_args!(
                "must be >= 2 * robot.body_radius ({body_diameter}) so robots do not start overlapping \
                 (got {min_spacing})"
            ),
        ));
    }
    let sites = lattice_sites(disc_radius, min_spacing, robots).len();
    if sites < robots {
        return Err(check.invalid(
            "init.disc_radius",
            format_args!(
                "is too small to place {robots} robots {min_spacing} m apart (room for about {sites}); \
                 enlarge init.disc_radius or reduce init.min_spacing (got {disc_radius})"
            ),
        ));
    }
    Ok(InitialConditions {
        disc_radius,
        min_spacing,
    })
}
