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

/// Declares each definition as a `pub static`: `IDENT = "package/Name" uses [TYPES]: "fields";`,
/// the types it uses in field order (none: no `uses`).
macro_rules! msg_definitions {
    ($(
        $(#[$doc:meta])*
        $ident:ident = $name:literal $(uses [$($uses:ident),*])?: $fields:expr;
    )*) => {$(
        $(#[$doc])*
        pub static $ident: MsgDefinition = MsgDefinition {
            name: $name,
            fields: $fields,
            uses: &[$($(&$uses),*)?],
        };
    )*};
}

msg_definitions! {
    /// `builtin_interfaces/Time`.
    TIME = "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n";
    /// `builtin_interfaces/Duration`.
    DURATION = "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n";
    /// `std_msgs/Header`.
    HEADER = "std_msgs/Header" uses [TIME]: "builtin_interfaces/Time stamp\nstring frame_id\n";
    /// `std_msgs/Float64`.
    FLOAT64 = "std_msgs/Float64": "float64 data\n";
    /// `std_msgs/ColorRGBA`.
    COLOR_RGBA = "std_msgs/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n";
    /// `geometry_msgs/Vector3`.
    VECTOR3 = "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n";
    /// `geometry_msgs/Point`.
    POINT = "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n";
    /// `geometry_msgs/Quaternion`.
    QUATERNION = "geometry_msgs/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";
    /// `geometry_msgs/Pose`.
    POSE = "geometry_msgs/Pose" uses [POINT, QUATERNION]:
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";
    /// `geometry_msgs/PoseWithCovariance`.
    POSE_WITH_COVARIANCE = "geometry_msgs/PoseWithCovariance" uses [POSE]:
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n";
    /// `geometry_msgs/Twist`.
    TWIST = "geometry_msgs/Twist" uses [VECTOR3]:
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n";
    /// `geometry_msgs/TwistWithCovariance`.
    TWIST_WITH_COVARIANCE = "geometry_msgs/TwistWithCovariance" uses [TWIST]:
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n";
    /// `geometry_msgs/Transform`.
    TRANSFORM = "geometry_msgs/Transform" uses [VECTOR3, QUATERNION]:
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n";
    /// `geometry_msgs/TransformStamped`.
    TRANSFORM_STAMPED = "geometry_msgs/TransformStamped" uses [HEADER, TRANSFORM]:
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n";
    /// `tf2_msgs/TFMessage`.
    TF_MESSAGE = "tf2_msgs/TFMessage" uses [TRANSFORM_STAMPED]:
        "geometry_msgs/TransformStamped[] transforms\n";
    /// `sensor_msgs/LaserScan`.
    LASER_SCAN = "sensor_msgs/LaserScan" uses [HEADER]:
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
        float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
        float32[] ranges\nfloat32[] intensities\n";
    /// `sensor_msgs/Imu`.
    IMU = "sensor_msgs/Imu" uses [HEADER, QUATERNION, VECTOR3]:
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n\
        float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n\
        float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n\
        float64[9] linear_acceleration_covariance\n";
    /// `sensor_msgs/CompressedImage` (a [`MARKER`]'s texture).
    COMPRESSED_IMAGE = "sensor_msgs/CompressedImage" uses [HEADER]:
        "std_msgs/Header header\nstring format\nuint8[] data\n";
    /// `nav_msgs/Odometry`.
    ODOMETRY = "nav_msgs/Odometry" uses [HEADER, POSE_WITH_COVARIANCE, TWIST_WITH_COVARIANCE]:
        "std_msgs/Header header\nstring child_frame_id\n\
        geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n";
    /// `visualization_msgs/UVCoordinate`.
    UV_COORDINATE = "visualization_msgs/UVCoordinate": "float32 u\nfloat32 v\n";
    /// `visualization_msgs/MeshFile`.
    MESH_FILE = "visualization_msgs/MeshFile": "string filename\nuint8[] data\n";
    /// `visualization_msgs/Marker` (ROS 2 Jazzy: with texture and mesh file).
    MARKER = "visualization_msgs/Marker" uses [
        HEADER, POSE, VECTOR3, COLOR_RGBA, DURATION, POINT, COMPRESSED_IMAGE, UV_COORDINATE,
        MESH_FILE
    ]:
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
        int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
        int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
        int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
        std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
        geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
        builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
        std_msgs/ColorRGBA[] colors\nstring texture_resource\n\
        sensor_msgs/CompressedImage texture\n\
        visualization_msgs/UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\n\
        visualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials\n";
    /// `visualization_msgs/MarkerArray`.
    MARKER_ARRAY = "visualization_msgs/MarkerArray" uses [MARKER]:
        "visualization_msgs/Marker[] markers\n";
}

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
