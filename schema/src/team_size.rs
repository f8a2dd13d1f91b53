//! A model's trained team sizes beside the team it drove, as `summary.json`, `eval --json` and
//! the scaling table record it: a figure for a size the model never saw is marked zero-shot.

use formation_proto::TeamSizeFit;
use serde::{Deserialize, Serialize};

/// One model of a team, against the team's size.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelTeamSize {
    /// The model id.
    pub model: String,
    /// The team sizes of its training data, ascending (`formation.envelope.team_sizes`).
    pub trained_team_sizes: Vec<usize>,
    /// The team's size.
    pub robots: usize,
    /// Where the team's size lies against the trained ones.
    pub fit: TeamSizeFit,
    /// Whether the model never saw teams of this size (`fit` is not `trained`).
    pub zero_shot: bool,
}

impl ModelTeamSize {
    /// The record for a model trained on `trained` driving a team of `robots`, or `None` when the
    /// model records no team sizes.
    pub fn new(model: &str, trained: &[usize], robots: usize) -> Option<ModelTeamSize> {
        let fit = TeamSizeFit::of(trained, robots)?;
        let mut trained_team_sizes = trained.to_vec();
        trained_team_sizes.sort_unstable();
        trained_team_sizes.dedup();
        Some(ModelTeamSize {
            model: model.to_owned(),
            trained_team_sizes,
            robots,
            fit,
            zero_shot: fit.is_zero_shot(),
        })
    }

    /// The terminal line for it ([`TeamSizeFit::describe`]); `None` for a trained size.
    pub fn describe(&self) -> Option<String> {
        self.fit
            .describe(&self.model, &self.trained_team_sizes, self.robots)
    }
}
