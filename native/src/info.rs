//! A step's info dict, stated once: its keys in order, the kind of each value, the `LineState`
//! fields the ROS backend reads it from, and the values of a line after a step. The single-line
//! env ([`crate::line`]) and the vector envs ([`crate::lines`]) build their infos from
//! [`info_of`]; the ROS backend's `vocabulary.state_info` builds its own from [`INFO`], exported as
//! `INFO_FIELDS` (a message is Python attributes there, one line's scalars or a batch's arrays).

use sorting_line::sim::Report;

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

/// The info of a line after a step, from its [`Report`], in the order of [`INFO`]. The node's
/// `state` message is built from the same report (`Report::of` in the library).
pub fn info_of(r: &Report) -> [Value; INFO.len()] {
    [
        Value::Float(r.accuracy),
        Value::Float(r.purity),
        Value::Float(r.recall_a),
        Value::Float(r.recall_b),
        Value::Float(r.speed),
        Value::Int(r.speed_index as i64),
        Value::Int(r.mode as i64),
        Value::Float(r.occupancy),
        Value::Containers(r.containers),
        Value::Int(i64::from(r.speed_changes)),
        Value::Float(r.cumulative_reward),
        Value::Int(i64::from(r.step)),
        // The node stamps tick k at k * tick_period (1 s): the seconds since the reset are the steps.
        Value::Float(f64::from(r.step)),
        Value::Seed(r.seed),
    ]
}

/// The keys of `kind`, in order (the rows of a batch's arrays of that kind).
pub fn keys_of(kinds: &[Kind]) -> Vec<&'static str> {
    INFO.iter().filter(|(_, kind, _)| kinds.contains(kind)).map(|(key, _, _)| *key).collect()
}
