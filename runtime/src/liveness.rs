//! When the world asks its transport which agents died.
//!
//! The question is dear where the transport answers it by listing every process of the run:
//! iceoryx2 opens, locks, stats and parses a file per node, which cost the world about 18 ms a
//! liveness period at 256 agents on 2 cores, half of all its work, and made its ticks late. An
//! agent whose message arrived less than a period ago was alive a moment ago, and one that dies
//! stops sending, so the world needs to ask only when an agent it waits for has been quiet for a
//! period.
//!
//! [`LivenessGate`] keeps that rule: when a liveness period ends, the transport is asked if an
//! agent that holds a robot sent nothing for at least a period, if a candidate was admitted and
//! has not said hello yet (it may die before it does), and in any case every
//! [`FULL_CHECK_EVERY`] periods (10 s at the default 100 ms), which also clears what dead strangers
//! left behind (between episodes, when agents are quiet, it is asked every period). Asked once a
//! second, the listing still made every 22nd tick of a 256-agent run late. A death is noticed at
//! the first period's end at least a period after the agent's last message. The gate is pure: the
//! exchange tells it what it heard and when, and when a period ends.

use std::time::{Duration, Instant};

/// The transport is asked at least once in this many liveness periods.
pub const FULL_CHECK_EVERY: u32 = 100;

/// When each robot's agent was last heard from, and how long the transport has not been asked.
#[derive(Debug, Clone)]
pub struct LivenessGate {
    last_heard: Vec<Option<Instant>>,
    periods_unasked: u32,
}

impl LivenessGate {
    /// A gate for `robots` robots, none heard yet.
    pub fn new(robots: usize) -> LivenessGate {
        LivenessGate {
            last_heard: vec![None; robots],
            periods_unasked: 0,
        }
    }

    /// A message of robot `robot`'s agent arrived at `now`.
    pub fn heard(&mut self, robot: usize, now: Instant) {
        if let Some(heard) = self.last_heard.get_mut(robot) {
            *heard = Some(now);
        }
    }

    /// A liveness period of length `period` ended at `now`: whether to ask the transport which
    /// agents died. `watched(robot)` says whether robot `robot` has an agent the world expects to
    /// hear from (one that said hello and has not been lost); `admission_pending` whether a
    /// candidate was admitted and has not said hello.
    pub fn period_ended(
        &mut self,
        now: Instant,
        period: Duration,
        watched: impl Fn(usize) -> bool,
        admission_pending: bool,
    ) -> bool {
        let quiet = |heard: Option<Instant>| {
            heard.is_none_or(|at| now.saturating_duration_since(at) >= period)
        };
        let someone_quiet = self
            .last_heard
            .iter()
            .enumerate()
            .any(|(robot, &heard)| quiet(heard) && watched(robot));
        let ask =
            someone_quiet || admission_pending || self.periods_unasked + 1 >= FULL_CHECK_EVERY;
        self.periods_unasked = if ask { 0 } else { self.periods_unasked + 1 };
        ask
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: Duration = Duration::from_millis(100);

    fn everyone(_: usize) -> bool {
        true
    }

    #[test]
    fn a_team_that_answers_every_tick_is_asked_about_once_in_a_hundred_periods() {
        let start = Instant::now();
        let mut gate = LivenessGate::new(3);
        let mut asked = Vec::new();
        // 50 ms ticks, a period ending every second tick.
        for tick in 0..500u32 {
            let now = start + Duration::from_millis(50) * tick;
            for robot in 0..3 {
                gate.heard(robot, now);
            }
            if tick % 2 == 1 {
                asked.push(gate.period_ended(now, PERIOD, everyone, false));
            }
        }
        let at: Vec<usize> = (0..asked.len()).filter(|&k| asked[k]).collect();
        assert_eq!(at, vec![99, 199]);
    }

    #[test]
    fn an_agent_quiet_for_a_period_is_asked_about_however_recently_the_last_period_ended() {
        let start = Instant::now();
        let mut gate = LivenessGate::new(2);
        gate.heard(0, start);
        gate.heard(1, start);
        assert!(!gate.period_ended(start + Duration::from_millis(5), PERIOD, everyone, false));
        // Robot 1 answers once more just after that period ended, then dies; robot 0 goes on.
        gate.heard(1, start + Duration::from_millis(10));
        gate.heard(0, start + Duration::from_millis(100));
        assert!(
            !gate.period_ended(start + Duration::from_millis(105), PERIOD, everyone, false),
            "robot 1 was heard 95 ms ago"
        );
        gate.heard(0, start + Duration::from_millis(200));
        assert!(
            gate.period_ended(start + Duration::from_millis(205), PERIOD, everyone, false),
            "robot 1 has been quiet for 195 ms"
        );
        assert!(
            gate.period_ended(start + Duration::from_millis(305), PERIOD, everyone, false),
            "and stays so until it is heard again"
        );
    }

    #[test]
    fn robots_without_an_agent_to_wait_for_do_not_force_the_question() {
        let start = Instant::now();
        let mut gate = LivenessGate::new(3);
        gate.heard(0, start);
        // Robot 1's agent is lost and robot 2 never had one.
        assert!(!gate.period_ended(start, PERIOD, |robot| robot == 0, false));
        assert!(
            gate.period_ended(start, PERIOD, |robot| robot == 0, true),
            "an admission pending"
        );
        assert!(
            gate.period_ended(start, PERIOD, everyone, false),
            "robots never heard from, once watched"
        );
    }

    #[test]
    fn a_message_from_a_robot_the_gate_does_not_know_is_ignored() {
        let start = Instant::now();
        let mut gate = LivenessGate::new(1);
        gate.heard(7, start);
        assert!(gate.period_ended(start, PERIOD, everyone, false));
    }
}
