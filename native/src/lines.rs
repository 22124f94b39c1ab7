//! A batch of lines for the vector envs: one `step` call steps every line with the GIL released
//! and writes the results into numpy arrays allocated once, at construction (no Python object per
//! line or per step). Python reads them as views and copies what it hands out.
//!
//! The arrays (entry k = line k): `observations` (N, 1|2) float32; `floats` (rows, N) float64
//! with rows `float_rows` (the reward, then the info's float keys); `ints` (rows, N) int64 with
//! rows `int_rows` (the info's int keys); `containers` (N, 4) uint32 (a, a_false, b, b_false);
//! `seeds` (N,) uint64; `truncated` (N,) bool; `masks` (N, actions) bool. `info()` is the info of
//! the last step as the vector envs hand it out, copies of these in the order of [`INFO`].

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use sorting_line::sim::line::action_mask;
use sorting_line::sim::{Action, Line, Report, Variant};

use crate::info::{info_of, keys_of, Kind, Value, INFO};
use crate::line::{not_steppable, write_observation};
use crate::{bridge_error, value_error, LineSettings, Spec};

/// The row of `floats` that holds the step's reward (the info's float keys follow it).
const REWARD_ROW: &str = "reward";

/// The rows of `floats`, in order.
fn float_rows() -> Vec<&'static str> {
    let mut rows = vec![REWARD_ROW];
    rows.extend(keys_of(&[Kind::Float, Kind::Time]));
    rows
}

/// The rows of `ints`, in order.
fn int_rows() -> Vec<&'static str> {
    keys_of(&[Kind::Int])
}

/// N lines (see the module docs).
#[pyclass(module = "sorting_line_gym._native")]
pub struct NativeLines {
    lines: Vec<Line>,
    reset_done: Vec<bool>,
    encoding: Variant,
    evolving: bool,
    #[pyo3(get)]
    observations: Py<PyArray2<f32>>,
    #[pyo3(get)]
    floats: Py<PyArray2<f64>>,
    #[pyo3(get)]
    ints: Py<PyArray2<i64>>,
    #[pyo3(get)]
    containers: Py<PyArray2<u32>>,
    #[pyo3(get)]
    seeds: Py<PyArray1<u64>>,
    #[pyo3(get)]
    truncated: Py<PyArray1<bool>>,
    #[pyo3(get)]
    masks: Py<PyArray2<bool>>,
}

/// The output arrays as slices, for the GIL-free part of a call.
struct Out<'a> {
    obs: &'a mut [f32],
    floats: &'a mut [f64],
    ints: &'a mut [i64],
    containers: &'a mut [u32],
    seeds: &'a mut [u64],
    truncated: &'a mut [bool],
    masks: &'a mut [bool],
}

#[pymethods]
impl NativeLines {
    #[new]
    fn new(py: Python<'_>, lines: usize, settings: LineSettings) -> PyResult<Self> {
        if lines == 0 || lines > 1 << 20 {
            return Err(value_error(format!("lines = {lines} is out of range: allowed 1 ..= {}", 1 << 20)));
        }
        let spec = Spec::new(&settings)?;
        let (encoding, evolving) = (spec.encoding(), spec.evolving());
        let dim = if encoding == Variant::Advanced { 2 } else { 1 };
        let made: Vec<Line> =
            (0..lines).map(|k| Line::with_evolution(spec.config.clone(), k as u64, spec.schedule.clone())).collect();
        Ok(NativeLines {
            reset_done: vec![false; lines],
            encoding,
            evolving,
            observations: PyArray2::zeros(py, [lines, dim], false).unbind(),
            floats: PyArray2::zeros(py, [float_rows().len(), lines], false).unbind(),
            ints: PyArray2::zeros(py, [int_rows().len(), lines], false).unbind(),
            containers: PyArray2::zeros(py, [lines, 4], false).unbind(),
            seeds: PyArray1::zeros(py, lines, false).unbind(),
            truncated: PyArray1::zeros(py, lines, false).unbind(),
            masks: PyArray2::from_vec2(py, &vec![vec![true; Action::count(encoding)]; lines])?.unbind(),
            lines: made,
        })
    }

    /// Resets the lines `indices` with `seeds` (same lengths); their observation rows, seeds and
    /// masks are written, and their step counters and KPIs start again at 0.
    fn reset(&mut self, py: Python<'_>, indices: PyReadonlyArray1<i64>, seeds: PyReadonlyArray1<u64>) -> PyResult<()> {
        let (indices, seeds) = (indices.as_slice()?, seeds.as_slice()?);
        if indices.len() != seeds.len() {
            return Err(value_error(format!("{} seeds for {} lines to reset", seeds.len(), indices.len())));
        }
        let n = self.lines.len();
        if let Some(bad) = indices.iter().find(|&&k| k < 0 || k as usize >= n) {
            return Err(value_error(format!("line index {bad} is out of range: allowed 0 ..= {}", n - 1)));
        }
        let (indices, seeds) = (indices.to_vec(), seeds.to_vec());
        let encoding = self.encoding;
        self.with_out(py, |lines, reset_done, evolving, out| {
            for (&k, &seed) in indices.iter().zip(&seeds) {
                let k = k as usize;
                lines[k].reset(Some(seed));
                reset_done[k] = true;
                write_line(&lines[k], k, (encoding, evolving), out, true);
            }
        })
    }

    /// Steps every line by its Gymnasium action (`actions`: int64, one per line). All actions are
    /// checked before any line steps.
    fn step(&mut self, py: Python<'_>, actions: PyReadonlyArray1<i64>) -> PyResult<()> {
        let actions = actions.as_slice()?;
        let n = self.lines.len();
        if actions.len() != n {
            return Err(value_error(format!(
                "a batch of {} actions for {n} lines: allowed exactly {n}",
                actions.len()
            )));
        }
        let count = Action::count(self.encoding) as i64;
        if let Some((k, a)) = actions.iter().enumerate().find(|(_, a)| !(0..count).contains(*a)) {
            return Err(value_error(format!(
                "action {a} of line {k} is not in Discrete({count}): allowed integers 0 ..= {}",
                count - 1
            )));
        }
        for (k, line) in self.lines.iter().enumerate() {
            if let Some(why) = not_steppable(line, self.reset_done[k]) {
                return Err(bridge_error(py, format!("line {k}: {why}")));
            }
        }
        let encoding = self.encoding;
        let decoded: Vec<Action> =
            actions.iter().map(|&a| Action::from_discrete(encoding, a as usize).expect("checked above")).collect();
        self.with_out(py, |lines, _, evolving, out| {
            for (k, (line, action)) in lines.iter_mut().zip(decoded).enumerate() {
                line.step(action);
                write_line(line, k, (encoding, evolving), out, false);
            }
        })
    }

    /// The row names of `floats` and `ints`.
    #[classattr]
    fn float_rows() -> Vec<&'static str> {
        float_rows()
    }

    #[classattr]
    fn int_rows() -> Vec<&'static str> {
        int_rows()
    }

    /// The step's reward per line, a copy.
    fn rewards<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let floats = self.floats.bind(py).try_readonly()?;
        let n = self.lines.len();
        Ok(PyArray1::from_slice(py, &floats.as_slice()?[..n]))
    }

    /// The info of the last step, keys in the order of the single line's (one array per key,
    /// entry k = line k; each a copy, so the next step leaves it as it was).
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let n = self.lines.len();
        let floats = self.floats.bind(py).try_readonly()?;
        let ints = self.ints.bind(py).try_readonly()?;
        let (floats, ints) = (floats.as_slice()?, ints.as_slice()?);
        let (mut float_row, mut int_row) = (1, 0); // row 0 of `floats` is the reward
        let info = PyDict::new(py);
        for (key, kind, _) in INFO {
            let key = PyString::intern(py, key);
            match kind {
                Kind::Float | Kind::Time => {
                    info.set_item(key, PyArray1::from_slice(py, &floats[float_row * n..(float_row + 1) * n]))?;
                    float_row += 1;
                }
                Kind::Int => {
                    info.set_item(key, PyArray1::from_slice(py, &ints[int_row * n..(int_row + 1) * n]))?;
                    int_row += 1;
                }
                Kind::Containers => info.set_item(key, self.containers.bind(py).to_owned_array().into_pyarray(py))?,
                Kind::Seed => info.set_item(key, self.seeds.bind(py).to_owned_array().into_pyarray(py))?,
            }
        }
        Ok(info)
    }

    fn __len__(&self) -> usize {
        self.lines.len()
    }
}

impl NativeLines {
    /// Runs `work` on the lines and the output arrays with the GIL released.
    fn with_out<F>(&mut self, py: Python<'_>, work: F) -> PyResult<()>
    where
        F: FnOnce(&mut [Line], &mut [bool], bool, &mut Out<'_>) + Send,
    {
        let mut obs = self.observations.bind(py).try_readwrite()?;
        let mut floats = self.floats.bind(py).try_readwrite()?;
        let mut ints = self.ints.bind(py).try_readwrite()?;
        let mut containers = self.containers.bind(py).try_readwrite()?;
        let mut seeds = self.seeds.bind(py).try_readwrite()?;
        let mut truncated = self.truncated.bind(py).try_readwrite()?;
        let mut masks = self.masks.bind(py).try_readwrite()?;
        let mut out = Out {
            obs: obs.as_slice_mut()?,
            floats: floats.as_slice_mut()?,
            ints: ints.as_slice_mut()?,
            containers: containers.as_slice_mut()?,
            seeds: seeds.as_slice_mut()?,
            truncated: truncated.as_slice_mut()?,
            masks: masks.as_slice_mut()?,
        };
        let (lines, reset_done, evolving) = (&mut self.lines, &mut self.reset_done, self.evolving);
        py.detach(|| work(lines, reset_done, evolving, &mut out));
        Ok(())
    }
}

/// Line `k`'s state into the output arrays (after a step, or a reset: no step yet, KPIs 0);
/// `line_kind` is how its actions decode and whether it evolves.
fn write_line(line: &Line, k: usize, line_kind: (Variant, bool), out: &mut Out<'_>, reset: bool) {
    let (encoding, evolving) = line_kind;
    let n = out.seeds.len();
    let dim = out.obs.len() / n;
    write_observation(line, evolving, &mut out.obs[k * dim..(k + 1) * dim]);
    out.seeds[k] = line.seed();
    out.truncated[k] = !reset && line.truncated();
    let actions = Action::count(encoding);
    let modes = !evolving || line.sort_modes_at_next_step();
    for (m, allowed) in out.masks[k * actions..(k + 1) * actions].iter_mut().zip(action_mask(encoding, modes)) {
        *m = allowed;
    }
    if reset {
        return;
    }
    let report = Report::of(line);
    out.floats[k] = report.reward; // the reward row
    let (mut float_row, mut int_row) = (1, 0);
    for value in info_of(&report) {
        match value {
            Value::Float(v) => {
                out.floats[float_row * n + k] = v;
                float_row += 1;
            }
            Value::Int(v) => {
                out.ints[int_row * n + k] = v;
                int_row += 1;
            }
            Value::Containers(v) => out.containers[k * 4..k * 4 + 4].copy_from_slice(&v),
            Value::Seed(_) => {} // written above, at a reset too
        }
    }
}
