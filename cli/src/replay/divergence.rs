//! One robot's tally of a replay: which steps were compared, skipped or could not be decided
//! again, and how far the replayed commands are from the recorded ones. Pure: no I/O, no model.

use std::collections::BTreeMap;

use formation_proto::WheelCmd;
use formation_proto::wire::TickOutcome;
use formation_schema::{ReplayReport, ReplayRobot};

/// Why a step could not be decided again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unreplayable {
    /// Its model is not one the recording holds (swapped in from outside it).
    UnknownModel,
    /// A realtime answer to a scan older than the replay keeps.
    ScanNotRecorded,
}

impl Unreplayable {
    /// The name in the report.
    pub fn name(self) -> &'static str {
        match self {
            Unreplayable::UnknownModel => "unknown_model",
            Unreplayable::ScanNotRecorded => "scan_not_recorded",
        }
    }
}

/// One robot's running tally.
#[derive(Debug, Clone, Default)]
pub struct RobotTally {
    steps: u64,
    skipped: BTreeMap<String, u64>,
    unreplayable: BTreeMap<String, u64>,
    /// `max(|Δleft|, |Δright|)` of every compared step whose decision gave a command.
    deltas: Vec<f64>,
    differing: u64,
    failed: u64,
    first: Option<u64>,
    last: Option<u64>,
    listed: Vec<u64>,
}

/// Two commands are the same when both wheels are the same `f64`, bit for bit.
pub fn bit_identical(a: WheelCmd, b: WheelCmd) -> bool {
    a.left.to_bits() == b.left.to_bits() && a.right.to_bits() == b.right.to_bits()
}

impl RobotTally {
    /// A step was read.
    pub fn read_step(&mut self) {
        self.steps += 1;
    }

    /// A step the world did not take an agent's fresh answer for.
    pub fn skip(&mut self, outcome: TickOutcome) {
        *self.skipped.entry(outcome.name().to_owned()).or_default() += 1;
    }

    /// A step that cannot be decided again.
    pub fn unreplayable(&mut self, why: Unreplayable) {
        *self.unreplayable.entry(why.name().to_owned()).or_default() += 1;
    }

    /// A compared step: `replayed` is `None` when the decision failed.
    pub fn compare(&mut self, tick: u64, recorded: WheelCmd, replayed: Option<WheelCmd>) {
        match replayed {
            Some(cmd) if bit_identical(cmd, recorded) => {
                self.deltas.push(0.0);
                return;
            }
            Some(cmd) => {
                let delta = (cmd.left - recorded.left)
                    .abs()
                    .max((cmd.right - recorded.right).abs());
                // Both are finite in a fresh step; a NaN would still count as differing.
                self.deltas
                    .push(if delta.is_nan() { f64::MAX } else { delta });
                self.differing += 1;
            }
            None => self.failed += 1,
        }
        self.first.get_or_insert(tick);
        self.last = Some(tick);
        if self.listed.len() < ReplayReport::LISTED_TICKS {
            self.listed.push(tick);
        }
    }

    /// Whether a compared step differed or failed.
    pub fn diverged(&self) -> bool {
        self.differing > 0 || self.failed > 0
    }

    /// The robot's row of the report.
    pub fn finish(mut self, robot: u32) -> ReplayRobot {
        self.deltas.sort_by(f64::total_cmp);
        ReplayRobot {
            robot,
            steps: self.steps,
            compared: self.deltas.len() as u64 + self.failed,
            skipped: self.skipped,
            unreplayable: self.unreplayable,
            differing: self.differing,
            failed: self.failed,
            p50_abs_delta: nearest_rank(&self.deltas, 0.50),
            p99_abs_delta: nearest_rank(&self.deltas, 0.99),
            max_abs_delta: self.deltas.last().copied().unwrap_or(0.0),
            first_differing_tick: self.first,
            last_differing_tick: self.last,
            differing_ticks: self.listed,
        }
    }
}

/// The nearest-rank `p`-quantile of sorted values (0 for none).
fn nearest_rank(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (p * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(left: f64, right: f64) -> WheelCmd {
        WheelCmd { left, right }
    }

    #[test]
    fn identical_commands_leave_no_divergence_and_bits_count() {
        let mut t = RobotTally::default();
        t.read_step();
        t.compare(0, cmd(0.1, -0.0), Some(cmd(0.1, -0.0)));
        assert!(!t.diverged());
        // +0.0 and -0.0 compare equal as numbers but are not the same bits.
        t.read_step();
        t.compare(1, cmd(0.1, -0.0), Some(cmd(0.1, 0.0)));
        assert!(t.diverged());
        let row = t.finish(3);
        assert_eq!(
            (row.robot, row.steps, row.compared, row.differing),
            (3, 2, 2, 1)
        );
        assert_eq!(row.first_differing_tick, Some(1));
        assert_eq!(row.max_abs_delta, 0.0);
    }

    #[test]
    fn quantiles_first_and_last_ticks_and_failures() {
        let mut t = RobotTally::default();
        for tick in 0..100u32 {
            let replayed = if tick < 90 {
                0.0
            } else {
                0.01 * f64::from(tick - 89)
            };
            t.compare(
                u64::from(tick),
                cmd(0.0, 0.0),
                Some(cmd(replayed, replayed)),
            );
        }
        t.skip(TickOutcome::Stale);
        t.unreplayable(Unreplayable::UnknownModel);
        let row = t.clone().finish(0);
        assert_eq!(row.differing, 10);
        assert_eq!(row.p50_abs_delta, 0.0);
        assert!((row.p99_abs_delta - 0.09).abs() < 1e-12, "{row:?}");
        assert!((row.max_abs_delta - 0.10).abs() < 1e-12, "{row:?}");
        assert_eq!(
            (row.first_differing_tick, row.last_differing_tick),
            (Some(90), Some(99))
        );
        assert_eq!(row.skipped["stale"], 1);
        assert_eq!(row.unreplayable["unknown_model"], 1);
        t.compare(100, cmd(0.0, 0.0), None);
        let row = t.finish(0);
        assert_eq!((row.failed, row.compared), (1, 101));
        assert_eq!(row.last_differing_tick, Some(100));
    }
}
