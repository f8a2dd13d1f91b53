//! The ROS 2 messages the agent exchanges, with their CDR layout, DDS type names and Jazzy hashes.
//!
//! Each message implements [`RosMessage`]: its ROS name (`geometry_msgs/msg/Twist`), the DDS type
//! name rmw_zenoh puts in key expressions (`geometry_msgs::msg::dds_::Twist_`, built by
//! `_create_type_name` in rmw_zenoh's `type_support_common.cpp` as namespace + `::dds_::` + name +
//! `_`), its RIHS01 type hash in ROS 2 Jazzy, and its encoding and bounded decoding. Fields are
//! written in declaration order, nested messages inline, exactly as the `.msg` files declare them.
//! The byte layouts and hashes are checked against `rosbags` in `tests/wire_format.rs`.

use crate::cdr::{CdrEncodeError, CdrError, CdrReader, CdrWriter, DecodeLimits};
use crate::schema::{self, MsgDefinition};
use crate::type_hash::TypeHash;

/// A ROS 2 message with a fixed CDR layout.
pub trait RosMessage: Sized {
    /// The ROS interface name, `package/msg/Name`.
    const ROS_NAME: &'static str;
    /// The DDS type name rmw_zenoh uses in key expressions, `package::msg::dds_::Name_`.
    const DDS_TYPE_NAME: &'static str;
    /// The RIHS01 type hash of this message in ROS 2 Jazzy (and later, while it is unchanged).
    const TYPE_HASH: &'static str;
    /// Its `.msg` definition, whose [`MsgDefinition::ros2msg`] is the schema a recording stores.
    const DEFINITION: &'static MsgDefinition;

    /// Writes the fields (after the encapsulation header).
    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError>;

    /// Reads the fields (after the encapsulation header).
    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;

    /// The whole CDR payload: encapsulation header and fields.
    fn to_cdr(&self) -> Result<Vec<u8>, CdrEncodeError> {
        let mut w = CdrWriter::new();
        self.write_fields(&mut w)?;
        Ok(w.into_bytes())
    }

    /// Decodes a whole CDR payload with the default [`DecodeLimits`].
    fn from_cdr(payload: &[u8]) -> Result<Self, CdrError> {
        Self::from_cdr_with_limits(payload, DecodeLimits::default())
    }

    /// Decodes a whole CDR payload with explicit limits.
    fn from_cdr_with_limits(payload: &[u8], limits: DecodeLimits) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(payload, limits)?;
        Self::read_fields(&mut r)
    }

    /// [`RosMessage::TYPE_HASH`] parsed at compile time (a malformed constant does not build).
    const TYPE_HASH_BYTES: TypeHash = TypeHash::from_constant(Self::TYPE_HASH);

    /// The parsed [`RosMessage::TYPE_HASH`].
    fn type_hash() -> TypeHash {
        Self::TYPE_HASH_BYTES
    }
}

/// A [`RosMessage`]'s names, definition and hash, inside its `impl` as
/// `message_identity! { "package" / "Name", &DEFINITION, "RIHS01_..." }`: its ROS name
/// `package/msg/Name` and the DDS type name rmw_zenoh builds from the same two parts
/// (`_create_type_name`: namespace + `::dds_::` + name + `_`), so the two cannot disagree.
macro_rules! message_identity {
    ($package:literal / $name:literal, $definition:expr, $type_hash:literal) => {
        const ROS_NAME: &'static str = concat!($package, "/msg/", $name);
        const DEFINITION: &'static MsgDefinition = $definition;
        const DDS_TYPE_NAME: &'static str = concat!($package, "::msg::dds_::", $name, "_");
        const TYPE_HASH: &'static str = $type_hash;
    };
}
pub(crate) use message_identity;

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second, `0..1_000_000_000`.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch, saturating at the `i32` seconds range.
    pub fn from_nanos(ns: i64) -> Time {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Time { sec, nanosec },
            Err(_) if sec < 0 => Time {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Time {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    /// Nanoseconds since the epoch.
    pub fn as_nanos(&self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    pub(crate) fn write(&self, w: &mut CdrWriter) {
        w.write_i32(self.sec);
        w.write_u32(self.nanosec);
    }

    pub(crate) fn read(r: &mut CdrReader<'_>) -> Result<Time, CdrError> {
        Ok(Time {
            sec: r.read_i32("header.stamp.sec")?,
            nanosec: r.read_u32("header.stamp.nanosec")?,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

impl Header {
    pub(crate) fn write(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.stamp.write(w);
        w.write_string("header.frame_id", &self.frame_id)
    }

    pub(crate) fn read(r: &mut CdrReader<'_>) -> Result<Header, CdrError> {
        Ok(Header {
            stamp: Time::read(r)?,
            frame_id: r.read_string("header.frame_id")?,
        })
    }
}

/// `geometry_msgs/msg/Vector3` (also the layout of `geometry_msgs/msg/Point`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl Vector3 {
    pub(crate) fn write(&self, w: &mut CdrWriter) {
        w.write_f64_array(&[self.x, self.y, self.z]);
    }

    pub(crate) fn read(r: &mut CdrReader<'_>, field: &'static str) -> Result<Vector3, CdrError> {
        let [x, y, z] = r.read_f64_array(field)?;
        Ok(Vector3 { x, y, z })
    }
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    /// The identity rotation, as the `.msg` default (`w = 1`).
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

impl Quaternion {
    pub(crate) fn write(&self, w: &mut CdrWriter) {
        w.write_f64_array(&[self.x, self.y, self.z, self.w]);
    }

    pub(crate) fn read(r: &mut CdrReader<'_>, field: &'static str) -> Result<Quaternion, CdrError> {
        let [x, y, z, w] = r.read_f64_array(field)?;
        Ok(Quaternion { x, y, z, w })
    }
}

/// `geometry_msgs/msg/Twist`: what a differential-drive base takes on `cmd_vel`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Linear velocity \[m/s\]; a planar base uses `x` (forward).
    pub linear: Vector3,
    /// Angular velocity \[rad/s\]; a planar base uses `z` (counter-clockwise).
    pub angular: Vector3,
}

impl Twist {
    fn write(&self, w: &mut CdrWriter) {
        self.linear.write(w);
        self.angular.write(w);
    }

    fn read(
        r: &mut CdrReader<'_>,
        linear: &'static str,
        angular: &'static str,
    ) -> Result<Twist, CdrError> {
        Ok(Twist {
            linear: Vector3::read(r, linear)?,
            angular: Vector3::read(r, angular)?,
        })
    }
}

impl RosMessage for Twist {
    message_identity! {
        "geometry_msgs" / "Twist", &schema::TWIST,
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.write(w);
        Ok(())
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Twist::read(r, "linear", "angular")
    }
}

/// `sensor_msgs/msg/LaserScan`: one planar scan.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserScan {
    /// Stamp of the first reading and the sensor's frame.
    pub header: Header,
    /// Angle of the first reading \[rad\], counter-clockwise from the frame's +x.
    pub angle_min: f32,
    /// Angle of the last reading \[rad\].
    pub angle_max: f32,
    /// Angle between readings \[rad\] (negative for a clockwise scan).
    pub angle_increment: f32,
    /// Time between readings \[s\].
    pub time_increment: f32,
    /// Time between scans \[s\].
    pub scan_time: f32,
    /// Smallest valid range \[m\].
    pub range_min: f32,
    /// Largest valid range \[m\].
    pub range_max: f32,
    /// Ranges \[m\]; values outside `[range_min, range_max]` are not returns.
    pub ranges: Vec<f32>,
    /// Intensities (device units), empty or one per range.
    pub intensities: Vec<f32>,
}

impl RosMessage for LaserScan {
    message_identity! {
        "sensor_msgs" / "LaserScan", &schema::LASER_SCAN,
        "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.header.write(w)?;
        w.write_f32(self.angle_min);
        w.write_f32(self.angle_max);
        w.write_f32(self.angle_increment);
        w.write_f32(self.time_increment);
        w.write_f32(self.scan_time);
        w.write_f32(self.range_min);
        w.write_f32(self.range_max);
        w.write_f32_sequence("ranges", &self.ranges)?;
        w.write_f32_sequence("intensities", &self.intensities)
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(LaserScan {
            header: Header::read(r)?,
            angle_min: r.read_f32("angle_min")?,
            angle_max: r.read_f32("angle_max")?,
            angle_increment: r.read_f32("angle_increment")?,
            time_increment: r.read_f32("time_increment")?,
            scan_time: r.read_f32("scan_time")?,
            range_min: r.read_f32("range_min")?,
            range_max: r.read_f32("range_max")?,
            ranges: r.read_f32_sequence("ranges")?,
            intensities: r.read_f32_sequence("intensities")?,
        })
    }
}

/// `sensor_msgs/msg/Imu`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Imu {
    /// Stamp and frame.
    pub header: Header,
    /// Orientation.
    pub orientation: Quaternion,
    /// Row-major 3x3 covariance of the orientation; element 0 = -1 means "no orientation".
    pub orientation_covariance: [f64; 9],
    /// Angular velocity \[rad/s\].
    pub angular_velocity: Vector3,
    /// Row-major 3x3 covariance of the angular velocity.
    pub angular_velocity_covariance: [f64; 9],
    /// Linear acceleration \[m/s²\].
    pub linear_acceleration: Vector3,
    /// Row-major 3x3 covariance of the linear acceleration.
    pub linear_acceleration_covariance: [f64; 9],
}

impl RosMessage for Imu {
    message_identity! {
        "sensor_msgs" / "Imu", &schema::IMU,
        "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.header.write(w)?;
        self.orientation.write(w);
        w.write_f64_array(&self.orientation_covariance);
        self.angular_velocity.write(w);
        w.write_f64_array(&self.angular_velocity_covariance);
        self.linear_acceleration.write(w);
        w.write_f64_array(&self.linear_acceleration_covariance);
        Ok(())
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Imu {
            header: Header::read(r)?,
            orientation: Quaternion::read(r, "orientation")?,
            orientation_covariance: r.read_f64_array("orientation_covariance")?,
            angular_velocity: Vector3::read(r, "angular_velocity")?,
            angular_velocity_covariance: r.read_f64_array("angular_velocity_covariance")?,
            linear_acceleration: Vector3::read(r, "linear_acceleration")?,
            linear_acceleration_covariance: r.read_f64_array("linear_acceleration_covariance")?,
        })
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Position (`geometry_msgs/msg/Point`, the layout of [`Vector3`]).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp and the frame of the pose (`odom`).
    pub header: Header,
    /// Frame of the twist (`base_link`).
    pub child_frame_id: String,
    /// Pose (`geometry_msgs/msg/PoseWithCovariance`).
    pub pose: Pose,
    /// Row-major 6x6 covariance of the pose.
    pub pose_covariance: [f64; 36],
    /// Twist in the child frame (`geometry_msgs/msg/TwistWithCovariance`).
    pub twist: Twist,
    /// Row-major 6x6 covariance of the twist.
    pub twist_covariance: [f64; 36],
}

impl Default for Odometry {
    fn default() -> Self {
        Odometry {
            header: Header::default(),
            child_frame_id: String::new(),
            pose: Pose::default(),
            pose_covariance: [0.0; 36],
            twist: Twist::default(),
            twist_covariance: [0.0; 36],
        }
    }
}

impl RosMessage for Odometry {
    message_identity! {
        "nav_msgs" / "Odometry", &schema::ODOMETRY,
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.header.write(w)?;
        w.write_string("child_frame_id", &self.child_frame_id)?;
        self.pose.position.write(w);
        self.pose.orientation.write(w);
        w.write_f64_array(&self.pose_covariance);
        self.twist.write(w);
        w.write_f64_array(&self.twist_covariance);
        Ok(())
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Odometry {
            header: Header::read(r)?,
            child_frame_id: r.read_string("child_frame_id")?,
            pose: Pose {
                position: Vector3::read(r, "pose.pose.position")?,
                orientation: Quaternion::read(r, "pose.pose.orientation")?,
            },
            pose_covariance: r.read_f64_array("pose.covariance")?,
            twist: Twist::read(r, "twist.twist.linear", "twist.twist.angular")?,
            twist_covariance: r.read_f64_array("twist.covariance")?,
        })
    }
}

/// `geometry_msgs/msg/Transform`: where a child frame lies in its parent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Transform {
    /// The child frame's origin in the parent frame \[m\].
    pub translation: Vector3,
    /// The child frame's orientation in the parent frame.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: one edge of the TF tree at one time.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// Stamp and the parent frame (`world`).
    pub header: Header,
    /// The child frame (`robot_0/base_link`).
    pub child_frame_id: String,
    /// The child in the parent.
    pub transform: Transform,
}

impl TransformStamped {
    /// The fewest bytes one element takes in a sequence: stamp, two empty strings, seven f64.
    const MIN_CDR_SIZE: usize = 8 + 5 + 5 + 7 * 8;

    fn write(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        self.header.write(w)?;
        w.write_string("transforms.child_frame_id", &self.child_frame_id)?;
        self.transform.translation.write(w);
        self.transform.rotation.write(w);
        Ok(())
    }

    fn read(r: &mut CdrReader<'_>) -> Result<TransformStamped, CdrError> {
        Ok(TransformStamped {
            header: Header::read(r)?,
            child_frame_id: r.read_string("transforms.child_frame_id")?,
            transform: Transform {
                translation: Vector3::read(r, "transforms.transform.translation")?,
                rotation: Quaternion::read(r, "transforms.transform.rotation")?,
            },
        })
    }
}

/// `tf2_msgs/msg/TFMessage`: what `/tf` and `/tf_static` carry, so that `tf2_echo`, RViz,
/// Foxglove and Rerun can place every robot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms, one per frame that moved.
    pub transforms: Vec<TransformStamped>,
}

impl RosMessage for TfMessage {
    message_identity! {
        "tf2_msgs" / "TFMessage", &schema::TF_MESSAGE,
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        w.write_sequence("transforms", &self.transforms, |w, transform| {
            transform.write(w)
        })
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let transforms = r.read_sequence(
            "transforms",
            TransformStamped::MIN_CDR_SIZE,
            TransformStamped::read,
        )?;
        Ok(TfMessage { transforms })
    }
}

/// `std_msgs/msg/Float64`: used for a heading goal φ* \[rad\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Float64 {
    /// The value.
    pub data: f64,
}

impl RosMessage for Float64 {
    message_identity! {
        "std_msgs" / "Float64", &schema::FLOAT64,
        "RIHS01_705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a"
    }

    fn write_fields(&self, w: &mut CdrWriter) -> Result<(), CdrEncodeError> {
        w.write_f64(self.data);
        Ok(())
    }

    fn read_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Float64 {
            data: r.read_f64("data")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DDS type name follows rmw_zenoh's `_create_type_name` from the ROS name.
    fn dds_name_from_ros_name(ros_name: &str) -> String {
        let (namespace, name) = ros_name.rsplit_once('/').unwrap();
        format!("{}::dds_::{name}_", namespace.replace('/', "::"))
    }

    fn check_names<M: RosMessage>() {
        assert_eq!(M::DDS_TYPE_NAME, dds_name_from_ros_name(M::ROS_NAME));
        assert_eq!(M::type_hash().to_string(), M::TYPE_HASH);
    }

    #[test]
    fn dds_type_names_follow_rmw_zenoh_and_hashes_parse() {
        check_names::<Twist>();
        check_names::<LaserScan>();
        check_names::<Imu>();
        check_names::<Odometry>();
        check_names::<Float64>();
        check_names::<TfMessage>();
        check_names::<crate::MarkerArray>();
    }

    #[test]
    fn time_converts_to_and_from_nanoseconds() {
        let t = Time::from_nanos(1_700_000_000_123_456_789);
        assert_eq!(
            t,
            Time {
                sec: 1_700_000_000,
                nanosec: 123_456_789
            }
        );
        assert_eq!(t.as_nanos(), 1_700_000_000_123_456_789);
        assert_eq!(
            Time::from_nanos(-1),
            Time {
                sec: -1,
                nanosec: 999_999_999
            }
        );
        assert_eq!(Time::from_nanos(i64::MAX).sec, i32::MAX);
        assert_eq!(Time::from_nanos(i64::MIN).sec, i32::MIN);
    }
}
