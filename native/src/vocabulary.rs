//! The line's facts as module attributes and functions of the extension, for
//! `sorting_line_gym.line.vocabulary` to re-export: Python states none of them again.
//!
//! - Constants: `VARIANTS`, `INPUTS`, `SETUPS`, `SPEEDS`, `SPEED_TOLERANCE`, `START_SPEED_INDEX`,
//!   `MODES`, `MODE_COUNT`, `MODE_LABELS` (wire value: label), `CATEGORIES`, `CATEGORY_UNKNOWN_CODE`,
//!   `CATEGORY_UNKNOWN_OBSERVATION`, `THRESHOLD`, `BELOW_THRESHOLD_REWARD`, `EPISODE_STEPS`,
//!   `MAX_EPISODE_STEPS`, `NODE_LINES`, `EVAL_FIRST_SEED` and `EVAL_EPISODES` (the paper's evaluation
//!   seeds), `ACTION_COUNTS` (per variant), `SETTING_RANGES` (name: (low, high, whether high is
//!   allowed)), `INFO_KEYS` and `INFO_FIELDS` (key, kind, `LineState` fields), `START_CONTENTS`
//!   (input, belt, machine: (A, B)), `START_ACCURACY`, `START_OCCUPANCY`, `LEVELS`.
//! - Builders: `observations(variant, quantity, category)`, `action_mask(variant, sort_modes)`,
//!   `level(quantity)` (the row of the rule-based agent's table), `speed_index_of(speed)`,
//!   `reward(accuracy, speed_index, threshold, penalty)` (the step reward).

use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use sorting_line::sim::accuracy::START_ACCURACY;
use sorting_line::sim::config::{
    EVAL_EPISODES, EVAL_FIRST_SEED, INPUT_KINDS, MAX_EPISODE_STEPS, MAX_NODE_LINES, SETUPS, VARIANTS,
};
use sorting_line::sim::evolution::{CATEGORY_UNKNOWN_CODE, CATEGORY_UNKNOWN_OBSERVATION};
use sorting_line::sim::line::{action_mask as mask_of, START_BELT, START_INPUT, START_MACHINE};
use sorting_line::sim::material::{CATEGORIES, SORT_MODES};
use sorting_line::sim::observation::{level as level_of, LEVELS};
use sorting_line::sim::reward::{reward as reward_of, BELOW_THRESHOLD_REWARD};
use sorting_line::sim::speed::{index_of_speed, SPEEDS, SPEED_COUNT, SPEED_TOLERANCE, START_SPEED_INDEX};
use sorting_line::sim::{Action, LineConfig, Variant};

use crate::info::INFO;
use crate::line::category_observation;
use crate::value_error;

fn variant_of(variant: &str) -> PyResult<Variant> {
    variant.parse().map_err(value_error)
}

/// The name serde gives a value (the form of `sorting_line vocabulary`, `trace` and parameter files).
fn serde_name(value: impl serde::Serialize) -> String {
    serde_json::to_value(value).ok().and_then(|v| v.as_str().map(str::to_owned)).unwrap_or_default()
}

/// The observation(s) for the input sensor's reading(s) and ratio category code(s): shape
/// `(1,)`/`(2,)` for one line, `(N, 1)`/`(N, 2)` for N (basic: the reading; advanced: reading,
/// category, the unknown code read as `CATEGORY_UNKNOWN_OBSERVATION`), float32 as the
/// observation space. The basic line ignores `category`.
#[pyfunction]
fn observations<'py>(
    py: Python<'py>,
    variant: &str,
    quantity: &Bound<'py, PyAny>,
    category: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let advanced = variant_of(variant)? == Variant::Advanced;
    let numpy = py.import("numpy")?;
    let q = numpy.call_method1("asarray", (quantity, "float64"))?.cast_into::<PyArrayDyn<f64>>()?;
    let q = q.try_readonly()?;
    let dim = if advanced { 2 } else { 1 };
    let mut shape = q.shape().to_vec();
    shape.push(dim);
    let mut out: Vec<f32> = Vec::with_capacity(q.len() * dim);
    if advanced {
        let c = numpy.call_method1("asarray", (category, "int64"))?.cast_into::<PyArrayDyn<i64>>()?;
        let c = c.try_readonly()?;
        if c.shape() != q.shape() {
            return Err(value_error(format!("{:?} categories for readings of shape {:?}", c.shape(), q.shape())));
        }
        for (&q, &c) in q.as_array().iter().zip(c.as_array().iter()) {
            out.extend([q as f32, category_observation(c)]);
        }
    } else {
        out.extend(q.as_array().iter().map(|&q| q as f32));
    }
    numpy::PyArray1::from_vec(py, out).reshape(shape)
}

/// Which Gymnasium actions the line takes now: all of them, but on an advanced line without sort
/// modes (an evolving line before its upgrade) only those of mode 0 (the library's mask rule).
#[pyfunction]
#[pyo3(signature = (variant, sort_modes=true))]
fn action_mask<'py>(py: Python<'py>, variant: &str, sort_modes: bool) -> PyResult<Bound<'py, numpy::PyArray1<bool>>> {
    Ok(numpy::PyArray1::from_vec(py, mask_of(variant_of(variant)?, sort_modes).collect()))
}

/// The row (0..=100) of the rule-based agent's table for a reading: `round(quantity * 100)`
/// with halves away from zero, clamped; NaN gives 0.
#[pyfunction]
fn level(quantity: f64) -> usize {
    level_of(quantity)
}

/// The index of one of the ten belt speeds (within `SPEED_TOLERANCE`), or None.
#[pyfunction]
fn speed_index_of(speed: f64) -> Option<usize> {
    index_of_speed(speed)
}

/// The step reward (src/sim/reward.rs `reward`) for accuracy value(s) in 0..=1 at a speed index,
/// float64 of the accuracies' shape: the accuracy and speed terms minus `penalty` (the switching
/// penalty a change of speed costs), a flat -0.1 below the threshold (default: the line's).
#[pyfunction]
#[pyo3(signature = (accuracy, speed_index, threshold=None, penalty=0.0))]
fn reward<'py>(
    py: Python<'py>,
    accuracy: &Bound<'py, PyAny>,
    speed_index: i64,
    threshold: Option<f64>,
    penalty: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let speed_index = usize::try_from(speed_index).ok().filter(|&i| i < SPEED_COUNT).ok_or_else(|| {
        value_error(format!("speed_index = {speed_index} is out of range: allowed 0 ..= {}", SPEED_COUNT - 1))
    })?;
    let threshold = threshold.unwrap_or(LineConfig::default().threshold);
    LineConfig::check_threshold(threshold).map_err(|e| value_error(e.to_string()))?;
    LineConfig::check_action_penalty(penalty).map_err(|e| value_error(e.to_string()))?;
    let a = py.import("numpy")?.call_method1("asarray", (accuracy, "float64"))?.cast_into::<PyArrayDyn<f64>>()?;
    let a = a.try_readonly()?;
    let mut out = Vec::with_capacity(a.len());
    for &accuracy in a.as_array().iter() {
        if !(0.0..=1.0).contains(&accuracy) {
            return Err(value_error(format!("accuracy = {accuracy} is out of range: allowed 0.0 ..= 1.0")));
        }
        out.push(reward_of(accuracy, threshold, speed_index, penalty));
    }
    numpy::PyArray1::from_vec(py, out).reshape(a.shape())
}

/// The setups, their input generator, sensor noise and switching penalty.
fn setups<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    for &s in &SETUPS {
        let c = LineConfig::for_setup(s, Variant::Basic);
        let setup = PyDict::new(py);
        setup.set_item("input", c.input.to_string())?;
        setup.set_item("obs_noise", c.obs_noise)?;
        setup.set_item("action_penalty", c.action_penalty)?;
        out.set_item(s.to_string(), setup)?;
    }
    Ok(out)
}

/// name: (low, high, whether high itself is allowed), each as `LineConfig::validate` checks it.
fn setting_ranges<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    use sorting_line::sim::config::{ACTION_PENALTY_RANGE, OBS_NOISE_RANGE, THRESHOLD_RANGE};
    type Check = fn(f64) -> Result<(), sorting_line::sim::config::ConfigError>;
    let ranges: [(&str, (f64, f64), Check); 3] = [
        ("obs_noise", OBS_NOISE_RANGE, LineConfig::check_obs_noise),
        ("action_penalty", ACTION_PENALTY_RANGE, LineConfig::check_action_penalty),
        ("threshold", THRESHOLD_RANGE, LineConfig::check_threshold),
    ];
    let out = PyDict::new(py);
    for (name, (low, high), check) in ranges {
        // Whether the top is open is the check's own answer, not a second statement of it.
        out.set_item(name, (low, high, check(high).is_ok()))?;
    }
    Ok(out)
}

fn info_fields<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
    let rows = INFO
        .iter()
        .map(|(key, kind, fields)| (*key, kind.name(), PyTuple::new(py, fields.iter()).expect("a tuple of str")))
        .collect::<Vec<_>>();
    PyTuple::new(py, rows)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    let names = |values: &mut dyn Iterator<Item = String>| PyTuple::new(py, values.collect::<Vec<_>>());
    m.add("VARIANTS", names(&mut VARIANTS.iter().map(|v| v.to_string()))?)?;
    m.add("INPUTS", names(&mut INPUT_KINDS.iter().map(|i| i.to_string()))?)?;
    m.add("SETUPS", setups(py)?)?;
    m.add("SPEEDS", PyTuple::new(py, SPEEDS)?)?;
    m.add("SPEED_TOLERANCE", SPEED_TOLERANCE)?;
    m.add("START_SPEED_INDEX", START_SPEED_INDEX)?;
    let modes = PyDict::new(py);
    for mode in SORT_MODES {
        modes.set_item(serde_name(mode), mode.index())?;
    }
    m.add("MODES", modes)?;
    m.add("MODE_COUNT", SORT_MODES.len())?;
    let labels = PyDict::new(py);
    for mode in SORT_MODES {
        labels.set_item(mode.index(), mode.label())?;
    }
    m.add("MODE_LABELS", labels)?;
    let categories = PyDict::new(py);
    for category in CATEGORIES {
        categories.set_item(serde_name(category), category.index())?;
    }
    m.add("CATEGORIES", categories)?;
    m.add("CATEGORY_UNKNOWN_CODE", CATEGORY_UNKNOWN_CODE)?;
    m.add("CATEGORY_UNKNOWN_OBSERVATION", CATEGORY_UNKNOWN_OBSERVATION)?;
    let defaults = LineConfig::default();
    m.add("THRESHOLD", defaults.threshold)?;
    m.add("BELOW_THRESHOLD_REWARD", BELOW_THRESHOLD_REWARD)?;
    m.add("EPISODE_STEPS", defaults.max_steps)?;
    m.add("MAX_EPISODE_STEPS", MAX_EPISODE_STEPS)?;
    m.add("EVAL_FIRST_SEED", EVAL_FIRST_SEED)?;
    m.add("EVAL_EPISODES", EVAL_EPISODES)?;
    m.add("NODE_LINES", MAX_NODE_LINES)?;
    let counts = PyDict::new(py);
    for variant in VARIANTS {
        counts.set_item(variant.to_string(), Action::count(variant))?;
    }
    m.add("ACTION_COUNTS", counts)?;
    m.add("SETTING_RANGES", setting_ranges(py)?)?;
    m.add("INFO_KEYS", PyTuple::new(py, INFO.iter().map(|(key, _, _)| *key))?)?;
    m.add("INFO_FIELDS", info_fields(py)?)?;
    let contents = PyDict::new(py);
    for (place, batch) in [("input", START_INPUT), ("belt", START_BELT), ("machine", START_MACHINE)] {
        contents.set_item(place, (batch.a, batch.b))?;
    }
    m.add("START_CONTENTS", contents)?;
    m.add("START_ACCURACY", START_ACCURACY)?;
    m.add("START_OCCUPANCY", START_BELT.occupancy())?;
    m.add("LEVELS", LEVELS)?;
    m.add_function(wrap_pyfunction!(observations, m)?)?;
    m.add_function(wrap_pyfunction!(action_mask, m)?)?;
    m.add_function(wrap_pyfunction!(level, m)?)?;
    m.add_function(wrap_pyfunction!(speed_index_of, m)?)?;
    m.add_function(wrap_pyfunction!(reward, m)?)?;
    Ok(())
}
