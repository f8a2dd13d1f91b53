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

    /// One line for the terminal about a team of `robots` and a model trained on `trained`, or
    /// `None` for a trained size: a note for a zero-shot size, a warning below the smallest.
    pub fn describe(self, model: &str, trained: &[usize], robots: usize) -> Option<String> {
        let sizes = trained
            .iter()
            .map(usize::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        match self {
            TeamSizeFit::Trained => None,
            TeamSizeFit::ZeroShot | TeamSizeFit::AboveTrained => Some(format!(
                "note: {robots} robots is zero-shot for model {model}: it was trained on teams of \
                 {sizes}"
            )),
            TeamSizeFit::BelowTrained => Some(format!(
                "warning: {robots} robots is fewer than model {model} was ever trained on (teams \
                 of {sizes}): each robot sees fewer neighbours than in any training image, so \
                 expect its formations to fail; use a team of at least {} robots or a model \
                 trained for {robots}",
                trained.iter().min().copied().unwrap_or(robots)
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn team_sizes_are_placed_against_the_trained_ones() {
        let trained = [3, 5, 8, 13, 16];
        assert_eq!(TeamSizeFit::of(&trained, 8), Some(TeamSizeFit::Trained));
        assert_eq!(
            TeamSizeFit::of(&trained, 2),
            Some(TeamSizeFit::BelowTrained)
        );
        assert_eq!(
            TeamSizeFit::of(&trained, 1),
            Some(TeamSizeFit::BelowTrained)
        );
        assert_eq!(TeamSizeFit::of(&trained, 11), Some(TeamSizeFit::ZeroShot));
        assert_eq!(
            TeamSizeFit::of(&trained, 24),
            Some(TeamSizeFit::AboveTrained)
        );
        assert_eq!(
            TeamSizeFit::of(&trained, 300),
            Some(TeamSizeFit::AboveTrained)
        );
        assert_eq!(TeamSizeFit::of(&[], 3), None);
        assert!(!TeamSizeFit::Trained.is_zero_shot());
        assert!(TeamSizeFit::AboveTrained.is_zero_shot());
    }

    #[test]
    fn only_untrained_sizes_are_described_and_small_teams_are_warned_about() {
        let trained = [3, 5];
        assert_eq!(TeamSizeFit::Trained.describe("m", &trained, 3), None);
        let above = TeamSizeFit::AboveTrained
            .describe("m", &trained, 24)
            .unwrap();
        assert!(
            above.starts_with("note: 24 robots is zero-shot for model m"),
            "{above}"
        );
        assert!(above.contains("teams of 3, 5"), "{above}");
        let below = TeamSizeFit::BelowTrained
            .describe("m", &trained, 2)
            .unwrap();
        assert!(below.starts_with("warning: 2 robots"), "{below}");
        assert!(below.contains("at least 3 robots"), "{below}");
    }

    #[test]
    fn the_fit_is_written_in_snake_case() {
        assert_eq!(
            serde_json::to_string(&TeamSizeFit::BelowTrained).unwrap(),
            "\"below_trained\""
        );
    }
}
