//! `sorting_line_gym._native`: the line model of the `sorting_line` library in-process, for
//! Python. No ROS and no DDS: a step is a function call, the same `Line::step` the node runs.
//!
//! - [`line::NativeLine`]: one line for a Gymnasium `Env` (a step returns Gymnasium's tuple,
//!   built in Rust).
//! - [`lines::NativeLines`]: a batch of lines stepped in one call with the GIL released, writing
//!   into numpy arrays allocated once (the vector envs' path).
//! - [`agents`]: the rule-based agents, offline evaluation and the exact oracle.
//! - [`vocabulary`]: the line's facts (constants, ranges, action counts, info keys, start
//!   contents) and its observation and mask builders, which the Python package re-exports;
//!   [`info`]: the one builder of a step's info.
//!
//! Nothing here may panic into Python: every input is checked first and a bad one raises
//! `ValueError` (or the bridge's `BridgeError` for a line used out of order) naming the value and
//! what is allowed.

use pyo3::prelude::*;
use pyo3::types::PyType;
use sorting_line::sim::evolution::Schedule;
use sorting_line::sim::{InputKind, LineConfig, Variant};

mod agents;
mod info;
mod line;
mod lines;
mod vocabulary;

/// A line's settings as the Python side passes them: one dict, `LineOptions.node_options` without
/// `lines` (variant, input, obs_noise, action_penalty, threshold, max_steps, optional evolution: a
/// schedule file).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub(crate) struct LineSettings {
    variant: String,
    input: String,
    obs_noise: f64,
    action_penalty: f64,
    threshold: f64,
    max_steps: u32,
    #[pyo3(default)]
    evolution: Option<String>,
}

/// A line's configuration, checked as the node checks it.
pub(crate) struct Spec {
    pub config: LineConfig,
    pub schedule: Schedule,
}

impl Spec {
    pub fn new(s: &LineSettings) -> PyResult<Self> {
        let variant: Variant = s.variant.parse().map_err(value_error)?;
        let input: InputKind = s.input.parse().map_err(value_error)?;
        let (obs_noise, action_penalty, threshold, max_steps) =
            (s.obs_noise, s.action_penalty, s.threshold, s.max_steps);
        let config = LineConfig { variant, input, obs_noise, action_penalty, threshold, max_steps };
        config.validate().map_err(|e| value_error(e.to_string()))?;
        let schedule = match &s.evolution {
            None => Schedule::default(),
            Some(path) => {
                let text =
                    std::fs::read_to_string(path).map_err(|e| value_error(format!("evolution = {path:?}: {e}")))?;
                Schedule::from_yaml(&text).map_err(|e| value_error(format!("evolution = {path:?}: {e}")))?
            }
        };
        schedule.validate().map_err(|e| value_error(format!("evolution: {e}")))?;
        Ok(Spec { config, schedule })
    }

    /// Whether the line evolves: then its actions are always advanced ones and its category
    /// reading may be unknown.
    pub fn evolving(&self) -> bool {
        !self.schedule.is_empty()
    }

    /// How Gymnasium actions decode: the evolving line takes advanced actions whatever its hardware.
    pub fn encoding(&self) -> Variant {
        if self.evolving() {
            Variant::Advanced
        } else {
            self.config.variant
        }
    }
}

pub(crate) fn value_error(message: impl Into<String>) -> PyErr {
    pyo3::exceptions::PyValueError::new_err(message.into())
}

/// The bridge's own error (`sorting_line_gym.line.errors.BridgeError`), as the ROS envs raise it.
pub(crate) fn bridge_error(py: Python<'_>, message: String) -> PyErr {
    let class = py
        .import("sorting_line_gym.line.errors")
        .and_then(|m| m.getattr("BridgeError"))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
    match class {
        Ok(class) => PyErr::from_type(class, message),
        Err(_) => pyo3::exceptions::PyRuntimeError::new_err(message),
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<line::NativeLine>()?;
    m.add_class::<lines::NativeLines>()?;
    agents::register(m)?;
    vocabulary::register(m)?;
    Ok(())
}
