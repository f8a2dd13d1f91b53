//! Differential-drive robots: the P3-DX-like body and wheel parameters, the wheel limits the world
//! enforces, and exact (arc) integration of the unicycle kinematics over one time step.
//!
//! Wheel speeds are rim speeds in m/s, so the kinematics need only the wheel separation `l`:
//! forward speed `v = (vR + vL) / 2`, turn rate `w = (vR - vL) / l`. Holding both wheel speeds
//! constant over a step moves the robot along a circular arc (a straight line when `w = 0`), which
//! [`integrate`] follows exactly rather than by Euler steps.

use formation_proto::{Pose, WheelCmd, wrap_angle};
use serde::{Deserialize, Serialize};

/// Geometry and limits of one differential-drive robot (all robots of a world share them).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotParams {
    /// Distance between the two wheels' contact points, `l` \[m\].
    pub wheel_separation: f64,
    /// Wheel radius \[m\]; converts rim speeds to wheel angular speeds (rad/s = rim / radius).
    pub wheel_radius: f64,
    /// Radius of the disc that stands for the body in ray casts and collision tests \[m\].
    pub body_radius: f64,
    /// Largest rim speed either wheel can reach, forwards or backwards \[m/s\].
    pub max_wheel_speed: f64,
    /// Largest change of a wheel's rim speed per second \[m/s^2\]; `None` means the wheels reach a
    /// commanded speed within one step.
    pub max_wheel_accel: Option<f64>,
}

impl Default for RobotParams {
    /// A Pioneer P3-DX: l = 0.331 m, wheel radius 0.0975 m, a 0.25 m body disc, wheels limited to
    /// 0.9 m/s (enough to still turn while cruising at the paper's 0.7 m/s), no acceleration limit.
    fn default() -> Self {
        RobotParams {
            wheel_separation: formation_proto::DEFAULT_WHEEL_SEPARATION_M,
            wheel_radius: 0.0975,
            body_radius: formation_proto::DEFAULT_BODY_RADIUS_M,
            max_wheel_speed: 0.9,
            max_wheel_accel: None,
        }
    }
}

impl RobotParams {
    /// What the robot knows of its own wheels, as its agent is told them: its top wheel speed
    /// and its acceleration limit.
    pub fn wheel_limits(&self) -> formation_proto::WheelLimits {
        formation_proto::WheelLimits {
            max_speed: Some(self.max_wheel_speed),
            max_accel: self.max_wheel_accel,
        }
    }

    /// The wheel speeds the robot can actually run for one step of `dt` seconds, given the
    /// `requested` command and the wheel speeds `current` at the start of the step.
    ///
    /// A command with a non-finite wheel speed is replaced by [`WheelCmd::BRAKE`]; each wheel is
    /// then saturated to `±max_wheel_speed` and, when an acceleration limit is set, moved from its
    /// current speed by at most `max_wheel_accel * dt` (braking included: a real wheel cannot stop
    /// at once either).
    pub fn achievable(&self, requested: WheelCmd, current: WheelCmd, dt: f64) -> WheelCmd {
        let target = if requested.is_finite() {
            requested
        } else {
            WheelCmd::BRAKE
        };
        let limit = self.max_wheel_speed;
        let mut left = target.left.clamp(-limit, limit);
        let mut right = target.right.clamp(-limit, limit);
        if let Some(accel) = self.max_wheel_accel {
            let step = accel * dt;
            left = left.clamp(current.left - step, current.left + step);
            right = right.clamp(current.right - step, current.right + step);
        }
        WheelCmd { left, right }
    }
}

/// Forward speed `v` \[m/s\] and turn rate `w` \[rad/s\] of a robot whose wheels run at `cmd`.
pub fn body_velocity(cmd: WheelCmd, params: &RobotParams) -> (f64, f64) {
    let forward = 0.5 * (cmd.right + cmd.left);
    let turn_rate = (cmd.right - cmd.left) / params.wheel_separation;
    (forward, turn_rate)
}

/// The pose reached after holding the wheel speeds `cmd` for `dt` seconds from `pose`.
///
/// Exact for constant wheel speeds: the robot moves along the chord of its circular arc, of length
/// `v dt sinc(w dt / 2)` in the direction `theta + w dt / 2`, which tends smoothly to the straight
/// line as `w` goes to zero. The returned heading is wrapped to (-pi, pi]. `cmd` is used as given;
/// [`RobotParams::achievable`] applies the wheel limits first.
pub fn integrate(pose: Pose, cmd: WheelCmd, params: &RobotParams, dt: f64) -> Pose {
    let (forward, turn_rate) = body_velocity(cmd, params);
    let turned = turn_rate * dt;
    let half_turn = 0.5 * turned;
    let chord = forward * dt * sinc(half_turn);
    let (sin_mid, cos_mid) = (pose.theta + half_turn).sin_cos();
    Pose::new(
        pose.x + chord * cos_mid,
        pose.y + chord * sin_mid,
        wrap_angle(pose.theta + turned),
    )
}

/// `sin(x) / x`, with its Taylor series near zero where the quotient loses precision.
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        // The next term, x^4 / 120, is below 1e-18 here.
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const DT: f64 = 0.05;

    fn assert_pose_near(actual: Pose, expected: Pose, tol: f64) {
        assert!(
            (actual.x - expected.x).abs() < tol
                && (actual.y - expected.y).abs() < tol
                && wrap_angle(actual.theta - expected.theta).abs() < tol,
            "pose {actual:?} differs from {expected:?} by more than {tol}"
        );
    }

    #[test]
    fn equal_wheel_speeds_drive_straight_along_the_heading() {
        let params = RobotParams::default();
        let start = Pose::new(1.0, -2.0, 0.7);
        let cmd = WheelCmd::new(0.6, 0.6);
        let end = (0..40).fold(start, |pose, _| integrate(pose, cmd, &params, DT));
        let distance = 0.6 * 40.0 * DT;
        let expected = Pose {
            x: 1.0 + distance * 0.7_f64.cos(),
            y: -2.0 + distance * 0.7_f64.sin(),
            theta: 0.7,
        };
        assert_pose_near(end, expected, 1e-12);
    }

    #[test]
    fn opposite_wheel_speeds_turn_in_place() {
        let params = RobotParams::default();
        let start = Pose::new(0.3, 0.4, 3.1);
        let cmd = WheelCmd::new(-0.2, 0.2);
        let end = integrate(start, cmd, &params, DT);
        let turn_rate = 0.4 / params.wheel_separation;
        let expected = Pose {
            x: 0.3,
            y: 0.4,
            theta: wrap_angle(3.1 + turn_rate * DT),
        };
        assert_pose_near(end, expected, 1e-12);
        assert!(
            end.theta < 0.0,
            "heading must wrap past pi, got {}",
            end.theta
        );
    }

    #[test]
    fn unequal_wheel_speeds_follow_the_closed_form_arc() {
        let params = RobotParams::default();
        let start = Pose::new(-1.0, 2.0, -2.5);
        let cmd = WheelCmd::new(0.35, 0.8);
        let dt = 0.37;
        let v = 0.5 * (0.35 + 0.8);
        let w = (0.8 - 0.35) / params.wheel_separation;
        let expected = Pose {
            x: -1.0 + v / w * ((-2.5 + w * dt).sin() - (-2.5_f64).sin()),
            y: 2.0 - v / w * ((-2.5 + w * dt).cos() - (-2.5_f64).cos()),
            theta: wrap_angle(-2.5 + w * dt),
        };
        assert_pose_near(integrate(start, cmd, &params, dt), expected, 1e-12);
    }

    #[test]
    fn a_full_circle_returns_to_the_start() {
        let params = RobotParams::default();
        let cmd = WheelCmd::new(0.3, 0.5);
        let w = 0.2 / params.wheel_separation;
        let steps = 1000;
        let dt = 2.0 * PI / w / steps as f64;
        let start = Pose::new(5.0, 5.0, 1.0);
        let mut pose = start;
        let radius = 0.4 / w;
        for _ in 0..steps {
            pose = integrate(pose, cmd, &params, dt);
            // The centre of the turn lies `radius` to the left of the start.
            let centre = (5.0 - radius * 1.0_f64.sin(), 5.0 + radius * 1.0_f64.cos());
            let off = ((pose.x - centre.0).powi(2) + (pose.y - centre.1).powi(2)).sqrt();
            assert!(
                (off - radius).abs() < 1e-9,
                "left the circle: {off} vs {radius}"
            );
        }
        assert_pose_near(pose, start, 1e-9);
    }

    #[test]
    fn tiny_turn_rates_match_the_straight_line_limit() {
        let params = RobotParams::default();
        let start = Pose::new(0.0, 0.0, 0.0);
        let cmd = WheelCmd {
            left: 0.5,
            right: 0.5 + 1e-12,
        };
        let end = integrate(start, cmd, &params, DT);
        assert!(
            (end.x - 0.5 * DT).abs() < 1e-12 && end.y.abs() < 1e-12,
            "{end:?}"
        );
    }

    #[test]
    fn saturation_keeps_both_wheels_within_the_limit() {
        let params = RobotParams::default();
        let limit = params.max_wheel_speed;
        for (left, right) in [(5.0, 0.1), (-3.0, 2.0), (0.2, -0.95), (f64::MAX, f64::MIN)] {
            let applied = params.achievable(WheelCmd { left, right }, WheelCmd::BRAKE, DT);
            assert!(
                applied.left.abs() <= limit && applied.right.abs() <= limit,
                "{applied:?}"
            );
            assert_eq!(applied.left, left.clamp(-limit, limit));
            assert_eq!(applied.right, right.clamp(-limit, limit));
        }
    }

    #[test]
    fn non_finite_commands_brake() {
        let params = RobotParams::default();
        for bad in [
            WheelCmd::new(f64::NAN, 0.5),
            WheelCmd::new(0.5, f64::INFINITY),
            WheelCmd::new(f64::NEG_INFINITY, f64::NAN),
        ] {
            let current = WheelCmd::new(0.4, 0.4);
            assert_eq!(params.achievable(bad, current, DT), WheelCmd::BRAKE);
        }
    }

    #[test]
    fn acceleration_limit_bounds_the_change_per_step() {
        let params = RobotParams {
            max_wheel_accel: Some(2.0),
            ..RobotParams::default()
        };
        let current = WheelCmd::new(0.5, -0.5);
        let applied = params.achievable(WheelCmd::new(-0.9, 0.9), current, DT);
        assert!((applied.left - 0.4).abs() < 1e-12 && (applied.right + 0.4).abs() < 1e-12);
        let small = params.achievable(WheelCmd::new(0.55, -0.5), current, DT);
        assert_eq!(
            small,
            WheelCmd {
                left: 0.55,
                right: -0.5
            }
        );
        let braking = params.achievable(WheelCmd::new(f64::NAN, 0.0), current, DT);
        assert!((braking.left - 0.4).abs() < 1e-12 && (braking.right + 0.4).abs() < 1e-12);
    }

    #[test]
    fn params_read_from_toml_fill_missing_keys_and_reject_unknown_ones() {
        let params: RobotParams = toml::from_str("max_wheel_speed = 0.7").expect("valid table");
        assert_eq!(params.max_wheel_speed, 0.7);
        assert_eq!(
            params.wheel_separation,
            RobotParams::default().wheel_separation
        );
        let error = toml::from_str::<RobotParams>("wheel_base = 0.3").expect_err("unknown key");
        assert!(error.to_string().contains("wheel_base"), "{error}");
    }
}
