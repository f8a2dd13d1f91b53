//! What a ROS 2 agent makes of what it received, without I/O: [`Decider`] readies each
//! LaserScan, with the newest orientation and goal, for the pilot that the runtime's agent loop
//! drives ([`Decider::on_scan`]: the scan on the model's ring, the heading, the goal), turns the
//! pilot's wheel speeds into one Twist for the robot's `cmd_vel` ([`Decider::on_wheels`]), or
//! gives the reason to brake; and it notices when the scans stop.
//!
//! The rules (the robot brakes, and the reason is told once, on each of these):
//! - a scan that cannot be put on the model's ring ([`formation_ros2::resample_scan`]: a partial
//!   circle unless allowed, bad angles or limits), or one where more than a quarter of the
//!   readings are NaN (REP-117: an erroneous measurement, unlike ±inf, which is no return; a few
//!   NaNs are taken as no return, as ROS drivers emit them for glass and dust);
//! - no orientation yet, an orientation older than the stale window (measured on this host's
//!   clock, at the scan's arrival), or one without a heading;
//! - a goal value not received yet;
//! - a decision the pilot refuses (a goal outside the model's envelope, a non-finite output:
//!   [`Decider::on_failed_decision`], or wheel speeds that make no Twist);
//! - no scan for the stale window ([`Decider::check_stale`]).
//!
//! Every scan the agent takes gets exactly one answer, stamped with the scan's own stamp, so a
//! tool, or the simulated team in lockstep, can tell which scan a Twist answers. Scans that come
//! faster than the agent decides are superseded: each decision takes the newest, and the older
//! ones go unanswered (a robot must act on what it sees now). Staleness is measured on arrival
//! at this host, so the robot's clock and this host's need not agree.

use std::time::{Duration, Instant};

use formation_proto::{Goal, WheelCmd};
use formation_ros2::{
    LaserScan, PartialScan, RingContract, Twist, resample_scan, twist_from_wheels,
};

/// Where a goal component comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum GoalValue {
    /// A fixed value given on the command line.
    Fixed(f64),
    /// The newest `std_msgs/Float64` on this topic.
    Topic(formation_ros2::TopicName),
}

/// The newest inputs besides the scan, as the subscriptions left them.
#[derive(Debug, Clone, Default)]
pub struct Inputs {
    /// The newest heading \[rad\] (or why the newest orientation had none) and when it arrived.
    pub orientation: Option<(Result<f64, String>, Instant)>,
    /// φ\*, d\*, v\* as far as known.
    pub goal: [Option<f64>; 3],
}

/// The goal components' names, for messages.
pub const GOAL_NAMES: [&str; 3] = [
    "the goal heading φ*",
    "the goal distance d*",
    "the goal speed v*",
];

/// A scan ready for the pilot: its readings on the model's ring, and the heading and goal to
/// decide with.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadyScan {
    /// The readings, resampled onto the model's ring \[m\].
    pub ranges: Vec<f32>,
    /// The robot's heading \[rad\], from the newest orientation.
    pub heading: f64,
    /// The goal, from the fixed values and the goal topics.
    pub goal: Goal,
}

/// What to send for a scan.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// Drive with this Twist.
    Drive(Twist),
    /// Brake (a zero Twist), for this reason.
    Brake(String),
}

/// Fixed facts of the agent: its topics (for messages), the model's ring, the robot.
#[derive(Debug, Clone)]
pub struct DeciderSettings {
    /// The scan topic.
    pub scan_topic: String,
    /// The orientation topic.
    pub orientation_topic: String,
    /// Where each goal component comes from, in [`GOAL_NAMES`] order.
    pub goal: [GoalValue; 3],
    /// The model's LIDAR ring.
    pub contract: RingContract,
    /// Whether a scan that does not cover the full circle is allowed (uncovered bearings read as
    /// no return).
    pub partial: PartialScan,
    /// An input older than this brakes the robot.
    pub stale: Duration,
    /// The robot's wheel separation \[m\].
    pub wheel_separation: f64,
}

/// The stale window a ROS 2 agent uses unless told otherwise (`--stale-ms`): 500 ms, the
/// `cmd_vel` timeout of ROS 2's `diff_drive_controller`, so the agent brakes no sooner than the
/// robot's own controller would. Real LIDARs publish at 5–20 Hz: at 10 Hz a scan is 100 ms
/// apart, and a window of one simulated tick (the launcher's 150 ms) would brake the robot on
/// one late scan. The simulated team passes the launcher's window explicitly.
pub const DEFAULT_STALE: Duration = Duration::from_millis(500);

/// The agent's decision state: the last reason it braked for, and when the last scan came.
#[derive(Debug)]
pub struct Decider {
    settings: DeciderSettings,
    braking_for: Option<String>,
    last_scan_at: Option<Instant>,
    started_at: Instant,
    warned_partial: bool,
}

/// More than this share of NaN readings marks a scan as erroneous.
const NAN_SHARE_LIMIT: f64 = 0.25;

impl Decider {
    /// A decider that starts waiting at `now`.
    pub fn new(settings: DeciderSettings, now: Instant) -> Decider {
        Decider {
            settings,
            braking_for: None,
            last_scan_at: None,
            started_at: now,
            warned_partial: false,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &DeciderSettings {
        &self.settings
    }

    /// The goal from the fixed values and the inputs, or the first missing component.
    fn goal(&self, inputs: &Inputs) -> Result<Goal, String> {
        let mut values = [0.0; 3];
        for (i, value) in values.iter_mut().enumerate() {
            *value = match (&self.settings.goal[i], inputs.goal[i]) {
                (GoalValue::Fixed(v), _) => *v,
                (GoalValue::Topic(_), Some(v)) => v,
                (GoalValue::Topic(topic), None) => {
                    return Err(format!(
                        "waiting for {} on {topic} (std_msgs/msg/Float64)",
                        GOAL_NAMES[i]
                    ));
                }
            };
        }
        Ok(Goal {
            phi_star: values[0],
            d_star: values[1],
            v_star: values[2],
        })
    }

    /// The heading to decide with, from the newest orientation.
    fn heading(&self, inputs: &Inputs, now: Instant) -> Result<f64, String> {
        let topic = &self.settings.orientation_topic;
        match &inputs.orientation {
            None => Err(format!("no orientation received on {topic} yet")),
            Some((_, at)) if now.saturating_duration_since(*at) > self.settings.stale => {
                Err(format!(
                    "the newest orientation on {topic} is {:.2} s old (the stale window is {:.2} s); is its publisher alive?",
                    now.saturating_duration_since(*at).as_secs_f64(),
                    self.settings.stale.as_secs_f64()
                ))
            }
            Some((Err(reason), _)) => Err(format!("the orientation on {topic}: {reason}")),
            Some((Ok(yaw), _)) => Ok(*yaw),
        }
    }

    /// Takes `scan`, arrived at `now`: what the pilot decides on with the newest `inputs` (the
    /// scan on the model's ring, the heading, the goal), or the reason to brake.
    pub fn on_scan(
        &mut self,
        scan: &LaserScan,
        inputs: &Inputs,
        now: Instant,
    ) -> Result<ReadyScan, String> {
        self.last_scan_at = Some(now);
        let ready = self.ready(scan, inputs, now);
        self.braking_for = ready.as_ref().err().cloned();
        ready
    }

    fn ready(
        &mut self,
        scan: &LaserScan,
        inputs: &Inputs,
        now: Instant,
    ) -> Result<ReadyScan, String> {
        let topic = &self.settings.scan_topic;
        let nans = scan.ranges.iter().filter(|r| r.is_nan()).count();
        if !scan.ranges.is_empty() && nans as f64 > NAN_SHARE_LIMIT * scan.ranges.len() as f64 {
            return Err(format!(
                "the LaserScan on {topic} has {nans} NaN readings of {} (NaN marks an erroneous \
                 measurement; more than a quarter means the sensor is failing)",
                scan.ranges.len()
            ));
        }
        let resampled = resample_scan(scan, self.settings.contract, self.settings.partial)
            .map_err(|e| format!("the LaserScan on {topic}: {e}"))?;
        if resampled.uncovered_beams > 0 && !self.warned_partial {
            self.warned_partial = true;
            tracing::warn!(
                "the LaserScan on {topic} leaves {} of the model's {} bearings uncovered; they \
                 read as no return",
                resampled.uncovered_beams,
                self.settings.contract.beams
            );
        }
        let heading = self.heading(inputs, now)?;
        let goal = self.goal(inputs)?;
        Ok(ReadyScan {
            ranges: resampled.ranges,
            heading,
            goal,
        })
    }

    /// The answer to the wheel speeds the pilot decided on the scan last taken: a Twist, or a
    /// brake when they make none.
    pub fn on_wheels(&mut self, wheels: WheelCmd) -> Answer {
        let answer =
            match twist_from_wheels(wheels.left, wheels.right, self.settings.wheel_separation) {
                Ok(twist) => Answer::Drive(twist),
                Err(e) => Answer::Brake(format!("the decision failed: {e}")),
            };
        self.braking_for = match &answer {
            Answer::Drive(_) => None,
            Answer::Brake(reason) => Some(reason.clone()),
        };
        answer
    }

    /// The brake for the scan last taken when the pilot could not decide on it (`why`: the
    /// error's chain).
    pub fn on_failed_decision(&mut self, why: &str) -> Answer {
        let reason = format!("the decision failed: {why}");
        self.braking_for = Some(reason.clone());
        Answer::Brake(reason)
    }

    /// At `now`: the reason to brake when no scan came for the stale window and the robot was
    /// not braked already (once per stall), else `None`.
    pub fn check_stale(&mut self, now: Instant) -> Option<String> {
        let since = self.last_scan_at.unwrap_or(self.started_at);
        let silent = now.saturating_duration_since(since);
        if silent <= self.settings.stale {
            return None;
        }
        let reason = match self.last_scan_at {
            Some(_) => format!(
                "no LaserScan on {} for {:.2} s (the stale window is {:.2} s)",
                self.settings.scan_topic,
                silent.as_secs_f64(),
                self.settings.stale.as_secs_f64()
            ),
            None => format!(
                "no LaserScan received on {} yet; is the topic right and its publisher up?",
                self.settings.scan_topic
            ),
        };
        // A stall is told once, and so is a stall right after a braking answer.
        if self
            .braking_for
            .as_ref()
            .is_some_and(|current| current.starts_with("no LaserScan"))
        {
            return None;
        }
        self.braking_for = Some(reason.clone());
        Some(reason)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_proto::WheelCmd;
    use formation_ros2::TopicName;
    use formation_runtime::agent::{BoxError, Pilot};
    use std::f64::consts::TAU;

    /// A pilot that drives both wheels at d* m/s and records what it was given.
    #[derive(Default)]
    struct Recorder {
        ranges: Vec<f32>,
        heading: Option<f64>,
        refuse: bool,
    }

    impl Pilot for Recorder {
        type Model = ();
        fn model_id(&self) -> &str {
            "recorder"
        }
        fn perceive(&mut self, ranges: &[f32], _goal: &Goal) -> Result<(), BoxError> {
            self.ranges = ranges.to_vec();
            Ok(())
        }
        fn decide(&mut self, heading: f64, goal: &Goal) -> Result<WheelCmd, BoxError> {
            if self.refuse {
                return Err("d* 3 m is outside the model's range 0.8–2.5 m".into());
            }
            self.heading = Some(heading);
            Ok(WheelCmd {
                left: goal.d_star,
                right: goal.d_star + 0.1,
            })
        }
        fn swap(&mut self, _model: ()) -> Result<(), BoxError> {
            Ok(())
        }
        fn set_wheel_limits(&mut self, _wheels: formation_proto::WheelLimits) {}
    }

    /// What the agent loop and the link make of `scan` with `pilot`: the ready scan decided on,
    /// then answered.
    fn answer(
        decider: &mut Decider,
        scan: &LaserScan,
        inputs: &Inputs,
        now: Instant,
        pilot: &mut Recorder,
    ) -> Answer {
        let ready = match decider.on_scan(scan, inputs, now) {
            Ok(ready) => ready,
            Err(reason) => return Answer::Brake(reason),
        };
        let decided = pilot
            .perceive(&ready.ranges, &ready.goal)
            .and_then(|()| pilot.decide(ready.heading, &ready.goal));
        match decided {
            Ok(wheels) => decider.on_wheels(wheels),
            Err(e) => decider.on_failed_decision(&e.to_string()),
        }
    }

    fn settings(partial: PartialScan) -> DeciderSettings {
        DeciderSettings {
            scan_topic: "/scan".into(),
            orientation_topic: "/imu".into(),
            goal: [
                GoalValue::Fixed(0.5),
                GoalValue::Topic(TopicName::new("/formation/goal/distance").unwrap()),
                GoalValue::Fixed(0.7),
            ],
            contract: RingContract {
                beams: 8,
                max_range: 10.0,
            },
            partial,
            stale: DEFAULT_STALE,
            wheel_separation: 0.331,
        }
    }

    fn scan(n: usize, span: f64, reading: impl Fn(usize) -> f32) -> LaserScan {
        let increment = (span / n as f64) as f32;
        LaserScan {
            angle_increment: increment,
            angle_max: increment * (n - 1) as f32,
            range_max: 30.0,
            ranges: (0..n).map(reading).collect(),
            ..LaserScan::default()
        }
    }

    /// A decider refusing partial scans, started at `start`, a fresh recording pilot, and a full
    /// scan of 16 beams all at 3 m.
    fn refusing_with_a_full_scan(start: Instant) -> (Decider, Recorder, LaserScan) {
        (
            Decider::new(settings(PartialScan::Refuse), start),
            Recorder::default(),
            scan(16, TAU, |_| 3.0),
        )
    }

    fn fresh(now: Instant) -> Inputs {
        Inputs {
            orientation: Some((Ok(0.25), now)),
            goal: [None, Some(1.5), None],
        }
    }

    #[test]
    fn a_full_scan_with_fresh_inputs_drives_with_the_pilots_wheels() {
        let now = Instant::now();
        let mut decider = Decider::new(settings(PartialScan::Refuse), now);
        let mut pilot = Recorder::default();
        let answer = answer(
            &mut decider,
            &scan(16, TAU, |i| i as f32),
            &fresh(now),
            now,
            &mut pilot,
        );
        let expected = twist_from_wheels(1.5, 1.6, 0.331).unwrap();
        assert_eq!(answer, Answer::Drive(expected));
        assert_eq!(pilot.heading, Some(0.25));
        assert_eq!(pilot.ranges, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 10.0, 10.0]);
    }

    #[test]
    fn missing_stale_or_broken_inputs_brake_with_the_reason() {
        let now = Instant::now();
        let (mut decider, mut pilot, full) = refusing_with_a_full_scan(now);
        let brake = |answer: Answer| match answer {
            Answer::Brake(reason) => reason,
            other => panic!("expected a brake, got {other:?}"),
        };

        let no_goal = Inputs {
            goal: [None; 3],
            ..fresh(now)
        };
        let reason = brake(answer(&mut decider, &full, &no_goal, now, &mut pilot));
        assert!(reason.contains("/formation/goal/distance"), "{reason}");

        let no_orientation = Inputs {
            orientation: None,
            ..fresh(now)
        };
        let reason = brake(answer(
            &mut decider,
            &full,
            &no_orientation,
            now,
            &mut pilot,
        ));
        assert!(
            reason.contains("no orientation received on /imu"),
            "{reason}"
        );

        let later = now + Duration::from_secs(2);
        let reason = brake(answer(&mut decider, &full, &fresh(now), later, &mut pilot));
        assert!(reason.contains("2.00 s old"), "{reason}");

        let half = scan(8, TAU / 2.0, |_| 3.0);
        let reason = brake(answer(&mut decider, &half, &fresh(now), now, &mut pilot));
        assert!(reason.contains("needs the full 360°"), "{reason}");

        let nan = scan(16, TAU, |i| if i % 2 == 0 { f32::NAN } else { 3.0 });
        let reason = brake(answer(&mut decider, &nan, &fresh(now), now, &mut pilot));
        assert!(reason.contains("8 NaN readings of 16"), "{reason}");

        pilot.refuse = true;
        let reason = brake(answer(&mut decider, &full, &fresh(now), now, &mut pilot));
        assert!(reason.contains("outside the model's range"), "{reason}");
    }

    #[test]
    fn a_partial_scan_may_be_allowed_and_a_few_nans_read_as_no_return() {
        let now = Instant::now();
        let mut decider = Decider::new(settings(PartialScan::AllowAsNoReturn), now);
        let mut pilot = Recorder::default();
        let half = scan(8, TAU / 2.0, |i| if i == 2 { f32::NAN } else { 3.0 });
        assert!(matches!(
            answer(&mut decider, &half, &fresh(now), now, &mut pilot),
            Answer::Drive(_)
        ));
        assert_eq!(pilot.ranges, [3.0, 10.0, 3.0, 3.0, 10.0, 10.0, 10.0, 10.0]);
    }

    #[test]
    fn a_stall_brakes_once_until_scans_come_again() {
        let start = Instant::now();
        let (mut decider, mut pilot, full) = refusing_with_a_full_scan(start);
        assert_eq!(
            decider.check_stale(start + Duration::from_millis(400)),
            None
        );
        let first = decider.check_stale(start + Duration::from_secs(1)).unwrap();
        assert!(
            first.contains("no LaserScan received on /scan yet"),
            "{first}"
        );
        assert_eq!(decider.check_stale(start + Duration::from_secs(2)), None);

        let at = start + Duration::from_secs(3);
        assert!(matches!(
            answer(&mut decider, &full, &fresh(at), at, &mut pilot),
            Answer::Drive(_)
        ));
        assert_eq!(decider.check_stale(at + Duration::from_millis(100)), None);
        let stall = decider.check_stale(at + Duration::from_secs(1)).unwrap();
        assert!(
            stall.contains("no LaserScan on /scan for 1.00 s"),
            "{stall}"
        );
        assert_eq!(decider.check_stale(at + Duration::from_secs(5)), None);
    }

    /// A 10 Hz LIDAR whose scans come late, by up to four periods, and a compass published with
    /// them: under the default window the robot keeps driving; only a real stall brakes it.
    #[test]
    fn the_default_window_rides_out_late_scans_of_a_10_hz_lidar() {
        let start = Instant::now();
        let (mut decider, mut pilot, full) = refusing_with_a_full_scan(start);
        let mut at = start;
        let mut orientation_at = start;
        for gap_ms in [100, 100, 250, 100, 450, 100] {
            at += Duration::from_millis(gap_ms);
            assert_eq!(decider.check_stale(at), None, "after a gap of {gap_ms} ms");
            // The orientation of the previous scan is the newest when this one arrives.
            let inputs = Inputs {
                orientation: Some((Ok(0.25), orientation_at)),
                goal: [None, Some(1.5), None],
            };
            assert!(
                matches!(
                    answer(&mut decider, &full, &inputs, at, &mut pilot),
                    Answer::Drive(_)
                ),
                "a scan {gap_ms} ms after the last one drives"
            );
            orientation_at = at;
        }
        assert!(
            decider
                .check_stale(at + Duration::from_millis(600))
                .is_some()
        );
    }
}
