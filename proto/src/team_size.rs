//! How a team's size relates to the team sizes a model was trained on: the model's envelope
//! records them (`formation.envelope.team_sizes`), and a run with another size is not refused
//! (a policy may well generalise) but marked, so that no figure passes as in-distribution when it
//! is zero-shot. The classification is here, beside the other shared values, so that the launcher,
//! `formation eval`, the scaling table and the files they write all say the same thing.

use serde::{Deserialize, Serialize};

/// Where a team size lies against the sizes a model was trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TeamSizeFit {
    /// The model was trained on teams of exactly this size.
    Trained,
    /// Within the trained sizes' range but not one of them: zero-shot, between sizes it saw.
    ZeroShot,
    /// Larger than every trained size: zero-shot, beyond what it saw.
    AboveTrained,
    /// Smaller than every trained size: zero-shot, and a robot then sees fewer neighbours than
    /// in any training image; expect it to fail (the shipped model fails every run of 2 robots).
    BelowTrained,
}

impl TeamSizeFit {
    /// Where `robots` lies against `trained` (any order); `None` when nothing is recorded.
    pub fn of(trained: &[usize], robots: usize) -> Option<TeamSizeFit> {
        let smallest = trained.iter().copied().min()?;
        let largest = trained.iter().copied().max()?;
        Some(if trained.contains(&robots) {
            TeamSizeFit::Trained
        } else if robots < smallest {
            TeamSizeFit::BelowTrained
        } else if robots > largest {
            TeamSizeFit::AboveTrained
        } else {
            TeamSizeFit::ZeroShot
        })
    }

    /// Whether the model never saw teams of this size.
    pub fn is_zero_shot(self) -> bool {
        self != TeamSizeFit::Trained
    }

    /// How far outside its trained sizes a team is, as a factor: `robots / largest` above them,
    /// `smallest / robots` below them, 1 inside their range.
    pub fn distance(trained: &[usize], robots: usize) -> f64 {
        let smallest = trained.iter().copied().min().unwrap_or(robots).max(1);
        let largest = trained.iter().copied().max().unwrap_or(robots).max(1);
        if robots > largest {
            robots as f64 / largest as f64
        } else if robots < smallest {
            smallest as f64 / robots.max(1) as f64
        } else {
            1.0
        }
    }

    /// One line for the terminal (and under the printed Table I) about a team of `robots` and a
    /// model trained on `trained`, or `None` for a trained size. One wording, scaled by how far
    /// outside the trained sizes the team is ([`TeamSizeFit::distance`]): a note between
    /// trained sizes; a warning outside them, that success will be lower; and from
    /// [`TeamSizeFit::FAR`] times outside, that its formations are expected to fail.
    pub fn describe(self, model: &str, trained: &[usize], robots: usize) -> Option<String> {
        let sizes = trained
            .iter()
            .map(usize::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        let distance = Self::distance(trained, robots);
        let side = match self {
            TeamSizeFit::Trained => return None,
            TeamSizeFit::ZeroShot => {
                return Some(format!(
                    "note: {robots} robots is zero-shot for model {model}, between the team sizes \
                     it was trained on ({sizes})"
                ));
            }
            TeamSizeFit::AboveTrained => "larger than the largest",
            TeamSizeFit::BelowTrained => "smaller than the smallest",
        };
        let (how_far, expect) = if distance >= Self::FAR {
            (
                "far outside",
                "expect its formations to fail (a model trained for this size is the fix)",
            )
        } else {
            ("outside", "expect lower success than at a trained size")
        };
        Some(format!(
            "warning: {robots} robots is zero-shot for model {model}, {how_far} the team sizes it \
             was trained on ({sizes}; {distance:.1}x {side}): {expect}"
        ))
    }

    /// How many times outside the trained sizes a team is said to be far outside them: the
    /// shipped model fails every run of 2 robots (1.5x below its 3) and succeeds in 0-3 % of runs
    /// of 48 (3x above its 16).
    pub const FAR: f64 = 1.5;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn team_sizes_are_placed_against_the_trained_ones() {
        let trained = [3, 5, 8, 13, 16];
        for (robots, fit) in [
            (8, TeamSizeFit::Trained),
            (2, TeamSizeFit::BelowTrained),
            (1, TeamSizeFit::BelowTrained),
            (11, TeamSizeFit::ZeroShot),
            (24, TeamSizeFit::AboveTrained),
            (300, TeamSizeFit::AboveTrained),
        ] {
            assert_eq!(
                TeamSizeFit::of(&trained, robots),
                Some(fit),
                "{robots} robots"
            );
        }
        assert_eq!(TeamSizeFit::of(&[], 3), None);
        assert!(!TeamSizeFit::Trained.is_zero_shot());
        assert!(TeamSizeFit::AboveTrained.is_zero_shot());
    }

    #[test]
    fn one_wording_scaled_by_how_far_outside_the_trained_sizes() {
        let trained = [3, 5, 8, 13, 16];
        assert_eq!(TeamSizeFit::Trained.describe("m", &trained, 8), None);
        let between = TeamSizeFit::ZeroShot.describe("m", &trained, 11).unwrap();
        assert!(
            between.starts_with("note: 11 robots is zero-shot for model m"),
            "{between}"
        );
        let near = TeamSizeFit::AboveTrained
            .describe("m", &trained, 20)
            .unwrap();
        assert!(
            near.starts_with("warning: 20 robots is zero-shot"),
            "{near}"
        );
        assert!(
            near.contains(", outside the team sizes") && near.contains("lower success"),
            "{near}"
        );
        // 48 robots (3x the largest) and 2 robots (1.5x below the smallest) are said alike.
        for (robots, factor, side) in [(48, "3.0x", "larger"), (2, "1.5x", "smaller")] {
            let fit = TeamSizeFit::of(&trained, robots).unwrap();
            let far = fit.describe("m", &trained, robots).unwrap();
            assert!(
                far.starts_with(&format!("warning: {robots} robots is zero-shot")),
                "{far}"
            );
            assert!(far.contains("far outside the team sizes it was trained on (3, 5, 8, 13, 16"));
            assert!(far.contains(&format!("{factor} {side}")), "{far}");
            assert!(far.contains("expect its formations to fail"), "{far}");
        }
    }

    #[test]
    fn the_fit_is_written_in_snake_case() {
        assert_eq!(
            serde_json::to_string(&TeamSizeFit::BelowTrained).unwrap(),
            "\"below_trained\""
        );
    }
}
