//! The topics of a run and the messages each tick puts on them, defined once: a recording
//! ([`crate::file`]) writes them to MCAP, and the live view (`formation run --foxglove`, in
//! formation-cli) serves them over Foxglove's WebSocket protocol.
//!
//! Topics, in slot order ([`Topics::all`]): `/tf` (one TFMessage per robot and sample, world →
//! `robot_<i>/base_link`), `/tf_static` (each robot's fixed frames), the goal on
//! `/formation/goal/{heading,distance,speed}` (Float64), the edges on `/formation/edges`
//! (MarkerArray, [`crate::edges`]), then per robot `/robot_<i>/scan` (LaserScan),
//! `/robot_<i>/odom` (Odometry), `/robot_<i>/cmd_vel` (Twist) and `/robot_<i>/replay`
//! ([`crate::replay`], recordings only). Every message is CDR with its `ros2msg` schema, the
//! message of the live ROS 2 team ([`formation_ros2::team`]), stamped with the tick's simulated
//! time.

use formation_ros2::msg::Time;
use formation_ros2::schema::MsgDefinition;
use formation_ros2::team::{self, GOAL_TOPICS};
use formation_ros2::{
    CdrEncodeError, Float64, LaserScan, MarkerArray, Odometry, RosMessage, TfMessage, Twist,
};

use crate::edges::{self, EdgeMarkers};
use crate::replay::{self, ReplayStep};
use crate::setup::TeamSetup;
use crate::tick::{FinalSample, SentCommand, TickRecord};

/// Where a topic sits in [`Topics::all`].
pub type Slot = usize;

/// One topic: its name and its ROS 2 message type.
#[derive(Debug, Clone)]
pub struct Topic {
    /// The topic, e.g. `/robot_0/scan`.
    pub name: String,
    /// The ROS interface name, `package/msg/Name`.
    pub type_name: &'static str,
    /// The type's definition (its `ros2msg` schema text).
    pub definition: &'static MsgDefinition,
}

impl Topic {
    fn of<M: RosMessage>(name: impl Into<String>) -> Topic {
        Topic {
            name: name.into(),
            type_name: M::ROS_NAME,
            definition: M::DEFINITION,
        }
    }
}

/// The slots of a team's topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Topics;

impl Topics {
    /// `/tf`.
    pub const TF: Slot = 0;
    /// `/tf_static`.
    pub const TF_STATIC: Slot = 1;
    /// The goal's heading, distance and speed.
    pub const GOAL: [Slot; 3] = [2, 3, 4];
    /// `/formation/edges`.
    pub const EDGES: Slot = 5;
    const FIRST_ROBOT: Slot = 6;
    const PER_ROBOT: Slot = 4;

    /// Robot `robot`'s scan.
    pub const fn scan(robot: usize) -> Slot {
        Self::FIRST_ROBOT + Self::PER_ROBOT * robot
    }

    /// Robot `robot`'s odometry.
    pub const fn odom(robot: usize) -> Slot {
        Self::scan(robot) + 1
    }

    /// Robot `robot`'s commanded Twist.
    pub const fn cmd_vel(robot: usize) -> Slot {
        Self::scan(robot) + 2
    }

    /// Robot `robot`'s replay channel (recordings only).
    pub const fn replay(robot: usize) -> Slot {
        Self::scan(robot) + 3
    }

    /// Whether `slot` is a replay channel: what an agent received and sent, for `formation
    /// replay`, which a recording holds and a live view leaves out.
    pub const fn is_replay(slot: Slot) -> bool {
        slot >= Self::FIRST_ROBOT && (slot - Self::FIRST_ROBOT) % Self::PER_ROBOT == 3
    }

    /// Every topic of a team of `n_robots`, in slot order.
    pub fn all(n_robots: usize) -> Vec<Topic> {
        let mut topics = vec![
            Topic::of::<TfMessage>("/tf"),
            Topic::of::<TfMessage>("/tf_static"),
        ];
        topics.extend(GOAL_TOPICS.iter().map(|t| Topic::of::<Float64>(*t)));
        topics.push(Topic::of::<MarkerArray>(edges::TOPIC));
        for robot in 0..n_robots {
            topics.push(Topic::of::<LaserScan>(team::robot_topic(robot, "scan")));
            topics.push(Topic::of::<Odometry>(team::robot_topic(robot, "odom")));
            topics.push(Topic::of::<Twist>(team::robot_topic(robot, "cmd_vel")));
            topics.push(Topic {
                name: replay::topic(robot),
                type_name: replay::TYPE_NAME,
                definition: &replay::REPLAY_STEP,
            });
        }
        topics
    }
}

/// Why a tick's messages were not all handed on.
#[derive(Debug, thiserror::Error)]
pub enum MessageError<E> {
    /// A message could not be encoded (a string with a NUL, a sequence too long for CDR).
    #[error("a {topic} message could not be encoded")]
    Encode {
        /// The topic.
        topic: String,
        /// Why.
        #[source]
        source: CdrEncodeError,
    },
    /// What takes the messages failed.
    #[error(transparent)]
    Sink(E),
}

/// What takes each encoded message: its slot, its time \[ns\] and its CDR bytes.
pub type Emit<'a, E> = dyn FnMut(Slot, u64, &[u8]) -> Result<(), E> + 'a;

/// Simulated time `t` \[s\] in nanoseconds (0 for a negative or non-finite time).
pub fn nanos(t: f64) -> u64 {
    let ns = (t * 1e9).round();
    if ns.is_finite() && ns > 0.0 {
        ns as u64
    } else {
        0
    }
}

/// A ROS time of `ns` nanoseconds.
pub(crate) fn stamp(ns: u64) -> Time {
    Time::from_nanos(i64::try_from(ns).unwrap_or(i64::MAX))
}

/// Whether the replay channel is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replay {
    /// Encoded (a recording).
    Included,
    /// Left out (a live view).
    Left,
}

/// The messages of one run's ticks, tick after tick (the edges follow the team).
#[derive(Debug)]
pub struct TickMessages {
    team: TeamSetup,
    edges: EdgeMarkers,
    replay: Replay,
    /// Every robot's `/tf` in one message a tick ([`TickMessages::with_one_tf_message`]).
    one_tf: bool,
    /// Each robot's last known model (a tick may leave it out).
    model_ids: Vec<String>,
}

fn put<M: RosMessage, E>(
    emit: &mut Emit<'_, E>,
    slot: Slot,
    ns: u64,
    msg: &M,
    topic: impl FnOnce() -> String,
) -> Result<(), MessageError<E>> {
    let data = msg.to_cdr().map_err(|source| MessageError::Encode {
        topic: topic(),
        source,
    })?;
    emit(slot, ns, &data).map_err(MessageError::Sink)
}

impl TickMessages {
    /// For the team `team`, before its first tick.
    pub fn new(team: TeamSetup, replay: Replay) -> TickMessages {
        TickMessages {
            edges: EdgeMarkers::new(team.neighbours, team.n_robots),
            team,
            replay,
            one_tf: false,
            model_ids: Vec::new(),
        }
    }

    /// The same, with every robot's `/tf` transform in one `TFMessage` a tick instead of one a
    /// robot (a live view, where each message costs the world about the same whatever its
    /// size; a recording keeps one a robot).
    pub fn with_one_tf_message(mut self) -> TickMessages {
        self.one_tf = true;
        self
    }

    /// The team.
    pub fn team(&self) -> &TeamSetup {
        &self.team
    }

    /// Each robot's fixed frames on `/tf_static`, at time 0.
    pub fn static_frames<E>(&self, emit: &mut Emit<'_, E>) -> Result<(), MessageError<E>> {
        for robot in 0..self.team.n_robots {
            let tf = team::static_tf_message(robot, Time::default());
            put(emit, Topics::TF_STATIC, 0, &tf, || "/tf_static".into())?;
        }
        Ok(())
    }

    /// One tick's messages: the goal, each robot's `/tf`, odometry, scan, command (and replay
    /// step), and the edges.
    pub fn tick<E>(
        &mut self,
        tick: &TickRecord,
        emit: &mut Emit<'_, E>,
    ) -> Result<(), MessageError<E>> {
        let ns = nanos(tick.time);
        let at = stamp(ns);
        let goal = [tick.goal.phi_star, tick.goal.d_star, tick.goal.v_star];
        for (slot, data) in goal.into_iter().enumerate() {
            put(emit, Topics::GOAL[slot], ns, &Float64 { data }, || {
                GOAL_TOPICS[slot].into()
            })?;
        }
        let n = self.team.n_robots.min(tick.poses.len());
        if self.one_tf {
            let mut tf = TfMessage {
                transforms: Vec::with_capacity(n),
            };
            for (robot, pose) in tick.poses.iter().enumerate().take(n) {
                let own = team::tf_message(robot, at, pose.x, pose.y, pose.theta);
                tf.transforms.extend(own.transforms);
            }
            put(emit, Topics::TF, ns, &tf, || "/tf".into())?;
        }
        for robot in 0..n {
            self.robot(robot, tick, ns, at, emit)?;
        }
        let markers = self.edges.next(at, &tick.poses, tick.goal.d_star);
        put(emit, Topics::EDGES, ns, &markers, || edges::TOPIC.into())
    }

    fn robot<E>(
        &mut self,
        robot: usize,
        tick: &TickRecord,
        ns: u64,
        at: Time,
        emit: &mut Emit<'_, E>,
    ) -> Result<(), MessageError<E>> {
        let pose = tick.poses[robot];
        let separation = self.team.wheel_separation;
        if !self.one_tf {
            let tf = team::tf_message(robot, at, pose.x, pose.y, pose.theta);
            put(emit, Topics::TF, ns, &tf, || "/tf".into())?;
        }
        let speeds = tick.wheel_speeds.get(robot).copied().unwrap_or_default();
        let wheels = team::Wheels {
            left: speeds.left,
            right: speeds.right,
            separation,
        };
        let odom = team::odometry_message(robot, at, (pose.x, pose.y), pose.theta, wheels);
        put(emit, Topics::odom(robot), ns, &odom, || {
            team::robot_topic(robot, "odom")
        })?;
        let ranges: &[f32] = tick.scans.get(robot).map_or(&[], Vec::as_slice);
        let scan = team::laser_scan_message(robot, at, ranges, self.team.max_range);
        put(emit, Topics::scan(robot), ns, &scan, || {
            team::robot_topic(robot, "scan")
        })?;
        let sent = tick.commands.get(robot).copied();
        let command = sent.map_or_else(Default::default, |c| c.wheels);
        let cmd_vel = team::Wheels {
            left: command.left,
            right: command.right,
            separation,
        };
        put(emit, Topics::cmd_vel(robot), ns, &cmd_vel.twist(), || {
            team::robot_topic(robot, "cmd_vel")
        })?;
        if self.replay == Replay::Included {
            self.replay_step(robot, tick, ns, emit)?;
        }
        Ok(())
    }

    fn replay_step<E>(
        &mut self,
        robot: usize,
        tick: &TickRecord,
        ns: u64,
        emit: &mut Emit<'_, E>,
    ) -> Result<(), MessageError<E>> {
        let sent = tick
            .commands
            .get(robot)
            .copied()
            .unwrap_or_else(|| SentCommand::in_process(Default::default()));
        if let Some(id) = tick.model_ids.get(robot) {
            if self.model_ids.len() <= robot {
                self.model_ids.resize(robot + 1, String::new());
            }
            if self.model_ids[robot] != *id {
                self.model_ids[robot].clone_from(id);
            }
        }
        let step = ReplayStep {
            robot: u32::try_from(robot).unwrap_or(u32::MAX),
            tick: tick.tick,
            time: tick.time,
            heading: tick.poses[robot].theta,
            goal: tick.goal,
            max_range: self.team.max_range as f32,
            ranges: tick.scans.get(robot).cloned().unwrap_or_default(),
            command: sent.wheels,
            outcome: sent.outcome,
            lag_ticks: sent.lag_ticks,
            model_id: self.model_ids.get(robot).cloned().unwrap_or_default(),
        };
        let data = step.to_cdr().map_err(|source| MessageError::Encode {
            topic: replay::topic(robot),
            source,
        })?;
        emit(Topics::replay(robot), ns, &data).map_err(MessageError::Sink)
    }

    /// The state after the last step, which no tick precedes: each robot's `/tf` and the edges
    /// at distance `d_star`.
    pub fn last<E>(
        &mut self,
        last: &FinalSample,
        d_star: f64,
        emit: &mut Emit<'_, E>,
    ) -> Result<(), MessageError<E>> {
        let ns = nanos(last.time);
        let at = stamp(ns);
        for (robot, pose) in last.poses.iter().enumerate() {
            let tf = team::tf_message(robot, at, pose.x, pose.y, pose.theta);
            put(emit, Topics::TF, ns, &tf, || "/tf".into())?;
        }
        let markers = self.edges.next(at, &last.poses, d_star);
        put(emit, Topics::EDGES, ns, &markers, || edges::TOPIC.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::{Goal, NeighbourRule, Pose, WheelCmd};

    fn team(n: usize) -> TeamSetup {
        TeamSetup {
            n_robots: n,
            max_range: 5.0,
            wheel_separation: 0.331,
            neighbours: NeighbourRule::AllPairs,
            wheels: formation_proto::WheelLimits::default(),
        }
    }

    fn tick(n: usize) -> TickRecord {
        TickRecord {
            tick: 3,
            time: 0.15,
            goal: Goal::new(0.5, 1.0, 0.7),
            poses: (0..n)
                .map(|i| Pose {
                    x: i as f64,
                    y: 0.0,
                    theta: 0.0,
                })
                .collect(),
            wheel_speeds: vec![WheelCmd::default(); n],
            scans: vec![vec![1.0; 8]; n],
            commands: vec![SentCommand::in_process(WheelCmd::default()); n],
            model_ids: Vec::new(),
        }
    }

    #[test]
    fn the_slots_name_the_topics_in_order() {
        let topics = Topics::all(2);
        assert_eq!(topics.len(), Topics::replay(1) + 1);
        assert_eq!(topics[Topics::TF].name, "/tf");
        assert_eq!(topics[Topics::TF_STATIC].name, "/tf_static");
        assert_eq!(topics[Topics::EDGES].name, "/formation/edges");
        assert_eq!(topics[Topics::scan(1)].name, "/robot_1/scan");
        assert_eq!(
            topics[Topics::scan(1)].type_name,
            "sensor_msgs/msg/LaserScan"
        );
        assert_eq!(topics[Topics::odom(0)].name, "/robot_0/odom");
        assert_eq!(topics[Topics::cmd_vel(1)].name, "/robot_1/cmd_vel");
        assert_eq!(topics[Topics::replay(1)].name, "/robot_1/replay");
        let replays: Vec<Slot> = (0..topics.len())
            .filter(|&s| Topics::is_replay(s))
            .collect();
        assert_eq!(replays, [Topics::replay(0), Topics::replay(1)]);
    }

    #[test]
    fn a_tick_without_replay_puts_every_viewed_topic_once() {
        let mut messages = TickMessages::new(team(2), Replay::Left);
        let mut seen = Vec::new();
        messages
            .tick::<()>(&tick(2), &mut |slot, ns, data| {
                assert_eq!(ns, 150_000_000);
                assert!(!data.is_empty());
                seen.push(slot);
                Ok(())
            })
            .unwrap();
        // Per robot: /tf, odom, scan and cmd_vel; the goal's three and the edges.
        assert_eq!(seen.len(), 3 + 2 * 4 + 1);
        assert!(!seen.iter().any(|&s| Topics::is_replay(s)));
        let mut with_replay = TickMessages::new(team(2), Replay::Included);
        let mut count = 0;
        with_replay
            .tick::<()>(&tick(2), &mut |_, _, _| {
                count += 1;
                Ok(())
            })
            .unwrap();
        assert_eq!(count, seen.len() + 2);
    }

    #[test]
    fn one_tf_message_carries_every_robots_transform_once_a_tick() {
        let mut per_robot = Vec::new();
        TickMessages::new(team(3), Replay::Left)
            .tick::<()>(&tick(3), &mut |slot, _, data| {
                if slot == Topics::TF {
                    per_robot.push(data.to_vec());
                }
                Ok(())
            })
            .unwrap();
        let mut one = Vec::new();
        let mut others = 0;
        TickMessages::new(team(3), Replay::Left)
            .with_one_tf_message()
            .tick::<()>(&tick(3), &mut |slot, _, data| {
                if slot == Topics::TF {
                    one.push(data.to_vec());
                } else {
                    others += 1;
                }
                Ok(())
            })
            .unwrap();
        assert_eq!((per_robot.len(), one.len()), (3, 1));
        assert_eq!(others, 3 + 3 * 3 + 1, "the other topics as before");
        let expected = TfMessage {
            transforms: (0..3)
                .flat_map(|r| {
                    team::tf_message(r, stamp(150_000_000), r as f64, 0.0, 0.0).transforms
                })
                .collect(),
        };
        assert_eq!(one[0], expected.to_cdr().unwrap());
    }

    #[test]
    fn a_failing_sink_stops_the_tick_with_its_error() {
        let mut messages = TickMessages::new(team(2), Replay::Left);
        let failed = messages.tick(&tick(2), &mut |_, _, _| Err("full"));
        assert!(matches!(failed, Err(MessageError::Sink("full"))));
    }
}
