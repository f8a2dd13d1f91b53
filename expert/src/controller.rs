//! The expert: the distance-based formation controller, a pure function of every robot's pose and the goal.
//!
//! Re-derived from the paper's equations:
//!
//! * **Point offset.** Each robot is controlled through the point `p_i = (x_i + c cos th_i, y_i + c sin th_i)`
//!   a distance `c` ahead of its axle, whose velocity a differential drive can set freely.
//! * **Formation term.** For every other robot `j`, with `p_ij = p_i - p_j` and `r = |p_ij|`, the gradient
//!   of the pair potential `V(r) = (r^2 - d*^2)^2 / r^2` is `tau_ij = 2 (r^4 - d*^4) / r^3 * p_ij / r`; the
//!   potential grows without bound as `r -> 0`, so the term also pushes robots apart at short range.
//!   The formation velocity is `f_i = -K3 sum_j tau_ij`.
//! * **Reference term.** `w = v* (cos phi*, sin phi*)`, its norm saturated to `max_reference_speed`.
//! * **To wheels.** With `u = f_i + w`: `v = cos th u_x + sin th u_y`, `omega = (-sin th u_x + cos th u_y) / c`,
//!   `vL = v - (l/2) omega`, `vR = v + (l/2) omega`, then both wheels scaled by one common factor so that
//!   `max(|vL|, |vR|) <= max_wheel_speed`; a common factor keeps the curvature, so a saturated robot still
//!   turns along the path it asked for, only slower.
//!
//! The expert sees ground-truth poses of all robots. It exists to generate demonstrations and as the
//! baseline the learned policy is compared with; it never runs inside an agent.

use formation_proto::{Goal, Pose, WheelCmd};
use formation_world::RobotParams;
use formation_world::episode::{Controller, ControllerError, Observation};
use serde::{Deserialize, Serialize};

/// Below this distance \[m\] between two offset points the pair's direction is undefined and the pair
/// contributes nothing (the bodies, 0.5 m across, would overlap long before).
const MIN_PAIR_DISTANCE: f64 = 1e-9;

/// The expert's gains.
///
/// The defaults are the paper's `K3 = 0.15`, `c = l/2` for the P3-DX (`l = 0.331 m`) and the paper's
/// 0.7 m/s cap on the reference velocity. They need no tuning: over the 100 runs of 60 s of
/// `scenarios/table1.toml` (noiseless LIDAR, 0.9 m/s wheel limit) the expert succeeds in 100 % of runs
/// at both 5 % and 10 %, converges (10 %) in 2.9 s median (0.7-5.9 s), holds the formation to
/// about 1e-15 relative error and the heading to about 1e-14 rad, without a collision. Reproduce with
/// `cargo run -p formation-expert --release --example expert_table1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExpertGains {
    /// Formation gain `K3` [1/(m s)]: scales the gradient of the pair potentials into a velocity.
    pub k_formation: f64,
    /// Distance `c`, in metres, from the axle centre to the controlled point, along the heading. Must be > 0.
    pub point_offset: f64,
    /// Upper bound \[m/s\] on the norm of the reference velocity `v* (cos phi*, sin phi*)`.
    pub max_reference_speed: f64,
}

impl Default for ExpertGains {
    fn default() -> Self {
        ExpertGains {
            k_formation: 0.15,
            point_offset: 0.331 / 2.0,
            max_reference_speed: 0.7,
        }
    }
}

/// Gains that cannot drive a robot.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("expert gain {field} = {value} is invalid: it must be {requirement}")]
pub struct InvalidGains {
    /// The offending field of [`ExpertGains`].
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must be instead.
    pub requirement: &'static str,
}

impl ExpertGains {
    /// Checks that every gain is finite and in range: `k_formation >= 0`, `point_offset > 0`,
    /// `max_reference_speed >= 0`.
    pub fn validate(&self) -> Result<(), InvalidGains> {
        let checks = [
            (
                "k_formation",
                self.k_formation,
                self.k_formation >= 0.0,
                "finite and >= 0",
            ),
            (
                "point_offset",
                self.point_offset,
                self.point_offset > 0.0,
                "finite and > 0",
            ),
            (
                "max_reference_speed",
                self.max_reference_speed,
                self.max_reference_speed >= 0.0,
                "finite and >= 0",
            ),
        ];
        for (field, value, in_range, requirement) in checks {
            if !(value.is_finite() && in_range) {
                return Err(InvalidGains {
                    field,
                    value,
                    requirement,
                });
            }
        }
        Ok(())
    }
}

/// The expert's wheel command for every robot, written to `out[i]` for `poses[i]`.
///
/// Every pair of robots is a formation edge (the paper's complete graph). Non-finite poses or goal
/// values give non-finite commands, which the world brakes; [`ExpertController`] refuses them up front.
///
/// # Panics
///
/// If `out.len() != poses.len()`.
pub fn expert_commands(
    poses: &[Pose],
    goal: &Goal,
    gains: &ExpertGains,
    robot: &RobotParams,
    out: &mut [WheelCmd],
) {
    assert_eq!(out.len(), poses.len(), "one output command per robot");
    let c = gains.point_offset;
    let offset_point = |pose: &Pose| (pose.x + c * pose.theta.cos(), pose.y + c * pose.theta.sin());
    let reference = reference_velocity(goal, gains.max_reference_speed);
    let d4 = goal.d_star.powi(4);

    for (i, (pose, cmd)) in poses.iter().zip(out.iter_mut()).enumerate() {
        let p_i = offset_point(pose);
        let mut gradient = (0.0, 0.0);
        for (j, other) in poses.iter().enumerate() {
            if j == i {
                continue;
            }
            let p_j = offset_point(other);
            let (dx, dy) = (p_i.0 - p_j.0, p_i.1 - p_j.1);
            let r = dx.hypot(dy);
            if r < MIN_PAIR_DISTANCE {
                continue;
            }
            // tau_ij = 2 (r^4 - d*^4) / r^3 * p_ij / r
            let magnitude = 2.0 * (r.powi(4) - d4) / r.powi(3);
            gradient.0 += magnitude * dx / r;
            gradient.1 += magnitude * dy / r;
        }
        let u = (
            reference.0 - gains.k_formation * gradient.0,
            reference.1 - gains.k_formation * gradient.1,
        );
        *cmd = point_velocity_to_wheels(u, pose.theta, c, robot);
    }
}

/// `v* (cos phi*, sin phi*)` with its norm capped at `max_speed`.
fn reference_velocity(goal: &Goal, max_speed: f64) -> (f64, f64) {
    let speed = goal.v_star.clamp(-max_speed, max_speed);
    (speed * goal.phi_star.cos(), speed * goal.phi_star.sin())
}

/// Inverts the point-offset kinematics: the wheel speeds that move the point `c` ahead of the axle at
/// velocity `u`, then scaled by one common factor into the wheel limit.
fn point_velocity_to_wheels(u: (f64, f64), theta: f64, c: f64, robot: &RobotParams) -> WheelCmd {
    let (sin, cos) = theta.sin_cos();
    let v = cos * u.0 + sin * u.1;
    let omega = (-sin * u.0 + cos * u.1) / c;
    let half_track = robot.wheel_separation / 2.0;
    saturate(
        WheelCmd {
            left: v - half_track * omega,
            right: v + half_track * omega,
        },
        robot.max_wheel_speed,
    )
}

/// Scales both wheels by the same factor so that neither exceeds `limit` in magnitude.
fn saturate(cmd: WheelCmd, limit: f64) -> WheelCmd {
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

/// The expert as a [`Controller`]: reads the ground-truth poses and the goal of each observation.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertController {
    gains: ExpertGains,
    robot: RobotParams,
}

impl ExpertController {
    /// An expert with these gains for robots with these parameters.
    pub fn new(gains: ExpertGains, robot: RobotParams) -> ExpertController {
        ExpertController { gains, robot }
    }

    /// The gains in use.
    pub fn gains(&self) -> &ExpertGains {
        &self.gains
    }

    /// The robot parameters in use.
    pub fn robot(&self) -> &RobotParams {
        &self.robot
    }
}

impl Controller for ExpertController {
    fn commands(
        &mut self,
        obs: &Observation<'_>,
        out: &mut [WheelCmd],
    ) -> Result<(), ControllerError> {
        check_inputs(obs.poses, &obs.goal, out.len())?;
        self.gains
            .validate()
            .map_err(|e| ControllerError::new(e.to_string()))?;
        expert_commands(obs.poses, &obs.goal, &self.gains, &self.robot, out);
        Ok(())
    }
}

/// Refuses what the expert cannot act on, naming the value.
pub(crate) fn check_inputs(
    poses: &[Pose],
    goal: &Goal,
    commands: usize,
) -> Result<(), ControllerError> {
    if commands != poses.len() {
        return Err(ControllerError::new(format!(
            "expert asked for {commands} commands but the observation has {} robots",
            poses.len()
        )));
    }
    if !(goal.d_star.is_finite() && goal.d_star > 0.0) {
        return Err(ControllerError::new(format!(
            "expert needs a finite d* > 0, got {}",
            goal.d_star
        )));
    }
    if !(goal.phi_star.is_finite() && goal.v_star.is_finite()) {
        return Err(ControllerError::new(format!(
            "expert needs a finite goal, got phi* = {}, v* = {}",
            goal.phi_star, goal.v_star
        )));
    }
    if let Some((i, pose)) = poses
        .iter()
        .enumerate()
        .find(|(_, p)| !(p.x.is_finite() && p.y.is_finite() && p.theta.is_finite()))
    {
        return Err(ControllerError::new(format!(
            "expert got a non-finite pose for robot {i}: {pose:?}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::wrap_angle;
    use std::f64::consts::PI;

    const DT: f64 = 0.05;

    fn goal(phi_star: f64, d_star: f64) -> Goal {
        Goal {
            phi_star,
            d_star,
            v_star: 0.7,
        }
    }

    /// Three robots on an equilateral triangle of side `side`, all heading `theta`.
    fn triangle(side: f64, theta: f64) -> Vec<Pose> {
        (0..3)
            .map(|k| {
                let a = 0.4 + k as f64 * 2.0 * PI / 3.0;
                let radius = side / 3.0_f64.sqrt();
                Pose {
                    x: 1.0 + radius * a.cos(),
                    y: -2.0 + radius * a.sin(),
                    theta,
                }
            })
            .collect()
    }

    /// Unicycle step with the exact arc, so the tests need nothing from the world but its types.
    fn integrate(pose: Pose, cmd: WheelCmd, robot: &RobotParams) -> Pose {
        let v = (cmd.right + cmd.left) / 2.0;
        let omega = (cmd.right - cmd.left) / robot.wheel_separation;
        let theta = pose.theta + omega * DT;
        let (dx, dy) = if omega.abs() < 1e-12 {
            (v * DT * pose.theta.cos(), v * DT * pose.theta.sin())
        } else {
            let radius = v / omega;
            (
                radius * (theta.sin() - pose.theta.sin()),
                -radius * (theta.cos() - pose.theta.cos()),
            )
        };
        Pose {
            x: pose.x + dx,
            y: pose.y + dy,
            theta: wrap_angle(theta),
        }
    }

    fn step(
        poses: &mut [Pose],
        goal: &Goal,
        gains: &ExpertGains,
        robot: &RobotParams,
    ) -> Vec<WheelCmd> {
        let mut cmds = vec![WheelCmd::BRAKE; poses.len()];
        expert_commands(poses, goal, gains, robot, &mut cmds);
        for (pose, cmd) in poses.iter_mut().zip(&cmds) {
            *pose = integrate(*pose, *cmd, robot);
        }
        cmds
    }

    fn distance(a: &Pose, b: &Pose) -> f64 {
        (a.x - b.x).hypot(a.y - b.y)
    }

    #[test]
    fn a_team_in_formation_drives_straight_at_v_star_and_stays_in_formation() {
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        for (d_star, phi) in [(1.0, 0.0), (1.5, 2.0), (2.0, -2.5)] {
            let g = goal(phi, d_star);
            let mut poses = triangle(d_star, phi);
            let mut cmds = vec![WheelCmd::BRAKE; 3];
            expert_commands(&poses, &g, &gains, &robot, &mut cmds);
            for cmd in &cmds {
                assert!(
                    (cmd.left - 0.7).abs() < 1e-9 && (cmd.right - 0.7).abs() < 1e-9,
                    "{cmd:?}"
                );
            }
            for _ in 0..200 {
                step(&mut poses, &g, &gains, &robot);
            }
            for (i, j) in [(0, 1), (0, 2), (1, 2)] {
                let error = (distance(&poses[i], &poses[j]) - d_star).abs() / d_star;
                assert!(error < 0.01, "pair ({i},{j}) error {error} at d* {d_star}");
            }
            assert!(poses.iter().all(|p| wrap_angle(p.theta - phi).abs() < 0.01));
        }
    }

    #[test]
    fn wheel_limits_hold_for_extreme_inputs() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let cases = [
            vec![
                Pose {
                    x: 0.0,
                    y: 0.0,
                    theta: 0.0,
                },
                Pose {
                    x: 500.0,
                    y: 10.0,
                    theta: 3.0,
                },
                Pose {
                    x: -80.0,
                    y: 900.0,
                    theta: -1.0,
                },
            ],
            vec![
                Pose {
                    x: 0.0,
                    y: 0.0,
                    theta: 1.0,
                },
                Pose {
                    x: 0.01,
                    y: 0.0,
                    theta: 1.0,
                },
            ],
        ];
        for poses in cases {
            let mut cmds = vec![WheelCmd::BRAKE; poses.len()];
            expert_commands(&poses, &goal(1.0, 2.0), &gains, &robot, &mut cmds);
            for cmd in &cmds {
                assert!(cmd.is_finite(), "{cmd:?}");
                let largest = cmd.left.abs().max(cmd.right.abs());
                assert!(largest <= robot.max_wheel_speed + 1e-12, "{cmd:?}");
                assert!(
                    largest > 0.5 * robot.max_wheel_speed,
                    "far from the goal, a wheel runs near its limit"
                );
            }
        }
    }

    #[test]
    fn saturation_keeps_the_ratio_of_the_wheels() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.3,
            },
            Pose {
                x: 40.0,
                y: 25.0,
                theta: 0.0,
            },
        ];
        let u = {
            // What robot 0 asks for before saturation, recomputed from the published formulas.
            let c = gains.point_offset;
            let p0 = (c * 0.3_f64.cos(), c * 0.3_f64.sin());
            let (dx, dy) = (p0.0 - (40.0 + c), p0.1 - 25.0);
            let r = dx.hypot(dy);
            let m = 2.0 * (r.powi(4) - 1.5_f64.powi(4)) / r.powi(3);
            let g = goal(0.0, 1.5);
            (
                0.7 * g.phi_star.cos() - gains.k_formation * m * dx / r,
                0.7 * g.phi_star.sin() - gains.k_formation * m * dy / r,
            )
        };
        let (sin, cos) = 0.3_f64.sin_cos();
        let v = cos * u.0 + sin * u.1;
        let omega = (-sin * u.0 + cos * u.1) / gains.point_offset;
        let raw = WheelCmd {
            left: v - robot.wheel_separation / 2.0 * omega,
            right: v + robot.wheel_separation / 2.0 * omega,
        };
        assert!(
            raw.left.abs().max(raw.right.abs()) > robot.max_wheel_speed,
            "the case must saturate"
        );

        let mut cmds = [WheelCmd::BRAKE; 2];
        expert_commands(&poses, &goal(0.0, 1.5), &gains, &robot, &mut cmds);
        let cmd = cmds[0];
        assert!((cmd.left.abs().max(cmd.right.abs()) - robot.max_wheel_speed).abs() < 1e-12);
        assert!(
            (cmd.left / cmd.right - raw.left / raw.right).abs() < 1e-9,
            "{cmd:?} vs {raw:?}"
        );
    }

    #[test]
    fn robots_too_close_are_pushed_apart() {
        let robot = RobotParams::default();
        let gains = ExpertGains::default();
        let g = goal(0.0, 2.0);
        // Side by side, 0.6 m apart, both heading along phi*.
        let mut poses = vec![
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 0.0,
                y: 0.6,
                theta: 0.0,
            },
        ];
        let start = distance(&poses[0], &poses[1]);
        let mut previous = start;
        for _ in 0..10 {
            step(&mut poses, &g, &gains, &robot);
            let now = distance(&poses[0], &poses[1]);
            assert!(now > previous, "distance fell from {previous} to {now}");
            previous = now;
        }
        assert!(
            previous > start + 0.05,
            "pushed apart by only {} m",
            previous - start
        );
    }

    #[test]
    fn a_scattered_team_converges_to_the_formation() {
        let (gains, robot) = (ExpertGains::default(), RobotParams::default());
        let g = goal(2.5, 1.5);
        let mut poses = vec![
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 2.0,
                y: 1.0,
                theta: 3.0,
            },
            Pose {
                x: -1.0,
                y: 2.5,
                theta: -1.5,
            },
        ];
        for _ in 0..(30.0 / DT) as usize {
            step(&mut poses, &g, &gains, &robot);
        }
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let error = (distance(&poses[i], &poses[j]) - 1.5).abs() / 1.5;
            assert!(error < 0.01, "pair ({i},{j}) error {error}");
        }
    }

    #[test]
    fn the_controller_refuses_bad_inputs_and_gains() {
        let poses = triangle(1.0, 0.0);
        let scans: Vec<Vec<f32>> = vec![Vec::new(); 3];
        let mut expert = ExpertController::new(ExpertGains::default(), RobotParams::default());
        let mut out = vec![WheelCmd::BRAKE; 3];
        let bad_goal = Observation {
            tick: 0,
            time: 0.0,
            goal: goal(0.0, 0.0),
            poses: &poses,
            scans: &scans,
        };
        assert!(
            expert
                .commands(&bad_goal, &mut out)
                .unwrap_err()
                .message
                .contains("d*")
        );
        let ok = Observation {
            goal: goal(0.0, 1.0),
            ..bad_goal
        };
        assert!(expert.commands(&ok, &mut out[..2]).is_err());
        let mut nan_poses = poses.clone();
        nan_poses[2].x = f64::NAN;
        let nan = Observation {
            poses: &nan_poses,
            ..ok
        };
        assert!(
            expert
                .commands(&nan, &mut out)
                .unwrap_err()
                .message
                .contains("robot 2")
        );
        expert.commands(&ok, &mut out).expect("valid inputs");

        let mut bad_gains = ExpertController::new(
            ExpertGains {
                point_offset: 0.0,
                ..ExpertGains::default()
            },
            RobotParams::default(),
        );
        let err = bad_gains.commands(&ok, &mut out).unwrap_err();
        assert!(err.message.contains("point_offset"), "{err}");
    }
}
