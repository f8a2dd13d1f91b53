//! CDR and the ROS 2 messages (formation-ros2): what a ROS 2 node of the team takes from a
//! foreign publisher over rmw_zenoh, a LaserScan above all.
//!
//! Case: one byte naming what the bytes are, then the bytes. Messages are whole CDR payloads
//! ([`RosMessage::from_cdr`]); a LaserScan is then put on the model's ring ([`resample_scan`],
//! 360 beams, 4 m) and an Imu's or Odometry's heading is read, as the agent does; besides, the
//! sample attachment ([`Attachment::decode`]), a data key expression ([`TopicKey::parse`]) and a
//! liveliness token ([`LivelinessToken::parse`]), whose bytes are text (decoded as UTF-8 first,
//! as Zenoh key expressions are). Decoded means every step accepted it.

use formation_ros2::msg::Vector3;
use formation_ros2::team::{laser_scan_message, odometry_message, tf_message};
use formation_ros2::{
    Attachment, Float64, HashConvention, Header, Imu, LaserScan, LivelinessToken, Odometry,
    PartialScan, Quaternion, RingContract, RosMessage, TfMessage, Time, TopicKey, TopicName, Twist,
    resample_scan,
};

use super::{Refusal, Scratch, Seed, Target, seed_error};
use crate::FuzzError;
use crate::mutate::Shape;

/// The target.
pub const TARGET: Target = Target {
    name: "ros2",
    about: "CDR and the ROS 2 messages from a foreign publisher, the attachment, key expressions \
            and liveliness tokens",
    run,
    seeds,
    tokens: &[
        &[0x00, 0x01, 0x00, 0x00],
        &[0xff, 0xff, 0xff, 0x7f],
        &[0x00, 0x00, 0x80, 0x7f],
        b"/",
        b"%",
        b"RIHS01_",
        b"@ros2_lv/",
        b"::,10:,:,:,,",
    ],
    shape: Shape::Bytes,
};

const SCAN: u8 = 0;
const TWIST: u8 = 1;
const IMU: u8 = 2;
const ODOMETRY: u8 = 3;
const TF: u8 = 4;
const FLOAT64: u8 = 5;
const ATTACHMENT: u8 = 6;
const KEY: u8 = 7;
const TOKEN: u8 = 8;

/// The model ring a LaserScan is put on.
const RING: RingContract = RingContract {
    beams: 360,
    max_range: 4.0,
};

fn run(_: &Scratch, case: &[u8]) -> Result<(), Refusal> {
    let Some((&kind, bytes)) = case.split_first() else {
        return Err(Refusal::named("empty"));
    };
    let text = || std::str::from_utf8(bytes).map_err(|_| Refusal::named("not UTF-8"));
    match kind % 9 {
        SCAN => {
            let scan = LaserScan::from_cdr(bytes).map_err(Refusal::of)?;
            resample_scan(&scan, RING, PartialScan::AllowAsNoReturn).map_err(Refusal::of)?;
        }
        TWIST => {
            Twist::from_cdr(bytes).map_err(Refusal::of)?;
        }
        IMU => {
            Imu::from_cdr(bytes)
                .map_err(Refusal::of)?
                .yaw()
                .map_err(Refusal::of)?;
        }
        ODOMETRY => {
            Odometry::from_cdr(bytes)
                .map_err(Refusal::of)?
                .yaw()
                .map_err(Refusal::of)?;
        }
        TF => {
            TfMessage::from_cdr(bytes).map_err(Refusal::of)?;
        }
        FLOAT64 => {
            Float64::from_cdr(bytes).map_err(Refusal::of)?;
        }
        ATTACHMENT => {
            Attachment::decode(bytes).map_err(Refusal::of)?;
        }
        KEY => {
            TopicKey::parse(text()?)
                .map_err(Refusal::of)?
                .expect_message::<LaserScan>()
                .map_err(Refusal::of)?;
        }
        _ => {
            let token = LivelinessToken::parse(text()?).map_err(Refusal::of)?;
            let _ = (token.gid(), token.to_string());
        }
    }
    Ok(())
}

/// A token as rmw_zenoh writes it for a `cmd_vel` publisher (the golden one of
/// `ros2/tests/wire_format.rs`, from a foreign node).
const CMD_VEL_TOKEN: &str = "@ros2_lv/0/7c4e5f0a1b2c3d4e5f60718293a4b5c6/0/3/MP/%/%robot_0/formation_agent/%cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a/::,10:,:,:,,";

fn tagged(kind: u8, bytes: &[u8]) -> Vec<u8> {
    let mut out = vec![kind];
    out.extend_from_slice(bytes);
    out
}

/// A foreign LIDAR's scan: 270°, clockwise, with NaN and inf readings and intensities.
fn foreign_scan(stamp: Time) -> LaserScan {
    LaserScan {
        header: Header {
            stamp,
            frame_id: "base_scan".into(),
        },
        angle_min: 2.356,
        angle_max: -2.356,
        angle_increment: -0.0174,
        time_increment: 1e-5,
        scan_time: 0.1,
        range_min: 0.12,
        range_max: 3.5,
        ranges: (0..271)
            .map(|k| match k % 50 {
                0 => f32::NAN,
                1 => f32::INFINITY,
                _ => 0.2 + k as f32 / 100.0,
            })
            .collect(),
        intensities: vec![100.0; 271],
    }
}

fn seeds() -> Result<Vec<Seed>, FuzzError> {
    let stamp = Time {
        sec: 12,
        nanosec: 500_000_000,
    };
    let ring: Vec<f32> = (0..360)
        .map(|k| {
            if k % 7 == 0 {
                4.0
            } else {
                0.5 + k as f32 / 200.0
            }
        })
        .collect();
    let scan = laser_scan_message(0, stamp, &ring, 4.0);
    let foreign = foreign_scan(stamp);
    let twist = Twist {
        linear: Vector3 {
            x: 0.3,
            y: 0.0,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: -0.4,
        },
    };
    let imu = Imu {
        header: Header {
            stamp,
            frame_id: "imu_link".into(),
        },
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.247,
            w: 0.969,
        },
        ..Imu::default()
    };
    let wheels = formation_ros2::team::Wheels {
        left: 0.28,
        right: 0.32,
        separation: 0.16,
    };
    let odometry = odometry_message(1, stamp, (1.5, -0.25), 0.5, wheels);
    let tf = tf_message(2, stamp, 1.0, 2.0, 0.3);
    let key = TopicKey::for_message::<LaserScan>(
        0,
        TopicName::new("/robot_0/scan").map_err(seed_error("ros2"))?,
        HashConvention::Rihs01,
    );
    let attachment = Attachment {
        sequence_number: 7,
        source_timestamp_ns: 1_700_000_000_123_456_789,
        source_gid: [0xa5; 16],
    };
    let cdr = |m: Result<Vec<u8>, _>| m.map_err(seed_error("ros2"));
    Ok(vec![
        ("scan.bin".into(), tagged(SCAN, &cdr(scan.to_cdr())?)),
        (
            "scan-foreign.bin".into(),
            tagged(SCAN, &cdr(foreign.to_cdr())?),
        ),
        ("twist.bin".into(), tagged(TWIST, &cdr(twist.to_cdr())?)),
        ("imu.bin".into(), tagged(IMU, &cdr(imu.to_cdr())?)),
        (
            "odometry.bin".into(),
            tagged(ODOMETRY, &cdr(odometry.to_cdr())?),
        ),
        ("tf.bin".into(), tagged(TF, &cdr(tf.to_cdr())?)),
        (
            "float64.bin".into(),
            tagged(FLOAT64, &cdr(Float64 { data: 0.785 }.to_cdr())?),
        ),
        (
            "attachment.bin".into(),
            tagged(ATTACHMENT, &attachment.encode()),
        ),
        ("key.bin".into(), tagged(KEY, key.to_string().as_bytes())),
        ("token.bin".into(), tagged(TOKEN, CMD_VEL_TOKEN.as_bytes())),
    ])
}
