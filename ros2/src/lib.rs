//! ROS 2 over rmw_zenoh, byte for byte and without I/O.
//!
//! What a process needs to be a ROS 2 node on a robot running rmw_zenoh (Jazzy), apart from a
//! Zenoh session: the CDR payloads of the messages it exchanges ([`msg`], [`cdr`]), their DDS type
//! names and RIHS01 hashes ([`msg::RosMessage`], [`type_hash`]), the key expressions samples travel
//! on ([`key_expr`]), the attachment every sample must carry ([`attachment`]), the liveliness
//! tokens that make it visible to `ros2 node list` and `ros2 topic info` ([`liveliness`]) and the
//! GIDs rmw_zenoh derives from them ([`gid`]), valid
//! ROS names ([`names`]), and the conversions between those messages and the agent's sensor and
//! command contract ([`convert`]). For recordings and viewers: each message's `ros2msg` schema
//! text ([`schema`]), the markers a viewer draws ([`visualization`]), and the messages a
//! simulated team publishes, built once for the live topics and for a recording ([`team`]).
//!
//! Every decoder here is total and bounded: malformed input is a typed error that says what is
//! wrong, never a panic, and nothing is allocated beyond what the input's length justifies.
//! The wire format was read from rmw_zenoh's sources (`liveliness_utils.cpp`,
//! `attachment_helpers.cpp`, `rmw_publisher_data.cpp`, `type_support_common.cpp`, `qos.cpp`) and
//! is checked against independent implementations (`rosbags`, `eclipse-zenoh`) by the byte-level
//! tests in `tests/wire_format.rs`, whose constants `scripts/golden.py` prints.

pub mod attachment;
pub mod cdr;
pub mod convert;
pub mod gid;
pub mod key_expr;
pub mod liveliness;
pub mod msg;
pub mod names;
pub mod schema;
pub mod team;
pub mod type_hash;
pub mod visualization;

pub use attachment::{Attachment, AttachmentError};
pub use cdr::{CdrEncodeError, CdrError, DecodeLimits};
pub use convert::{
    PartialScan, ResampledScan, RingContract, ScanError, quaternion_from_yaw, resample_scan,
    twist_from_wheels, wheels_from_twist, yaw_from_quaternion,
};
pub use key_expr::{HashConvention, KeyExprError, TopicKey};
pub use liveliness::{EntityKind, LivelinessToken, NodeIdentity, Qos, TopicEndpoint};
pub use msg::{
    Float64, Header, Imu, LaserScan, Odometry, Quaternion, RosMessage, TfMessage, Time, Transform,
    TransformStamped, Twist, Vector3,
};
pub use names::{NameError, Namespace, NodeName, TopicName};
pub use schema::MsgDefinition;
pub use type_hash::{TypeHash, TypeHashField};
pub use visualization::{ColorRgba, Duration, Marker, MarkerArray};
