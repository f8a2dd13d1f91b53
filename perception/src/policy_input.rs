//! The rest of a policy's input beside the image, and how its output becomes wheel speeds.
//!
//! A policy takes `(delta_phi, d*)` next to the occupancy image ([`policy_aux`]) and answers wheel
//! speeds at its training speed `v_train`, which the robot scales to the goal's speed
//! ([`scale_to_goal_speed`]). The running agent (`formation-robot-agent`) and the Python bindings
//! (`formation-python`, whose policy runs in Python) call these same functions, so a policy driven
//! from Python sees, and moves its robot by, exactly the numbers the agent's would.

use formation_proto::{Goal, WheelCmd, wrap_angle};

/// Why a goal cannot be turned into a policy's input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyInputError {
    /// d* is not a positive finite distance.
    #[error("d* must be > 0, got {d_star}")]
    DStar {
        /// The goal's d* \[m\].
        d_star: f64,
    },
    /// The heading, phi* or v* is NaN or infinite.
    #[error("non-finite input (phi* {phi_star}, heading {heading}, v* {v_star})")]
    NonFinite {
        /// The goal's phi* \[rad\].
        phi_star: f64,
        /// The robot's heading \[rad\].
        heading: f64,
        /// The goal's v* \[m/s\].
        v_star: f64,
    },
}

/// The policy's auxiliary input `(delta_phi, d*)` for a robot with this heading and goal:
/// `delta_phi = wrap(phi* - heading)`, both narrowed to `f32`.
pub fn policy_aux(heading: f64, goal: &Goal) -> Result<[f32; 2], PolicyInputError> {
    if !(goal.d_star.is_finite() && goal.d_star > 0.0) {
        return Err(PolicyInputError::DStar {
            d_star: goal.d_star,
        });
    }
    if !(goal.phi_star.is_finite() && heading.is_finite() && goal.v_star.is_finite()) {
        return Err(PolicyInputError::NonFinite {
            phi_star: goal.phi_star,
            heading,
            v_star: goal.v_star,
        });
    }
    Ok([
        wrap_angle(goal.phi_star - heading) as f32,
        goal.d_star as f32,
    ])
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

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(phi_star: f64, d_star: f64) -> Goal {
        Goal {
            phi_star,
            d_star,
            v_star: 0.5,
        }
    }

    #[test]
    fn the_aux_input_is_the_wrapped_heading_error_and_d_star() {
        let aux = policy_aux(3.0, &goal(-3.0, 1.5)).unwrap();
        assert_eq!(aux, [wrap_angle(-6.0) as f32, 1.5]);
        assert!(aux[0] > 0.0 && aux[0] < 0.3);
    }

    #[test]
    fn a_bad_goal_is_refused_with_its_values() {
        assert_eq!(
            policy_aux(0.0, &goal(0.0, 0.0)).unwrap_err().to_string(),
            "d* must be > 0, got 0"
        );
        let err = policy_aux(f64::NAN, &goal(0.0, 1.0)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "non-finite input (phi* 0, heading NaN, v* 0.5)"
        );
    }

    #[test]
    fn outputs_scale_with_the_goal_speed() {
        let cmd = scale_to_goal_speed([0.25, -0.5], 1.0, 0.5);
        assert_eq!((cmd.left, cmd.right), (0.5, -1.0));
    }
}
