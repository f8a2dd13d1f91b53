//! A fixture shared by the world's unit tests: the small team of the episode loop's and the run
//! journal's tests ([`RampTeam`]).

use crate::scenario::{RunSpec, Scenario};

/// Three robots whose common heading ramps at 0.3 rad/s, for `duration_s`, under the goal
/// (`v_star`, `d_star`), each with a LIDAR of `beams` beams and range noise `noise_std`.
pub(crate) struct RampTeam {
    pub(crate) duration_s: f64,
    pub(crate) v_star: f64,
    pub(crate) d_star: f64,
    pub(crate) beams: usize,
    pub(crate) noise_std: f64,
}

impl Default for RampTeam {
    /// One second at v* = 0.5 m/s and d* = 1.5 m, 90 beams without noise.
    fn default() -> Self {
        RampTeam {
            duration_s: 1.0,
            v_star: 0.5,
            d_star: 1.5,
            beams: 90,
            noise_std: 0.0,
        }
    }
}

impl RampTeam {
    /// Run `run` of the scenario `name` whose seed is `seed`.
    pub(crate) fn run_spec(&self, name: &str, seed: u64, run: usize) -> RunSpec {
        let RampTeam {
            duration_s,
            v_star,
            d_star,
            beams,
            noise_std,
        } = self;
        let text = format!(
            r#"
name = "{name}"
robots = 3
duration_s = {duration_s:?}
seed = {seed}
[goal]
v_star = {v_star:?}
d_star = {d_star:?}
[heading]
schedule = "ramp"
omega = 0.3
[lidar]
beams = {beams}
noise_std = {noise_std:?}
"#
        );
        Scenario::from_toml_str(&text, name)
            .unwrap()
            .run_spec(seed, run)
    }
}
