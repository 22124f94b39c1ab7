//! A step's info dict, stated once: its keys in order, the kind of each value, the `LineState`
//! fields the ROS backend reads it from, and the values of a line after a step. The single-line
//! env ([`crate::line`]) and the vector envs ([`crate::lines`]) build their infos from
//! [`info_of`]; the ROS backend's `vocabulary.state_info` builds its own from [`INFO`], exported as
//! `INFO_FIELDS` (a message is Python attributes there, one line's scalars or a batch's arrays).

use sorting_line::sim::Line;

/// How a value of the info is typed in Python.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A float (float64 in a batch).
    Float,
    /// An int (int64 in a batch).
    Int,
    /// The four container counters `(a, a_false, b, b_false)`: a tuple of ints (an (N, 4) uint32
    /// array in a batch).
    Containers,
    /// The episode's seed: an int (uint64 in a batch: seeds reach 2**64 - 1).
    Seed,
    /// Simulated seconds since the episode's reset: a float, from the message's stamp, not a field.
    Time,
}

impl Kind {
    /// The name `INFO_FIELDS` gives it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Float => "float",
            Kind::Int => "int",
            Kind::Containers => "containers",
            Kind::Seed => "seed",
            Kind::Time => "time",
        }
    }
}

/// The info keys of a step, in order (docs/gymnasium.md lists them), each with its kind and the
/// `LineState` fields it is read from.
pub const INFO: [(&str, Kind, &[&str]); 14] = [
    ("accuracy", Kind::Float, &["accuracy"]),
    ("purity", Kind::Float, &["purity"]),
    ("recall_a", Kind::Float, &["recall_a"]),
    ("recall_b", Kind::Float, &["recall_b"]),
    ("speed", Kind::Float, &["speed"]),
    ("speed_index", Kind::Int, &["speed_index"]),
    ("mode", Kind::Int, &["mode"]),
    ("occupancy", Kind::Float, &["occupancy"]),
    ("containers", Kind::Containers, &["container_a", "container_a_false", "container_b", "container_b_false"]),
    ("speed_changes", Kind::Int, &["speed_changes"]),
    ("cumulative_reward", Kind::Float, &["cumulative_reward"]),
    ("step", Kind::Int, &["step"]),
    ("sim_time", Kind::Time, &[]),
    ("seed", Kind::Seed, &["seed"]),
];

/// One value of the info (its [`Kind`]; a `Time` is a `Float`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Float(f64),
    Int(i64),
    Containers([u32; 4]),
    Seed(u64),
}

/// The info of `line` after a step whose batch was sorted at `accuracy` with the belt at
/// `occupancy` (the step's outcome), in the order of [`INFO`]. The values are the ROS env's:
/// `LineState::of` in the node fills the same fields from the same `Line`.
pub fn info_of(line: &Line, accuracy: f64, occupancy: f64) -> [Value; INFO.len()] {
    let c = line.containers();
    let count = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
    [
        Value::Float(accuracy),
        Value::Float(c.purity()),
        Value::Float(c.recall_a()),
        Value::Float(c.recall_b()),
        Value::Float(line.speed()),
        Value::Int(line.speed_index() as i64),
        Value::Int(line.mode() as i64),
        Value::Float(occupancy),
        Value::Containers([count(c.a), count(c.a_false), count(c.b), count(c.b_false)]),
        Value::Int(i64::from(line.speed_changes())),
        Value::Float(line.cumulative_reward()),
        Value::Int(i64::from(line.step_count())),
        // The node stamps tick k at k * tick_period (1 s): the seconds since the reset are the steps.
        Value::Float(f64::from(line.step_count())),
        Value::Seed(line.seed()),
    ]
}

/// The keys of `kind`, in order (the rows of a batch's arrays of that kind).
pub fn keys_of(kinds: &[Kind]) -> Vec<&'static str> {
    INFO.iter().filter(|(_, kind, _)| kinds.contains(kind)).map(|(key, _, _)| *key).collect()
}
