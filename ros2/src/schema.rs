//! The `ros2msg` definitions of the messages, as ROS 2 bags store them next to their data.
//!
//! A recording (MCAP with the `ros2` profile, or a rosbag2) names each channel's message type and
//! carries its definition, so that a reader without ROS installed (Foxglove, Rerun, `rosbags`,
//! Python's `mcap-ros2-support`) can decode the CDR bytes. The definition is the message's own
//! `.msg` fields (comments dropped, constants kept), followed by every message type it uses,
//! each once, in the order a depth-first walk over the fields first meets them, each after a line
//! of 80 `=` and a line `MSG: package/Name`, exactly as rosbag2 (and `rosbags`'
//! `generate_msgdef(..., ros_version=2)`) writes it; `tests/wire_format.rs` compares the text
//! byte for byte with `rosbags`'.

/// One `.msg` definition: its name, its own fields, and the message types those fields use.
#[derive(Debug)]
pub struct MsgDefinition {
    /// `package/Name`, as a `MSG:` line names it (no `/msg/`).
    pub name: &'static str,
    /// The fields and constants, one per line, each line ending in `\n`.
    pub fields: &'static str,
    /// The message types the fields use, in field order.
    pub uses: &'static [&'static MsgDefinition],
}

/// The line between two definitions.
const SEPARATOR: &str =
    "================================================================================\n";

impl MsgDefinition {
    /// The full `ros2msg` schema text: these fields, then every definition they use once.
    pub fn ros2msg(&'static self) -> String {
        let mut seen: Vec<&'static str> = vec![self.name];
        let mut text = String::from(self.fields);
        let mut stack: Vec<&'static MsgDefinition> = self.uses.iter().rev().copied().collect();
        while let Some(def) = stack.pop() {
            if seen.contains(&def.name) {
                continue;
            }
            seen.push(def.name);
            text.push_str(SEPARATOR);
            text.push_str("MSG: ");
            text.push_str(def.name);
            text.push('\n');
            text.push_str(def.fields);
            stack.extend(def.uses.iter().rev().copied());
        }
        text
    }
}

/// `builtin_interfaces/Time`.
pub static TIME: MsgDefinition = MsgDefinition {
    name: "builtin_interfaces/Time",
    fields: "int32 sec\nuint32 nanosec\n",
    uses: &[],
};

/// `builtin_interfaces/Duration`.
pub static DURATION: MsgDefinition = MsgDefinition {
    name: "builtin_interfaces/Duration",
    fields: "int32 sec\nuint32 nanosec\n",
    uses: &[],
};

/// `std_msgs/Header`.
pub static HEADER: MsgDefinition = MsgDefinition {
    name: "std_msgs/Header",
    fields: "builtin_interfaces/Time stamp\nstring frame_id\n",
    uses: &[&TIME],
};

/// `std_msgs/Float64`.
pub static FLOAT64: MsgDefinition = MsgDefinition {
    name: "std_msgs/Float64",
    fields: "float64 data\n",
    uses: &[],
};

/// `std_msgs/ColorRGBA`.
pub static COLOR_RGBA: MsgDefinition = MsgDefinition {
    name: "std_msgs/ColorRGBA",
    fields: "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    uses: &[],
};

/// `geometry_msgs/Vector3`.
pub static VECTOR3: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Vector3",
    fields: "float64 x\nfloat64 y\nfloat64 z\n",
    uses: &[],
};

/// `geometry_msgs/Point`.
pub static POINT: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Point",
    fields: "float64 x\nfloat64 y\nfloat64 z\n",
    uses: &[],
};

/// `geometry_msgs/Quaternion`.
pub static QUATERNION: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Quaternion",
    fields: "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    uses: &[],
};

/// `geometry_msgs/Pose`.
pub static POSE: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Pose",
    fields: "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    uses: &[&POINT, &QUATERNION],
};

/// `geometry_msgs/PoseWithCovariance`.
pub static POSE_WITH_COVARIANCE: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/PoseWithCovariance",
    fields: "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    uses: &[&POSE],
};

/// `geometry_msgs/Twist`.
pub static TWIST: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Twist",
    fields: "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    uses: &[&VECTOR3],
};

/// `geometry_msgs/TwistWithCovariance`.
pub static TWIST_WITH_COVARIANCE: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/TwistWithCovariance",
    fields: "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    uses: &[&TWIST],
};

/// `geometry_msgs/Transform`.
pub static TRANSFORM: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/Transform",
    fields: "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    uses: &[&VECTOR3, &QUATERNION],
};

/// `geometry_msgs/TransformStamped`.
pub static TRANSFORM_STAMPED: MsgDefinition = MsgDefinition {
    name: "geometry_msgs/TransformStamped",
    fields: "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    uses: &[&HEADER, &TRANSFORM],
};

/// `tf2_msgs/TFMessage`.
pub static TF_MESSAGE: MsgDefinition = MsgDefinition {
    name: "tf2_msgs/TFMessage",
    fields: "geometry_msgs/TransformStamped[] transforms\n",
    uses: &[&TRANSFORM_STAMPED],
};

/// `sensor_msgs/LaserScan`.
pub static LASER_SCAN: MsgDefinition = MsgDefinition {
    name: "sensor_msgs/LaserScan",
    fields: "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
             float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
             float32[] ranges\nfloat32[] intensities\n",
    uses: &[&HEADER],
};

/// `sensor_msgs/Imu`.
pub static IMU: MsgDefinition = MsgDefinition {
    name: "sensor_msgs/Imu",
    fields: "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n\
             float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n\
             float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n\
             float64[9] linear_acceleration_covariance\n",
    uses: &[&HEADER, &QUATERNION, &VECTOR3],
};

/// `sensor_msgs/CompressedImage` (a [`MARKER`]'s texture).
pub static COMPRESSED_IMAGE: MsgDefinition = MsgDefinition {
    name: "sensor_msgs/CompressedImage",
    fields: "std_msgs/Header header\nstring format\nuint8[] data\n",
    uses: &[&HEADER],
};

/// `nav_msgs/Odometry`.
pub static ODOMETRY: MsgDefinition = MsgDefinition {
    name: "nav_msgs/Odometry",
    fields: "std_msgs/Header header\nstring child_frame_id\n\
             geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    uses: &[&HEADER, &POSE_WITH_COVARIANCE, &TWIST_WITH_COVARIANCE],
};

/// `visualization_msgs/UVCoordinate`.
pub static UV_COORDINATE: MsgDefinition = MsgDefinition {
    name: "visualization_msgs/UVCoordinate",
    fields: "float32 u\nfloat32 v\n",
    uses: &[],
};

/// `visualization_msgs/MeshFile`.
pub static MESH_FILE: MsgDefinition = MsgDefinition {
    name: "visualization_msgs/MeshFile",
    fields: "string filename\nuint8[] data\n",
    uses: &[],
};

/// `visualization_msgs/Marker` (ROS 2 Jazzy: with texture and mesh file).
pub static MARKER: MsgDefinition = MsgDefinition {
    name: "visualization_msgs/Marker",
    fields: "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
             int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
             int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
             int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
             std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
             geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
             builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
             std_msgs/ColorRGBA[] colors\nstring texture_resource\n\
             sensor_msgs/CompressedImage texture\n\
             visualization_msgs/UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\n\
             visualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials\n",
    uses: &[
        &HEADER,
        &POSE,
        &VECTOR3,
        &COLOR_RGBA,
        &DURATION,
        &POINT,
        &COMPRESSED_IMAGE,
        &UV_COORDINATE,
        &MESH_FILE,
    ],
};

/// `visualization_msgs/MarkerArray`.
pub static MARKER_ARRAY: MsgDefinition = MsgDefinition {
    name: "visualization_msgs/MarkerArray",
    fields: "visualization_msgs/Marker[] markers\n",
    uses: &[&MARKER],
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_definition_lists_each_type_it_uses_once_depth_first() {
        let text = ODOMETRY.ros2msg();
        let names: Vec<&str> = text
            .lines()
            .filter_map(|l| l.strip_prefix("MSG: "))
            .collect();
        assert_eq!(
            names,
            [
                "std_msgs/Header",
                "builtin_interfaces/Time",
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "geometry_msgs/TwistWithCovariance",
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3",
            ]
        );
        assert!(text.starts_with("std_msgs/Header header\n"));
        assert_eq!(FLOAT64.ros2msg(), "float64 data\n");
    }
}
