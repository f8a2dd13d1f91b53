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

use formation_proto::RangeInput;
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

/// The native module: `Scenario`, `Batch`, `range_input` and the exceptions.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(range_input, m)?)?;
    m.add_class::<scenario::PyScenario>()?;
    m.add_class::<batch::Batch>()?;
    m.add("ScenarioError", m.py().get_type::<ScenarioError>())?;
    m.add("EpisodeOver", m.py().get_type::<EpisodeOver>())?;
    Ok(())
}
