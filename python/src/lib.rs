//! The native module of the `formation` Python package (`formation._native`), built with PyO3.
//!
//! It holds no simulation logic of its own: scenarios are read and validated by
//! `formation_world::scenario` (with the CLI's messages), runs are set up by
//! `Scenario::run_spec` and played tick by tick by `formation_world::Episode` (the loop
//! `formation eval` runs), the policy's inputs come from `formation_perception`, the expert from
//! `formation_expert`, the neighbour rule from `formation_world::neighbours` and the metrics from
//! `formation_world::metrics`. So run `R` of seed `S` here is run `R` of `formation eval --seed S`,
//! bit for bit.
//!
//! * [`scenario`]: `Scenario`, loaded from a file with optional overrides.
//! * [`batch`]: `Batch`, `B` runs of one scenario stepped together in parallel (rayon), numpy
//!   arrays in and out; the Python environments are built on it (a single run is a batch of one).
//! * [`range_input`]: a model's `formation.ranges` read by the agent's own `RangeInput::parse`.
//! * [`neighbour_input`]: a model's `formation.neighbours` read by the agent's own
//!   `NeighbourInput::parse`.
//! * [`detect_neighbours`]: the neighbours one robot detects in its own scan, by
//!   `formation_perception::neighbours`, the detector collection and the agent use.

use formation_perception::neighbours::{DetectedNeighbour, DetectorSettings, NeighbourDetector};
use formation_proto::{DEFAULT_BODY_RADIUS_M, LidarSpec, NeighbourInput, RangeInput};
use numpy::{AllowTypeChange, PyArray2, PyArrayLike1, PyArrayMethods};
use pyo3::prelude::*;

pub mod batch;
pub mod scenario;

pyo3::create_exception!(
    _native,
    ScenarioError,
    pyo3::exceptions::PyValueError,
    "A scenario that cannot be read or is not valid: the message names the file, the key and the fix."
);
pyo3::create_exception!(
    _native,
    EpisodeOver,
    pyo3::exceptions::PyRuntimeError,
    "A step after the last tick of a run: reset to start another run."
);

/// `(sectors, clip)` of a model's range input, its `formation.ranges` (`"sectors=K,clip=C"`),
/// read and checked by the agent's own [`RangeInput::parse`]; a `ValueError` says what is wrong.
#[pyfunction]
pub fn range_input(text: &str) -> PyResult<(usize, f32)> {
    let spec = RangeInput::parse(text).map_err(|e| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "range input {text:?} (the model's formation.ranges): {e}"
        ))
    })?;
    Ok((spec.sectors, spec.clip))
}

/// `(slots, threshold, nearest, features)` of a model's neighbour input, its
/// `formation.neighbours` (`"slots=K,threshold=T,nearest=M[,hidden=1]"`), read and checked by
/// the agent's own [`NeighbourInput::parse`]; `features` is the numbers a slot holds (4, or 6
/// with `hidden=1`). A `ValueError` says what is wrong.
#[pyfunction]
pub fn neighbour_input(text: &str) -> PyResult<(usize, f64, usize, usize)> {
    let spec = NeighbourInput::parse(text).map_err(|e| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "neighbour input {text:?} (the model's formation.neighbours): {e}"
        ))
    })?;
    Ok((spec.slots, spec.threshold, spec.nearest, spec.features()))
}

/// The neighbours one robot detects in its own scan (`scan[k]` the range of beam `k`, at
/// body-frame bearing `2 pi k / len(scan)`; a range of `max_range` or more, NaN, infinite or
/// negative is no return): each one's centre `(x ahead, y left)` in metres, nearest first, as a
/// `(k, 2)` float64 array. `body_radius` is every robot's (the world's default unless given).
/// The detector is `formation_perception::neighbours`, the agent's own; a `ValueError` names a
/// bad setting.
#[pyfunction]
#[pyo3(signature = (scan, max_range = 10.0, body_radius = DEFAULT_BODY_RADIUS_M))]
pub fn detect_neighbours<'py>(
    py: Python<'py>,
    scan: PyArrayLike1<'py, f32, AllowTypeChange>,
    max_range: f64,
    body_radius: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if !(max_range.is_finite() && max_range > 0.0) {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "max_range must be a positive finite number of metres, got {max_range}"
        )));
    }
    let mut detector = NeighbourDetector::new(DetectorSettings::with_body_radius(body_radius))
        .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
    let scan = scan.as_slice().map_err(|e| {
        pyo3::exceptions::PyValueError::new_err(format!("scan must be a contiguous 1-D array: {e}"))
    })?;
    let lidar = LidarSpec {
        beams: scan.len(),
        max_range,
    };
    let mut found: Vec<DetectedNeighbour> = Vec::new();
    detector.detect(scan, &lidar, &mut found);
    let centres: Vec<f64> = found.iter().flat_map(|f| [f.x, f.y]).collect();
    numpy::PyArray1::from_vec(py, centres).reshape([found.len(), 2])
}

/// The native module: `Scenario`, `Batch`, `range_input`, `neighbour_input`, `detect_neighbours`
/// and the exceptions.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(range_input, m)?)?;
    m.add_function(wrap_pyfunction!(neighbour_input, m)?)?;
    m.add_function(wrap_pyfunction!(detect_neighbours, m)?)?;
    m.add_class::<scenario::PyScenario>()?;
    m.add_class::<batch::Batch>()?;
    m.add("ScenarioError", m.py().get_type::<ScenarioError>())?;
    m.add("EpisodeOver", m.py().get_type::<EpisodeOver>())?;
    Ok(())
}
