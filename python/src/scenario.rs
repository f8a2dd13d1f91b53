//! `Scenario`: a scenario file read and validated by `formation_world::scenario`, with the same
//! messages as the CLI, optionally with some keys overridden and the team resized.

use std::path::PathBuf;

use formation_world::Scenario;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use crate::ScenarioError;

/// A validated scenario.
///
/// `Scenario(path, robots=None, overrides=None)` reads the file as `formation eval --scenario
/// path` does; `overrides` maps dotted keys to values (`{"goal.v_star": 0.5}`) set before
/// validation, so an unknown key or a bad value raises `ScenarioError` with the CLI's message;
/// `robots` resizes the team as `formation eval --robots` does.
#[pyclass(name = "Scenario", module = "formation._native", frozen)]
#[derive(Debug, Clone)]
pub struct PyScenario {
    pub(crate) scenario: Scenario,
}

#[pymethods]
impl PyScenario {
    #[new]
    #[pyo3(signature = (path, robots=None, overrides=None))]
    fn new(
        path: PathBuf,
        robots: Option<usize>,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyScenario> {
        let overrides = match overrides {
            Some(dict) => toml_overrides(dict)?,
            None => Vec::new(),
        };
        let scenario = Scenario::from_path_overridden(&path, &overrides)
            .map_err(|e| ScenarioError::new_err(e.to_string()))?;
        let scenario = match robots {
            Some(robots) => scenario
                .with_robots(robots)
                .map_err(|e| ScenarioError::new_err(e.to_string()))?,
            None => scenario,
        };
        Ok(PyScenario { scenario })
    }

    /// The scenario's name.
    #[getter]
    fn name(&self) -> &str {
        self.scenario.name()
    }

    /// Team size.
    #[getter]
    fn robots(&self) -> usize {
        self.scenario.n_robots()
    }

    /// The base seed of the scenario's runs (`formation eval` without `--seed`).
    #[getter]
    fn seed(&self) -> u64 {
        self.scenario.seed()
    }

    /// How many runs `formation eval` makes without `--runs`.
    #[getter]
    fn runs(&self) -> usize {
        self.scenario.runs()
    }

    /// Simulated duration of a run \[s\].
    #[getter]
    fn duration_s(&self) -> f64 {
        self.scenario.duration_s()
    }

    /// Time step \[s\].
    #[getter]
    fn dt(&self) -> f64 {
        self.scenario.world_config().dt
    }

    /// Desired speed v* \[m/s\]; `None` where it is drawn per run (`goal.v_star_range`, see
    /// `v_star_range`).
    #[getter]
    fn v_star(&self) -> Option<f64> {
        self.scenario.v_star().fixed()
    }

    /// `(slowest, fastest)` v* \[m/s\] drawn per run (`goal.v_star_range`); `None` for a fixed v*.
    #[getter]
    fn v_star_range(&self) -> Option<(f64, f64)> {
        match self.scenario.v_star() {
            formation_world::scenario::VStarPlan::Range { min, max } => Some((min, max)),
            formation_world::scenario::VStarPlan::Fixed(_) => None,
        }
    }

    /// LIDAR beams per scan.
    #[getter]
    fn beams(&self) -> usize {
        self.scenario.world_config().lidar.beams
    }

    /// LIDAR maximum range \[m\].
    #[getter]
    fn max_range(&self) -> f64 {
        self.scenario.world_config().lidar.max_range
    }

    /// LIDAR range noise (standard deviation \[m\]).
    #[getter]
    fn noise_std(&self) -> f64 {
        self.scenario.world_config().lidar_noise.noise_std
    }

    /// The largest wheel speed a robot runs \[m/s\]; commands are saturated to it.
    #[getter]
    fn max_wheel_speed(&self) -> f64 {
        self.scenario.world_config().robot.max_wheel_speed
    }

    /// The resolved settings as JSON (what run logs record of the scenario).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.scenario)
            .map_err(|e| ScenarioError::new_err(format!("cannot write the scenario: {e}")))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scenario(name={:?}, robots={}, duration_s={}, seed={})",
            self.scenario.name(),
            self.scenario.n_robots(),
            self.scenario.duration_s(),
            self.scenario.seed()
        )
    }
}

/// The overrides of a Python dict: dotted string keys, TOML-representable values.
fn toml_overrides(dict: &Bound<'_, PyDict>) -> PyResult<Vec<(String, toml::Value)>> {
    dict.iter()
        .map(|(key, value)| {
            let key: String = key.extract().map_err(|_| {
                PyTypeError::new_err(format!(
                    "scenario override keys are dotted strings such as \"goal.v_star\", got {key:?}"
                ))
            })?;
            let value = toml_value(&value).map_err(|e| {
                PyTypeError::new_err(format!("scenario override {key}: {}", e.value(dict.py())))
            })?;
            Ok((key, value))
        })
        .collect()
}

/// A Python value as TOML: bool, int, float, str, and lists, tuples and dicts of them.
fn toml_value(value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if value.is_instance_of::<PyInt>() {
        return Ok(toml::Value::Integer(value.extract()?));
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(value.extract()?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()?
            .map(|item| toml_value(&item?))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(toml::Value::Array(items));
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (key, item) in dict.iter() {
            table.insert(key.extract()?, toml_value(&item)?);
        }
        return Ok(toml::Value::Table(table));
    }
    Err(PyTypeError::new_err(format!(
        "{} cannot be written in TOML; give a bool, int, float, str, list or dict",
        value.get_type().name()?
    )))
}
