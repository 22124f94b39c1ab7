//! A batch of lines for the vector envs: one `step` call steps every line with the GIL released
//! and writes the results into numpy arrays allocated once, at construction (no Python object per
//! line or per step). Python reads them as views and copies what it hands out.
//!
//! The arrays (entry k = line k): `observations` (N, 1|2) float32; `floats` (9, N) float64 with
//! rows [`FLOAT_ROWS`]; `ints` (4, N) int64 with rows [`INT_ROWS`]; `containers` (N, 4) uint32 (a,
//! a_false, b, b_false); `seeds` (N,) uint64; `truncated` (N,) bool; `masks` (N, actions) bool.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use sorting_line::sim::{Action, Line, Variant};

use crate::line::{action_count, not_steppable, write_observation};
use crate::{bridge_error, value_error, LineSettings, Spec};

/// The rows of `floats`, in order.
pub const FLOAT_ROWS: [&str; 9] =
    ["reward", "accuracy", "purity", "recall_a", "recall_b", "speed", "occupancy", "cumulative_reward", "sim_time"];
/// The rows of `ints`, in order.
pub const INT_ROWS: [&str; 4] = ["speed_index", "mode", "speed_changes", "step"];

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
            floats: PyArray2::zeros(py, [FLOAT_ROWS.len(), lines], false).unbind(),
            ints: PyArray2::zeros(py, [INT_ROWS.len(), lines], false).unbind(),
            containers: PyArray2::zeros(py, [lines, 4], false).unbind(),
            seeds: PyArray1::zeros(py, lines, false).unbind(),
            truncated: PyArray1::zeros(py, lines, false).unbind(),
            masks: PyArray2::from_vec2(py, &vec![vec![true; action_count(encoding)]; lines])?.unbind(),
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
        self.with_out(py, |lines, reset_done, evolving, out| {
            for (&k, &seed) in indices.iter().zip(&seeds) {
                let k = k as usize;
                lines[k].reset(Some(seed));
                reset_done[k] = true;
                write_line(&lines[k], k, evolving, out, true);
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
        let count = action_count(self.encoding) as i64;
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
                write_line(line, k, evolving, out, false);
            }
        })
    }

    /// The row names of `floats` and `ints`.
    #[classattr]
    fn float_rows() -> Vec<&'static str> {
        FLOAT_ROWS.to_vec()
    }

    #[classattr]
    fn int_rows() -> Vec<&'static str> {
        INT_ROWS.to_vec()
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

/// Line `k`'s state into the output arrays (after a step, or a reset: no step yet, KPIs 0).
fn write_line(line: &Line, k: usize, evolving: bool, out: &mut Out<'_>, reset: bool) {
    let n = out.seeds.len();
    let dim = out.obs.len() / n;
    write_observation(line, evolving, &mut out.obs[k * dim..(k + 1) * dim]);
    out.seeds[k] = line.seed();
    out.truncated[k] = !reset && line.truncated();
    let actions = out.masks.len() / n;
    let modes = !evolving || line.sort_modes_at_next_step();
    for (a, m) in out.masks[k * actions..(k + 1) * actions].iter_mut().enumerate() {
        *m = modes || a % 3 == 0;
    }
    if reset {
        return;
    }
    let c = line.containers();
    let last = line.last_step().expect("a line that stepped has a last step");
    let floats = [
        last.reward,
        last.accuracy,
        c.purity(),
        c.recall_a(),
        c.recall_b(),
        line.speed(),
        last.occupancy,
        line.cumulative_reward(),
        f64::from(line.step_count()),
    ];
    for (row, v) in floats.into_iter().enumerate() {
        out.floats[row * n + k] = v;
    }
    let ints =
        [line.speed_index() as i64, line.mode() as i64, i64::from(line.speed_changes()), i64::from(line.step_count())];
    for (row, v) in ints.into_iter().enumerate() {
        out.ints[row * n + k] = v;
    }
    let count = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
    out.containers[k * 4..k * 4 + 4].copy_from_slice(&[count(c.a), count(c.a_false), count(c.b), count(c.b_false)]);
}
