//! How a policy's input is checked and how its output becomes wheel speeds.
//!
//! What a policy takes and answers is its model's declaration ([`PolicyIo`], in
//! `formation_proto::policy_io`): an image, the scalars beside it, and an output
//! ([`PolicyOutput`]). A goal is checked once where it enters a robot ([`check_goal`]); a wheels
//! output is scaled to the goal's speed ([`scale_to_goal_speed`]); a formation velocity in the
//! robot's frame gets the reference term added ([`formation_velocity_to_wheels`]);
//! [`command_of_output`] picks the one the model declares. A formation velocity is the
//! expert's law as if the wheels had no acceleration limit; a robot whose wheels have one shapes
//! it to a speed its point can still brake from ([`shape_for_wheels`], the expert's own
//! [`braking_speed`]), so one model serves robots with any limit, or none, at full speed. The
//! running agent (`formation-robot-agent`) and the Python bindings (`formation-python`, whose
//! policy runs in Python) call these same functions, so a policy driven from Python sees, and
//! moves its robot by, exactly the numbers the agent's would.

#[cfg(doc)]
use formation_proto::PolicyIo;
use formation_proto::robot::{CheckedGoal, GoalError};
use formation_proto::{AuxInput, Goal, PolicyOutput, WheelCmd, WheelLimits};

/// Why a goal or a heading cannot be turned into a policy's input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyInputError {
    /// d* is not a positive finite distance.
    #[error("d* must be > 0, got {d_star}")]
    DStar {
        /// The goal's d* \[m\].
        d_star: f64,
    },
    /// phi* or v* is NaN or infinite.
    #[error("non-finite goal (phi* {phi_star}, v* {v_star})")]
    NonFiniteGoal {
        /// The goal's phi* \[rad\].
        phi_star: f64,
        /// The goal's v* \[m/s\].
        v_star: f64,
    },
    /// The robot's compass heading is NaN or infinite.
    #[error("non-finite heading {heading}: check the robot's compass")]
    NonFiniteHeading {
        /// The heading \[rad\].
        heading: f64,
    },
}

/// Checks a goal where it enters a robot: d* a positive finite distance, phi* and v* finite
/// ([`CheckedGoal::new`], whose errors these are). A robot holds a checked goal until the next
/// one, so nothing checks it again on each tick.
pub fn check_goal(goal: &Goal) -> Result<(), PolicyInputError> {
    CheckedGoal::new(*goal).map(|_| ()).map_err(|e| match e {
        GoalError::DStar { d_star } => PolicyInputError::DStar { d_star },
        GoalError::NonFinite { phi_star, v_star } => {
            PolicyInputError::NonFiniteGoal { phi_star, v_star }
        }
    })
}

/// Checks the robot's own heading, which changes every tick.
pub fn check_heading(heading: f64) -> Result<(), PolicyInputError> {
    if heading.is_finite() {
        Ok(())
    } else {
        Err(PolicyInputError::NonFiniteHeading { heading })
    }
}

/// The wheel command of a policy output `[left, right]` (at the training speed `v_train`) for a
/// goal speed `v_star`: both wheels times `K = v* / v_train` (the paper's speed scaling).
pub fn scale_to_goal_speed(wheels: [f32; 2], v_star: f64, v_train: f64) -> WheelCmd {
    let k = v_star / v_train;
    WheelCmd {
        left: k * f64::from(wheels[0]),
        right: k * f64::from(wheels[1]),
    }
}

/// The expert's team gain `K` \[1/(m s)\] under a neighbour graph, for which a formation
/// velocity is shaped ([`shape_for_wheels`]): the labels' gain (`ExpertGains::k_formation_graph`'s
/// default, which the expert's tests check against this).
pub const SHAPING_GAIN: f64 = 1.0;

/// The share of a wheel acceleration limit a formation velocity may spend braking
/// (`ExpertGains::braking_share`'s default, which the expert's tests check against this).
pub const SHAPING_BRAKING_SHARE: f64 = 0.25;

/// The speed \[m/s\] at which a point whose formation law asks for `speed` under the gain
/// `k_formation` may approach its equilibrium when it can brake at `braking_accel` \[m/s²\]:
/// `speed / sqrt(1 + k speed / (2 braking_accel))` with `k = 8 k_formation` (one pair's
/// stiffness at d*). Near the formation it is the law itself; far from it, a point
/// braking at `braking_accel` stops in time from at most `sqrt(2 braking_accel speed / k)`: the
/// expert's shaping under an acceleration limit (see `formation_expert::controller`).
pub fn braking_speed(speed: f64, k_formation: f64, braking_accel: f64) -> f64 {
    let stiffness = 8.0 * k_formation;
    speed / (1.0 + stiffness * speed / (2.0 * braking_accel)).sqrt()
}

/// A formation velocity `f` \[m/s\] of the unlimited law shaped for wheels that accelerate at
/// most `max_wheel_accel` \[m/s²\] ([`braking_speed`] with [`SHAPING_GAIN`] and
/// [`SHAPING_BRAKING_SHARE`]): the same direction, a speed the point can brake from. Without a
/// limit, `f` itself.
pub fn shape_for_wheels(f: (f64, f64), max_wheel_accel: Option<f64>) -> (f64, f64) {
    let Some(accel) = max_wheel_accel else {
        return f;
    };
    let speed = f.0.hypot(f.1);
    if speed.is_nan() || speed <= 0.0 {
        return f;
    }
    let scale = braking_speed(speed, SHAPING_GAIN, SHAPING_BRAKING_SHARE * accel) / speed;
    (f.0 * scale, f.1 * scale)
}

pub use formation_proto::MAX_REFERENCE_SPEED;

/// The wheel command of a formation-velocity output `f = (f_x, f_y)` \[m/s\] in the robot's frame,
/// for a robot `delta_phi` off the goal's heading at goal speed `v_star`, within its `wheels`.
///
/// `f` is shaped for the acceleration limit first ([`shape_for_wheels`]). The controlled point
/// lies half a wheel track ahead of the axle (the expert's `c = l/2`), so its velocity `u` in
/// the robot's frame sets `v = u_x`, `ω = u_y / c` and the wheels `v ∓ (l/2) ω = u_x ∓ u_y`
/// whatever the track `l`. `u = f + v (cos Δφ, sin Δφ)`: the reference term `v (cos φ*, sin φ*)`
/// seen from the robot, at `v` = v* capped to ±[`MAX_REFERENCE_SPEED`] as the expert caps it.
/// Where a wheel would exceed the speed limit, both are scaled by one
/// factor into it, as the expert saturates its own command: the point keeps its direction (the
/// world's own limit clips each wheel apart, which turns the robot off it).
pub fn formation_velocity_to_wheels(
    f: [f32; 2],
    delta_phi: f64,
    v_star: f64,
    wheels: WheelLimits,
) -> WheelCmd {
    let f = shape_for_wheels((f64::from(f[0]), f64::from(f[1])), wheels.max_accel);
    let (sin, cos) = delta_phi.sin_cos();
    let reference_speed = v_star.clamp(-MAX_REFERENCE_SPEED, MAX_REFERENCE_SPEED);
    let u_x = f.0 + reference_speed * cos;
    let u_y = f.1 + reference_speed * sin;
    let cmd = WheelCmd {
        left: u_x - u_y,
        right: u_x + u_y,
    };
    match wheels.max_speed {
        Some(limit) => saturate_together(cmd, limit),
        None => cmd,
    }
}

/// Scales both wheels by one factor so that neither exceeds `limit` in magnitude (the expert's
/// saturation); a command within it, or one that is not finite, is left as it is.
pub fn saturate_together(cmd: WheelCmd, limit: f64) -> WheelCmd {
    let largest = cmd.left.abs().max(cmd.right.abs());
    if largest > limit {
        let scale = limit / largest;
        WheelCmd {
            left: cmd.left * scale,
            right: cmd.right * scale,
        }
    } else {
        cmd
    }
}

/// The wheel command of a policy's two output values `values`, as its declared `output` says
/// they are meant (a `wheels` output at its training speed `v_train`, [`PolicyIo`]'s two
/// fields), for a robot with this heading under this goal, within its `wheels` (which bound and
/// shape a formation velocity; a wheels output was trained for one robot and is taken as it is).
pub fn command_of_output(
    output: PolicyOutput,
    v_train: f64,
    values: [f32; 2],
    heading: f64,
    goal: &Goal,
    wheels: WheelLimits,
) -> WheelCmd {
    match output {
        PolicyOutput::Wheels => scale_to_goal_speed(values, goal.v_star, v_train),
        // The heading error as the network is fed it, narrowed to f32.
        PolicyOutput::FormationVelocity => formation_velocity_to_wheels(
            values,
            f64::from(AuxInput::HeadingError.value(heading, goal) as f32),
            goal.v_star,
            wheels,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No limit told.
    const NONE: WheelLimits = WheelLimits {
        max_speed: None,
        max_accel: None,
    };
    /// A 1.0 m/s² acceleration limit and no speed limit told.
    const ACCEL_ONLY: WheelLimits = WheelLimits {
        max_speed: None,
        max_accel: Some(1.0),
    };

    fn goal(phi_star: f64, d_star: f64) -> Goal {
        Goal::new(phi_star, d_star, 0.5)
    }

    #[test]
    fn a_bad_goal_or_heading_is_refused_with_its_values() {
        assert_eq!(check_goal(&goal(0.0, 1.5)), Ok(()));
        assert_eq!(
            check_goal(&goal(0.0, 0.0)).unwrap_err().to_string(),
            "d* must be > 0, got 0"
        );
        assert_eq!(
            check_goal(&goal(f64::NAN, 1.0)).unwrap_err().to_string(),
            "non-finite goal (phi* NaN, v* 0.5)"
        );
        assert!(check_heading(0.3).is_ok());
        assert!(
            check_heading(f64::INFINITY)
                .unwrap_err()
                .to_string()
                .contains("compass")
        );
    }

    #[test]
    fn outputs_scale_with_the_goal_speed() {
        let cmd = scale_to_goal_speed([0.25, -0.5], 1.0, 0.5);
        assert_eq!((cmd.left, cmd.right), (0.5, -1.0));
    }

    #[test]
    fn a_formation_velocity_becomes_the_wheels_that_move_the_point_half_a_track_ahead() {
        // On heading with no correction: straight on at v*.
        let cmd = formation_velocity_to_wheels([0.0, 0.0], 0.0, 0.5, NONE);
        assert_eq!((cmd.left, cmd.right), (0.5, 0.5));
        // Goal heading 90° to the left, standing still otherwise: the point is asked to move
        // sideways at v*, which turns the robot left on the spot (ω = v* / c).
        let cmd = formation_velocity_to_wheels([0.0, 0.0], std::f64::consts::FRAC_PI_2, 0.4, NONE);
        assert!((cmd.left + 0.4).abs() < 1e-12 && (cmd.right - 0.4).abs() < 1e-12);
        // The correction adds to the reference term and does not scale with v*.
        let slow = formation_velocity_to_wheels([0.1, 0.0], 0.0, 0.3, NONE);
        let fast = formation_velocity_to_wheels([0.1, 0.0], 0.0, 0.6, NONE);
        assert!((slow.left - 0.4).abs() < 1e-6 && (fast.left - 0.7).abs() < 1e-6);
        // Above the expert's cap the reference term is the cap's, as the expert's is, so the
        // correction keeps the wheel speed it had below it.
        let capped = formation_velocity_to_wheels([0.1, 0.0], 0.0, 0.8, NONE);
        assert!(
            (capped.left - (0.1 + MAX_REFERENCE_SPEED)).abs() < 1e-6,
            "{capped:?}"
        );
        // The point's velocity from these wheels, with l = 0.331 and c = l/2, is f + reference.
        let (l, c) = (0.331, 0.331 / 2.0);
        let f = [0.05_f32, -0.12_f32];
        let cmd = formation_velocity_to_wheels(f, 0.3, 0.7, NONE);
        let v = (cmd.left + cmd.right) / 2.0;
        let omega = (cmd.right - cmd.left) / l;
        assert!((v - (f64::from(f[0]) + 0.7 * 0.3f64.cos())).abs() < 1e-9);
        assert!((c * omega - (f64::from(f[1]) + 0.7 * 0.3f64.sin())).abs() < 1e-9);
    }

    #[test]
    fn the_declared_output_picks_the_conversion() {
        let goal = Goal {
            phi_star: 0.5,
            d_star: 1.5,
            v_star: 0.35,
        };
        assert_eq!(
            command_of_output(
                PolicyOutput::Wheels,
                0.7,
                [0.7, 0.35],
                0.3,
                &goal,
                ACCEL_ONLY
            ),
            scale_to_goal_speed([0.7, 0.35], 0.35, 0.7)
        );
        assert_eq!(
            command_of_output(
                PolicyOutput::FormationVelocity,
                0.7,
                [0.1, 0.0],
                0.3,
                &goal,
                NONE
            ),
            formation_velocity_to_wheels([0.1, 0.0], f64::from((0.5_f64 - 0.3) as f32), 0.35, NONE)
        );
    }

    #[test]
    fn a_limit_shapes_a_formation_velocity_as_the_expert_does_and_no_limit_keeps_it() {
        let f = (0.3, -0.4);
        assert_eq!(shape_for_wheels(f, None), f);
        assert_eq!(shape_for_wheels((0.0, 0.0), Some(1.0)), (0.0, 0.0));
        let shaped = shape_for_wheels(f, Some(1.0));
        // The direction is kept, the speed is the braking speed: 0.5 / sqrt(1 + 8 * 0.5 / 0.5).
        assert!((shaped.0 / shaped.1 - f.0 / f.1).abs() < 1e-12);
        let speed = shaped.0.hypot(shaped.1);
        assert!((speed - 0.5 / 9.0_f64.sqrt()).abs() < 1e-12, "{speed}");
        // A looser limit shapes less; small corrections are almost untouched.
        let loose = shape_for_wheels(f, Some(4.0));
        assert!(loose.0.hypot(loose.1) > speed);
        let small = shape_for_wheels((0.01, 0.0), Some(1.0));
        assert!(small.0 > 0.0085 && small.0 < 0.01);
        // Through the wheels: under a limit the command is the shaped velocity's.
        let goal = Goal {
            phi_star: 0.2,
            d_star: 1.5,
            v_star: 0.5,
        };
        let limited = command_of_output(
            PolicyOutput::FormationVelocity,
            0.7,
            [0.3, -0.4],
            0.0,
            &goal,
            ACCEL_ONLY,
        );
        let expected = formation_velocity_to_wheels(
            [shaped.0 as f32, shaped.1 as f32],
            f64::from(0.2_f32),
            0.5,
            NONE,
        );
        assert!((limited.left - expected.left).abs() < 1e-6);
        assert!((limited.right - expected.right).abs() < 1e-6);
    }

    #[test]
    fn a_speed_limit_scales_both_wheels_by_one_factor_as_the_expert_saturates() {
        let limits = WheelLimits {
            max_speed: Some(0.9),
            max_accel: None,
        };
        // Within the limit: the same command as with none.
        let within = formation_velocity_to_wheels([0.05, 0.1], 0.0, 0.7, limits);
        assert_eq!(
            within,
            formation_velocity_to_wheels([0.05, 0.1], 0.0, 0.7, NONE)
        );
        // Beyond it: 0.7 + 0.1 - 0.4 and 0.7 + 0.1 + 0.4 -> (0.4, 1.2) scaled by 0.75.
        let free = formation_velocity_to_wheels([0.1, 0.4], 0.0, 0.7, NONE);
        let cmd = formation_velocity_to_wheels([0.1, 0.4], 0.0, 0.7, limits);
        assert!((free.left - 0.4).abs() < 1e-6 && (free.right - 1.2).abs() < 1e-6);
        assert!((cmd.right - 0.9).abs() < 1e-12, "{cmd:?}");
        assert!((cmd.left / cmd.right - free.left / free.right).abs() < 1e-12);
        // The command a policy sends is the expert's saturation of the same point velocity.
        let big = saturate_together(
            WheelCmd {
                left: -3.0,
                right: 1.5,
            },
            0.9,
        );
        assert!((big.left + 0.9).abs() < 1e-12 && (big.right - 0.45).abs() < 1e-12);
        assert!(limits.is_valid() && NONE.is_valid());
        assert!(
            !WheelLimits {
                max_speed: Some(0.0),
                max_accel: None
            }
            .is_valid()
        );
    }
}
