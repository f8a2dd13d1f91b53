//! The planar LIDAR ring: noiseless ranges from one robot to the other robots' bodies, ray-cast with
//! parry2d.
//!
//! Beam `k` of `B` leaves the sensor (at the robot's pose) at body-frame bearing `2 pi k / B`,
//! counter-clockwise from the robot's heading, and reads the distance to the first body it meets,
//! or `max_range` when it meets none within range. The robot's own body is never hit.
//!
//! Casting every beam against every body would cost `O(N^2 B)` per tick for `N` robots. Instead,
//! for each other body within reach, only the beams inside the angular interval the body subtends
//! are cast, so the work per sensor is `O(N)` plus the number of beams that can actually hit.
//! Measurement noise is not added here: [`crate::World::scan_into`] adds it from the world's RNG.

use std::f64::consts::TAU;

use formation_proto::{LidarSpec, Pose};
use parry2d::math::{Point, Vector};
use parry2d::query::{Ray, RayCast};
use parry2d::shape::Ball;

use crate::robot::RobotParams;

/// Writes the noiseless ranges \[m\] of robot `own`'s LIDAR ring into `out`, given every robot's
/// pose; all bodies are discs of `params.body_radius` centred at their poses.
///
/// Beams that hit nothing within `lidar.max_range` read exactly `lidar.max_range as f32`. If `own`'s
/// sensor lies inside another body (the robots collided), every beam reads 0.
///
/// # Panics
///
/// If `own` is not an index of `poses` or `out.len()` differs from `lidar.beams`: both are
/// programming errors of the caller, never a consequence of scenario input.
pub fn cast_scan(
    poses: &[Pose],
    own: usize,
    params: &RobotParams,
    lidar: &LidarSpec,
    out: &mut [f32],
) {
    assert_eq!(
        out.len(),
        lidar.beams,
        "cast_scan: the output buffer holds {} ranges but the LIDAR has {} beams",
        out.len(),
        lidar.beams
    );
    let max_range = lidar.max_range;
    out.fill(max_range as f32);
    let sensor = poses[own];
    let beams = lidar.beams;
    if beams == 0 {
        return;
    }
    let beam_step = TAU / beams as f64;
    let radius = params.body_radius;
    let body = Ball::new(radius as f32);
    let (sin_heading, cos_heading) = sensor.theta.sin_cos();

    for (index, other) in poses.iter().enumerate() {
        if index == own {
            continue;
        }
        // The body's centre in the sensor's frame (x along the heading), computed in f64 so that
        // far-from-origin worlds keep the ranges' precision after the cast to parry's f32.
        let (dx, dy) = (other.x - sensor.x, other.y - sensor.y);
        let forward = cos_heading * dx + sin_heading * dy;
        let left = -sin_heading * dx + cos_heading * dy;
        let distance = forward.hypot(left);
        // False for bodies out of reach and for non-finite poses, which no beam can hit.
        let within_reach = distance - radius < max_range;
        if !within_reach {
            continue;
        }
        if distance <= radius {
            out.fill(0.0);
            return;
        }

        // Only beams within the half-width asin(r / d) of the body's bearing can hit it; one beam of
        // margin on each side absorbs rounding, and the exact cast decides.
        let bearing = left.atan2(forward);
        let half_width = (radius / distance).asin();
        let first = ((bearing - half_width) / beam_step).floor() as i64;
        let last = ((bearing + half_width) / beam_step).ceil() as i64;
        // The body as seen from a ray leaving the origin is the same as a ray leaving `-centre`
        // towards a ball at the origin: parry's local cast, without isometry transforms.
        let origin = Point::new(-forward as f32, -left as f32);
        let (mut sin_beam, mut cos_beam) = (first as f64 * beam_step).sin_cos();
        let (sin_step, cos_step) = beam_step.sin_cos();
        for k in first..=last {
            let ray = Ray::new(origin, Vector::new(cos_beam as f32, sin_beam as f32));
            if let Some(range) = body.cast_local_ray(&ray, max_range as f32, true) {
                // The window spans at most half the ring plus margins, so no beam is visited twice.
                let slot = &mut out[k.rem_euclid(beams as i64) as usize];
                *slot = slot.min(range);
            }
            // Rotate the beam direction by one step (exact to ~1e-15 over a window's few hundred).
            (sin_beam, cos_beam) = (
                sin_beam * cos_step + cos_beam * sin_step,
                cos_beam * cos_step - sin_beam * sin_step,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn lidar() -> LidarSpec {
        LidarSpec {
            beams: 900,
            max_range: 10.0,
            noise_std: 0.0,
        }
    }

    fn scan(poses: &[Pose], own: usize) -> Vec<f32> {
        let lidar = lidar();
        let mut out = vec![f32::NAN; lidar.beams];
        cast_scan(poses, own, &RobotParams::default(), &lidar, &mut out);
        out
    }

    /// Exact range along body bearing `beam_angle` from a sensor to a disc of radius `r` at body-frame
    /// `(fx, fy)`, by the closed-form ray-circle intersection.
    fn closed_form_range(beam_angle: f64, fx: f64, fy: f64, r: f64) -> Option<f64> {
        let (dy, dx) = beam_angle.sin_cos();
        let along = dx * fx + dy * fy;
        let across2 = fx * fx + fy * fy - along * along;
        (along > 0.0 && across2 <= r * r).then(|| along - (r * r - across2).sqrt())
    }

    #[test]
    fn a_body_straight_ahead_is_hit_by_beam_zero_at_its_surface() {
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 3.0,
                y: 0.0,
                theta: 1.0,
            },
        ];
        let ranges = scan(&poses, 0);
        assert!(
            (ranges[0] - 2.75).abs() < 1e-4,
            "beam 0 reads {}",
            ranges[0]
        );
        // The body subtends asin(0.25 / 3) = 4.78 deg on each side: 11 beams of 0.4 deg each way.
        let per_side = ((0.25_f64 / 3.0).asin() / (TAU / 900.0)).floor() as usize;
        let hits: Vec<usize> = (0..900).filter(|&k| ranges[k] < 10.0).collect();
        assert_eq!(hits.len(), 2 * per_side + 1, "beams hit: {hits:?}");
        for (k, &range) in ranges.iter().enumerate().take(880).skip(20) {
            assert_eq!(
                range, 10.0,
                "beam {k} far from the body must read max_range"
            );
        }
    }

    #[test]
    fn the_hit_beam_follows_the_sensor_heading() {
        // Body to the world's +y, sensor heading +x rotated by 30 deg: the body is at body bearing
        // 60 deg, which is beam 150.
        let poses = [
            Pose {
                x: 1.0,
                y: 1.0,
                theta: PI / 6.0,
            },
            Pose {
                x: 1.0,
                y: 5.0,
                theta: 0.0,
            },
        ];
        let ranges = scan(&poses, 0);
        assert!(
            (ranges[150] - 3.75).abs() < 1e-4,
            "beam 150 reads {}",
            ranges[150]
        );
        assert_eq!(ranges[0], 10.0);
        assert_eq!(ranges[375], 10.0);
        // The observed robot sees the sensor robot at world bearing -90 deg, i.e. body beam 675.
        let back = scan(&poses, 1);
        assert!(
            (back[675] - 3.75).abs() < 1e-4,
            "beam 675 reads {}",
            back[675]
        );
    }

    #[test]
    fn every_beam_matches_closed_form_ray_circle_ranges() {
        let poses = [
            Pose {
                x: 20.0,
                y: -7.0,
                theta: -2.0,
            },
            Pose {
                x: 21.1,
                y: -6.2,
                theta: 0.0,
            },
            Pose {
                x: 17.5,
                y: -8.0,
                theta: 0.0,
            },
            Pose {
                x: 22.0,
                y: -11.0,
                theta: 0.0,
            },
            Pose {
                x: 29.0,
                y: -7.0,
                theta: 0.0,
            },
            Pose {
                x: 40.0,
                y: -7.0,
                theta: 0.0,
            },
        ];
        let ranges = scan(&poses, 0);
        let sensor = poses[0];
        let (s, c) = sensor.theta.sin_cos();
        for (k, &range) in ranges.iter().enumerate() {
            let angle = TAU * k as f64 / 900.0;
            let expected = poses[1..]
                .iter()
                .filter_map(|p| {
                    let (dx, dy) = (p.x - sensor.x, p.y - sensor.y);
                    closed_form_range(angle, c * dx + s * dy, -s * dx + c * dy, 0.25)
                })
                .filter(|&r| r <= 10.0)
                .fold(10.0_f64, f64::min);
            assert!(
                (range as f64 - expected).abs() < 1e-4,
                "beam {k}: {range} vs {expected}"
            );
        }
        // Four bodies are within range; their windows must add up to many hit beams.
        assert!(ranges.iter().filter(|&&r| r < 10.0).count() > 100);
    }

    #[test]
    fn a_nearer_body_occludes_a_farther_one_on_the_same_bearing() {
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 5.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 2.0,
                y: 0.0,
                theta: 0.0,
            },
        ];
        let ranges = scan(&poses, 0);
        assert!(
            (ranges[0] - 1.75).abs() < 1e-4,
            "beam 0 reads {}",
            ranges[0]
        );
    }

    #[test]
    fn a_lone_robot_reads_max_range_everywhere() {
        let ranges = scan(
            &[Pose {
                x: 1.0,
                y: 2.0,
                theta: 0.3,
            }],
            0,
        );
        assert!(ranges.iter().all(|&r| r == 10.0));
    }

    #[test]
    fn bodies_beyond_max_range_are_not_seen() {
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 10.3,
                y: 0.0,
                theta: 0.0,
            },
        ];
        assert!(scan(&poses, 0).iter().all(|&r| r == 10.0));
        let near_limit = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 10.2,
                y: 0.0,
                theta: 0.0,
            },
        ];
        let ranges = scan(&near_limit, 0);
        assert!(
            (ranges[0] - 9.95).abs() < 1e-4,
            "beam 0 reads {}",
            ranges[0]
        );
    }

    #[test]
    fn a_sensor_inside_another_body_reads_zero() {
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 0.1,
                y: 0.0,
                theta: 0.0,
            },
        ];
        assert!(scan(&poses, 0).iter().all(|&r| r == 0.0));
    }

    #[test]
    fn a_body_across_the_beam_zero_seam_hits_beams_on_both_sides() {
        // Slightly below the +x axis: bearing about -1 deg, so the window wraps past beam 0.
        let poses = [
            Pose {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            Pose {
                x: 2.0,
                y: -0.035,
                theta: 0.0,
            },
        ];
        let ranges = scan(&poses, 0);
        assert!(ranges[0] < 10.0 && ranges[3] < 10.0 && ranges[899] < 10.0 && ranges[890] < 10.0);
        assert!(ranges[100..800].iter().all(|&r| r == 10.0));
    }
}
