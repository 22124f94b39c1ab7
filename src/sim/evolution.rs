//! The evolving line: a schedule of changes that happen to a line during a run (the paper's
//! "evolving industrial environments": minor changes such as more sensor noise or a new quality
//! threshold, major ones such as a machine or a sensor upgrade), plus input-sensor faults in the
//! spirit of the real-world RL suite (RWRL). Pure data and validation; the line applies it
//! (`line.rs`), so a schedule, a seed and the actions fix the trajectory.
//!
//! # File format (YAML; JSON is YAML too)
//! ```yaml
//! # The paper's upgrade: basic B for 2000 episodes, then the sorting machine gets its modes and
//! # the ratio sensor is fitted (advanced B).
//! events:
//!   - at: {episode: 2001}
//!     sort_modes: true        # machine upgrade
//!     ratio_sensor: true      # sensor upgrade
//!   - at: {tick: 150000}
//!     obs_noise: 0.3
//!     threshold: 0.8
//!   - at: {tick: 200000}
//!     input_fault: {kind: stuck, ticks: 20}
//! ```
//! An event has one `at` (`{episode: E}` or `{tick: T}`) and sets one or more of:
//! - `obs_noise`, `action_penalty`, `threshold`: as in the line configuration, same ranges;
//! - `input`: the input generator, `random`, `seasonal` (the nine seasonal patterns) or
//!   `seasonal3` (the three-pattern set); the generator carries on drawing from the line's input
//!   stream, a seasonal one starting a new pattern at once (setting the input it already has
//!   changes nothing);
//! - `sort_modes`: the machine upgrade on (`true`) or off;
//! - `ratio_sensor`: the sensor upgrade on (`true`) or off;
//! - `input_fault`: `{kind: stuck | dropped, ticks: N}`, a fault of the input (quantity) sensor.
//!
//! Unknown fields are refused. Validation names the event (its index in `events`, from 0, and
//! its `at`), the field, the value and the allowed range, with the ranges of
//! [`LineConfig::validate`] (one source).
//!
//! # When an event applies
//! - Ticks count the line's steps since it was built, across episodes (a reset takes no tick).
//!   `at: {tick: T}` applies at the start of tick T, before anything of that step: the outcome of
//!   tick T is the first to show it (its reward, its accuracy, the observation it returns).
//! - Episodes are the line's: episode 0 is the state the line is built in (the first record of
//!   `sorting_line trace`, a node before its first reset), episode E starts at the E-th reset
//!   (Gymnasium's E-th `env.reset()`, `sorting_line eval`'s E-th episode). `at: {episode: E}`
//!   applies at that reset, before its seed is used and before its observation is read, so a
//!   seeded reset after an upgrade starts exactly like a new line of the upgraded setup.
//! - Events at the same point apply in file order; a later one overrides an earlier one's field.
//!
//! # What the changes mean
//! - **Machine upgrade off** (`sort_modes: false`, and the basic variant until an upgrade): only
//!   sort mode 0 is valid ([`crate::sim::Line::action_mask`]). A step commanding another mode is
//!   not an error, it runs in mode 0, as the basic line has always ignored the mode; the outcome's
//!   `action.mode` says what ran. Accuracy has no mode effect (the basic line's model).
//! - **Sensor upgrade off** (`ratio_sensor: false`, and the basic variant until an upgrade): the
//!   observation's category is unknown. [`crate::sim::Line::category_reading`] is `None`; on the
//!   wire (a `uint8` category field) it is [`CATEGORY_UNKNOWN_CODE`] = 3, and in the advanced
//!   Gymnasium observation `Box(0, 2, (2,))` its slot holds [`CATEGORY_UNKNOWN_OBSERVATION`] =
//!   0.5: inside the box, so the evolving env keeps the advanced spaces throughout, and a value
//!   no category takes (they are 0, 1, 2), so an agent can tell "no sensor" from "mixed batch".
//!   `Observation::category` itself keeps the true category of the next batch, as the basic
//!   line has always carried it: consumers show the reading, not the truth.
//! - **Input fault**: the fault is active from its event for N ticks (for an episode event: the
//!   reset's reading and the first N steps of the episode); every input reading taken while it is
//!   active is faulty, a reset's included. `stuck`: the reading repeats the last reading the
//!   sensor delivered before the fault began (0.0 for a fault at episode 0, before any reading;
//!   a faulty reading if a fault was already active). `dropped`: the reading is 0.0 (RWRL sets
//!   dropped values to zero). Only the quantity reading is affected, not the ratio sensor. A new
//!   fault replaces one in progress.
//!
//! # Random streams
//! An event never shifts a stream it does not name. The input stream (`rng::Stream::Input`) is
//! drawn only by the input generator: only an `input` event touches it, so every other event
//! leaves the material that arrives unchanged. The noise stream (`rng::Stream::Noise`) is drawn
//! a fixed number of times per step whatever `obs_noise`, `threshold`, `action_penalty`, the
//! ratio sensor or a fault say: the observation-noise draw is taken even when the noise is 0 or
//! the reading is faulty. The one thing that changes its draw count is the machine's mode
//! effect (a matching mode takes a second accuracy draw), which is the accuracy model of the
//! machine a `sort_modes` event names; kept as it is so that an upgraded line is exactly an
//! advanced line.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::config::{ConfigError, InputKind, LineConfig};
use super::material::Category;

/// The `uint8` category code that says "no ratio sensor, category unknown" on the wire.
pub const CATEGORY_UNKNOWN_CODE: u8 = 3;

/// The category slot of the advanced Gymnasium observation `Box(0, 2, (2,))` while the line has
/// no ratio sensor (see the module docs).
pub const CATEGORY_UNKNOWN_OBSERVATION: f64 = 0.5;

/// The wire code of a category reading: the category's number, or [`CATEGORY_UNKNOWN_CODE`].
pub fn category_code(reading: Option<Category>) -> u8 {
    reading.map_or(CATEGORY_UNKNOWN_CODE, |c| c as u8)
}

/// Largest tick an event may name: what a ROS `int64` parameter or a signed 64-bit JSON reader
/// holds.
pub const MAX_TICK: u64 = i64::MAX as u64;
/// Longest input fault, in ticks (the longest episode).
pub const MAX_FAULT_TICKS: u32 = super::config::MAX_EPISODE_STEPS;

/// When an event applies (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "RawAt", into = "RawAt")]
pub enum At {
    /// At the reset that starts this episode (0: when the line is built).
    Episode(u32),
    /// At the start of this tick (steps since the line was built).
    Tick(u64),
}

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            At::Episode(e) => write!(f, "episode {e}"),
            At::Tick(t) => write!(f, "tick {t}"),
        }
    }
}

/// `at` as written: `{episode: E}` or `{tick: T}`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAt {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    episode: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tick: Option<u64>,
}

impl TryFrom<RawAt> for At {
    type Error = String;
    fn try_from(raw: RawAt) -> Result<Self, String> {
        match (raw.episode, raw.tick) {
            (Some(e), None) => Ok(At::Episode(e)),
            (None, Some(t)) => Ok(At::Tick(t)),
            _ => Err("`at` needs exactly one of `episode` or `tick`, e.g. {episode: 100} or {tick: 5000}".into()),
        }
    }
}

impl From<At> for RawAt {
    fn from(at: At) -> Self {
        match at {
            At::Episode(e) => RawAt { episode: Some(e), tick: None },
            At::Tick(t) => RawAt { episode: None, tick: Some(t) },
        }
    }
}

/// What a faulty input sensor reads (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FaultKind {
    /// Repeats the last reading delivered before the fault.
    Stuck,
    /// Reads 0.0.
    Dropped,
}

/// A fault of the input sensor lasting `ticks` ticks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputFault {
    pub kind: FaultKind,
    pub ticks: u32,
}

/// One change of the line. Fields left out are not changed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Event {
    pub at: At,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obs_noise: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_penalty: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<InputKind>,
    /// The machine upgrade (sort modes) on or off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sort_modes: Option<bool>,
    /// The sensor upgrade (ratio sensor) on or off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ratio_sensor: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_fault: Option<InputFault>,
}

/// The fields an event can set, for messages.
pub const EVENT_FIELDS: &str = "obs_noise, action_penalty, threshold, input, sort_modes, ratio_sensor, input_fault";

impl Event {
    /// An event at `at` that changes nothing yet (fill in the fields).
    pub fn at(at: At) -> Self {
        Event {
            at,
            obs_noise: None,
            action_penalty: None,
            threshold: None,
            input: None,
            sort_modes: None,
            ratio_sensor: None,
            input_fault: None,
        }
    }

    fn changes_something(&self) -> bool {
        self.obs_noise.is_some()
            || self.action_penalty.is_some()
            || self.threshold.is_some()
            || self.input.is_some()
            || self.sort_modes.is_some()
            || self.ratio_sensor.is_some()
            || self.input_fault.is_some()
    }

    /// Checks every value against its range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.changes_something() {
            return Err(ConfigError {
                field: "(event)",
                value: "nothing".into(),
                allowed: "at least one of the fields",
            });
        }
        if let At::Tick(t) = self.at {
            if t > MAX_TICK {
                return Err(ConfigError {
                    field: "at.tick",
                    value: t.to_string(),
                    allowed: "0 ..= 9223372036854775807",
                });
            }
        }
        self.obs_noise.map_or(Ok(()), LineConfig::check_obs_noise)?;
        self.action_penalty.map_or(Ok(()), LineConfig::check_action_penalty)?;
        self.threshold.map_or(Ok(()), LineConfig::check_threshold)?;
        if let Some(fault) = self.input_fault {
            if !(1..=MAX_FAULT_TICKS).contains(&fault.ticks) {
                return Err(ConfigError {
                    field: "input_fault.ticks",
                    value: fault.ticks.to_string(),
                    allowed: "1 ..= 1000000",
                });
            }
        }
        Ok(())
    }
}

/// A bad event: which one, and what is wrong with it.
#[derive(Clone, Debug, PartialEq)]
pub struct EvolutionError {
    /// Index in `events`, from 0.
    pub index: usize,
    pub at: At,
    pub error: ConfigError,
}

impl fmt::Display for EvolutionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "evolution event {} (at {}): ", self.index, self.at)?;
        if self.error.field == "(event)" {
            write!(f, "changes nothing: set at least one of {EVENT_FIELDS}")
        } else {
            self.error.fmt(f)
        }
    }
}

impl std::error::Error for EvolutionError {}

/// An evolution schedule: the events, in file order. The empty schedule changes nothing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    pub events: Vec<Event>,
}

impl Schedule {
    pub fn new(events: Vec<Event>) -> Self {
        Schedule { events }
    }

    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// Checks every event; the first bad one is named.
    pub fn validate(&self) -> Result<(), EvolutionError> {
        for (index, event) in self.events.iter().enumerate() {
            event.validate().map_err(|error| EvolutionError { index, at: event.at, error })?;
        }
        Ok(())
    }

    /// Parses and validates a schedule file's text.
    pub fn from_yaml(text: &str) -> Result<Self, String> {
        let schedule: Schedule = serde_yaml::from_str(text).map_err(|e| format!("not an evolution schedule: {e}"))?;
        schedule.validate().map_err(|e| e.to_string())?;
        Ok(schedule)
    }

    /// The events that apply at `at`, in the order they apply, with their indices.
    pub fn events_at(&self, at: At) -> impl Iterator<Item = (usize, &Event)> {
        self.events.iter().enumerate().filter(move |(_, e)| e.at == at)
    }
}

/// A line's progress through its schedule: which events are still to come.
#[derive(Clone, Debug, Default)]
pub(crate) struct Timeline {
    schedule: Schedule,
    /// Event indices in the order they apply: by point, then file order.
    by_episode: Vec<usize>,
    by_tick: Vec<usize>,
    next_episode: usize,
    next_tick: usize,
}

impl Timeline {
    pub(crate) fn new(schedule: Schedule) -> Self {
        let mut by_episode: Vec<usize> =
            (0..schedule.events.len()).filter(|&i| matches!(schedule.events[i].at, At::Episode(_))).collect();
        let mut by_tick: Vec<usize> =
            (0..schedule.events.len()).filter(|&i| matches!(schedule.events[i].at, At::Tick(_))).collect();
        // Stable sorts: events at the same point keep their file order.
        by_episode.sort_by_key(|&i| schedule.events[i].at);
        by_tick.sort_by_key(|&i| schedule.events[i].at);
        Timeline { schedule, by_episode, by_tick, next_episode: 0, next_tick: 0 }
    }

    pub(crate) fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    /// The tick of the next tick event; `u64::MAX` (never reached: ticks stop at [`MAX_TICK`])
    /// when none is left. The line compares its tick with this once per step.
    pub(crate) fn due_tick(&self) -> u64 {
        match self.by_tick.get(self.next_tick).map(|&i| self.schedule.events[i].at) {
            Some(At::Tick(t)) => t,
            _ => u64::MAX,
        }
    }

    /// The events due at the start of `tick` (and any skipped before it), consumed.
    pub(crate) fn take_due_at_tick(&mut self, tick: u64) -> Vec<Event> {
        let reached = |at| matches!(at, At::Tick(t) if t <= tick);
        take_due(&self.schedule.events, &self.by_tick, &mut self.next_tick, reached)
    }

    /// The events due when `episode` starts (and any skipped before it), consumed.
    pub(crate) fn take_due_at_episode(&mut self, episode: u32) -> Vec<Event> {
        let reached = |at| matches!(at, At::Episode(e) if e <= episode);
        take_due(&self.schedule.events, &self.by_episode, &mut self.next_episode, reached)
    }
}

/// The events of `order` from `*next` on whose point is `reached`; `*next` moves past them.
fn take_due(events: &[Event], order: &[usize], next: &mut usize, reached: impl Fn(At) -> bool) -> Vec<Event> {
    let mut due = Vec::new();
    while let Some(&i) = order.get(*next) {
        if !reached(events[i].at) {
            break;
        }
        due.push(events[i].clone());
        *next += 1;
    }
    due
}

/// A fault in progress.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ActiveFault {
    pub kind: FaultKind,
    /// Ticks it still lasts (the current one included).
    pub remaining: u32,
    /// What a stuck sensor reads.
    #[serde(skip)]
    pub(crate) stuck_at: f64,
}

impl ActiveFault {
    /// The reading of the faulty sensor.
    pub(crate) fn reading(&self) -> f64 {
        match self.kind {
            FaultKind::Stuck => self.stuck_at,
            FaultKind::Dropped => 0.0,
        }
    }
}

/// What a line is now: the settings events can change, for traces and diagnostics.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub obs_noise: f64,
    pub action_penalty: f64,
    pub threshold: f64,
    pub input: InputKind,
    pub sort_modes: bool,
    pub ratio_sensor: bool,
    /// The input fault in progress, if any.
    pub input_fault: Option<ActiveFault>,
}

/// A fault's name as events and messages spell it.
pub fn fault_name(kind: FaultKind) -> &'static str {
    match kind {
        FaultKind::Stuck => "stuck",
        FaultKind::Dropped => "dropped",
    }
}

/// The fields an event sets, with their new values as YAML scalars, in the message's order.
pub fn event_changes(event: &Event) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    let mut put = |field, value: Option<String>| {
        if let Some(value) = value {
            out.push((field, value));
        }
    };
    put("obs_noise", event.obs_noise.map(|v| v.to_string()));
    put("action_penalty", event.action_penalty.map(|v| v.to_string()));
    put("threshold", event.threshold.map(|v| v.to_string()));
    put("input", event.input.map(|v| v.to_string()));
    put("sort_modes", event.sort_modes.map(|v| v.to_string()));
    put("ratio_sensor", event.ratio_sensor.map(|v| v.to_string()));
    put("input_fault", event.input_fault.map(|f| format!("{} {}", fault_name(f.kind), f.ticks)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = "
events:
  - at: {episode: 2001}
    sort_modes: true        # machine upgrade
    ratio_sensor: true      # sensor upgrade
  - at: {tick: 150000}
    obs_noise: 0.3
    threshold: 0.8
  - at: {tick: 200000}
    input_fault: {kind: stuck, ticks: 20}
";

    #[test]
    fn the_documented_example_parses() {
        let s = Schedule::from_yaml(EXAMPLE).unwrap();
        assert_eq!(s.events.len(), 3);
        assert_eq!(s.events[0].at, At::Episode(2001));
        assert_eq!((s.events[0].sort_modes, s.events[0].ratio_sensor), (Some(true), Some(true)));
        assert_eq!((s.events[1].obs_noise, s.events[1].threshold), (Some(0.3), Some(0.8)));
        assert_eq!(s.events[2].input_fault, Some(InputFault { kind: FaultKind::Stuck, ticks: 20 }));
        // The module docs show the same text.
        let doc = include_str!("evolution.rs");
        let documented: String = doc
            .lines()
            .skip_while(|l| !l.starts_with("//! ```yaml"))
            .skip(1)
            .take_while(|l| !l.starts_with("//! ```"))
            .map(|l| format!("{}\n", l.trim_start_matches("//!").strip_prefix(' ').unwrap_or("")))
            .collect();
        assert_eq!(Schedule::from_yaml(&documented).unwrap(), s);
    }

    #[test]
    fn bad_values_name_event_field_value_and_range() {
        let e = Schedule::from_yaml(
            "events:\n  - at: {tick: 5}\n    obs_noise: 0.1\n  - at: {tick: 500}\n    threshold: 1.2\n",
        )
        .unwrap_err();
        assert_eq!(e, "evolution event 1 (at tick 500): threshold = 1.2 is out of range: allowed 0.0 ..< 1.0");
        let e = Schedule::from_yaml("events:\n  - at: {episode: 3}\n    input_fault: {kind: dropped, ticks: 0}\n")
            .unwrap_err();
        assert_eq!(e, "evolution event 0 (at episode 3): input_fault.ticks = 0 is out of range: allowed 1 ..= 1000000");
        let e = Schedule::from_yaml("events:\n  - at: {episode: 3}\n").unwrap_err();
        assert!(
            e.starts_with("evolution event 0 (at episode 3): changes nothing: set at least one of obs_noise"),
            "{e}"
        );
        let e = Schedule::from_yaml("events:\n  - at: {tick: 9223372036854775808}\n    threshold: 0.5\n").unwrap_err();
        assert!(e.contains("at.tick = 9223372036854775808 is out of range: allowed 0 ..= 9223372036854775807"), "{e}");
    }

    #[test]
    fn malformed_files_say_where() {
        let e = Schedule::from_yaml("events:\n  - at: {tick: 5}\n    treshold: 0.8\n").unwrap_err();
        assert!(e.contains("events[0]") && e.contains("unknown field `treshold`"), "{e}");
        let e = Schedule::from_yaml("events:\n  - at: {tick: 5, episode: 2}\n    threshold: 0.8\n").unwrap_err();
        assert!(e.contains("events[0]") && e.contains("exactly one of `episode` or `tick`"), "{e}");
        let e = Schedule::from_yaml("events:\n  - at: {tick: 5}\n    input: sine\n").unwrap_err();
        assert!(e.contains("events[0].input") && e.contains("unknown variant `sine`"), "{e}");
        let e =
            Schedule::from_yaml("events:\n  - at: {tick: 5}\n    input_fault: {kind: frozen, ticks: 3}\n").unwrap_err();
        assert!(e.contains("unknown variant `frozen`"), "{e}");
        assert!(Schedule::from_yaml("").is_err());
        assert_eq!(Schedule::from_yaml("events: []\n").unwrap(), Schedule::default());
    }

    #[test]
    fn yaml_round_trips() {
        let s = Schedule::from_yaml(EXAMPLE).unwrap();
        let text = serde_yaml::to_string(&s).unwrap();
        assert_eq!(Schedule::from_yaml(&text).unwrap(), s, "{text}");
    }

    #[test]
    fn timeline_orders_by_point_then_file_order() {
        let mut a = Event::at(At::Tick(7));
        a.threshold = Some(0.5);
        let mut b = Event::at(At::Tick(3));
        b.threshold = Some(0.6);
        let mut c = Event::at(At::Tick(7));
        c.threshold = Some(0.4);
        let mut t = Timeline::new(Schedule::new(vec![a, b, c]));
        assert_eq!(t.due_tick(), 3);
        assert!(t.take_due_at_tick(2).is_empty());
        assert_eq!(t.take_due_at_tick(3).iter().map(|e| e.threshold).collect::<Vec<_>>(), [Some(0.6)]);
        assert_eq!(t.due_tick(), 7);
        assert_eq!(t.take_due_at_tick(7).iter().map(|e| e.threshold).collect::<Vec<_>>(), [Some(0.5), Some(0.4)]);
        assert_eq!(t.due_tick(), u64::MAX);
    }

    #[test]
    fn category_codes() {
        assert_eq!(category_code(None), CATEGORY_UNKNOWN_CODE);
        assert_eq!(category_code(Some(Category::Negative)), 2);
        assert!((0.0..=2.0).contains(&CATEGORY_UNKNOWN_OBSERVATION));
        assert!(crate::sim::material::CATEGORIES.iter().all(|&c| c as u8 as f64 != CATEGORY_UNKNOWN_OBSERVATION));
    }
}
