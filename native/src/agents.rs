//! The library's non-learning agents and its offline evaluation, callable from Python without the
//! `sorting_line` CLI: `Agent` (rba, rba-hold, bayes, random, constant:K[:M|:cat], the names of
//! `sorting_line eval --agent`), `evaluate` and `oracle_eval` (the JSON of `sorting_line eval
//! --json` and `sorting_line oracle --json`, as dicts), `oracle` (one seed's optimum), `policy`
//! (the tables of `sorting_line policy`) and `table` (the rows of `sorting_line table`).

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sorting_line::eval::{add_oracle, evaluate as run_eval, evaluate_oracle};
use sorting_line::sim::agent::{Agent as LibAgent, AgentSpec};
use sorting_line::sim::material::{Category, CATEGORIES};
use sorting_line::sim::rba::{analysis_table, policy as lib_policy, ANALYSIS_COLUMNS};
use sorting_line::sim::speed::SPEED_COUNT;
use sorting_line::sim::{oracle as lib_oracle, LineConfig, Observation, Setup, Variant};

use crate::{value_error, LineSettings, Spec};

/// A library agent deciding from Gymnasium observations.
#[pyclass(module = "sorting_line_gym._native", name = "Agent")]
pub struct NativeAgent {
    agent: LibAgent,
    encoding: Variant,
}

#[pymethods]
impl NativeAgent {
    #[new]
    #[pyo3(signature = (name, settings, seed=0))]
    fn new(name: &str, settings: LineSettings, seed: u64) -> PyResult<Self> {
        let spec = Spec::new(&settings)?;
        let parsed: AgentSpec = name.parse().map_err(value_error)?;
        let agent = LibAgent::new(parsed, &spec.config, seed).map_err(value_error)?;
        Ok(NativeAgent { agent, encoding: spec.config.variant })
    }

    /// The Gymnasium action for a reading (0..1), its ratio category (0, 1, 2) and the belt's
    /// current speed index.
    fn act(&mut self, quantity: f64, category: u8, current_speed_index: usize) -> PyResult<usize> {
        if !(0.0..=1.0).contains(&quantity) {
            return Err(value_error(format!("quantity = {quantity} is out of range: allowed 0.0 ..= 1.0")));
        }
        let category = Category::from_index(category).ok_or_else(|| {
            value_error(format!("category = {category} is out of range: allowed {}", category_codes()))
        })?;
        if current_speed_index >= SPEED_COUNT {
            return Err(value_error(format!(
                "current_speed_index = {current_speed_index} is out of range: allowed 0 ..= {}",
                SPEED_COUNT - 1
            )));
        }
        let action = self.agent.act(Observation { quantity, category }, current_speed_index);
        Ok(action.to_discrete(self.encoding))
    }

    /// Starts an episode (the random agent's stream restarts from `seed`).
    fn reseed(&mut self, seed: u64) {
        self.agent.reseed(seed);
    }
}

/// The ratio categories' codes, as an error message lists them (`0, 1, 2`).
fn category_codes() -> String {
    CATEGORIES.iter().map(|c| c.index().to_string()).collect::<Vec<_>>().join(", ")
}

fn json_to_py<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| value_error(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// `sorting_line eval --json` as a dict: `agent` over `episodes` episodes, episode i seeded
/// `seed + i` (on the evolving line if the settings name a schedule); `gap` adds the oracle.
#[pyfunction]
#[pyo3(signature = (agent, settings, episodes, seed, gap=false))]
fn evaluate<'py>(
    py: Python<'py>,
    agent: &str,
    settings: LineSettings,
    episodes: usize,
    seed: u64,
    gap: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let spec = Spec::new(&settings)?;
    let parsed: AgentSpec = agent.parse().map_err(value_error)?;
    let summary = py.detach(|| {
        let mut summary = run_eval(&spec.config, &spec.schedule, parsed, episodes, seed, |_| {})?;
        if gap {
            add_oracle(&mut summary)?;
        }
        Ok::<_, String>(summary)
    });
    json_to_py(py, &summary.map_err(value_error)?)
}

/// `sorting_line oracle --json` as a dict.
#[pyfunction]
fn oracle_eval<'py>(
    py: Python<'py>,
    settings: LineSettings,
    episodes: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyAny>> {
    let spec = Spec::new(&settings)?;
    let summary = py.detach(|| evaluate_oracle(&spec.config, episodes, seed, |_| {})).map_err(value_error)?;
    json_to_py(py, &summary)
}

/// The clairvoyant optimum of the episode a reset with `seed` starts: (reward, Gymnasium actions).
#[pyfunction]
fn oracle(py: Python<'_>, settings: LineSettings, seed: u64) -> PyResult<(f64, Vec<usize>)> {
    let spec = Spec::new(&settings)?;
    let best = py.detach(|| lib_oracle::solve(&spec.config, seed)).map_err(value_error)?;
    let actions = best.actions.iter().map(|a| a.to_discrete(spec.config.variant)).collect();
    Ok((best.reward, actions))
}

/// The tables of `rba` and `rba-hold` for a setup and variant, as `sorting_line policy --json`
/// prints them (`sim::rba::policy`), as a dict.
#[pyfunction]
fn policy<'py>(py: Python<'py>, setup: &str, variant: &str) -> PyResult<Bound<'py, PyAny>> {
    let setup: Setup = setup.parse().map_err(value_error)?;
    let variant: Variant = variant.parse().map_err(value_error)?;
    json_to_py(py, &lib_policy(setup, variant))
}

/// The rows of `sorting_line table --variant VARIANT --threshold THRESHOLD` (`sim::rba::analysis`,
/// the rule-based agent's expected-reward analysis; the threshold defaults to the line's): one
/// dict per CSV row, column name to the text the CLI prints.
#[pyfunction]
#[pyo3(signature = (variant, threshold=None))]
fn table<'py>(py: Python<'py>, variant: &str, threshold: Option<f64>) -> PyResult<Bound<'py, PyList>> {
    let variant: Variant = variant.parse().map_err(value_error)?;
    let threshold = threshold.unwrap_or(LineConfig::default().threshold);
    let rows = analysis_table(variant, threshold).map_err(|e| value_error(e.to_string()))?;
    let out = PyList::empty(py);
    for row in &rows {
        let fields = PyDict::new(py);
        for (column, text) in ANALYSIS_COLUMNS.iter().zip(row.fields()) {
            fields.set_item(*column, text)?;
        }
        out.append(fields)?;
    }
    Ok(out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeAgent>()?;
    m.add_function(wrap_pyfunction!(policy, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(oracle_eval, m)?)?;
    m.add_function(wrap_pyfunction!(oracle, m)?)?;
    m.add_function(wrap_pyfunction!(table, m)?)?;
    Ok(())
}
