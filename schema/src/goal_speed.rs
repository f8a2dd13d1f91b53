//! A model's trained goal speed beside the v* of the runs it drove, as `summary.json`,
//! `eval --json` and the scaling table record it: a figure at a v* the model was not trained at
//! is marked, in the team sizes' wording ([`formation_proto::GoalSpeedFit`]).

use formation_proto::{GoalSpeedFit, PolicyOutput};
use serde::{Deserialize, Serialize};

/// One model of a team, against the runs' v*.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelGoalSpeed {
    /// The model id.
    pub model: String,
    /// The v* \[m/s\] of its training data (`formation.v_train`).
    pub trained_v_star: f64,
    /// The runs' v* \[m/s\].
    pub v_star: f64,
    /// `v_star / trained_v_star`: the scale applied to a `wheels` output.
    pub factor: f64,
    /// Where the runs' v* lies against the trained one.
    pub fit: GoalSpeedFit,
    /// What its output is (`formation.output`): a `formation_velocity` output is not scaled
    /// but gets its reference term at the runs' v*. Absent for `wheels`.
    #[serde(default, skip_serializing_if = "PolicyOutput::is_wheels")]
    pub output: PolicyOutput,
}

impl ModelGoalSpeed {
    /// The record for a model trained at `v_train`, answering `output`, driving runs at
    /// `v_star`, or `None` when `v_train` is not a positive speed.
    pub fn new(
        model: &str,
        v_train: f64,
        v_star: f64,
        output: PolicyOutput,
    ) -> Option<ModelGoalSpeed> {
        let fit = GoalSpeedFit::of(v_train, v_star)?;
        Some(ModelGoalSpeed {
            model: model.to_owned(),
            trained_v_star: v_train,
            v_star,
            factor: v_star / v_train,
            fit,
            output,
        })
    }

    /// Whether the runs' v* is not the trained one.
    pub fn is_outside(&self) -> bool {
        self.fit.is_outside()
    }

    /// The terminal line for it ([`GoalSpeedFit::describe`]); `None` at the trained v*.
    pub fn describe(&self) -> Option<String> {
        self.fit
            .describe(&self.model, self.trained_v_star, self.v_star, self.output)
    }
}
