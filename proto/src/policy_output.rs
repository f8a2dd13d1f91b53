//! What a policy's one output means: the model declares it (`formation.output` in its ONNX
//! metadata), and every consumer (the agent, replay, swaps, the Python package) turns it into
//! wheel speeds the same way (`formation_perception::policy_input::command_of_output`).

use std::fmt;

/// The fastest reference term the expert's law adds \[m/s\] (the default of its
/// `max_reference_speed` gain, which is this constant): a goal faster than this is driven at this
/// speed, which keeps the rest of a wheel's speed for corrections (a P3-DX's wheels top out at
/// 0.9 m/s). An agent caps the reference term it adds to a formation-velocity output alike
/// (`formation_perception::policy_input::formation_velocity_to_wheels`), so that above it the
/// policy keeps the correction authority its teacher had.
pub const MAX_REFERENCE_SPEED: f64 = 0.7;

/// What a model's one output means, as its `formation.output` metadata declares it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PolicyOutput {
    /// `wheels`: (left, right) wheel speeds \[m/s\] at the training speed `v_train`, which the
    /// agent scales by `v* / v_train` (the paper's output, and that of models that declare none).
    #[default]
    Wheels,
    /// `formation_velocity`: `(f_x, f_y)` \[m/s\] in the robot's frame (x ahead, y to the left), the
    /// velocity the robot's controlled point (half a wheel track ahead of its axle, the point the
    /// expert steers) should move at on top of the reference term. The agent adds the reference
    /// term `v* (cos Δφ, sin Δφ)` itself, so the correction does not shrink with v*.
    FormationVelocity,
}

impl PolicyOutput {
    /// Its `formation.output` value, which is also its tensor's name.
    pub fn name(self) -> &'static str {
        match self {
            PolicyOutput::Wheels => "wheels",
            PolicyOutput::FormationVelocity => "formation_velocity",
        }
    }

    /// Whether it is the paper's `wheels` output.
    pub fn is_wheels(&self) -> bool {
        *self == PolicyOutput::Wheels
    }

    /// The output a `formation.output` value names, if this build knows it.
    pub fn parse(text: &str) -> Option<PolicyOutput> {
        [PolicyOutput::Wheels, PolicyOutput::FormationVelocity]
            .into_iter()
            .find(|o| o.name() == text)
    }
}

impl fmt::Display for PolicyOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_output_parses_from_its_own_name_and_nothing_else_does() {
        for output in [PolicyOutput::Wheels, PolicyOutput::FormationVelocity] {
            assert_eq!(PolicyOutput::parse(output.name()), Some(output));
            assert_eq!(output.to_string(), output.name());
        }
        assert_eq!(PolicyOutput::parse("Wheels"), None);
        assert_eq!(PolicyOutput::parse(""), None);
        assert_eq!(PolicyOutput::default(), PolicyOutput::Wheels);
    }
}
