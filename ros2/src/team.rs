//! The messages a simulated team of robots publishes, built once for every place that publishes
//! them: the ROS 2 world's live topics (`formation-runtime`) and a recording of a run
//! (`formation-record`), so that a viewer sees the same frames, stamps and values in both.
//!
//! Each robot `i` has the frames `robot_<i>/odom`, `robot_<i>/base_link` and `robot_<i>/laser`
//! under one fixed frame [`WORLD_FRAME`], and the topics of the multi-robot convention
//! (`/robot_<i>/scan`, `/robot_<i>/odom`, `/robot_<i>/cmd_vel`); the team shares `/tf`,
//! `/tf_static` and the goal topics. The functions take plain numbers (this crate depends on no
//! other crate of the workspace): a pose is `x`, `y` \[m\] and a heading \[rad\].

use crate::convert::{quaternion_from_yaw, twist_from_wheels};
use crate::msg::{
    Header, LaserScan, Odometry, Pose, TfMessage, Time, Transform, TransformStamped, Twist, Vector3,
};

/// The fixed frame every robot is placed in on `/tf`.
pub const WORLD_FRAME: &str = "world";

/// The team's goal topics: the heading φ* \[rad\], the distance d* \[m\] and the speed v* \[m/s\],
/// each a `std_msgs/msg/Float64`.
pub const GOAL_TOPICS: [&str; 3] = [
    "/formation/goal/heading",
    "/formation/goal/distance",
    "/formation/goal/speed",
];

/// Robot `robot`'s frame `name` (`odom`, `base_link`, `laser`): `robot_<i>/<name>`.
pub fn robot_frame(robot: usize, name: &str) -> String {
    format!("robot_{robot}/{name}")
}

/// Robot `robot`'s topic `name` (`scan`, `odom`, `cmd_vel`): `/robot_<i>/<name>`.
pub fn robot_topic(robot: usize, name: &str) -> String {
    format!("/robot_{robot}/{name}")
}

/// One TF edge at `stamp`: `child` at `(x, y)` with heading `yaw` in `parent`.
pub fn transform(
    stamp: Time,
    parent: &str,
    child: String,
    x: f64,
    y: f64,
    yaw: f64,
) -> TransformStamped {
    TransformStamped {
        header: Header {
            stamp,
            frame_id: parent.to_owned(),
        },
        child_frame_id: child,
        transform: Transform {
            translation: Vector3 { x, y, z: 0.0 },
            rotation: quaternion_from_yaw(yaw),
        },
    }
}

/// Robot `robot`'s `/tf` at `stamp`: `world` → `robot_<i>/base_link`, its true pose (the
/// simulation's ground truth, for viewers; what the robot itself senses is in its scan and
/// odometry).
pub fn tf_message(robot: usize, stamp: Time, x: f64, y: f64, yaw: f64) -> TfMessage {
    TfMessage {
        transforms: vec![transform(
            stamp,
            WORLD_FRAME,
            robot_frame(robot, "base_link"),
            x,
            y,
            yaw,
        )],
    }
}

/// Robot `robot`'s `/tf_static`: `world` → `robot_<i>/odom` (the simulated odometry is the true
/// pose, so its frame is the world's) and `robot_<i>/base_link` → `robot_<i>/laser` (the LIDAR
/// sits on the axle centre, the origin of its rays).
pub fn static_tf_message(robot: usize, stamp: Time) -> TfMessage {
    TfMessage {
        transforms: vec![
            transform(
                stamp,
                WORLD_FRAME,
                robot_frame(robot, "odom"),
                0.0,
                0.0,
                0.0,
            ),
            transform(
                stamp,
                &robot_frame(robot, "base_link"),
                robot_frame(robot, "laser"),
                0.0,
                0.0,
                0.0,
            ),
        ],
    }
}

/// Wheel rim speeds \[m/s\] and the base they turn: what odometry and `cmd_vel` carry as a Twist.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wheels {
    /// Left wheel rim speed \[m/s\].
    pub left: f64,
    /// Right wheel rim speed \[m/s\].
    pub right: f64,
    /// Distance between the wheels \[m\].
    pub separation: f64,
}

impl Wheels {
    /// The Twist of these wheel speeds, or a zero Twist for speeds that are not finite (never
    /// the world's) rather than no message.
    pub fn twist(&self) -> Twist {
        twist_from_wheels(self.left, self.right, self.separation).unwrap_or_default()
    }
}

/// Robot `robot`'s Odometry at `stamp`: its position, `heading` as the orientation (what its
/// compass reads), and the twist of the wheel speeds it ran over the last step, as wheel encoders
/// give it.
pub fn odometry_message(
    robot: usize,
    stamp: Time,
    (x, y): (f64, f64),
    heading: f64,
    wheels: Wheels,
) -> Odometry {
    Odometry {
        header: Header {
            stamp,
            frame_id: robot_frame(robot, "odom"),
        },
        child_frame_id: robot_frame(robot, "base_link"),
        pose: Pose {
            position: Vector3 { x, y, z: 0.0 },
            orientation: quaternion_from_yaw(heading),
        },
        twist: wheels.twist(),
        ..Odometry::default()
    }
}

/// Robot `robot`'s LaserScan at `stamp` from its ring of `ranges` (beam `k` at bearing
/// `2π k / n` counter-clockwise from +x, `max_range` where nothing was hit): in `robot_<i>/laser`,
/// a beam without a return as +inf (REP-117).
pub fn laser_scan_message(robot: usize, stamp: Time, ranges: &[f32], max_range: f64) -> LaserScan {
    let beams = ranges.len();
    let max_range = max_range as f32;
    let increment = (std::f64::consts::TAU / beams.max(1) as f64) as f32;
    LaserScan {
        header: Header {
            stamp,
            frame_id: robot_frame(robot, "laser"),
        },
        angle_min: 0.0,
        angle_max: increment * beams.saturating_sub(1) as f32,
        angle_increment: increment,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: 0.0,
        range_max: max_range,
        ranges: ranges
            .iter()
            .map(|&r| if r >= max_range { f32::INFINITY } else { r })
            .collect(),
        intensities: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::yaw_from_quaternion;

    #[test]
    fn frames_and_topics_follow_the_multi_robot_convention() {
        assert_eq!(robot_frame(3, "base_link"), "robot_3/base_link");
        assert_eq!(robot_topic(12, "cmd_vel"), "/robot_12/cmd_vel");
        let tf = tf_message(2, Time::default(), 1.5, -0.5, 0.25);
        let edge = &tf.transforms[0];
        assert_eq!(edge.header.frame_id, WORLD_FRAME);
        assert_eq!(edge.child_frame_id, "robot_2/base_link");
        assert_eq!(edge.transform.translation.x, 1.5);
        assert!((yaw_from_quaternion(&edge.transform.rotation).unwrap() - 0.25).abs() < 1e-15);
    }

    #[test]
    fn a_scan_reports_no_return_as_infinity_and_spans_the_ring() {
        let scan = laser_scan_message(0, Time::default(), &[1.0, 5.0, 2.0, 5.0], 5.0);
        assert_eq!(scan.ranges, [1.0, f32::INFINITY, 2.0, f32::INFINITY]);
        assert_eq!(scan.header.frame_id, "robot_0/laser");
        assert!((scan.angle_increment - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert!((scan.angle_max - 3.0 * std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    }

    #[test]
    fn odometry_carries_the_wheels_twist_and_a_zero_twist_for_bad_speeds() {
        let wheels = Wheels {
            left: 0.2,
            right: 0.4,
            separation: 0.2,
        };
        let odom = odometry_message(1, Time::default(), (1.0, 2.0), 0.5, wheels);
        assert!((odom.twist.linear.x - 0.3).abs() < 1e-12);
        assert!((odom.twist.angular.z - 1.0).abs() < 1e-12);
        let bad = Wheels {
            left: f64::NAN,
            ..wheels
        };
        assert_eq!(bad.twist(), Twist::default());
    }
}
