//! Rust mirrors of every message the node sends or receives: plain data, a leaf that imports
//! nothing of the line (what a hosted line looks like in them is `ros::node::line_messages`). CDR
//! is positional: each struct lists the fields of its .msg file (msg/msg, msg/srv) in the same
//! order with the same types; constants in a .msg file are not fields. `MessageTypeName`s are next
//! to the types.

use ros2_client::{Message, MessageTypeName, ServiceTypeName};
use serde::{Deserialize, Serialize};

/// The interface package built from msg/.
pub const INTERFACES: &str = "sorting_line_interfaces";

/// builtin_interfaces/Time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    pub fn from_nanos(nanos: u64) -> Self {
        Time { sec: (nanos / 1_000_000_000) as i32, nanosec: (nanos % 1_000_000_000) as u32 }
    }
    /// Nanoseconds since zero; negative times (never sent by us) map below zero.
    pub fn nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// std_msgs/Header.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// sorting_line_interfaces/MaterialInput: the input sensor.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaterialInput {
    pub header: Header,
    pub episode: u32,
    pub step: u32,
    pub quantity: f64,
    pub amount_a: u32,
    pub amount_b: u32,
    pub occupancy: f64,
}

/// sorting_line_interfaces/BeltOccupancy.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BeltOccupancy {
    pub header: Header,
    pub episode: u32,
    pub step: u32,
    pub occupancy: f64,
    pub speed: f64,
    pub amount_a: u32,
    pub amount_b: u32,
}

/// sorting_line_interfaces/MaterialRatio: the ratio sensor (advanced line).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaterialRatio {
    pub header: Header,
    pub episode: u32,
    pub step: u32,
    pub ratio: f64,
    pub category: u8,
}

/// sorting_line_interfaces/LineState: the full result of one tick.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LineState {
    pub header: Header,
    pub episode: u32,
    pub step: u32,
    pub seed: u64,
    pub speed: f64,
    pub speed_index: u8,
    pub mode: u8,
    pub occupancy: f64,
    pub accuracy: f64,
    pub reward: f64,
    pub cumulative_reward: f64,
    pub purity: f64,
    pub recall_a: f64,
    pub recall_b: f64,
    pub container_a: u32,
    pub container_a_false: u32,
    pub container_b: u32,
    pub container_b_false: u32,
    pub speed_changes: u32,
    pub observation_quantity: f64,
    pub observation_category: u8,
    pub terminated: bool,
    pub truncated: bool,
}

/// sorting_line_interfaces/SpeedCommand.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpeedCommand {
    pub header: Header,
    pub speed: f64,
}

/// sorting_line_interfaces/SortModeCommand.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SortModeCommand {
    pub header: Header,
    pub mode: u8,
}

/// sorting_line_interfaces/ResetEvent: published on every reset (services are not recorded in bags).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetEvent {
    pub header: Header,
    pub episode: u32,
    pub seed: u64,
    /// Whether the streams restarted from `seed` (a seeded reset) or carried on: a replay of a
    /// bag needs to know, and the same seed twice in a row cannot tell.
    pub seeded: bool,
}

/// sorting_line_interfaces/EvolutionEvent: events of a line's evolution schedule that applied
/// (or, for a tick, are about to), and the line's whole setup after them (msg/EvolutionEvent.msg).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvolutionEvent {
    pub header: Header,
    pub episode: u32,
    pub tick: u64,
    pub at_reset: bool,
    pub event_indices: Vec<u32>,
    pub changed: Vec<String>,
    pub values: Vec<String>,
    pub obs_noise: f64,
    pub action_penalty: f64,
    pub threshold: f64,
    pub input: String,
    pub sort_modes: bool,
    pub ratio_sensor: bool,
    pub input_fault: String,
    pub input_fault_ticks: u32,
}

/// sorting_line_interfaces/LineCommands: one command per line, for vectorised clients.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LineCommands {
    pub header: Header,
    pub stamp_sec: Vec<i32>,
    pub stamp_nanosec: Vec<u32>,
    pub speeds: Vec<f64>,
    pub modes: Vec<u8>,
}

/// sorting_line_interfaces/LineStates: every line's state as arrays (struct of arrays).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LineStates {
    pub header: Header,
    pub stamp_sec: Vec<i32>,
    pub stamp_nanosec: Vec<u32>,
    pub episode: Vec<u32>,
    pub step: Vec<u32>,
    pub seed: Vec<u64>,
    pub speed: Vec<f64>,
    pub speed_index: Vec<u8>,
    pub mode: Vec<u8>,
    pub occupancy: Vec<f64>,
    pub accuracy: Vec<f64>,
    pub reward: Vec<f64>,
    pub cumulative_reward: Vec<f64>,
    pub purity: Vec<f64>,
    pub recall_a: Vec<f64>,
    pub recall_b: Vec<f64>,
    pub container_a: Vec<u32>,
    pub container_a_false: Vec<u32>,
    pub container_b: Vec<u32>,
    pub container_b_false: Vec<u32>,
    pub speed_changes: Vec<u32>,
    pub observation_quantity: Vec<f64>,
    pub observation_category: Vec<u8>,
    pub truncated: Vec<bool>,
}

impl LineStates {
    /// Lays out per-line states as arrays.
    pub fn from_states(header: Header, states: &[LineState]) -> Self {
        let col = |f: &dyn Fn(&LineState) -> f64| states.iter().map(f).collect::<Vec<f64>>();
        LineStates {
            header,
            stamp_sec: states.iter().map(|s| s.header.stamp.sec).collect(),
            stamp_nanosec: states.iter().map(|s| s.header.stamp.nanosec).collect(),
            episode: states.iter().map(|s| s.episode).collect(),
            step: states.iter().map(|s| s.step).collect(),
            seed: states.iter().map(|s| s.seed).collect(),
            speed: col(&|s| s.speed),
            speed_index: states.iter().map(|s| s.speed_index).collect(),
            mode: states.iter().map(|s| s.mode).collect(),
            occupancy: col(&|s| s.occupancy),
            accuracy: col(&|s| s.accuracy),
            reward: col(&|s| s.reward),
            cumulative_reward: col(&|s| s.cumulative_reward),
            purity: col(&|s| s.purity),
            recall_a: col(&|s| s.recall_a),
            recall_b: col(&|s| s.recall_b),
            container_a: states.iter().map(|s| s.container_a).collect(),
            container_a_false: states.iter().map(|s| s.container_a_false).collect(),
            container_b: states.iter().map(|s| s.container_b).collect(),
            container_b_false: states.iter().map(|s| s.container_b_false).collect(),
            speed_changes: states.iter().map(|s| s.speed_changes).collect(),
            observation_quantity: col(&|s| s.observation_quantity),
            observation_category: states.iter().map(|s| s.observation_category).collect(),
            truncated: states.iter().map(|s| s.truncated).collect(),
        }
    }
}

/// sorting_line_interfaces/ResetLine request.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetLineRequest {
    pub has_seed: bool,
    pub seed: u64,
}

/// sorting_line_interfaces/ResetLine response.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetLineResponse {
    pub success: bool,
    pub message: String,
    pub seed: u64,
    pub episode: u32,
    pub stamp: Time,
    pub quantity: f64,
    pub category: u8,
}

/// sorting_line_interfaces/ResetLines request.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetLinesRequest {
    pub lines: Vec<u32>,
    pub has_seed: Vec<bool>,
    pub seeds: Vec<u64>,
}

/// sorting_line_interfaces/ResetLines response.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetLinesResponse {
    pub success: bool,
    pub message: String,
    pub states: LineStates,
}

/// rosgraph_msgs/Clock (not builtin_interfaces/Time: ROS tools match on the type name).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}

/// diagnostic_msgs/KeyValue.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// diagnostic_msgs/DiagnosticStatus.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

/// diagnostic_msgs/DiagnosticArray.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

/// DiagnosticStatus levels.
pub const DIAGNOSTIC_OK: u8 = 0;
pub const DIAGNOSTIC_WARN: u8 = 1;

macro_rules! messages {
    ($($ty:ident => ($pkg:expr, $name:literal)),+ $(,)?) => {
        $(impl Message for $ty {})+
        /// The ROS type name of a message mirror.
        pub trait Typed {
            fn type_name() -> MessageTypeName;
        }
        $(impl Typed for $ty {
            fn type_name() -> MessageTypeName {
                MessageTypeName::new($pkg, $name)
            }
        })+
    };
}

messages! {
    MaterialInput => (INTERFACES, "MaterialInput"),
    BeltOccupancy => (INTERFACES, "BeltOccupancy"),
    MaterialRatio => (INTERFACES, "MaterialRatio"),
    LineState => (INTERFACES, "LineState"),
    SpeedCommand => (INTERFACES, "SpeedCommand"),
    SortModeCommand => (INTERFACES, "SortModeCommand"),
    ResetEvent => (INTERFACES, "ResetEvent"),
    EvolutionEvent => (INTERFACES, "EvolutionEvent"),
    LineCommands => (INTERFACES, "LineCommands"),
    LineStates => (INTERFACES, "LineStates"),
    Clock => ("rosgraph_msgs", "Clock"),
    DiagnosticArray => ("diagnostic_msgs", "DiagnosticArray"),
}
impl Message for ResetLineRequest {}
impl Message for ResetLineResponse {}
impl Message for ResetLinesRequest {}
impl Message for ResetLinesResponse {}

/// The ResetLine service type.
pub fn reset_service_type() -> ServiceTypeName {
    ServiceTypeName::new(INTERFACES, "ResetLine")
}

/// The ResetLines service type.
pub fn batch_reset_service_type() -> ServiceTypeName {
    ServiceTypeName::new(INTERFACES, "ResetLines")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_round_trips_nanos() {
        let t = Time::from_nanos(3_250_000_000);
        assert_eq!(t, Time { sec: 3, nanosec: 250_000_000 });
        assert_eq!(t.nanos(), 3_250_000_000);
    }

    /// Field order is the wire format: keep the mirrors and the .msg files in step.
    #[test]
    fn mirrors_list_the_msg_fields_in_order() {
        let root = env!("CARGO_MANIFEST_DIR");
        let fields = |file: &str| -> Vec<String> {
            std::fs::read_to_string(format!("{root}/msg/{file}"))
                .unwrap()
                .lines()
                .map(|l| l.split('#').next().unwrap().trim().to_string())
                .filter(|l| !l.is_empty() && !l.contains('=') && l != "---")
                .map(|l| l.split_whitespace().nth(1).unwrap().to_string())
                .collect()
        };
        // serde_yaml's mapping keeps the struct's declaration order.
        let yaml_fields = |y: serde_yaml::Value| -> Vec<String> {
            y.as_mapping().unwrap().keys().map(|k| k.as_str().unwrap().to_string()).collect()
        };
        let check = |file: &str, y: serde_yaml::Value| assert_eq!(yaml_fields(y), fields(file), "{file}");
        check("msg/MaterialInput.msg", serde_yaml::to_value(MaterialInput::default()).unwrap());
        check("msg/BeltOccupancy.msg", serde_yaml::to_value(BeltOccupancy::default()).unwrap());
        check("msg/MaterialRatio.msg", serde_yaml::to_value(MaterialRatio::default()).unwrap());
        check("msg/LineState.msg", serde_yaml::to_value(LineState::default()).unwrap());
        check("msg/SpeedCommand.msg", serde_yaml::to_value(SpeedCommand::default()).unwrap());
        check("msg/SortModeCommand.msg", serde_yaml::to_value(SortModeCommand::default()).unwrap());
        check("msg/ResetEvent.msg", serde_yaml::to_value(ResetEvent::default()).unwrap());
        check("msg/EvolutionEvent.msg", serde_yaml::to_value(EvolutionEvent::default()).unwrap());
        check("msg/LineCommands.msg", serde_yaml::to_value(LineCommands::default()).unwrap());
        check("msg/LineStates.msg", serde_yaml::to_value(LineStates::default()).unwrap());
        let batch = fields("srv/ResetLines.srv");
        let request = yaml_fields(serde_yaml::to_value(ResetLinesRequest::default()).unwrap());
        let response = yaml_fields(serde_yaml::to_value(ResetLinesResponse::default()).unwrap());
        assert_eq!([request, response].concat(), batch);
        let srv = fields("srv/ResetLine.srv");
        let request = yaml_fields(serde_yaml::to_value(ResetLineRequest::default()).unwrap());
        let response = yaml_fields(serde_yaml::to_value(ResetLineResponse::default()).unwrap());
        assert_eq!([request, response].concat(), srv);
    }
}
