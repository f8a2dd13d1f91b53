//! The response gauge (`formation gauge --json`): how strongly a policy corrects formation errors,
//! against the expert's label recomputed on the policy's own states, binned by the label's size.
//!
//! Both vectors are formation velocities \[m/s\] in the world frame: the controlled point's
//! velocity that a wheel command sets (the point `c` ahead of the axle, after the expert's own
//! saturation for the label, before any acceleration limit for the policy), minus the reference
//! term `v* (cos φ*, sin φ*)`. In a bin, the slope is `Σ p·l / Σ |l|²` (1 for a policy that moves
//! as far as its teacher asks, 0.1 for one that moves a tenth as far), and the RMS error is
//! `sqrt(mean |p - l|²)`.

use serde::{Deserialize, Serialize};

/// The bins' edges \[m/s\] of the label's size: 0.05–0.1, 0.1–0.2, 0.2–0.4 and 0.4–0.8 m/s.
pub const RESPONSE_BIN_EDGES: [f64; 5] = [0.05, 0.1, 0.2, 0.4, 0.8];

/// A bin with fewer samples than this is reported, not judged.
pub const MIN_JUDGED_SAMPLES: u64 = 500;

/// One bin of the label's size.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseBin {
    /// Lower edge of the label's size \[m/s\], inclusive.
    pub label_min: f64,
    /// Upper edge \[m/s\], exclusive.
    pub label_max: f64,
    /// Robot-samples whose label falls in the bin.
    pub samples: u64,
    /// `Σ p·l / Σ |l|²`; absent without samples.
    pub slope: Option<f64>,
    /// `sqrt(mean |p - l|²)` \[m/s\]; absent without samples.
    pub rms_error: Option<f64>,
    /// Whether the bin holds at least [`MIN_JUDGED_SAMPLES`] samples.
    pub judged: bool,
}

/// One controller on one team size.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseRow {
    /// `expert` or `policy`.
    pub controller: String,
    /// The model id (policy only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Team size.
    pub robots: usize,
    /// Runs played.
    pub runs: usize,
    /// Fraction (0..1) of the runs that succeed at 10 % (strict check), for context.
    pub success_rate_10: f64,
    /// Robot-samples gauged in all, inside or outside the bins.
    pub samples: u64,
    /// The bins, in [`RESPONSE_BIN_EDGES`] order.
    pub bins: Vec<ResponseBin>,
}

/// What `formation gauge --json` writes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseCurve {
    /// The scenario gauged.
    pub scenario: String,
    /// Base seed of its runs.
    pub seed: u64,
    /// Simulated seconds per run.
    pub duration_s: f64,
    /// Every how many ticks a state is gauged.
    pub stride: u64,
    /// The expert's gains that label the states, as JSON (the scored expert's unless set).
    pub expert_gains: serde_json::Value,
    /// One row per controller and team size, in the order asked.
    pub rows: Vec<ResponseRow>,
}
