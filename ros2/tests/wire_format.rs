//! Byte-level checks of the wire format against independent implementations.
//!
//! The constants in `golden/mod.rs` were printed by `ros2/scripts/golden.py`: the CDR payloads and
//! RIHS01 hashes by `rosbags` 0.11.9 (`Stores.ROS2_JAZZY`), the attachment by `eclipse-zenoh`'s
//! serializer, the `ros2msg` schema texts by `rosbags`' `generate_msgdef(..., ros_version=2)`.
//! The message values below mirror the ones in that script. Each test encodes the same message
//! here and compares bytes, decodes the golden bytes back, and checks the hash.

mod golden;

use std::f64::consts::PI;

use formation_ros2::cdr::CdrError;
use formation_ros2::gid::{entity_gid, xxh3_128};
use formation_ros2::msg::{Pose, Quaternion, Vector3};
use formation_ros2::visualization::{CompressedImage, MeshFile};
use formation_ros2::{
    Attachment, ColorRgba, DecodeLimits, Duration, Float64, Header, Imu, LaserScan,
    LivelinessToken, Marker, MarkerArray, Odometry, RosMessage, TfMessage, Time, Transform,
    TransformStamped, Twist,
};

fn hex(text: &str) -> Vec<u8> {
    assert!(text.len().is_multiple_of(2));
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
        .collect()
}

/// Encodes `message`, compares with the golden bytes, decodes them back, checks the hash.
fn check<M: RosMessage + PartialEq + std::fmt::Debug>(message: &M, golden_hex: &str, hash: &str) {
    let golden = hex(golden_hex);
    let encoded = message.to_cdr().unwrap();
    assert_eq!(
        encoded,
        golden,
        "{} encodes differently from rosbags",
        M::ROS_NAME
    );
    assert_eq!(&M::from_cdr(&golden).unwrap(), message);
    assert_eq!(
        M::TYPE_HASH,
        hash,
        "{} hash differs from rosbags",
        M::ROS_NAME
    );
    assert_eq!(M::type_hash().to_string(), hash);
    // Every strict prefix is a typed error, never a panic.
    for len in 0..golden.len() {
        assert!(
            M::from_cdr(&golden[..len]).is_err(),
            "{} prefix {len}",
            M::ROS_NAME
        );
    }
}

/// [`check`]s `message`, and the message's default (an empty sequence) against `empty_hex`.
fn check_with_empty<M: RosMessage + PartialEq + std::fmt::Debug + Default>(
    message: &M,
    golden_hex: &str,
    empty_hex: &str,
    hash: &str,
) {
    check(message, golden_hex, hash);
    check(&M::default(), empty_hex, hash);
}

fn twist() -> Twist {
    Twist {
        linear: Vector3 {
            x: 0.25,
            y: -0.5,
            z: 1.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.125,
            z: -1.5,
        },
    }
}

fn scan() -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time {
                sec: 1_700_000_000,
                nanosec: 123_456_789,
            },
            frame_id: "laser".into(),
        },
        angle_min: -PI as f32,
        angle_max: PI as f32,
        angle_increment: (PI / 2.0) as f32,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.12,
        range_max: 3.5,
        ranges: vec![1.0, 2.5, f32::INFINITY, 0.05],
        intensities: vec![],
    }
}

fn quaternion_about_z(half_angle: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: half_angle.sin(),
        w: half_angle.cos(),
    }
}

#[test]
fn twist_matches_rosbags() {
    check(&twist(), golden::TWIST_CDR, golden::TWIST_HASH);
}

#[test]
fn laser_scan_with_odd_frame_id_matches_rosbags() {
    check(&scan(), golden::SCAN_CDR, golden::LASER_SCAN_HASH);
}

#[test]
fn laser_scan_with_empty_sequences_matches_rosbags() {
    let empty = LaserScan {
        header: Header {
            stamp: Time {
                sec: -1,
                nanosec: 999_999_999,
            },
            frame_id: "base_scan".into(),
        },
        ..LaserScan::default()
    };
    check(&empty, golden::SCAN_EMPTY_CDR, golden::LASER_SCAN_HASH);
}

#[test]
fn imu_with_padding_before_float64_matches_rosbags() {
    let imu = Imu {
        header: Header {
            stamp: Time {
                sec: 42,
                nanosec: 7,
            },
            frame_id: "imu_link".into(),
        },
        orientation: quaternion_about_z(0.25),
        orientation_covariance: std::array::from_fn(|i| 0.01 * (i + 1) as f64),
        angular_velocity: Vector3 {
            x: 0.1,
            y: -0.2,
            z: 0.3,
        },
        angular_velocity_covariance: std::array::from_fn(|i| if i == 0 { -1.0 } else { 0.0 }),
        linear_acceleration: Vector3 {
            x: 0.0,
            y: 0.0,
            z: 9.81,
        },
        linear_acceleration_covariance: std::array::from_fn(|i| i as f64),
    };
    check(&imu, golden::IMU_CDR, golden::IMU_HASH);
    // The header string "imu_link" ends at body offset 21; the quaternion starts at 24.
    let bytes = hex(golden::IMU_CDR);
    assert_eq!(&bytes[4 + 21..4 + 24], &[0, 0, 0]);
    assert!((imu.yaw().unwrap() - 0.5).abs() < 1e-12);
}

#[test]
fn odometry_matches_rosbags() {
    let odom = Odometry {
        header: Header {
            stamp: Time {
                sec: 3,
                nanosec: 500_000_000,
            },
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        pose: Pose {
            position: Vector3 {
                x: 1.5,
                y: -2.0,
                z: 0.0,
            },
            orientation: quaternion_about_z(-0.5),
        },
        pose_covariance: std::array::from_fn(|i| i as f64 / 10.0),
        twist: Twist {
            linear: Vector3 {
                x: 0.3,
                ..Vector3::default()
            },
            angular: Vector3 {
                z: -0.4,
                ..Vector3::default()
            },
        },
        twist_covariance: std::array::from_fn(|i| (35 - i) as f64),
    };
    check(&odom, golden::ODOM_CDR, golden::ODOMETRY_HASH);
    assert!((odom.yaw().unwrap() + 1.0).abs() < 1e-12);
}

#[test]
fn float64_matches_rosbags() {
    check(
        &Float64 { data: PI / 3.0 },
        golden::HEADING_CDR,
        golden::FLOAT64_HASH,
    );
}

/// The two robots of `TF` in golden.py.
fn tf() -> TfMessage {
    TfMessage {
        transforms: (0..2)
            .map(|i| {
                let half = 0.3 * f64::from(i + 1);
                TransformStamped {
                    header: Header {
                        stamp: Time {
                            sec: 12,
                            nanosec: 500_000_000,
                        },
                        frame_id: "world".into(),
                    },
                    child_frame_id: format!("robot_{i}/base_link"),
                    transform: Transform {
                        translation: Vector3 {
                            x: 1.5 * f64::from(i) - 0.25,
                            y: -0.75 + f64::from(i),
                            z: 0.0,
                        },
                        rotation: Quaternion {
                            x: 0.0,
                            y: 0.0,
                            z: half.sin(),
                            w: half.cos(),
                        },
                    },
                }
            })
            .collect(),
    }
}

#[test]
fn tf_message_with_padding_after_frame_ids_matches_rosbags() {
    check_with_empty(
        &tf(),
        golden::TF_CDR,
        golden::TF_EMPTY_CDR,
        golden::TF_MESSAGE_HASH,
    );
}

/// One marker of `MARKERS` in golden.py.
#[expect(
    clippy::too_many_arguments,
    reason = "mirrors golden.py's marker(), one argument per field that varies"
)]
fn marker(
    ns: &str,
    id: i32,
    kind: i32,
    points: Vec<Vector3>,
    colors: Vec<ColorRgba>,
    text: &str,
    frame_locked: bool,
    uv_coordinates: Vec<(f32, f32)>,
    texture_data: Vec<u8>,
) -> Marker {
    Marker {
        header: Header {
            stamp: Time {
                sec: 7,
                nanosec: 250_000_000,
            },
            frame_id: "world".into(),
        },
        ns: ns.into(),
        id,
        kind,
        action: 0,
        pose: Pose {
            position: Vector3 {
                x: 0.5,
                y: -1.25,
                z: 0.0,
            },
            orientation: quaternion_about_z(0.2),
        },
        scale: Vector3 {
            x: 0.03,
            y: 0.0,
            z: 0.0,
        },
        color: ColorRgba {
            r: 0.25,
            g: 0.5,
            b: 0.75,
            a: 1.0,
        },
        lifetime: Duration { sec: 1, nanosec: 5 },
        frame_locked,
        points,
        colors,
        texture_resource: String::new(),
        texture: CompressedImage {
            header: Header::default(),
            format: "png".into(),
            data: texture_data,
        },
        uv_coordinates,
        text: text.into(),
        mesh_resource: String::new(),
        mesh_file: MeshFile::default(),
        mesh_use_embedded_materials: false,
    }
}

/// `MARKERS` in golden.py: a line list of two edges with a colour per point, and a text marker.
fn markers() -> MarkerArray {
    let point = |x, y| Vector3 { x, y, z: 0.0 };
    let colors = (0..4)
        .map(|i| ColorRgba {
            r: i as f32 / 4.0,
            g: 1.0 - i as f32 / 4.0,
            b: 0.0,
            a: 1.0,
        })
        .collect();
    MarkerArray {
        markers: vec![
            marker(
                "edges",
                0,
                5,
                vec![
                    point(0.0, 0.0),
                    point(1.5, 0.0),
                    point(1.5, 0.0),
                    point(0.75, 1.3),
                ],
                colors,
                "",
                true,
                Vec::new(),
                vec![1, 2, 3],
            ),
            marker(
                "edge_errors",
                3,
                9,
                Vec::new(),
                Vec::new(),
                "e=+1.5%",
                false,
                vec![(0.5, 0.25)],
                Vec::new(),
            ),
        ],
    }
}

#[test]
fn marker_array_with_bools_bytes_and_text_matches_rosbags() {
    check_with_empty(
        &markers(),
        golden::MARKERS_CDR,
        golden::MARKERS_EMPTY_CDR,
        golden::MARKER_ARRAY_HASH,
    );
}

/// The schema text a recording stores for a message type, as rosbag2 writes it.
fn ros2msg_of<M: RosMessage>() -> String {
    M::DEFINITION.ros2msg()
}

#[test]
fn ros2msg_schemas_match_rosbags_definitions() {
    let ours = [
        (Twist::ROS_NAME, ros2msg_of::<Twist>()),
        (LaserScan::ROS_NAME, ros2msg_of::<LaserScan>()),
        (Imu::ROS_NAME, ros2msg_of::<Imu>()),
        (Odometry::ROS_NAME, ros2msg_of::<Odometry>()),
        (Float64::ROS_NAME, ros2msg_of::<Float64>()),
        (TfMessage::ROS_NAME, ros2msg_of::<TfMessage>()),
        (MarkerArray::ROS_NAME, ros2msg_of::<MarkerArray>()),
    ];
    assert_eq!(ours.len(), golden::ROS2MSG.len());
    for ((name, text), (golden_name, golden_text)) in ours.iter().zip(golden::ROS2MSG) {
        assert_eq!(name, golden_name);
        assert_eq!(text, golden_text, "{name}");
    }
}

/// The default limits without a cap on a sequence's length, so that only the bytes present
/// refuse a count.
fn uncapped_sequences() -> DecodeLimits {
    DecodeLimits {
        max_sequence_len: u32::MAX,
        ..DecodeLimits::default()
    }
}

#[test]
fn a_tf_message_declaring_more_transforms_than_present_is_refused() {
    let mut bytes = hex(golden::TF_CDR);
    assert_eq!(&bytes[4..8], &2u32.to_le_bytes());
    bytes[4..8].copy_from_slice(&3u32.to_le_bytes());
    assert!(TfMessage::from_cdr(&bytes).is_err());
    bytes[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        TfMessage::from_cdr_with_limits(&bytes, uncapped_sequences()),
        Err(CdrError::SequenceBeyondInput {
            field: "transforms",
            ..
        })
    ));
}

#[test]
fn attachment_matches_zenoh_serializer() {
    let attachment = Attachment {
        sequence_number: 7,
        source_timestamp_ns: 1_700_000_000_123_456_789,
        source_gid: std::array::from_fn(|i| 0xa0 + i as u8),
    };
    let golden = hex(golden::ATTACHMENT);
    assert_eq!(attachment.encode().to_vec(), golden);
    assert_eq!(Attachment::decode(&golden), Ok(attachment));
    for len in 0..golden.len() {
        assert!(Attachment::decode(&golden[..len]).is_err(), "prefix {len}");
    }
}

#[test]
fn a_scan_declaring_more_ranges_than_present_is_refused() {
    let mut bytes = hex(golden::SCAN_CDR);
    // The ranges count sits after the header (8 + 4 + 6 + 2 padding = 20) and seven float32s (28).
    let count_at = 4 + 20 + 28;
    assert_eq!(&bytes[count_at..count_at + 4], &4u32.to_le_bytes());
    bytes[count_at..count_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        LaserScan::from_cdr_with_limits(&bytes, uncapped_sequences()),
        Err(CdrError::SequenceBeyondInput {
            field: "ranges",
            declared: u32::MAX,
            ..
        })
    ));
    assert!(matches!(
        LaserScan::from_cdr(&bytes),
        Err(CdrError::SequenceTooLong {
            field: "ranges",
            ..
        })
    ));
}

#[test]
fn a_big_endian_payload_is_refused() {
    let mut bytes = hex(golden::TWIST_CDR);
    bytes[1] = 0x00;
    let err = Twist::from_cdr(&bytes).unwrap_err();
    assert_eq!(
        err,
        CdrError::UnsupportedEncapsulation {
            found: [0, 0, 0, 0]
        }
    );
    assert!(err.to_string().contains("little-endian"));
}

#[test]
fn xxh3_128_matches_the_reference_library_over_every_length_class() {
    for &(len, expected) in golden::XXH3_128 {
        let pattern: Vec<u8> = (0..len).map(|i| ((31 * i + 7) % 251) as u8).collect();
        assert_eq!(xxh3_128(&pattern), expected, "length {len}");
    }
}

#[test]
fn publisher_gid_matches_rmw_zenohs_derivation() {
    let gid = hex(golden::GID);
    assert_eq!(entity_gid(golden::GID_TOKEN).to_vec(), gid);
    let token = LivelinessToken::parse(golden::GID_TOKEN).unwrap();
    assert_eq!(token.to_string(), golden::GID_TOKEN);
    assert_eq!(token.gid().to_vec(), gid);
}
