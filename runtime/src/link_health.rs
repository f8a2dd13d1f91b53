//! Telling the user, while the run goes on, that a robot's link is degraded.
//!
//! A watchdog that brakes a robot now and then keeps the run safe, but a link that loses or delays
//! enough commands changes what the run measures, and the files say so only afterwards.
//! [`LinkMonitor`] watches one robot's tick outcomes in a sliding window of
//! [`DEGRADED_WINDOW`] of the run's time: when more than
//! [`DEGRADED_SHARE_PERCENT`] % of the window's
//! ticks (of a full window, so a short start cannot trip it) were braked, it returns a
//! [`WorldEvent::LinkDegraded`] naming the robot, the braked ticks by reason and the newest round
//! trip, at most once per [`REPORT_INTERVAL`] per robot (on the exchange's clock). The world
//! prints the event for its launcher, which prints one line per event
//! ([`degraded_link_message`]).
//!
//! It is pure: outcomes and instants in, events out, so its rules are unit-tested below.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use formation_proto::wire::{DEGRADED_SHARE_PERCENT, TickOutcome, WorldEvent};

/// How much of the run's time the window spans.
pub const DEGRADED_WINDOW: Duration = Duration::from_secs(5);

/// The shortest time between two reports of one robot.
pub const REPORT_INTERVAL: Duration = Duration::from_secs(1);

/// One tick as the monitor remembers it.
#[derive(Debug, Clone, Copy)]
struct Seen {
    outcome: TickOutcome,
    round_trip: Option<Duration>,
}

/// One robot's sliding window of tick outcomes, and when it last reported.
#[derive(Debug, Clone)]
pub struct LinkMonitor {
    robot: usize,
    window_ticks: usize,
    window: Duration,
    recent: VecDeque<Seen>,
    /// Braked ticks in the window, by [`TickOutcome::ALL`] index.
    braked: [u64; TickOutcome::ALL.len()],
    last_report: Option<Instant>,
}

fn slot(outcome: TickOutcome) -> usize {
    TickOutcome::ALL
        .iter()
        .position(|&o| o == outcome)
        .unwrap_or_default()
}

impl LinkMonitor {
    /// A monitor of robot `robot` for ticks of `dt`.
    pub fn new(robot: usize, dt: Duration) -> LinkMonitor {
        let mut monitor = LinkMonitor {
            robot,
            window_ticks: 1,
            window: DEGRADED_WINDOW,
            recent: VecDeque::new(),
            braked: [0; TickOutcome::ALL.len()],
            last_report: None,
        };
        monitor.begin_episode(dt);
        monitor
    }

    /// A new episode with ticks of `dt`: the window starts empty; the last report's time stays,
    /// so a new run does not repeat a report made a moment ago.
    pub fn begin_episode(&mut self, dt: Duration) {
        let ticks = if dt.is_zero() {
            1
        } else {
            DEGRADED_WINDOW.as_nanos().div_ceil(dt.as_nanos())
        };
        self.window_ticks = usize::try_from(ticks)
            .unwrap_or(usize::MAX)
            .clamp(1, 100_000);
        self.window = dt.saturating_mul(u32::try_from(self.window_ticks).unwrap_or(u32::MAX));
        self.recent.clear();
        self.braked = [0; TickOutcome::ALL.len()];
    }

    /// The window's length in ticks.
    pub fn window_ticks(&self) -> usize {
        self.window_ticks
    }

    /// Takes tick `tick`'s outcome (and the used command's round trip, if one was used) at `now`;
    /// returns the report to make, if the window is degraded and the robot was not reported
    /// within the last [`REPORT_INTERVAL`].
    pub fn observe(
        &mut self,
        tick: u64,
        outcome: TickOutcome,
        round_trip: Option<Duration>,
        now: Instant,
    ) -> Option<WorldEvent> {
        if self.recent.len() == self.window_ticks
            && let Some(oldest) = self.recent.pop_front()
            && oldest.outcome.braked()
        {
            self.braked[slot(oldest.outcome)] -= 1;
        }
        self.recent.push_back(Seen {
            outcome,
            round_trip,
        });
        if outcome.braked() {
            self.braked[slot(outcome)] += 1;
        }
        let braked: u64 = self.braked.iter().sum();
        let window_ticks = self.window_ticks as u64;
        let degraded = braked.saturating_mul(100) > DEGRADED_SHARE_PERCENT * window_ticks;
        let quiet = self
            .last_report
            .is_none_or(|at| now.saturating_duration_since(at) >= REPORT_INTERVAL);
        if !degraded || !quiet {
            return None;
        }
        self.last_report = Some(now);
        let reasons: BTreeMap<String, u64> = TickOutcome::ALL
            .iter()
            .zip(self.braked)
            .filter(|&(_, count)| count > 0)
            .map(|(outcome, count)| (outcome.name().to_owned(), count))
            .collect();
        let round_trip_us = self
            .recent
            .iter()
            .rev()
            .find_map(|seen| seen.round_trip)
            .map(|rt| u64::try_from(rt.as_micros()).unwrap_or(u64::MAX));
        Some(WorldEvent::LinkDegraded {
            robot: self.robot,
            tick,
            window_ms: u64::try_from(self.window.as_millis()).unwrap_or(u64::MAX),
            window_ticks,
            braked,
            reasons,
            round_trip_us,
        })
    }
}

/// The line the launcher (`formation run`) prints for a [`WorldEvent::LinkDegraded`] (`None` for any other event):
/// the robot, how many of the window's ticks were braked and why, and the newest round trip.
pub fn degraded_link_message(event: &WorldEvent) -> Option<String> {
    let WorldEvent::LinkDegraded {
        robot,
        tick,
        window_ms,
        window_ticks,
        braked,
        reasons,
        round_trip_us,
    } = event
    else {
        return None;
    };
    let reasons: Vec<String> = reasons
        .iter()
        .map(|(reason, count)| format!("{reason} {count}"))
        .collect();
    let round_trip = match round_trip_us {
        Some(us) => format!("round trip {:.1} ms", *us as f64 / 1000.0),
        None => "no command used in the window".to_owned(),
    };
    Some(format!(
        "robot {robot}: degraded link at tick {tick}: {braked} of its last {window_ticks} ticks \
         ({:.1} s) braked ({}); {round_trip}",
        *window_ms as f64 / 1000.0,
        reasons.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: Duration = Duration::from_millis(50);

    /// Feeds `outcomes` one tick per `DT` from `start` (tick `first` on), returning the ticks at
    /// which a report was made and the reports.
    fn feed(
        monitor: &mut LinkMonitor,
        start: Instant,
        first: u64,
        outcomes: &[TickOutcome],
    ) -> Vec<WorldEvent> {
        let mut reports = Vec::new();
        for (k, &outcome) in outcomes.iter().enumerate() {
            let tick = first + k as u64;
            let now = start + DT * u32::try_from(tick).unwrap();
            let round_trip = (outcome == TickOutcome::Fresh).then(|| Duration::from_micros(tick));
            reports.extend(monitor.observe(tick, outcome, round_trip, now));
        }
        reports
    }

    #[test]
    fn five_percent_of_a_full_window_is_tolerated_and_one_more_tick_is_reported() {
        use TickOutcome::{Fresh, Missing, Stale};
        let start = Instant::now();
        let mut monitor = LinkMonitor::new(2, DT);
        assert_eq!(monitor.window_ticks(), 100, "5 s at 20 Hz");
        // 5 braked ticks of 100: exactly 5 %, not more.
        let mut ticks = vec![Fresh; 95];
        ticks.extend([Stale; 5]);
        assert_eq!(feed(&mut monitor, start, 0, &ticks), []);
        // A sixth within the window: reported at once, with the reasons and the newest round trip.
        let reports = feed(&mut monitor, start, 100, &[Missing]);
        assert_eq!(
            reports,
            [WorldEvent::LinkDegraded {
                robot: 2,
                tick: 100,
                window_ms: 5000,
                window_ticks: 100,
                braked: 6,
                reasons: BTreeMap::from([("missing".to_owned(), 1), ("stale".to_owned(), 5)]),
                // Tick 94 was the last fresh one.
                round_trip_us: Some(94),
            }]
        );
    }

    #[test]
    fn braked_ticks_that_left_the_window_no_longer_count() {
        use TickOutcome::{Fresh, Stale};
        let start = Instant::now();
        let mut monitor = LinkMonitor::new(0, DT);
        // 6 braked ticks spread over 200 ticks: never more than 5 in any 100.
        let mut ticks = Vec::new();
        for _ in 0..6 {
            ticks.extend([Stale]);
            ticks.extend([Fresh; 33]);
        }
        assert_eq!(feed(&mut monitor, start, 0, &ticks), []);
    }

    #[test]
    fn a_degraded_link_is_reported_at_most_once_a_second_and_a_new_episode_starts_afresh() {
        use TickOutcome::{AgentDown, Fresh};
        let start = Instant::now();
        let mut monitor = LinkMonitor::new(1, DT);
        // 3 s with every tick braked: reported at the 6th braked tick, then once a second.
        let reports = feed(&mut monitor, start, 0, &[AgentDown; 60]);
        let ticks: Vec<u64> = reports
            .iter()
            .map(|r| match r {
                WorldEvent::LinkDegraded {
                    tick,
                    round_trip_us,
                    ..
                } => {
                    assert_eq!(*round_trip_us, None, "no command used");
                    *tick
                }
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(ticks, [5, 25, 45]);
        monitor.begin_episode(DT);
        assert_eq!(feed(&mut monitor, start, 60, &[Fresh; 10]), []);
        // A faster lockstep tick makes a longer window in ticks.
        monitor.begin_episode(Duration::from_millis(10));
        assert_eq!(monitor.window_ticks(), 500);
    }

    #[test]
    fn a_degraded_link_is_one_line_naming_the_robot_the_reasons_and_the_round_trip() {
        let event = WorldEvent::LinkDegraded {
            robot: 2,
            tick: 140,
            window_ms: 5000,
            window_ticks: 100,
            braked: 12,
            reasons: BTreeMap::from([("missing".to_owned(), 2), ("stale".to_owned(), 10)]),
            round_trip_us: Some(102_500),
        };
        assert_eq!(
            degraded_link_message(&event).as_deref(),
            Some(
                "robot 2: degraded link at tick 140: 12 of its last 100 ticks (5.0 s) braked \
                 (missing 2, stale 10); round trip 102.5 ms"
            )
        );
        assert_eq!(degraded_link_message(&WorldEvent::Finished), None);
    }
}
