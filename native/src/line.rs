//! One line for a Gymnasium `Env`: `reset` and `step` return what the env returns, the
//! observation, the info dict and (evolving line) its announcements built here, so a step costs
//! one call from Python. The values are the ROS env's: the node's `state` message and this info
//! are both built from the library's `sim::Report` of the same `Line`.

use numpy::PyArray1;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use sorting_line::sim::evolution::CATEGORY_UNKNOWN_OBSERVATION;
use sorting_line::sim::evolution::{category_code, event_changes, At, Settings, CATEGORY_UNKNOWN_CODE};
use sorting_line::sim::line::action_mask;
use sorting_line::sim::{Action, Line, Report, Variant};

use crate::info::{info_of, Value, INFO};
use crate::{bridge_error, LineSettings, Spec};

/// The category code a line reports (the ROS node's `observation_category`): the true category of
/// the next batch, or on an evolving line the ratio sensor's reading (3: no sensor yet).
pub(crate) fn category_of(line: &Line, evolving: bool) -> u8 {
    if evolving {
        category_code(line.category_reading())
    } else {
        line.observation().category as u8
    }
}

/// The observation vector (float32, as `vocabulary.observations`) into `out` (1 or 2 entries).
pub(crate) fn write_observation(line: &Line, evolving: bool, out: &mut [f32]) {
    out[0] = line.observation().quantity as f32;
    if out.len() > 1 {
        out[1] = category_observation(i64::from(category_of(line, evolving)));
    }
}

/// The observation slot of a category code: the code, or [`CATEGORY_UNKNOWN_OBSERVATION`] for
/// the unknown one (no ratio sensor yet): inside the advanced Box(0, 2) and no category's value.
pub(crate) fn category_observation(code: i64) -> f32 {
    if code == i64::from(CATEGORY_UNKNOWN_CODE) {
        CATEGORY_UNKNOWN_OBSERVATION as f32
    } else {
        code as f32
    }
}

/// Why a line cannot step now, if it cannot: never reset, or its episode reached its time limit.
pub(crate) fn not_steppable(line: &Line, reset_done: bool) -> Option<String> {
    if !reset_done {
        return Some("step() before reset()".into());
    }
    line.truncated().then(|| {
        format!(
            "step() after the end of the episode (step {} of max_episode_steps = {}): reset() first",
            line.step_count(),
            line.config().max_steps
        )
    })
}

/// One sorting line (see the module docs).
#[pyclass(module = "sorting_line_gym._native")]
pub struct NativeLine {
    line: Line,
    encoding: Variant,
    evolving: bool,
    reset_done: bool,
}

#[pymethods]
impl NativeLine {
    #[new]
    fn new(settings: LineSettings) -> PyResult<Self> {
        let spec = Spec::new(&settings)?;
        let (encoding, evolving) = (spec.encoding(), spec.evolving());
        let line = Line::with_evolution(spec.config, 0, spec.schedule);
        Ok(NativeLine { line, encoding, evolving, reset_done: false })
    }

    /// Starts an episode from `seed`: (observation, info) as the env's reset returns them.
    fn reset<'py>(&mut self, py: Python<'py>, seed: u64) -> PyResult<Bound<'py, PyTuple>> {
        self.line.reset(Some(seed));
        self.reset_done = true;
        let info = PyDict::new(py);
        info.set_item(intern!(py, "seed"), self.line.seed())?;
        info.set_item(intern!(py, "step"), 0)?;
        if self.evolving {
            let episode = self.line.episode();
            let announced = PyList::empty(py);
            let indices: Vec<usize> = self.line.evolution().events_at(At::Episode(episode)).map(|(i, _)| i).collect();
            if !indices.is_empty() {
                announced.append(self.event_info(py, true, &indices)?)?;
            }
            self.add_evolution(py, &info, announced)?;
        }
        (self.observation(py), info).into_pyobject(py)
    }

    /// One step: (observation, reward, terminated, truncated, info), or `ValueError` for an
    /// action outside the action space (the line is left as it was).
    fn step<'py>(&mut self, py: Python<'py>, action: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyTuple>> {
        let count = Action::count(self.encoding);
        let index = action.extract::<i64>().ok().filter(|a| (0..count as i64).contains(a));
        let Some(index) = index else {
            let shown = action.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into());
            return Err(crate::value_error(format!(
                "action {shown} is not in Discrete({count}): allowed integers 0 ..= {}",
                count - 1
            )));
        };
        if let Some(why) = not_steppable(&self.line, self.reset_done) {
            return Err(bridge_error(py, why));
        }
        let action = Action::from_discrete(self.encoding, index as usize).expect("checked above");
        let outcome = self.line.step(action);
        let info = self.info(py)?;
        if self.evolving {
            self.add_evolution(py, &info, PyList::empty(py))?;
        }
        (self.observation(py), outcome.reward, false, outcome.truncated, info).into_pyobject(py)
    }

    /// Valid Gymnasium actions now: all of them, but on an evolving line only mode 0 while the
    /// next step runs without sort modes (and before the first reset, as the ROS env knows no
    /// settings yet).
    fn action_mask<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        let modes = !self.evolving || (self.reset_done && self.line.sort_modes_at_next_step());
        PyArray1::from_vec(py, action_mask(self.encoding, modes).collect())
    }

    /// The settings the next step runs with (evolving line's `settings`).
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        settings_dict(py, &self.next_settings())
    }

    /// Steps since the line was built, over all episodes.
    #[getter]
    fn tick(&self) -> u64 {
        self.line.tick()
    }

    /// Episodes started since the line was built.
    #[getter]
    fn episode(&self) -> u32 {
        self.line.episode()
    }
}

impl NativeLine {
    fn observation<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        let mut out = [0.0f32; 2];
        let dim = if self.encoding == Variant::Advanced { 2 } else { 1 };
        write_observation(&self.line, self.evolving, &mut out[..dim]);
        PyArray1::from_slice(py, &out[..dim])
    }

    /// The info of the step just taken ([`crate::info`]), as the single-line env reports it.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let info = PyDict::new(py);
        for ((key, _, _), value) in INFO.iter().zip(info_of(&Report::of(&self.line))) {
            let key = PyString::intern(py, key);
            match value {
                Value::Float(v) => info.set_item(key, v)?,
                Value::Int(v) => info.set_item(key, v)?,
                Value::Containers(v) => info.set_item(key, PyTuple::new(py, v)?)?,
                Value::Seed(v) => info.set_item(key, v)?,
            }
        }
        Ok(info)
    }

    /// The settings after the events due at the next step (what the ROS env has been told).
    fn next_settings(&self) -> Settings {
        self.line.pending_tick_events().map_or_else(|| self.line.settings(), |(_, after)| after)
    }

    /// The evolving env's `evolution`, `settings` and `line_tick` keys, after the events of the
    /// next step were announced into `announced`.
    fn add_evolution<'py>(
        &self,
        py: Python<'py>,
        info: &Bound<'py, PyDict>,
        announced: Bound<'py, PyList>,
    ) -> PyResult<()> {
        if let Some((indices, _)) = self.line.pending_tick_events() {
            announced.append(self.event_info(py, false, &indices)?)?;
        }
        info.set_item(intern!(py, "evolution"), announced)?;
        info.set_item(intern!(py, "settings"), settings_dict(py, &self.next_settings())?)?;
        info.set_item(intern!(py, "line_tick"), self.line.tick())?;
        Ok(())
    }

    /// One announcement as the env's info lists it: `{"at_reset", "episode", "tick", "changed"}`.
    fn event_info<'py>(&self, py: Python<'py>, at_reset: bool, indices: &[usize]) -> PyResult<Bound<'py, PyDict>> {
        let events = &self.line.evolution().events;
        let changed = PyDict::new(py);
        for &i in indices {
            for (field, value) in event_changes(&events[i]) {
                changed.set_item(field, value)?;
            }
        }
        let out = PyDict::new(py);
        out.set_item(intern!(py, "at_reset"), at_reset)?;
        out.set_item(intern!(py, "episode"), self.line.episode())?;
        out.set_item(intern!(py, "tick"), self.line.tick())?;
        out.set_item(intern!(py, "changed"), changed)?;
        Ok(out)
    }
}

/// The evolving env's `settings` dict.
pub(crate) fn settings_dict<'py>(py: Python<'py>, s: &Settings) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item(intern!(py, "obs_noise"), s.obs_noise)?;
    out.set_item(intern!(py, "action_penalty"), s.action_penalty)?;
    out.set_item(intern!(py, "threshold"), s.threshold)?;
    out.set_item(intern!(py, "input"), s.input.to_string())?;
    out.set_item(intern!(py, "sort_modes"), s.sort_modes)?;
    out.set_item(intern!(py, "ratio_sensor"), s.ratio_sensor)?;
    Ok(out)
}
