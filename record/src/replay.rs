//! The replay channel: per robot and tick, exactly what the agent received and what it sent.
//!
//! One definition, versioned: [`REPLAY_STEP`], the `.msg` text of `formation_msgs/msg/ReplayStep`
//! (format version [`FORMAT_VERSION`], a constant of the definition and a field of every
//! message). Each message is little-endian CDR with that `ros2msg` schema, on the topic
//! `/robot_<i>/replay`, so any ROS 2 aware reader decodes it from the file alone (Foxglove plots
//! it, `mcap-ros2-support` and `rosbags` read it), while the values stay bit for bit what the
//! runtime carried: the scan's ranges as the `f32` the agent was sent (its `ScanMsg`, a beam
//! without a return at the maximum range, not +inf as on `/robot_<i>/scan`), the heading and
//! goal as `f64`, and the wheel command as the `f64` pair the agent sent.
//!
//! A later change to the layout gets a new version (and a new constant), and a reader refuses a
//! version it does not know ([`ReplayError::Version`]).

use formation_proto::wire::TickOutcome;
use formation_proto::{Goal, WheelCmd};
use formation_ros2::cdr::{CdrEncodeError, CdrError, CdrReader, CdrWriter, DecodeLimits};
use formation_ros2::schema::MsgDefinition;

/// The version of the layout this crate writes and reads.
pub const FORMAT_VERSION: u8 = 1;

/// The ROS type name of the replay messages.
pub const TYPE_NAME: &str = "formation_msgs/msg/ReplayStep";

/// The replay topic of robot `robot`.
pub fn topic(robot: usize) -> String {
    formation_ros2::team::robot_topic(robot, "replay")
}

/// `formation_msgs/ReplayStep`, version 1. The outcome is what the world's watchdog made of the
/// command (in-process runs: fresh, or non-finite); `lag_ticks` is how many ticks before this
/// one the scan was published that the command answered (realtime runs; 0 otherwise), so a
/// replay feeds the agent the scan of tick `tick - lag_ticks` and compares with `left`/`right`.
pub static REPLAY_STEP: MsgDefinition = MsgDefinition {
    name: "formation_msgs/ReplayStep",
    fields: "uint8 FORMAT_VERSION=1\n\
             uint8 OUTCOME_FRESH=0\nuint8 OUTCOME_MISSING=1\nuint8 OUTCOME_STALE=2\n\
             uint8 OUTCOME_NON_FINITE=3\nuint8 OUTCOME_AGENT_FAILED=4\nuint8 OUTCOME_AGENT_DOWN=5\n\
             uint8 format_version\nuint32 robot\nuint64 tick\nfloat64 time\n\
             float64 heading\nfloat64 phi_star\nfloat64 d_star\nfloat64 v_star\n\
             float32 max_range\nfloat32[] ranges\n\
             float64 left\nfloat64 right\nuint8 outcome\nuint32 lag_ticks\nstring model_id\n",
    uses: &[],
};

/// One robot's tick, as the replay channel holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayStep {
    /// The robot.
    pub robot: u32,
    /// Tick index `k` within the run.
    pub tick: u64,
    /// Simulated time `k dt` \[s\].
    pub time: f64,
    /// The robot's own heading, its compass \[rad\].
    pub heading: f64,
    /// The goal it was given.
    pub goal: Goal,
    /// The LIDAR's maximum range \[m\]: a beam without a return reads this.
    pub max_range: f32,
    /// The ranges it was sent \[m\].
    pub ranges: Vec<f32>,
    /// The command it sent, as the world took it.
    pub command: WheelCmd,
    /// What the world's watchdog made of it.
    pub outcome: TickOutcome,
    /// How many ticks older than this one the scan was that the command answered.
    pub lag_ticks: u32,
    /// The model that decided (empty for the expert or when unknown).
    pub model_id: String,
}

/// Why a replay message could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Not valid CDR for the layout.
    #[error("a replay message is not valid CDR")]
    Cdr(#[from] CdrError),
    /// Written in a layout this build does not read.
    #[error(
        "a replay message has format version {found}; this build reads version {FORMAT_VERSION}: \
         use the formation version that recorded it"
    )]
    Version {
        /// The version the message says.
        found: u8,
    },
    /// The outcome code is not one of the definition's.
    #[error("a replay message has the unknown outcome code {0}")]
    Outcome(u8),
}

/// The code of an outcome in the definition (`OUTCOME_*`).
pub fn outcome_code(outcome: TickOutcome) -> u8 {
    match outcome {
        TickOutcome::Fresh => 0,
        TickOutcome::Missing => 1,
        TickOutcome::Stale => 2,
        TickOutcome::NonFinite => 3,
        TickOutcome::AgentFailed => 4,
        TickOutcome::AgentDown => 5,
    }
}

impl ReplayStep {
    /// The CDR payload.
    pub fn to_cdr(&self) -> Result<Vec<u8>, CdrEncodeError> {
        let mut w = CdrWriter::with_capacity(128 + 4 * self.ranges.len() + self.model_id.len());
        w.write_u8(FORMAT_VERSION);
        w.write_u32(self.robot);
        w.write_u64(self.tick);
        for v in [
            self.time,
            self.heading,
            self.goal.phi_star,
            self.goal.d_star,
            self.goal.v_star,
        ] {
            w.write_f64(v);
        }
        w.write_f32(self.max_range);
        w.write_f32_sequence("ranges", &self.ranges)?;
        w.write_f64(self.command.left);
        w.write_f64(self.command.right);
        w.write_u8(outcome_code(self.outcome));
        w.write_u32(self.lag_ticks);
        w.write_string("model_id", &self.model_id)?;
        Ok(w.into_bytes())
    }

    /// Decodes a payload, refusing another format version.
    pub fn from_cdr(payload: &[u8]) -> Result<ReplayStep, ReplayError> {
        let mut r = CdrReader::new(payload, DecodeLimits::default())?;
        let version = r.read_u8("format_version")?;
        if version != FORMAT_VERSION {
            return Err(ReplayError::Version { found: version });
        }
        let robot = r.read_u32("robot")?;
        let tick = r.read_u64("tick")?;
        let time = r.read_f64("time")?;
        let heading = r.read_f64("heading")?;
        let goal = Goal {
            phi_star: r.read_f64("phi_star")?,
            d_star: r.read_f64("d_star")?,
            v_star: r.read_f64("v_star")?,
        };
        let max_range = r.read_f32("max_range")?;
        let ranges = r.read_f32_sequence("ranges")?;
        let command = WheelCmd {
            left: r.read_f64("left")?,
            right: r.read_f64("right")?,
        };
        let code = r.read_u8("outcome")?;
        let outcome = *TickOutcome::ALL
            .get(usize::from(code))
            .ok_or(ReplayError::Outcome(code))?;
        Ok(ReplayStep {
            robot,
            tick,
            time,
            heading,
            goal,
            max_range,
            ranges,
            command,
            outcome,
            lag_ticks: r.read_u32("lag_ticks")?,
            model_id: r.read_string("model_id")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step() -> ReplayStep {
        ReplayStep {
            robot: 2,
            tick: 41,
            time: 2.05,
            heading: -0.1,
            goal: Goal {
                phi_star: 0.3,
                d_star: 1.5,
                v_star: 0.2,
            },
            max_range: 5.0,
            ranges: vec![1.25, 5.0, f32::from_bits(0x3f80_0001)],
            command: WheelCmd {
                left: f64::from_bits(0x3fd5_5555_5555_5556),
                right: -0.0,
            },
            outcome: TickOutcome::Stale,
            lag_ticks: 2,
            model_id: "paper@ab12".into(),
        }
    }

    #[test]
    fn a_step_round_trips_bit_for_bit() {
        let s = step();
        let back = ReplayStep::from_cdr(&s.to_cdr().unwrap()).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.command.right.to_bits(), (-0.0f64).to_bits());
        assert_eq!(back.ranges[2].to_bits(), 0x3f80_0001);
    }

    #[test]
    fn every_outcome_has_its_code_in_the_definition() {
        for outcome in TickOutcome::ALL {
            let code = outcome_code(outcome);
            assert_eq!(TickOutcome::ALL[usize::from(code)], outcome);
            let name = format!("OUTCOME_{}={code}\n", outcome.name().to_uppercase());
            assert!(REPLAY_STEP.fields.contains(&name), "{name}");
        }
        assert!(
            REPLAY_STEP
                .fields
                .starts_with(&format!("uint8 FORMAT_VERSION={FORMAT_VERSION}\n"))
        );
    }

    #[test]
    fn another_version_truncation_and_bad_codes_are_typed_errors() {
        let mut bytes = step().to_cdr().unwrap();
        for len in 0..bytes.len() {
            assert!(ReplayStep::from_cdr(&bytes[..len]).is_err(), "prefix {len}");
        }
        bytes[4] = 2;
        assert!(matches!(
            ReplayStep::from_cdr(&bytes),
            Err(ReplayError::Version { found: 2 })
        ));
    }
}
