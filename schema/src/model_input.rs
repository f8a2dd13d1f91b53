//! The input a model declares in its ONNX metadata (the `formation.occupancy.*` window and the
//! `formation.lidar.*` sensor it was trained for), as `summary.json`, `eval --json`, shards and
//! the scaling table record it, so a reader (the report) can say what each policy was given.
//!
//! The record is filled from the model contract the agents load (`formation_onnx::ModelMetadata`),
//! never parsed again from the model file here.

use formation_proto::{BeyondWindow, OccupancySpec};
use serde::{Deserialize, Serialize};

/// What one model is given: its occupancy window and the LIDAR it was trained for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelInput {
    /// The model id.
    pub model: String,
    /// The occupancy window it declares: cells on a side, cell size \[m\] (at its reference d*
    /// when the window scales with d*), what happens to far hits, and the reference d*.
    pub occupancy: OccupancySpec,
    /// LIDAR beams it was trained with (`formation.lidar.beams`).
    pub lidar_beams: usize,
    /// LIDAR maximum range \[m\] it was trained with (`formation.lidar.max_range`).
    pub lidar_max_range_m: f64,
    /// LIDAR range noise \[m\] of its training data, when recorded (`formation.lidar.noise_std`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lidar_noise_std_m: Option<f64>,
    /// Smallest and largest d* \[m\] of its training data, when recorded
    /// (`formation.envelope.d_star_min` and `_max`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trained_d_star_m: Option<[f64; 2]>,
}

impl ModelInput {
    /// One line saying what the model is given, e.g. `50 × 50 cells of 0.1 m at d* = 1.5 m
    /// (scales with d*: 0.053-0.167 m over the model's d* range 0.8-2.5 m), far hits on the
    /// border; 900-beam 10 m LIDAR`.
    pub fn describe(&self) -> String {
        let spec = &self.occupancy;
        let cells = format!("{0} × {0} cells", spec.size_px);
        let window = match spec.d_star_ref_m {
            None => format!(
                "{cells} of {} m (a fixed {} m window)",
                trim_number(spec.resolution_m),
                trim_number(spec.window_m())
            ),
            Some(reference) => {
                let scaling = match self.trained_d_star_m {
                    Some([lo, hi]) => format!(
                        "scales with d*: {}-{} m over the model's d* range {}-{} m",
                        trim_number(spec.at_d_star(lo).resolution_m),
                        trim_number(spec.at_d_star(hi).resolution_m),
                        trim_number(lo),
                        trim_number(hi)
                    ),
                    None => "scales with d*".to_owned(),
                };
                format!(
                    "{cells} of {} m at d* = {} m ({scaling})",
                    trim_number(spec.resolution_m),
                    trim_number(reference)
                )
            }
        };
        let far = match spec.beyond {
            BeyondWindow::Drop => "far hits dropped",
            BeyondWindow::Border => "far hits on the border",
        };
        let noise = match self.lidar_noise_std_m {
            Some(noise) if noise > 0.0 => format!(", noise {} m", trim_number(noise)),
            Some(_) => ", no noise".to_owned(),
            None => String::new(),
        };
        format!(
            "{window}, {far}; {}-beam {} m LIDAR{noise}",
            self.lidar_beams,
            trim_number(self.lidar_max_range_m)
        )
    }
}

/// `x` with at most three decimals and no trailing zeros (`0.1`, `0.053`, `10`), as the report
/// and these descriptions print figures.
pub fn trim_number(x: f64) -> String {
    trim_decimals(x, 3)
}

/// `x` with at most `places` decimals and no trailing zeros; never `-0`.
pub fn trim_decimals(x: f64, places: usize) -> String {
    let text = format!("{x:.places$}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".to_owned()
    } else {
        text.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> ModelInput {
        ModelInput {
            model: "paper-1".into(),
            occupancy: OccupancySpec::PAPER,
            lidar_beams: 900,
            lidar_max_range_m: 10.0,
            lidar_noise_std_m: None,
            trained_d_star_m: None,
        }
    }

    #[test]
    fn a_fixed_window_says_its_cells_its_window_and_that_far_hits_are_dropped() {
        assert_eq!(
            paper().describe(),
            "50 × 50 cells of 0.1 m (a fixed 5 m window), far hits dropped; 900-beam 10 m LIDAR"
        );
    }

    #[test]
    fn a_scaled_window_says_its_reference_and_its_cells_over_the_trained_range() {
        let scaled = crate::tests::scaled_model_input();
        assert_eq!(
            scaled.describe(),
            "50 × 50 cells of 0.1 m at d* = 1.5 m (scales with d*: 0.053-0.167 m over the \
             model's d* range 0.8-2.5 m), far hits on the border; 900-beam 10 m LIDAR, noise 0.01 m"
        );
        let unbounded = ModelInput {
            trained_d_star_m: None,
            lidar_noise_std_m: Some(0.0),
            ..scaled
        };
        assert!(
            unbounded
                .describe()
                .contains("at d* = 1.5 m (scales with d*), far hits on the border")
        );
        assert!(unbounded.describe().ends_with("LIDAR, no noise"));
    }

    #[test]
    fn numbers_keep_three_decimals_without_trailing_zeros() {
        assert_eq!(trim_number(0.1), "0.1");
        assert_eq!(trim_number(10.0), "10");
        assert_eq!(trim_number(0.05333), "0.053");
        assert_eq!(trim_number(-0.0001), "0");
    }
}
