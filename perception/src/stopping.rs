//! The agent's stopping governor: a wheel command slowed, under a wheel acceleration limit, to a
//! speed from which the robot can still stop before its body touches what its own scan shows
//! close ahead of it (or behind it, when it reverses).
//!
//! The formation law commands a point velocity as if the wheels reached any speed within a tick.
//! Under a limit `a` a robot needs `v² / (2a)` to stop, and in the first seconds of a run, when
//! robots start at rest with random headings, one robot can back or drive into a neighbour that
//! is still turning on the spot: over 1,400 runs of `teams-generalist-accel` the shipped policy
//! and the expert each touched another robot in 5 runs, every time in such a transient, with the
//! robots already closer than d\*.
//!
//! The governor reads only what the robot has: its scan, its goal's d\*, its wheel acceleration
//! limit and the command about to be sent. A diff-drive body moves only along its heading, so
//! the clearance is the distance the body can travel straight ahead (or back) before its disc
//! of radius `R` touches a scan return ([`clearance`]). When that clearance is below
//! [`ENGAGE_FRACTION_OF_D_STAR`] of d\* less the two bodies (a neighbour in the robot's path
//! is then already outside the strict check's 10 % band), the forward speed is limited to
//! `sqrt(2 β a (s − m))`, with `β` = [`BRAKING_SHARE`] (two robots closing on each other each
//! stop within half the clearance) and `m` = [`STOPPING_MARGIN_M`]; the wheel difference, and
//! so the turn, is kept. Without an acceleration limit, or with the path clear, the command is
//! returned unchanged, bit for bit, so nothing changes for a robot whose wheels have no limit
//! and for a team in formation.
//!
//! The governor knows no velocities: it treats what it sees as standing still. That is why it
//! engages only inside the band: a teammate in the robot's path at d\* moves away with the
//! team, and a stationary-obstacle rule would hold the follower of a small-d\* formation below
//! v\* (at d\* = 0.8 m and 1.0 m/s², to about 0.5 m/s).

use formation_proto::{LidarSpec, WheelCmd};

/// The fraction of d\* (centre to centre) below which a body in the robot's path engages the
/// governor: the strict check's 10 % band, outside which a neighbour this close already fails it.
pub const ENGAGE_FRACTION_OF_D_STAR: f64 = 0.9;

/// The share of the wheel acceleration limit the governor plans to brake with: two robots
/// closing on each other each stop within half the clearance.
pub const BRAKING_SHARE: f64 = 0.5;

/// The clearance \[m\] the governor plans to keep between the robot's body and the nearest
/// return in its path when it has stopped: the command answers a scan taken a tick before the
/// wheels act on it (0.05 s at 0.9 m/s is 4.5 cm), and the wheels reach it a tick later still.
/// With 0.05 m the run that had touched (3 robots, run 13 of `teams-generalist-accel`) passed
/// with 5 mm between the bodies; with 0.1 m, with 2.5 cm.
pub const STOPPING_MARGIN_M: f64 = 0.1;

/// The unit direction of each beam of a LIDAR, computed once per robot (beam 0 along the
/// robot's +x axis, counter-clockwise, as [`LidarSpec`] defines them).
#[derive(Debug, Clone, PartialEq)]
pub struct BeamDirections {
    cos_sin: Vec<(f64, f64)>,
}

impl BeamDirections {
    /// The directions of `lidar`'s beams.
    pub fn new(lidar: &LidarSpec) -> BeamDirections {
        let step = std::f64::consts::TAU / lidar.beams.max(1) as f64;
        BeamDirections {
            cos_sin: (0..lidar.beams)
                .map(|beam| {
                    let (sin, cos) = (beam as f64 * step).sin_cos();
                    (cos, sin)
                })
                .collect(),
        }
    }
}

/// The distance \[m\] a disc of `body_radius` centred on the LIDAR can travel along its heading
/// (`forward`) or against it before it touches one of `scan`'s returns, counting only returns
/// nearer than `reach` (beyond it, or with no return in the path, `f64::INFINITY`). Ranges that
/// are not finite, or at or beyond the LIDAR's range, hit nothing; a return inside the body
/// gives 0.
pub fn clearance(
    scan: &[f32],
    beams: &BeamDirections,
    body_radius: f64,
    forward: bool,
    reach: f64,
) -> f64 {
    let sign = if forward { 1.0 } else { -1.0 };
    let mut nearest = f64::INFINITY;
    for (&range, &(cos, sin)) in scan.iter().zip(&beams.cos_sin) {
        let range = f64::from(range);
        if range.is_nan() || range >= reach {
            continue;
        }
        let range = range.max(0.0);
        let (along, across) = (sign * range * cos, range * sin);
        if along <= 0.0 || across.abs() >= body_radius {
            continue;
        }
        // The body touches the return once its centre has moved `along - sqrt(R² - across²)`.
        let travel = along - (body_radius * body_radius - across * across).sqrt();
        nearest = nearest.min(travel.max(0.0));
    }
    nearest
}

/// `command` with its forward speed limited to one the robot can stop from before its body of
/// `body_radius` touches what `scan` shows in its path, under a wheel acceleration limit
/// `max_accel` \[m/s²\] and a goal of `d_star` (see the module's documentation). Unchanged without
/// a limit, when the robot does not move along its heading, or when its path is clear to
/// [`ENGAGE_FRACTION_OF_D_STAR`] of d\* (centre to centre).
pub fn keep_stopping_distance(
    command: WheelCmd,
    scan: &[f32],
    beams: &BeamDirections,
    body_radius: f64,
    d_star: f64,
    max_accel: Option<f64>,
) -> WheelCmd {
    let Some(accel) = max_accel.filter(|a| a.is_finite() && *a > 0.0) else {
        return command;
    };
    let speed = 0.5 * (command.left + command.right);
    if speed.is_nan() || speed == 0.0 {
        return command;
    }
    // A body whose centre is nearer than the engaging distance has its near side at most this
    // far from the scanner.
    let engage = ENGAGE_FRACTION_OF_D_STAR * d_star - 2.0 * body_radius;
    let reach = engage + body_radius;
    let travel = clearance(scan, beams, body_radius, speed > 0.0, reach);
    if travel >= engage {
        return command;
    }
    let allowed = (2.0 * BRAKING_SHARE * accel * (travel - STOPPING_MARGIN_M).max(0.0)).sqrt();
    if speed.abs() <= allowed {
        return command;
    }
    let limited = allowed.copysign(speed);
    let half_difference = 0.5 * (command.right - command.left);
    WheelCmd {
        left: limited - half_difference,
        right: limited + half_difference,
    }
}

#[cfg(test)]
mod tests {
    use formation_proto::Pose;
    use formation_world::RobotParams;
    use formation_world::lidar::cast_scan;

    use super::*;

    const R: f64 = 0.25;

    /// The noiseless scan (the world's own ray cast) of a robot at the origin heading +x among
    /// bodies of the default radius centred at `bodies`.
    fn scan_of(bodies: &[(f64, f64)]) -> (Vec<f32>, BeamDirections) {
        let lidar = LidarSpec::default();
        let poses: Vec<Pose> = std::iter::once((0.0, 0.0))
            .chain(bodies.iter().copied())
            .map(|(x, y)| Pose::new(x, y, 0.0))
            .collect();
        let mut scan = vec![0.0; lidar.beams];
        cast_scan(&poses, 0, &RobotParams::default(), &lidar, &mut scan);
        (scan, BeamDirections::new(&lidar))
    }

    fn command(left: f64, right: f64) -> WheelCmd {
        WheelCmd { left, right }
    }

    #[test]
    fn the_clearance_is_the_travel_until_the_bodies_touch() {
        let (scan, beams) = scan_of(&[(1.0, 0.0), (-2.0, 0.1)]);
        // Centres 1.0 apart on the heading: the discs touch after 0.5.
        let ahead = clearance(&scan, &beams, R, true, 10.0);
        assert!((ahead - 0.5).abs() < 0.01, "{ahead}");
        // Behind, 0.1 m off the axis: centre distance along the axis when touching is
        // sqrt(0.5² - 0.1²).
        let behind = clearance(&scan, &beams, R, false, 10.0);
        let expected = 2.0 - (0.25f64 - 0.01).sqrt();
        assert!(
            (behind - expected).abs() < 0.02,
            "{behind} against {expected}"
        );
        // Beyond the reach, nothing counts.
        assert_eq!(clearance(&scan, &beams, R, true, 0.7), f64::INFINITY);
    }

    #[test]
    fn a_body_beside_the_path_leaves_it_clear() {
        // Centre 0.6 to the side: the discs never meet going straight.
        let (scan, beams) = scan_of(&[(0.3, 0.6), (0.0, -0.55)]);
        assert_eq!(clearance(&scan, &beams, R, true, 10.0), f64::INFINITY);
        assert_eq!(clearance(&scan, &beams, R, false, 10.0), f64::INFINITY);
    }

    #[test]
    fn without_a_limit_or_with_a_clear_path_the_command_is_unchanged() {
        let (scan, beams) = scan_of(&[(0.7, 0.0)]);
        let fast = command(0.8, 0.9);
        for limit in [None, Some(0.0), Some(f64::NAN)] {
            assert_eq!(
                keep_stopping_distance(fast, &scan, &beams, R, 1.0, limit),
                fast
            );
        }
        // At d* = 0.7 m a body 0.7 m ahead is in formation: not engaged.
        assert_eq!(
            keep_stopping_distance(fast, &scan, &beams, R, 0.7, Some(1.0)),
            fast
        );
        // Reversing away from it: not engaged either.
        let back = command(-0.8, -0.7);
        assert_eq!(
            keep_stopping_distance(back, &scan, &beams, R, 1.0, Some(1.0)),
            back
        );
        // Turning on the spot moves the body nowhere.
        let spin = command(-0.5, 0.5);
        assert_eq!(
            keep_stopping_distance(spin, &scan, &beams, R, 1.0, Some(1.0)),
            spin
        );
    }

    #[test]
    fn a_body_too_close_in_the_path_limits_the_speed_and_keeps_the_turn() {
        // Centres 0.7 apart at d* = 1.0: the clearance is 0.2 m.
        let (scan, beams) = scan_of(&[(0.7, 0.0)]);
        let limited = keep_stopping_distance(command(0.8, 0.6), &scan, &beams, R, 1.0, Some(1.0));
        let allowed = (2.0 * BRAKING_SHARE * (0.2 - STOPPING_MARGIN_M)).sqrt();
        let speed = 0.5 * (limited.left + limited.right);
        assert!((speed - allowed).abs() < 0.01, "{speed} against {allowed}");
        assert!((limited.right - limited.left - (0.6 - 0.8)).abs() < 1e-12);
        // A slower command stays as it was.
        let slow = command(0.2, 0.3);
        assert_eq!(
            keep_stopping_distance(slow, &scan, &beams, R, 1.0, Some(1.0)),
            slow
        );
        // Behind, the same for a reversing robot; a body touching stops it.
        let (scan, beams) = scan_of(&[(-0.5, 0.0)]);
        let stopped = keep_stopping_distance(command(-0.6, -0.4), &scan, &beams, R, 1.0, Some(1.0));
        assert!((stopped.left + stopped.right).abs() < 1e-9, "{stopped:?}");
        assert!((stopped.right - stopped.left - 0.2).abs() < 1e-12);
    }

    #[test]
    fn two_robots_closing_head_on_stop_apart() {
        // Two robots on one line, each driving at the other at 0.9 m/s from 2 m apart, with
        // 1 m/s² wheels and d* = 1.5 m: each sees the other in its scan (straight ahead) and
        // governs its own command; the world's limit ramps each speed. Ungoverned, they would
        // touch at 0.83 s.
        let (accel, dt) = (1.0, 0.05);
        let (mut x, mut speed) = ([0.0f64, 2.0], [0.9f64, 0.9]);
        let mut closest = f64::INFINITY;
        for _ in 0..200 {
            let gap = x[1] - x[0];
            let (scan, beams) = scan_of(&[(gap, 0.0)]);
            for speed in &mut speed {
                let wanted = command(0.9, 0.9);
                let cmd = keep_stopping_distance(wanted, &scan, &beams, R, 1.5, Some(accel));
                let target = 0.5 * (cmd.left + cmd.right);
                *speed += (target - *speed).clamp(-accel * dt, accel * dt);
            }
            x[0] += speed[0] * dt;
            x[1] -= speed[1] * dt;
            closest = closest.min(x[1] - x[0]);
        }
        assert!(
            closest > 2.0 * R,
            "the bodies touched: centres {closest} apart"
        );
        assert!(closest < 2.0 * R + 0.2, "they stopped far apart: {closest}");
    }
}
