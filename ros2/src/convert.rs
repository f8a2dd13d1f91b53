//! Conversions between ROS messages and the agent's contract: a real LaserScan resampled onto the
//! model's LIDAR ring, the heading from an Imu or Odometry quaternion, and a Twist from wheel speeds.
//!
//! The model's sensor contract (`formation_proto::LidarSpec`, `formation_perception::occupancy`): `beams`
//! ranges, beam `k` at bearing `2 pi k / beams` counter-clockwise from the robot's +x axis, and a
//! beam that hits nothing reports exactly the maximum range (the renderer draws only ranges in
//! `[0, max_range)`). A resampled scan keeps that contract: each model beam takes the reading
//! whose angular sector (the reading's angle ± half an increment) contains the beam's bearing;
//! readings outside `[range_min, range_max]`, NaN and ±inf (as REP-117 and ROS drivers use them)
//! become "no return", written as the model's maximum range, and hits beyond the model's range are
//! clamped to it, as the simulated LIDAR cannot see past it either.
//!
//! The scan is assumed to lie in the robot's body frame (the laser mounted at the axle centre,
//! facing forward); a mounting offset is the caller's to correct through the scan's angles.

use std::f64::consts::{PI, TAU};

use thiserror::Error;

use crate::msg::{Imu, LaserScan, Odometry, Quaternion, Twist, Vector3};

/// What to do with model bearings the scan does not cover.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartialScan {
    /// Refuse the scan ([`ScanError::PartialCircle`]): the model was trained on a full ring.
    Refuse,
    /// Treat uncovered bearings as no return (the caller should warn once).
    AllowAsNoReturn,
}

/// The model's LIDAR ring, as plain numbers (`formation_proto::LidarSpec` without the noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RingContract {
    /// Beams evenly spread over 360°, beam 0 along +x, counter-clockwise.
    pub beams: usize,
    /// Maximum range \[m\]; a beam with no return reports exactly this.
    pub max_range: f64,
}

/// A scan on the model's ring.
#[derive(Debug, Clone, PartialEq)]
pub struct ResampledScan {
    /// One range per model beam \[m\].
    pub ranges: Vec<f32>,
    /// Model beams that the scan does not cover (set to no return).
    pub uncovered_beams: usize,
    /// Model beams whose reading was invalid (NaN, inf, outside the scan's limits).
    pub invalid_readings: usize,
}

/// Why a scan cannot be put on the model's ring.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ScanError {
    /// The model contract itself is unusable.
    #[error(
        "the model's LIDAR contract needs at least one beam and a positive finite maximum range, got {beams} beams and {max_range} m"
    )]
    BadContract {
        /// Beams.
        beams: usize,
        /// Maximum range.
        max_range: f64,
    },
    /// The scan has no readings.
    #[error("the LaserScan has no ranges")]
    Empty,
    /// The scan's angles are unusable.
    #[error(
        "the LaserScan's angle_min ({angle_min}) and angle_increment ({angle_increment}) must be finite and the increment non-zero"
    )]
    BadAngles {
        /// `angle_min`.
        angle_min: f32,
        /// `angle_increment`.
        angle_increment: f32,
    },
    /// The scan's range limits are unusable.
    #[error(
        "the LaserScan's range limits [{range_min}, {range_max}] are not a range of non-negative numbers"
    )]
    BadRangeLimits {
        /// `range_min`.
        range_min: f32,
        /// `range_max`.
        range_max: f32,
    },
    /// The scan leaves some of the model's bearings uncovered.
    #[error(
        "the LaserScan covers {covered_deg:.1}° ({readings} readings from {angle_min_deg:.1}° every {increment_deg:.3}°) but the model needs the full 360°: {beams} beams, beam k at 360·k/{beams}° counter-clockwise from the robot's +x axis; {uncovered_beams} of them have no reading (allow a partial scan to treat those as no return)"
    )]
    PartialCircle {
        /// Angular span the readings cover \[deg\].
        covered_deg: f64,
        /// Readings in the scan.
        readings: usize,
        /// `angle_min` \[deg\].
        angle_min_deg: f64,
        /// `angle_increment` \[deg\].
        increment_deg: f64,
        /// The model's beams.
        beams: usize,
        /// Model beams without a reading.
        uncovered_beams: usize,
    },
}

/// Puts a LaserScan on the model's ring. See the module documentation for the rules.
pub fn resample_scan(
    scan: &LaserScan,
    contract: RingContract,
    partial: PartialScan,
) -> Result<ResampledScan, ScanError> {
    let RingContract { beams, max_range } = contract;
    if beams == 0 || !(max_range.is_finite() && max_range > 0.0) {
        return Err(ScanError::BadContract { beams, max_range });
    }
    if scan.ranges.is_empty() {
        return Err(ScanError::Empty);
    }
    let increment = f64::from(scan.angle_increment);
    let angle_min = f64::from(scan.angle_min);
    if !(angle_min.is_finite() && increment.is_finite() && increment != 0.0) {
        return Err(ScanError::BadAngles {
            angle_min: scan.angle_min,
            angle_increment: scan.angle_increment,
        });
    }
    let (range_min, range_max) = (scan.range_min, scan.range_max);
    // Written so that NaN limits fail too; range_max may be +inf.
    if !(range_min >= 0.0 && range_max >= range_min) {
        return Err(ScanError::BadRangeLimits {
            range_min,
            range_max,
        });
    }

    let readings = scan.ranges.len();
    let step = increment.abs();
    // A bearing lies in reading i's sector if within half a step of its angle; the tolerance
    // absorbs float32 rounding of the scan's angles.
    let half_sector = 0.5 * step * (1.0 + 1e-3) + 1e-6;
    let no_return = max_range as f32;
    let mut ranges = Vec::with_capacity(beams);
    let mut uncovered_beams = 0;
    let mut invalid_readings = 0;
    for k in 0..beams {
        let bearing = TAU * k as f64 / beams as f64;
        // Angle from the first reading towards the scan's direction, in [0, 2 pi).
        let along = if increment > 0.0 {
            (bearing - angle_min).rem_euclid(TAU)
        } else {
            (angle_min - bearing).rem_euclid(TAU)
        };
        let index = nearest_reading(along, step, half_sector, readings);
        let Some(index) = index else {
            uncovered_beams += 1;
            ranges.push(no_return);
            continue;
        };
        let reading = scan.ranges[index];
        if reading.is_finite() && reading >= range_min && reading <= range_max {
            ranges.push(reading.min(no_return));
        } else {
            invalid_readings += 1;
            ranges.push(no_return);
        }
    }
    if uncovered_beams > 0 && partial == PartialScan::Refuse {
        return Err(ScanError::PartialCircle {
            covered_deg: (step * readings as f64).min(TAU).to_degrees(),
            readings,
            angle_min_deg: angle_min.to_degrees(),
            increment_deg: increment.to_degrees(),
            beams,
            uncovered_beams,
        });
    }
    Ok(ResampledScan {
        ranges,
        uncovered_beams,
        invalid_readings,
    })
}

/// The reading whose sector holds the angle `along` (in `[0, 2 pi)` from the first reading), if
/// any; the angle is also tried one turn back, for a bearing just before the first reading.
fn nearest_reading(along: f64, step: f64, half_sector: f64, readings: usize) -> Option<usize> {
    [along, along - TAU].into_iter().find_map(|angle| {
        let position = (angle / step).round();
        if position < 0.0 || position >= readings as f64 {
            return None;
        }
        ((angle - position * step).abs() <= half_sector).then_some(position as usize)
    })
}

/// Why a heading cannot be read from an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum OrientationError {
    /// A component is NaN or infinite.
    #[error("the orientation quaternion ({x}, {y}, {z}, {w}) is not finite")]
    NotFinite {
        /// x.
        x: f64,
        /// y.
        y: f64,
        /// z.
        z: f64,
        /// w.
        w: f64,
    },
    /// The quaternion is (nearly) zero, or rotates the x axis onto the vertical.
    #[error(
        "the orientation quaternion ({x}, {y}, {z}, {w}) defines no heading (zero, or x axis vertical)"
    )]
    NoHeading {
        /// x.
        x: f64,
        /// y.
        y: f64,
        /// z.
        z: f64,
        /// w.
        w: f64,
    },
    /// The Imu says it has no orientation estimate (`orientation_covariance[0] == -1`).
    #[error(
        "the Imu publishes no orientation (orientation_covariance[0] is -1); use an IMU with an orientation filter or an Odometry topic"
    )]
    ImuWithoutOrientation,
}

/// The heading (yaw) of a quaternion \[rad\], counter-clockwise from +x, in (-pi, pi].
///
/// `atan2(2(wz + xy), w² + x² − y² − z²)`: the z-y-x Euler yaw, which needs no normalisation
/// because both arguments scale with the squared norm.
pub fn yaw_from_quaternion(q: &Quaternion) -> Result<f64, OrientationError> {
    let Quaternion { x, y, z, w } = *q;
    if ![x, y, z, w].iter().all(|c| c.is_finite()) {
        return Err(OrientationError::NotFinite { x, y, z, w });
    }
    let sin_term = 2.0 * (w * z + x * y);
    let cos_term = w * w + x * x - y * y - z * z;
    let norm_sq = w * w + x * x + y * y + z * z;
    if sin_term.hypot(cos_term) <= 1e-9 * norm_sq.max(f64::MIN_POSITIVE) || norm_sq < 1e-12 {
        return Err(OrientationError::NoHeading { x, y, z, w });
    }
    let yaw = sin_term.atan2(cos_term);
    Ok(if yaw <= -PI { yaw + TAU } else { yaw })
}

impl Imu {
    /// The heading of the Imu's orientation, refusing an Imu without one.
    pub fn yaw(&self) -> Result<f64, OrientationError> {
        if self.orientation_covariance[0] == -1.0 {
            return Err(OrientationError::ImuWithoutOrientation);
        }
        yaw_from_quaternion(&self.orientation)
    }
}

impl Odometry {
    /// The heading of the odometry pose.
    pub fn yaw(&self) -> Result<f64, OrientationError> {
        yaw_from_quaternion(&self.pose.orientation)
    }
}

/// Why wheel speeds cannot become a Twist.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum TwistError {
    /// The wheel separation is not a positive finite length.
    #[error("wheel separation must be a positive finite length, got {0} m")]
    BadWheelSeparation(f64),
    /// A wheel speed is NaN or infinite.
    #[error("wheel speeds must be finite, got left {left} m/s and right {right} m/s")]
    NotFinite {
        /// Left wheel speed.
        left: f64,
        /// Right wheel speed.
        right: f64,
    },
}

/// The Twist of a differential-drive base from its wheel rim speeds \[m/s\]:
/// `linear.x = (right + left) / 2`, `angular.z = (right − left) / wheel_separation`.
pub fn twist_from_wheels(
    left: f64,
    right: f64,
    wheel_separation: f64,
) -> Result<Twist, TwistError> {
    if !(wheel_separation.is_finite() && wheel_separation > 0.0) {
        return Err(TwistError::BadWheelSeparation(wheel_separation));
    }
    if !(left.is_finite() && right.is_finite()) {
        return Err(TwistError::NotFinite { left, right });
    }
    Ok(Twist {
        linear: Vector3 {
            x: (right + left) / 2.0,
            ..Vector3::default()
        },
        angular: Vector3 {
            z: (right - left) / wheel_separation,
            ..Vector3::default()
        },
    })
}

/// The wheel rim speeds \[m/s\] a differential-drive base runs for a Twist, as
/// ros2_controllers' `diff_drive_controller` computes them: `left = linear.x − angular.z · l / 2`,
/// `right = linear.x + angular.z · l / 2`. The other components (a diff-drive base cannot move
/// sideways or roll) are ignored. The inverse of [`twist_from_wheels`] up to rounding.
pub fn wheels_from_twist(twist: &Twist, wheel_separation: f64) -> (f64, f64) {
    let half_turn = twist.angular.z * wheel_separation / 2.0;
    (twist.linear.x - half_turn, twist.linear.x + half_turn)
}

/// The orientation of a heading `yaw` \[rad\] about +z: `(0, 0, sin(yaw / 2), cos(yaw / 2))`.
pub fn quaternion_from_yaw(yaw: f64) -> Quaternion {
    let (sin, cos) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: sin,
        w: cos,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONTRACT: RingContract = RingContract {
        beams: 8,
        max_range: 10.0,
    };

    /// A full-circle scan of `n` readings starting at `angle_min`, reading i = `range(i)`.
    fn scan(n: usize, angle_min: f32, range: impl Fn(usize) -> f32) -> LaserScan {
        let increment = (TAU / n as f64) as f32;
        LaserScan {
            angle_min,
            angle_max: angle_min + increment * (n - 1) as f32,
            angle_increment: increment,
            range_min: 0.1,
            range_max: 30.0,
            ranges: (0..n).map(range).collect(),
            ..LaserScan::default()
        }
    }

    #[test]
    fn a_matching_scan_passes_through_beam_for_beam() {
        let s = scan(8, 0.0, |i| 1.0 + i as f32);
        let out = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap();
        assert_eq!(out.ranges, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert_eq!((out.uncovered_beams, out.invalid_readings), (0, 0));
    }

    #[test]
    fn a_scan_from_minus_pi_is_rotated_onto_the_ring() {
        // Reading i at -pi + i*pi/4: model beam k (bearing k*pi/4) is reading (k + 4) % 8.
        let s = scan(8, -std::f32::consts::PI, |i| i as f32 + 1.0);
        let out = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap();
        assert_eq!(out.ranges, vec![5.0, 6.0, 7.0, 8.0, 1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn a_clockwise_scan_is_mirrored() {
        let mut s = scan(8, 0.0, |i| i as f32 + 1.0);
        s.angle_increment = -s.angle_increment;
        let out = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap();
        // Bearing k*pi/4 counter-clockwise is reading (8 - k) % 8 of a clockwise scan.
        assert_eq!(out.ranges, vec![1.0, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0]);
    }

    #[test]
    fn a_denser_scan_takes_the_reading_at_each_bearing() {
        let s = scan(720, 0.0, |i| (i % 360) as f32 / 100.0 + 0.5);
        let out = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap();
        for (k, &r) in out.ranges.iter().enumerate() {
            assert_eq!(r, ((k * 90) % 360) as f32 / 100.0 + 0.5, "beam {k}");
        }
    }

    #[test]
    fn invalid_readings_become_the_models_max_range() {
        let values = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.05,
            31.0,
            2.0,
            12.0,
            0.1,
        ];
        let s = scan(8, 0.0, |i| values[i]);
        let out = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap();
        // NaN, +inf, -inf, below range_min, above range_max: no return; 12 m clamps to 10 m;
        // exactly range_min is valid.
        assert_eq!(
            out.ranges,
            vec![10.0, 10.0, 10.0, 10.0, 10.0, 2.0, 10.0, 0.1]
        );
        assert_eq!(out.invalid_readings, 5);
    }

    #[test]
    fn a_partial_scan_is_refused_saying_what_the_model_needs() {
        // 270° from -135°, like a Hokuyo: bearings 135°..225° (beams 3..=5 of 8) are missing.
        let n = 271;
        let increment = (270f64.to_radians() / (n - 1) as f64) as f32;
        let s = LaserScan {
            angle_min: (-135f64).to_radians() as f32,
            angle_increment: increment,
            range_min: 0.1,
            range_max: 30.0,
            ranges: vec![1.0; n],
            ..LaserScan::default()
        };
        let err = resample_scan(&s, CONTRACT, PartialScan::Refuse).unwrap_err();
        assert!(
            matches!(
                err,
                ScanError::PartialCircle {
                    uncovered_beams: 1,
                    beams: 8,
                    ..
                }
            ),
            "{err:?}"
        );
        let message = err.to_string();
        assert!(message.contains("full 360°"), "{message}");
        assert!(message.contains("allow a partial scan"), "{message}");
        assert!(
            message.contains("counter-clockwise from the robot's +x axis"),
            "{message}"
        );

        let out = resample_scan(&s, CONTRACT, PartialScan::AllowAsNoReturn).unwrap();
        assert_eq!(out.uncovered_beams, 1);
        assert_eq!(out.ranges[4], 10.0, "the beam at 180° has no reading");
        assert_eq!(
            out.ranges[3], 1.0,
            "the beam at 135° is the scan's last reading"
        );
    }

    #[test]
    fn unusable_scans_and_contracts_are_typed_errors() {
        let good = scan(8, 0.0, |_| 1.0);
        let refusal = |scan: LaserScan| resample_scan(&scan, CONTRACT, PartialScan::Refuse);
        let empty = LaserScan {
            ranges: vec![],
            ..good.clone()
        };
        assert_eq!(refusal(empty), Err(ScanError::Empty));
        let no_increment = LaserScan {
            angle_increment: 0.0,
            ..good.clone()
        };
        assert!(matches!(
            refusal(no_increment),
            Err(ScanError::BadAngles { .. })
        ));
        let nan_range = LaserScan {
            range_max: f32::NAN,
            ..good.clone()
        };
        assert!(matches!(
            refusal(nan_range),
            Err(ScanError::BadRangeLimits { .. })
        ));
        assert!(matches!(
            resample_scan(
                &good,
                RingContract {
                    beams: 0,
                    max_range: 10.0
                },
                PartialScan::Refuse
            ),
            Err(ScanError::BadContract { .. })
        ));
    }

    fn yaw_quaternion(yaw: f64) -> Quaternion {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: (yaw / 2.0).sin(),
            w: (yaw / 2.0).cos(),
        }
    }

    #[test]
    fn yaw_is_recovered_from_quaternions() {
        for yaw in [0.0, 0.5, -1.0, 3.0, -3.0, PI] {
            let got = yaw_from_quaternion(&yaw_quaternion(yaw)).unwrap();
            assert!((got - yaw).abs() < 1e-12, "{yaw} -> {got}");
        }
        // -pi wraps to pi, as formation_proto::wrap_angle does.
        assert!((yaw_from_quaternion(&yaw_quaternion(-PI)).unwrap() - PI).abs() < 1e-12);
        // Unnormalised quaternions give the same yaw.
        let mut q = yaw_quaternion(1.2);
        q.z *= 3.0;
        q.w *= 3.0;
        assert!((yaw_from_quaternion(&q).unwrap() - 1.2).abs() < 1e-12);
        // A small roll does not disturb the heading of a level-ish robot much.
        let rolled = Quaternion {
            x: 0.05,
            ..yaw_quaternion(0.7)
        };
        assert!((yaw_from_quaternion(&rolled).unwrap() - 0.7).abs() < 0.01);
    }

    #[test]
    fn bad_orientations_are_refused() {
        let zero = Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        assert!(matches!(
            yaw_from_quaternion(&zero),
            Err(OrientationError::NoHeading { .. })
        ));
        let nan = Quaternion {
            w: f64::NAN,
            ..Quaternion::default()
        };
        assert!(matches!(
            yaw_from_quaternion(&nan),
            Err(OrientationError::NotFinite { .. })
        ));
        let mut imu = Imu {
            orientation: yaw_quaternion(0.3),
            ..Imu::default()
        };
        assert!((imu.yaw().unwrap() - 0.3).abs() < 1e-12);
        imu.orientation_covariance[0] = -1.0;
        assert_eq!(imu.yaw(), Err(OrientationError::ImuWithoutOrientation));
        let mut odom = Odometry::default();
        odom.pose.orientation = yaw_quaternion(-2.0);
        assert!((odom.yaw().unwrap() + 2.0).abs() < 1e-12);
    }

    #[test]
    fn twist_follows_differential_drive_kinematics() {
        let t = twist_from_wheels(0.2, 0.4, 0.5).unwrap();
        assert!((t.linear.x - 0.3).abs() < 1e-15);
        assert!((t.angular.z - 0.4).abs() < 1e-15);
        assert_eq!(
            (t.linear.y, t.linear.z, t.angular.x, t.angular.y),
            (0.0, 0.0, 0.0, 0.0)
        );
        let spin = twist_from_wheels(-0.1, 0.1, 0.2).unwrap();
        assert_eq!((spin.linear.x, spin.angular.z), (0.0, 1.0));
        assert_eq!(twist_from_wheels(0.0, 0.0, 0.3).unwrap(), Twist::default());
        assert!(matches!(
            twist_from_wheels(f64::NAN, 0.0, 0.3),
            Err(TwistError::NotFinite { .. })
        ));
        assert_eq!(
            twist_from_wheels(0.1, 0.1, 0.0),
            Err(TwistError::BadWheelSeparation(0.0))
        );
    }

    #[test]
    fn wheels_and_twists_round_trip_and_yaw_survives_a_quaternion() {
        let l = 0.331;
        for (left, right) in [(0.3, 0.5), (-0.2, 0.2), (0.7, 0.7), (0.0, -0.9)] {
            let twist = twist_from_wheels(left, right, l).unwrap();
            let (l2, r2) = wheels_from_twist(&twist, l);
            assert!((l2 - left).abs() < 1e-12 && (r2 - right).abs() < 1e-12);
        }
        for yaw in [0.0, 1.0, -2.5, PI - 1e-9, -PI + 1e-9] {
            let back = yaw_from_quaternion(&quaternion_from_yaw(yaw)).unwrap();
            assert!((back - yaw).abs() < 1e-12, "{yaw} -> {back}");
        }
    }
}
