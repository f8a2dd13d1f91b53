#!/usr/bin/env python3
"""Golden byte strings for formation-ros2's wire-format tests, from independent implementations.

The CDR payloads and RIHS01 type hashes come from `rosbags` (pure-Python ROS 2 message types,
`Stores.ROS2_JAZZY`); the rmw_zenoh attachment comes from `eclipse-zenoh`'s own serializer
(`zenoh.ext.z_serialize`), which implements the same Zenoh serialization format as the
`zenoh::ext::Serializer` that rmw_zenoh_cpp's `AttachmentData::serialize_to_zbytes` uses; the
XXH3-128 digests behind entity GIDs come from the `xxhash` package (the reference C library).

The output is Rust source: regenerate the test constants with

    python3 -m venv /tmp/ros2venv
    /tmp/ros2venv/bin/pip install rosbags==0.11.9 eclipse-zenoh==1.10.2 xxhash==3.5.0
    /tmp/ros2venv/bin/python ros2/scripts/golden.py > ros2/tests/golden/mod.rs

The message values below are mirrored by the Rust tests that use these constants.
"""

import math

import numpy as np
import xxhash
from rosbags.typesys import Stores, get_typestore
from zenoh.ext import Int64, UInt8, z_serialize

ts = get_typestore(Stores.ROS2_JAZZY)
T = ts.types

Time = T["builtin_interfaces/msg/Time"]
Header = T["std_msgs/msg/Header"]
Vector3 = T["geometry_msgs/msg/Vector3"]
Point = T["geometry_msgs/msg/Point"]
Quaternion = T["geometry_msgs/msg/Quaternion"]
Pose = T["geometry_msgs/msg/Pose"]
Twist = T["geometry_msgs/msg/Twist"]
PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
TwistWithCovariance = T["geometry_msgs/msg/TwistWithCovariance"]
LaserScan = T["sensor_msgs/msg/LaserScan"]
Imu = T["sensor_msgs/msg/Imu"]
Odometry = T["nav_msgs/msg/Odometry"]
Float64 = T["std_msgs/msg/Float64"]
Transform = T["geometry_msgs/msg/Transform"]
TransformStamped = T["geometry_msgs/msg/TransformStamped"]
TFMessage = T["tf2_msgs/msg/TFMessage"]
Duration = T["builtin_interfaces/msg/Duration"]
ColorRGBA = T["std_msgs/msg/ColorRGBA"]
CompressedImage = T["sensor_msgs/msg/CompressedImage"]
MeshFile = T["visualization_msgs/msg/MeshFile"]
UVCoordinate = T["visualization_msgs/msg/UVCoordinate"]
Marker = T["visualization_msgs/msg/Marker"]
MarkerArray = T["visualization_msgs/msg/MarkerArray"]


def f64s(values):
    return np.array(values, dtype=np.float64)


def f32s(values):
    return np.array(values, dtype=np.float32)


TWIST = Twist(linear=Vector3(0.25, -0.5, 1.0), angular=Vector3(0.0, 0.125, -1.5))

# frame_id "laser": 5 characters, so the string (length 6 with its NUL) ends off a 4-byte boundary
# and the float32 fields after it need padding.
SCAN = LaserScan(
    header=Header(stamp=Time(sec=1700000000, nanosec=123456789), frame_id="laser"),
    angle_min=-math.pi,
    angle_max=math.pi,
    angle_increment=math.pi / 2,
    time_increment=0.0,
    scan_time=0.1,
    range_min=0.12,
    range_max=3.5,
    ranges=f32s([1.0, 2.5, math.inf, 0.05]),
    intensities=f32s([]),
)

# Both sequences empty; frame_id "base_scan" has 9 characters (length 10 with its NUL).
SCAN_EMPTY = LaserScan(
    header=Header(stamp=Time(sec=-1, nanosec=999999999), frame_id="base_scan"),
    angle_min=0.0,
    angle_max=0.0,
    angle_increment=0.0,
    time_increment=0.0,
    scan_time=0.0,
    range_min=0.0,
    range_max=0.0,
    ranges=f32s([]),
    intensities=f32s([]),
)

# frame_id "imu_link": 8 characters (length 9), so the float64 quaternion after it needs padding
# to an 8-byte boundary.
IMU = Imu(
    header=Header(stamp=Time(sec=42, nanosec=7), frame_id="imu_link"),
    orientation=Quaternion(0.0, 0.0, math.sin(0.25), math.cos(0.25)),
    orientation_covariance=f64s([0.01 * (i + 1) for i in range(9)]),
    angular_velocity=Vector3(0.1, -0.2, 0.3),
    angular_velocity_covariance=f64s([-1.0] + [0.0] * 8),
    linear_acceleration=Vector3(0.0, 0.0, 9.81),
    linear_acceleration_covariance=f64s([float(i) for i in range(9)]),
)

ODOM = Odometry(
    header=Header(stamp=Time(sec=3, nanosec=500000000), frame_id="odom"),
    child_frame_id="base_link",
    pose=PoseWithCovariance(
        pose=Pose(Point(1.5, -2.0, 0.0), Quaternion(0.0, 0.0, math.sin(-0.5), math.cos(-0.5))),
        covariance=f64s([float(i) / 10.0 for i in range(36)]),
    ),
    twist=TwistWithCovariance(
        twist=Twist(linear=Vector3(0.3, 0.0, 0.0), angular=Vector3(0.0, 0.0, -0.4)),
        covariance=f64s([float(35 - i) for i in range(36)]),
    ),
)

HEADING = Float64(data=math.pi / 3)

# Two robots on /tf: "world" (6 bytes with its NUL) and "robot_0/base_link" (18) leave the
# float64 fields after them off an 8-byte boundary, so the layout needs padding in both places.
TF = TFMessage(
    transforms=[
        TransformStamped(
            header=Header(stamp=Time(sec=12, nanosec=500000000), frame_id="world"),
            child_frame_id=f"robot_{i}/base_link",
            transform=Transform(
                translation=Vector3(1.5 * i - 0.25, -0.75 + i, 0.0),
                rotation=Quaternion(0.0, 0.0, math.sin(0.3 * (i + 1)), math.cos(0.3 * (i + 1))),
            ),
        )
        for i in range(2)
    ]
)
TF_EMPTY = TFMessage(transforms=[])


def marker(ns, id_, type_, action, points, colors, text, frame_locked, uv, texture_data):
    return Marker(
        header=Header(stamp=Time(sec=7, nanosec=250000000), frame_id="world"),
        ns=ns,
        id=id_,
        type=type_,
        action=action,
        pose=Pose(Point(0.5, -1.25, 0.0), Quaternion(0.0, 0.0, math.sin(0.2), math.cos(0.2))),
        scale=Vector3(0.03, 0.0, 0.0),
        color=ColorRGBA(r=0.25, g=0.5, b=0.75, a=1.0),
        lifetime=Duration(sec=1, nanosec=5),
        frame_locked=frame_locked,
        points=points,
        colors=colors,
        texture_resource="",
        texture=CompressedImage(
            header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), format="png", data=texture_data
        ),
        uv_coordinates=uv,
        text=text,
        mesh_resource="",
        mesh_file=MeshFile(filename="", data=np.array([], dtype=np.uint8)),
        mesh_use_embedded_materials=False,
    )


# A line list of two edges with a colour per point, then a text marker: bools, strings ending
# off a 4-byte boundary ("edges" 6 bytes, "e=+1.5%" 8), a uint8 sequence and float32 pairs, so
# padding is needed after several of them.
MARKERS = MarkerArray(
    markers=[
        marker(
            "edges",
            0,
            5,
            0,
            [Point(0.0, 0.0, 0.0), Point(1.5, 0.0, 0.0), Point(1.5, 0.0, 0.0), Point(0.75, 1.3, 0.0)],
            [ColorRGBA(r=float(i) / 4, g=1.0 - float(i) / 4, b=0.0, a=1.0) for i in range(4)],
            "",
            True,
            [],
            np.array([1, 2, 3], dtype=np.uint8),
        ),
        marker("edge_errors", 3, 9, 0, [], [], "e=+1.5%", False, [UVCoordinate(u=0.5, v=0.25)],
               np.array([], dtype=np.uint8)),
    ]
)
MARKERS_EMPTY = MarkerArray(markers=[])

# rmw_zenoh_cpp AttachmentData: (int64 sequence_number, int64 source_timestamp,
# std::array<uint8_t, 16> source_gid); a std::array is serialized as a sequence.
ATTACHMENT_SEQUENCE = 7
ATTACHMENT_TIMESTAMP_NS = 1700000000123456789
ATTACHMENT_GID = bytes(range(0xA0, 0xB0))
ATTACHMENT = bytes(
    z_serialize(
        (
            Int64(ATTACHMENT_SEQUENCE),
            Int64(ATTACHMENT_TIMESTAMP_NS),
            [UInt8(b) for b in ATTACHMENT_GID],
        )
    ).to_bytes()
)


def cdr(message, typename):
    return bytes(ts.serialize_cdr(message, typename, little_endian=True))


def rust_const(name, text):
    """A `&str` constant laid out as rustfmt (max width 100) lays it out."""
    one_line = f'pub const {name}: &str = "{text}";'
    wrapped = f'    "{text}";'
    if len(one_line) <= 100 or len(wrapped) > 100:
        return one_line
    return f"pub const {name}: &str =\n{wrapped}"


def emit(name, data, source):
    print(f"/// {source}")
    print(rust_const(name, data.hex()))


print("//! Golden byte strings and type hashes for the wire-format tests.")
print("//!")
print("//! GENERATED by `ros2/scripts/golden.py` (rosbags 0.11.9, `Stores.ROS2_JAZZY`; eclipse-zenoh")
print("//! for the attachment). Do not edit: regenerate. The message values are in that script and")
print("//! are mirrored by the tests that use these constants.")
print()
emit("TWIST_CDR", cdr(TWIST, "geometry_msgs/msg/Twist"), "rosbags serialize_cdr of TWIST")
emit("SCAN_CDR", cdr(SCAN, "sensor_msgs/msg/LaserScan"), "rosbags serialize_cdr of SCAN")
emit("SCAN_EMPTY_CDR", cdr(SCAN_EMPTY, "sensor_msgs/msg/LaserScan"), "rosbags serialize_cdr of SCAN_EMPTY")
emit("IMU_CDR", cdr(IMU, "sensor_msgs/msg/Imu"), "rosbags serialize_cdr of IMU")
emit("ODOM_CDR", cdr(ODOM, "nav_msgs/msg/Odometry"), "rosbags serialize_cdr of ODOM")
emit("HEADING_CDR", cdr(HEADING, "std_msgs/msg/Float64"), "rosbags serialize_cdr of HEADING")
emit("TF_CDR", cdr(TF, "tf2_msgs/msg/TFMessage"), "rosbags serialize_cdr of TF")
emit("TF_EMPTY_CDR", cdr(TF_EMPTY, "tf2_msgs/msg/TFMessage"), "rosbags serialize_cdr of TF_EMPTY")
emit("MARKERS_CDR", cdr(MARKERS, "visualization_msgs/msg/MarkerArray"), "rosbags serialize_cdr of MARKERS")
emit("MARKERS_EMPTY_CDR", cdr(MARKERS_EMPTY, "visualization_msgs/msg/MarkerArray"), "rosbags serialize_cdr of MARKERS_EMPTY")
emit("ATTACHMENT", ATTACHMENT, "zenoh.ext.z_serialize of (Int64 7, Int64 1700000000123456789, [UInt8 0xa0..=0xaf])")
print()
for const, typename in [
    ("TWIST_HASH", "geometry_msgs/msg/Twist"),
    ("LASER_SCAN_HASH", "sensor_msgs/msg/LaserScan"),
    ("IMU_HASH", "sensor_msgs/msg/Imu"),
    ("ODOMETRY_HASH", "nav_msgs/msg/Odometry"),
    ("FLOAT64_HASH", "std_msgs/msg/Float64"),
    ("TF_MESSAGE_HASH", "tf2_msgs/msg/TFMessage"),
    ("MARKER_ARRAY_HASH", "visualization_msgs/msg/MarkerArray"),
]:
    print(f"/// rosbags hash_rihs01(\"{typename}\")")
    print(rust_const(const, ts.hash_rihs01(typename)))

# XXH3-128 (seed 0) of the byte pattern (31 i + 7) mod 251, over every length class of the
# algorithm and the block boundaries of the long path; and the GID of one liveliness token
# (low 64 bits then high 64 bits, little-endian, as rmw_zenoh stores it).
XXH3_LENGTHS = [0, 1, 2, 3, 4, 5, 7, 8, 9, 15, 16, 17, 31, 32, 33, 63, 64, 65, 96, 97, 127, 128,
                129, 130, 159, 160, 200, 239, 240, 241, 255, 256, 500, 1023, 1024, 1025, 1100,
                2047, 2048, 2049, 3000]
print()
print("/// `(length, xxhash.xxh3_128(pattern(length)).intdigest())` with `pattern(n)[i] = (31 i + 7) % 251`.")
print("pub const XXH3_128: &[(usize, u128)] = &[")
for n in XXH3_LENGTHS:
    data = bytes((31 * i + 7) % 251 for i in range(n))
    print(f"    ({n}, 0x{xxhash.xxh3_128(data).intdigest():032x}),")
print("];")
GID_TOKEN = ("@ros2_lv/0/7c4e5f0a1b2c3d4e5f60718293a4b5c6/0/3/MP/%/%robot_0/formation_agent/%cmd_vel/"
             "geometry_msgs::msg::dds_::Twist_/" + ts.hash_rihs01("geometry_msgs/msg/Twist") + "/::,10:,:,:,,")
digest = xxhash.xxh3_128(GID_TOKEN.encode()).intdigest()
print(f"/// The liveliness token whose GID follows (`xxhash.xxh3_128`, low half then high half, LE).")
print(rust_const("GID_TOKEN", GID_TOKEN))
print("/// rmw_zenoh's GID of `GID_TOKEN`.")
print(rust_const("GID", digest.to_bytes(16, "little").hex()))

# The ros2msg schema text rosbag2 stores for each message type (rosbags' generate_msgdef with
# ros_version=2): the type's fields, then every type it uses after a MSG: line.
print()
print("/// `(type, rosbags generate_msgdef(type, ros_version=2))`: the ros2msg schema text of each message.")
print("pub const ROS2MSG: &[(&str, &str)] = &[")
for typename in [
    "geometry_msgs/msg/Twist",
    "sensor_msgs/msg/LaserScan",
    "sensor_msgs/msg/Imu",
    "nav_msgs/msg/Odometry",
    "std_msgs/msg/Float64",
    "tf2_msgs/msg/TFMessage",
    "visualization_msgs/msg/MarkerArray",
]:
    text, _ = ts.generate_msgdef(typename, ros_version=2)
    escaped = text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    print(f'    (\n        "{typename}",\n        "{escaped}",\n    ),')
print("];")
