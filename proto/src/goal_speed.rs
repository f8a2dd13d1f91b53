//! How a run's goal speed v* relates to the v* a model was trained at: a model records one
//! (`formation.v_train`; every run of its training data used it). A `wheels` output is scaled
//! by v*/v_train; a `formation_velocity` output gets the reference term at the run's own v*
//! and keeps its corrections as trained ([`PolicyOutput`]). A run at another v* is not refused
//! (either may well carry) but marked, so that no figure passes as in-distribution when it is
//! not. The classification is here,
//! beside the team-size one ([`crate::TeamSizeFit`]), and says it in the same wording, scaled by
//! how far from v_train the run is ([`GoalSpeedFit::distance`], v*/v_train or its inverse):
//!
//! - within [`GoalSpeedFit::TOLERANCE`] (1 %) of v_train: trained, no mark;
//! - up to [`GoalSpeedFit::NEAR`] (1.15x) either way: a note;
//! - beyond it: a warning that the figures are zero-shot, to be compared with the expert's;
//! - from [`GoalSpeedFit::FAR`] (1.5x, the team sizes' threshold) either way: the same warning,
//!   said to be far outside, with a model trained near this v* as the fix if they fall short.
//!
//! Unlike a team size, a v* off the trained one is not said to fail: the commands follow v*,
//! and each model's card gives its figures at other speeds. The mark says the figure is
//! zero-shot, not that it is poor.

use serde::{Deserialize, Serialize};

use crate::{MAX_REFERENCE_SPEED, PolicyOutput};

/// Where a run's v* lies against the v* a model was trained at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalSpeedFit {
    /// The model was trained at this v* (within [`GoalSpeedFit::TOLERANCE`]).
    Trained,
    /// Faster than the model was trained at.
    Faster,
    /// Slower than the model was trained at (v* = 0 included).
    Slower,
}

impl GoalSpeedFit {
    /// The relative difference under which a v* counts as the trained one (1 %).
    pub const TOLERANCE: f64 = 0.01;

    /// How many times away from v_train a v* is still only noted (1.15x, about ±15 %).
    pub const NEAR: f64 = 1.15;

    /// How many times away from v_train a v* is said to be far outside it (1.5x, as for team
    /// sizes: [`crate::TeamSizeFit::FAR`]).
    pub const FAR: f64 = 1.5;

    /// Where `v_star` lies against `v_train`; `None` when `v_train` is not a positive finite
    /// speed (nothing to compare with).
    pub fn of(v_train: f64, v_star: f64) -> Option<GoalSpeedFit> {
        if !(v_train.is_finite() && v_train > 0.0) {
            return None;
        }
        Some(if (v_star - v_train).abs() <= Self::TOLERANCE * v_train {
            GoalSpeedFit::Trained
        } else if v_star > v_train {
            GoalSpeedFit::Faster
        } else {
            GoalSpeedFit::Slower
        })
    }

    /// Whether the model was not trained at this v*.
    pub fn is_outside(self) -> bool {
        self != GoalSpeedFit::Trained
    }

    /// How far from v_train a v* is, as a factor of at least 1: `v_star / v_train` above it,
    /// `v_train / v_star` below it (infinite at v* = 0).
    pub fn distance(v_train: f64, v_star: f64) -> f64 {
        if v_star >= v_train {
            v_star / v_train
        } else if v_star > 0.0 {
            v_train / v_star
        } else {
            f64::INFINITY
        }
    }

    /// One line for the terminal (and under the printed Table I) about a run at `v_star` driven
    /// by `model`, trained at `v_train`, whose output is `output`, or `None` at the trained v*.
    /// One wording, scaled by [`GoalSpeedFit::distance`] (see the module's thresholds).
    pub fn describe(
        self,
        model: &str,
        v_train: f64,
        v_star: f64,
        output: PolicyOutput,
    ) -> Option<String> {
        let side = match self {
            GoalSpeedFit::Trained => return None,
            GoalSpeedFit::Faster => "faster",
            GoalSpeedFit::Slower => "slower",
        };
        let distance = Self::distance(v_train, v_star);
        let speeds = format!(
            "v* = {} m/s, model {model} was trained at v* = {} m/s",
            trim(v_star),
            trim(v_train)
        );
        let how_far = if distance.is_finite() {
            format!("{distance:.2}x {side}")
        } else {
            "standing still".to_owned()
        };
        if distance < Self::NEAR {
            let follows = match output {
                PolicyOutput::Wheels => "its commands are scaled by v*/v_train".to_owned(),
                PolicyOutput::FormationVelocity if v_star.abs() > MAX_REFERENCE_SPEED => format!(
                    "its reference term is capped at {} m/s as the expert's is, so the team \
                     moves at that speed; its corrections are as trained",
                    trim(MAX_REFERENCE_SPEED)
                ),
                PolicyOutput::FormationVelocity => "its reference term follows v* as the \
                                                    expert's does, its corrections are as trained"
                    .to_owned(),
            };
            return Some(format!("note: {speeds} ({how_far}); {follows}"));
        }
        let (outside, expect) = if distance >= Self::FAR {
            (
                "far outside",
                "its figures are zero-shot: compare them with the expert's at this v*, and train \
                 a model near this v* if they fall short",
            )
        } else {
            (
                "outside",
                "its figures are zero-shot: compare them with the expert's at this v*",
            )
        };
        Some(format!(
            "warning: {speeds}: {outside} its trained v* ({how_far}): {expect}"
        ))
    }
}

/// A speed as written in a scenario: `0.4`, `0.75`, `1` (at most three decimals).
fn trim(value: f64) -> String {
    let text = format!("{value:.3}");
    text.trim_end_matches('0').trim_end_matches('.').to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goal_speeds_are_placed_against_the_trained_one() {
        assert_eq!(GoalSpeedFit::of(0.7, 0.7), Some(GoalSpeedFit::Trained));
        assert_eq!(GoalSpeedFit::of(0.7, 0.705), Some(GoalSpeedFit::Trained));
        assert_eq!(GoalSpeedFit::of(0.7, 0.75), Some(GoalSpeedFit::Faster));
        assert_eq!(GoalSpeedFit::of(0.7, 0.4), Some(GoalSpeedFit::Slower));
        assert_eq!(GoalSpeedFit::of(0.7, 0.0), Some(GoalSpeedFit::Slower));
        assert_eq!(GoalSpeedFit::of(0.0, 0.7), None);
        assert_eq!(GoalSpeedFit::of(f64::NAN, 0.7), None);
        assert!(!GoalSpeedFit::Trained.is_outside());
        assert!(GoalSpeedFit::Slower.is_outside());
        assert_eq!(GoalSpeedFit::distance(0.7, 1.4), 2.0);
        assert_eq!(GoalSpeedFit::distance(0.8, 0.4), 2.0);
        assert_eq!(GoalSpeedFit::distance(0.7, 0.0), f64::INFINITY);
    }

    #[test]
    fn one_wording_scaled_by_how_far_from_the_trained_speed() {
        let line = |v_star: f64| {
            GoalSpeedFit::of(0.7, v_star)
                .unwrap()
                .describe("m", 0.7, v_star, PolicyOutput::Wheels)
        };
        assert_eq!(line(0.7), None);
        let near = line(0.75).unwrap();
        assert!(
            near.starts_with(
                "note: v* = 0.75 m/s, model m was trained at v* = 0.7 m/s (1.07x faster)"
            ),
            "{near}"
        );
        let outside = line(0.56).unwrap();
        assert!(outside.starts_with("warning: v* = 0.56 m/s"), "{outside}");
        assert!(
            outside.contains(
                ": outside its trained v* (1.25x slower): its figures are zero-shot: compare them \
                 with the expert's at this v*"
            ) && !outside.contains("train a model"),
            "{outside}"
        );
        // 0.4 (1.75x slower), 1.4 (2x faster) and standing still are said alike.
        for (v_star, how_far) in [
            (0.4, "1.75x slower"),
            (1.4, "2.00x faster"),
            (0.0, "standing still"),
        ] {
            let far = line(v_star).unwrap();
            assert!(far.starts_with("warning: v* = "), "{far}");
            assert!(
                far.contains(&format!("far outside its trained v* ({how_far})")),
                "{far}"
            );
            assert!(
                far.contains("zero-shot") && far.contains("train a model near this v*"),
                "{far}"
            );
        }
        // Just inside each threshold keeps the milder word.
        assert!(line(0.7 * 1.14).unwrap().starts_with("note: "));
        assert!(!line(0.7 * 1.49).unwrap().contains("far outside"));
    }

    #[test]
    fn the_fit_is_written_in_snake_case() {
        assert_eq!(
            serde_json::to_string(&GoalSpeedFit::Slower).unwrap(),
            "\"slower\""
        );
    }
}
