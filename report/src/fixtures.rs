//! Fixtures the unit tests of several modules share.

use formation_schema::{Quantiles, ScalingRow};

/// A row of a scaling table or a reality ladder: `controller` (and its `model`) on `robots`
/// under all pairs over 100 runs, successful at 10 % in the share `success` and at 5 % in 0.1
/// less, with a median convergence time of `2 + robots` seconds.
pub fn scaling_row(
    controller: &str,
    model: Option<&str>,
    robots: usize,
    success: f64,
) -> ScalingRow {
    let json = serde_json::json!({
        "controller": controller,
        "model": model,
        "robots": robots,
        "neighbours": "all_pairs",
        "runs": 100,
        "success_rate_5": success - 0.1,
        "success_rate_10": success,
        "anchor_success_rate": success,
        "convergence_s": Quantiles {
            min: 0.5,
            q1: 1.0,
            median: 2.0 + robots as f64,
            q3: 3.0,
            max: 9.0,
            count: 100,
        },
        "rel_formation_error": null,
        "max_edge_window_error": null,
        "collisions": 0
    });
    serde_json::from_value(json).expect("a scaling row")
}
