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
//! limit and the command about to be sent. A diff-drive body moves only along its heading, and
//! a held command drives it along a circle (or a line), so the clearance `s` is the distance
//! the body can travel along that path, ahead or back, before its disc, of radius `R` grown by
//! [`SAFETY_MARGIN_M`] all round, touches a scan return ([`clearance`]; the agent takes the
//! wheels to be [`formation_proto::DEFAULT_WHEEL_SEPARATION_M`] apart, as it takes bodies to be
//! [`formation_proto::DEFAULT_BODY_RADIUS_M`] across). When a body in that path is closer than
//! [`ENGAGE_FRACTION_OF_D_STAR`] of d\* centre to centre (it is then already outside the strict
//! check's 10 % band), the forward speed is limited to `sqrt(2 β a s)`, with `β` =
//! [`BRAKING_SHARE`] (two robots closing on each other each stop within half the clearance); the
//! wheel difference, and so the turn, is kept.
//! Without an acceleration limit, or with the path clear, the command is returned unchanged, bit
//! for bit, so nothing changes for a robot whose wheels have no limit and for a team in
//! formation.
//!
//! The path is the arc, and the margin is grown sideways too: a robot that passes a neighbour
//! with a centimetre to spare and turns as it goes swings into it (run 146 of 32 robots did
//! with a straight path and a margin kept only ahead, and run 199 of 13 with a straight path).
//!
//! The governor knows no velocities: it treats what it sees as standing still. That is why it
//! engages only inside the band: a teammate in the robot's path at d\* moves away with the
//! team, and a stationary-obstacle rule would hold the follower of a small-d\* formation below
//! v\* (at d\* = 0.8 m and 1.0 m/s², to about 0.5 m/s).

use formation_proto::WheelCmd;

use crate::beams::BeamDirections;

/// The fraction of d\* (centre to centre) below which a body in the robot's path engages the
/// governor: the strict check's 10 % band, outside which a neighbour this close already fails it.
pub const ENGAGE_FRACTION_OF_D_STAR: f64 = 0.9;

/// The share of the wheel acceleration limit the governor plans to brake with: two robots
/// closing on each other each stop within half the clearance.
pub const BRAKING_SHARE: f64 = 0.5;

/// How far \[m\] the governor grows the robot's body all round: the command answers a scan taken
/// a tick before the wheels act on it (0.05 s at 0.9 m/s is 4.5 cm), the wheels reach it a tick
/// later still, and a turning robot's path swings sideways. Kept only ahead, 0.05 m let the run
/// that had touched (3 robots, run 13 of `teams-generalist-accel`) pass with 5 mm between the
/// bodies, and 0.1 m with 2.5 cm.
pub const SAFETY_MARGIN_M: f64 = 0.1;

/// The course a wheel command drives while it is held: the centre's signed speed along the
/// heading and its curvature (turn per metre travelled; 0 for a straight line).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Course {
    /// Forward (> 0) or backward (< 0).
    pub forward: bool,
    /// `ω / |v|` \[1/m\], positive turning left (counter-clockwise).
    pub curvature: f64,
}

impl Course {
    /// The path of `command` on wheels `wheel_separation` apart; `None` for a command that does
    /// not move the centre (turning on the spot, or not finite).
    pub fn of_command(command: WheelCmd, wheel_separation: f64) -> Option<Course> {
        let speed = 0.5 * (command.left + command.right);
        let turn = (command.right - command.left) / wheel_separation;
        let curvature = turn / speed.abs();
        (speed.is_finite() && speed != 0.0 && curvature.is_finite()).then_some(Course {
            forward: speed > 0.0,
            curvature,
        })
    }
}

/// Courses that bend less than this \[1/m\] are taken as straight.
const STRAIGHT_CURVATURE: f64 = 1e-6;

/// The distance \[m\] the centre of a disc of `radius` on the LIDAR travels along `path` before
/// the disc touches one of `scan`'s returns, counting only returns nearer than `reach` (beyond
/// it, or with no return on the path, `f64::INFINITY`). Ranges that are not finite, or at or
/// beyond the LIDAR's range, hit nothing; a return the disc already touches ahead of it gives 0,
/// and one behind it on a straight path none.
pub fn clearance(
    scan: &[f32],
    beams: &BeamDirections,
    radius: f64,
    path: Course,
    reach: f64,
) -> f64 {
    let sign = if path.forward { 1.0 } else { -1.0 };
    let straight = path.curvature.abs() < STRAIGHT_CURVATURE;
    let mut nearest = f64::INFINITY;
    for (&range, &(cos, sin)) in scan.iter().zip(beams.as_slice()) {
        let range = f64::from(range);
        if range.is_nan() || range >= reach {
            continue;
        }
        let range = range.max(0.0);
        // The return in a frame whose +x is the direction of travel, so that a reversing robot's
        // path is a forward one with its curvature mirrored.
        let (along, across) = (sign * range * cos, range * sin);
        let travel = if straight {
            straight_travel(along, across, radius)
        } else {
            arc_travel(along, across, radius, sign * path.curvature)
        };
        nearest = nearest.min(travel);
    }
    nearest
}

/// How far a disc of `radius` at the origin travels along +x before it touches `(along, across)`.
fn straight_travel(along: f64, across: f64, radius: f64) -> f64 {
    if along <= 0.0 || across.abs() >= radius {
        return f64::INFINITY;
    }
    (along - (radius * radius - across * across).sqrt()).max(0.0)
}

/// How far a disc of `radius` at the origin, heading +x on a circle of `curvature` (> 0 turning
/// left), travels before it touches `(along, across)`.
fn arc_travel(along: f64, across: f64, radius: f64, curvature: f64) -> f64 {
    // The circle's centre is `1 / curvature` to the left; the disc's centre goes round it at
    // `rho`, counter-clockwise when turning left.
    let rho = 1.0 / curvature.abs();
    let centre_y = 1.0 / curvature;
    let (qx, qy) = (along, across - centre_y);
    let distance = qx.hypot(qy);
    if (distance - rho).abs() >= radius {
        return f64::INFINITY;
    }
    // The disc touches the return while its centre is within `half` of the return's angle.
    let cos_half = (rho * rho + distance * distance - radius * radius) / (2.0 * rho * distance);
    let half = cos_half.clamp(-1.0, 1.0).acos();
    let start = (-centre_y).atan2(0.0);
    let turn = if curvature > 0.0 { 1.0 } else { -1.0 };
    let ahead = (turn * (qy.atan2(qx) - start)).rem_euclid(std::f64::consts::TAU);
    if ahead <= half {
        0.0
    } else {
        rho * (ahead - half)
    }
}

/// `command` with its forward speed limited to one the robot can stop from before its body of
/// `body_radius`, grown by [`SAFETY_MARGIN_M`], touches what `scan` shows in its path, under a
/// wheel acceleration limit `max_accel` \[m/s²\] and a goal of `d_star` (see the module's
/// documentation). Unchanged without a limit, when the robot does not move along its heading,
/// or when its path is clear of bodies closer than [`ENGAGE_FRACTION_OF_D_STAR`] of d\* (centre
/// to centre).
pub fn keep_stopping_distance(
    command: WheelCmd,
    scan: &[f32],
    beams: &BeamDirections,
    body_radius: f64,
    wheel_separation: f64,
    d_star: f64,
    max_accel: Option<f64>,
) -> WheelCmd {
    let Some(accel) = max_accel.filter(|a| a.is_finite() && *a > 0.0) else {
        return command;
    };
    let Some(path) = Course::of_command(command, wheel_separation) else {
        return command;
    };
    let grown = body_radius + SAFETY_MARGIN_M;
    // A body in line whose centre is at the engaging distance is this far from the grown disc;
    // no return beyond `reach` can be nearer than that along any path.
    let engage = ENGAGE_FRACTION_OF_D_STAR * d_star - body_radius - grown;
    let reach = engage + grown;
    let travel = clearance(scan, beams, grown, path, reach);
    if travel >= engage {
        return command;
    }
    let allowed = (2.0 * BRAKING_SHARE * accel * travel).sqrt();
    let speed = 0.5 * (command.left + command.right);
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
    use formation_proto::{LidarSpec, Pose};
    use formation_world::RobotParams;
    use formation_world::lidar::cast_scan;

    use super::*;

    const R: f64 = formation_proto::DEFAULT_BODY_RADIUS_M;
    const W: f64 = formation_proto::DEFAULT_WHEEL_SEPARATION_M;
    const AHEAD: Course = Course {
        forward: true,
        curvature: 0.0,
    };
    const BACK: Course = Course {
        forward: false,
        curvature: 0.0,
    };

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
        (scan, BeamDirections::new(lidar.beams))
    }

    fn command(left: f64, right: f64) -> WheelCmd {
        WheelCmd { left, right }
    }

    #[test]
    fn the_clearance_is_the_travel_until_the_bodies_touch() {
        let (scan, beams) = scan_of(&[(1.0, 0.0), (-2.0, 0.1)]);
        // Centres 1.0 apart on the heading: the discs touch after 0.5.
        let ahead = clearance(&scan, &beams, R, AHEAD, 10.0);
        assert!((ahead - 0.5).abs() < 0.01, "{ahead}");
        // Behind, 0.1 m off the axis: centre distance along the axis when touching is
        // sqrt(0.5² - 0.1²).
        let behind = clearance(&scan, &beams, R, BACK, 10.0);
        let expected = 2.0 - (0.25f64 - 0.01).sqrt();
        assert!(
            (behind - expected).abs() < 0.02,
            "{behind} against {expected}"
        );
        // Beyond the reach, nothing counts.
        assert_eq!(clearance(&scan, &beams, R, AHEAD, 0.7), f64::INFINITY);
    }

    #[test]
    fn a_body_beside_the_path_leaves_it_clear() {
        // Centre 0.6 to the side: the discs never meet going straight.
        let (scan, beams) = scan_of(&[(0.3, 0.6), (0.0, -0.55)]);
        assert_eq!(clearance(&scan, &beams, R, AHEAD, 10.0), f64::INFINITY);
        assert_eq!(clearance(&scan, &beams, R, BACK, 10.0), f64::INFINITY);
        // One 1 cm clear of the body's side, a little behind: reversing, the robot would graze it
        // once it turned, so the margin holds it; driving on, nothing is in its path.
        let (scan, beams) = scan_of(&[(-0.2, 0.51)]);
        let back = command(-0.4, -0.3);
        let held = keep_stopping_distance(back, &scan, &beams, R, W, 1.5, Some(1.0));
        assert!(held.left + held.right > back.left + back.right, "{held:?}");
        let on = command(0.4, 0.3);
        assert_eq!(
            keep_stopping_distance(on, &scan, &beams, R, W, 1.5, Some(1.0)),
            on
        );
    }

    #[test]
    fn without_a_limit_or_with_a_clear_path_the_command_is_unchanged() {
        let (scan, beams) = scan_of(&[(0.7, 0.0)]);
        let fast = command(0.8, 0.9);
        for limit in [None, Some(0.0), Some(f64::NAN)] {
            assert_eq!(
                keep_stopping_distance(fast, &scan, &beams, R, W, 1.0, limit),
                fast
            );
        }
        // At d* = 0.7 m a body 0.7 m ahead is in formation: not engaged.
        assert_eq!(
            keep_stopping_distance(fast, &scan, &beams, R, W, 0.7, Some(1.0)),
            fast
        );
        // Reversing away from it: not engaged either.
        let back = command(-0.8, -0.7);
        assert_eq!(
            keep_stopping_distance(back, &scan, &beams, R, W, 1.0, Some(1.0)),
            back
        );
        // Turning on the spot moves the body nowhere.
        let spin = command(-0.5, 0.5);
        assert_eq!(
            keep_stopping_distance(spin, &scan, &beams, R, W, 1.0, Some(1.0)),
            spin
        );
    }

    #[test]
    fn the_arc_clearance_is_where_the_turning_disc_first_touches() {
        // Against the disc stepped along its circle a millimetre at a time for 20 m, for returns
        // around the robot and curvatures both ways, forward and back.
        let returns = [
            (0.8, 0.3),
            (0.5, -0.6),
            (-0.7, 0.2),
            (0.1, 0.45),
            (1.4, -0.1),
        ];
        for curvature in [2.0, -2.0, 0.7, -0.3, 5.0] {
            for forward in [true, false] {
                for &(x, y) in &returns {
                    let sign = if forward { 1.0 } else { -1.0 };
                    let mut stepped = f64::INFINITY;
                    for step in 0..20_000 {
                        let s = f64::from(step) * 1e-3;
                        let heading = curvature * s;
                        // The centre after `s` along the heading (or against it), the heading
                        // turning by `curvature` a metre either way.
                        let (cx, cy) = (
                            sign * heading.sin() / curvature,
                            sign * (1.0 - heading.cos()) / curvature,
                        );
                        if (x - cx).hypot(y - cy) <= 0.35 {
                            stepped = s;
                            break;
                        }
                    }
                    let found = arc_travel(sign * x, y, 0.35, sign * curvature);
                    assert!(
                        (found - stepped).abs() < 2e-3 || (found > 19.9 && stepped.is_infinite()),
                        "curvature {curvature}, forward {forward}, ({x}, {y}): {found} against {stepped}"
                    );
                }
            }
        }
        // A body beside the robot that a straight path misses is in a turning one's way.
        let (scan, beams) = scan_of(&[(0.4, -0.7)]);
        assert_eq!(clearance(&scan, &beams, R, AHEAD, 10.0), f64::INFINITY);
        let right = Course {
            forward: true,
            curvature: -2.5,
        };
        assert!(clearance(&scan, &beams, R, right, 10.0) < 0.5);
    }

    #[test]
    fn a_body_too_close_in_the_path_limits_the_speed_and_keeps_the_turn() {
        // Centres 0.7 apart at d* = 1.0: 0.2 m between the bodies, less the margin.
        let (scan, beams) = scan_of(&[(0.7, 0.0)]);
        let straight =
            keep_stopping_distance(command(0.8, 0.8), &scan, &beams, R, W, 1.0, Some(1.0));
        let allowed = (2.0 * BRAKING_SHARE * (0.2 - SAFETY_MARGIN_M)).sqrt();
        assert!(
            (straight.left - allowed).abs() < 0.01,
            "{straight:?} against {allowed}"
        );
        assert_eq!(straight.left, straight.right);
        // Turning, the limit is that of the arc it drives, and the turn is kept.
        let wanted = command(0.8, 0.6);
        let limited = keep_stopping_distance(wanted, &scan, &beams, R, W, 1.0, Some(1.0));
        let path = Course::of_command(wanted, W).expect("it moves");
        let travel = clearance(&scan, &beams, R + SAFETY_MARGIN_M, path, 10.0);
        let speed = 0.5 * (limited.left + limited.right);
        assert!(travel > 0.1 && (speed - (2.0 * BRAKING_SHARE * travel).sqrt()).abs() < 1e-12);
        assert!((limited.right - limited.left - (0.6 - 0.8)).abs() < 1e-12);
        // A slower command stays as it was.
        let slow = command(0.2, 0.25);
        assert_eq!(
            keep_stopping_distance(slow, &scan, &beams, R, W, 1.0, Some(1.0)),
            slow
        );
        // Behind, the same for a reversing robot; a body touching stops it.
        let (scan, beams) = scan_of(&[(-0.5, 0.0)]);
        let stopped =
            keep_stopping_distance(command(-0.6, -0.4), &scan, &beams, R, W, 1.0, Some(1.0));
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
                let cmd = keep_stopping_distance(wanted, &scan, &beams, R, W, 1.5, Some(accel));
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
