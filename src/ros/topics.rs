//! The node's endpoints as one table: every topic, service and action, its name, type, direction,
//! where its name lives (a line's namespace, the node's, absolute, the node's private one), the
//! QoS it is created with and on which lines it exists. The node names its endpoints from here,
//! `sorting_line vocabulary` prints the table (under "topics" and "qos_profiles"), and the Python
//! package's copy (`sorting_line_gym.line.topics`) is checked against that print; the docs' topic
//! table is written from the Python copy (launch_scripts/docs.py), so the three cannot drift.
//!
//! Names only: the types' mirrors are `ros::messages` and `ros::simulation_interfaces` (a test
//! below checks each type named here against its mirror's), the QoS profiles themselves
//! `ros::qos`, and names are resolved against namespaces and remaps in `ros::names`.

use serde::Serialize;

use super::messages::INTERFACES;
use super::simulation_interfaces::{SimService, ACTION, PACKAGE as SIMULATION_INTERFACES};

/// What the node does with an endpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    Publishes,
    Subscribes,
    /// A service server.
    Service,
    /// An action server.
    Action,
}

/// Where an endpoint's name lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Scope {
    /// Relative to a line's namespace (the node's with one line, `<ns>/line_<k>` with more).
    Line,
    /// Relative to the node's namespace, one for all its lines.
    Node,
    /// Absolute (the name starts with `/`).
    Global,
    /// In the node's private namespace (`~/name`: `<ns>/<node name>/name`).
    Private,
}

/// On which lines an endpoint exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum When {
    Always,
    /// The line's hardware: on the advanced line, and on an evolving line while it has the ratio
    /// sensor (`sensors/ratio`) or sort modes (`cmd/sort_mode`).
    Advanced,
    /// Only on an evolving line (`--evolution`).
    Evolving,
}

/// The QoS an endpoint has. The node creates its own with `ros::qos`; ros2-client creates the
/// graph's (`/rosout`, `/parameter_events`) as rcl does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Qos {
    /// `qos::default_profile`.
    Default,
    /// rcl_action's (`qos::action_status_profile` for the status topic).
    Action,
    Rosout,
    ParameterEvents,
}

impl Qos {
    pub const ALL: [Qos; 4] = [Qos::Default, Qos::Action, Qos::Rosout, Qos::ParameterEvents];

    /// The profile in words, as the docs write it.
    pub fn describe(self) -> &'static str {
        match self {
            Qos::Default => "reliable, volatile, keep-last 10",
            Qos::Action => "rcl_action's: status reliable, transient-local, keep-last 1; the rest default",
            Qos::Rosout => "reliable, transient-local, keep-last 1, lifespan 10 s",
            Qos::ParameterEvents => "reliable, transient-local, keep-last 1",
        }
    }

    /// The name `vocabulary` prints (serde's).
    pub fn key(self) -> String {
        serde_json::json!(self).as_str().unwrap_or_default().to_owned()
    }
}

/// An interface type: `package/interface/name`, interface `msg`, `srv` or `action`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Type {
    pub package: &'static str,
    pub interface: &'static str,
    pub name: &'static str,
}

impl std::fmt::Display for Type {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}/{}", self.package, self.interface, self.name)
    }
}

const fn ours(interface: &'static str, name: &'static str) -> Type {
    Type { package: INTERFACES, interface, name }
}

/// One endpoint of the node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Topic {
    /// Relative to its scope (absolute for [`Scope::Global`]).
    pub name: &'static str,
    pub kind: Kind,
    pub ty: Type,
    pub scope: Scope,
    pub qos: Qos,
    pub when: When,
    /// A short remark for the docs' table (empty: none).
    pub note: &'static str,
}

const fn line(name: &'static str, kind: Kind, ty: Type, when: When, note: &'static str) -> Topic {
    Topic { name, kind, ty, scope: Scope::Line, qos: Qos::Default, when, note }
}

pub const INPUT: Topic = line("input", Kind::Publishes, ours("msg", "MaterialInput"), When::Always, "");
pub const BELT_OCCUPANCY: Topic =
    line("belt/occupancy", Kind::Publishes, ours("msg", "BeltOccupancy"), When::Always, "");
pub const SENSORS_RATIO: Topic =
    line("sensors/ratio", Kind::Publishes, ours("msg", "MaterialRatio"), When::Advanced, "");
pub const STATE: Topic = line("state", Kind::Publishes, ours("msg", "LineState"), When::Always, "last in each tick");
pub const RESET_EVENT: Topic = line("events/reset", Kind::Publishes, ours("msg", "ResetEvent"), When::Always, "");
pub const EVOLUTION_EVENT: Topic =
    line("events/evolution", Kind::Publishes, ours("msg", "EvolutionEvent"), When::Evolving, "");
pub const SPEED_CMD: Topic = line("cmd/speed", Kind::Subscribes, ours("msg", "SpeedCommand"), When::Always, "");
pub const SORT_MODE_CMD: Topic =
    line("cmd/sort_mode", Kind::Subscribes, ours("msg", "SortModeCommand"), When::Advanced, "");
pub const RESET: Topic = line("reset", Kind::Service, ours("srv", "ResetLine"), When::Always, "");

const fn node_wide(name: &'static str, kind: Kind, ty: Type, note: &'static str) -> Topic {
    Topic { name, kind, ty, scope: Scope::Node, qos: Qos::Default, when: When::Always, note }
}

pub const BATCH_CMD: Topic =
    node_wide("batch/cmd", Kind::Subscribes, ours("msg", "LineCommands"), "every line's command, as arrays");
pub const BATCH_STATE: Topic =
    node_wide("batch/state", Kind::Publishes, ours("msg", "LineStates"), "every line's state, as arrays");
pub const BATCH_RESET: Topic = node_wide("batch/reset", Kind::Service, ours("srv", "ResetLines"), "");

const fn global(name: &'static str, ty: Type, qos: Qos, note: &'static str) -> Topic {
    Topic { name, kind: Kind::Publishes, ty, scope: Scope::Global, qos, when: When::Always, note }
}

pub const CLOCK: Topic = global(
    "/clock",
    Type { package: "rosgraph_msgs", interface: "msg", name: "Clock" },
    Qos::Default,
    "matches best-effort readers",
);
pub const DIAGNOSTICS: Topic = global(
    "/diagnostics",
    Type { package: "diagnostic_msgs", interface: "msg", name: "DiagnosticArray" },
    Qos::Default,
    "1 Hz",
);
/// ros2-client's, as rcl's: the node's log.
pub const ROSOUT: Topic =
    global("/rosout", Type { package: "rcl_interfaces", interface: "msg", name: "Log" }, Qos::Rosout, "");
/// ros2-client's, as rcl's: the parameters' announcements.
pub const PARAMETER_EVENTS: Topic = global(
    "/parameter_events",
    Type { package: "rcl_interfaces", interface: "msg", name: "ParameterEvent" },
    Qos::ParameterEvents,
    "",
);

/// A service in the private namespace, in package `package`.
const fn private(name: &'static str, package: &'static str, ty: &'static str, note: &'static str) -> Topic {
    let ty = Type { package, interface: "srv", name: ty };
    Topic { name, kind: Kind::Service, ty, scope: Scope::Private, qos: Qos::Default, when: When::Always, note }
}

/// ros2-client's parameter services, as rcl serves them.
const PARAMETERS: &str = "sets are refused with a reason";
const fn parameter_service(name: &'static str, ty: &'static str) -> Topic {
    private(name, "rcl_interfaces", ty, PARAMETERS)
}

const fn simulation(service: SimService) -> Topic {
    private(service.name(), SIMULATION_INTERFACES, service.type_name(), "")
}

/// The simulation_interfaces services, in the order of [`SimService::ALL`].
pub const SIMULATION_SERVICES: [Topic; 5] = [
    simulation(SimService::ALL[0]),
    simulation(SimService::ALL[1]),
    simulation(SimService::ALL[2]),
    simulation(SimService::ALL[3]),
    simulation(SimService::ALL[4]),
];

/// The row of a simulation_interfaces service.
pub fn simulation_service(service: SimService) -> &'static Topic {
    let k = SimService::ALL.iter().position(|&s| s == service).unwrap_or_default();
    &SIMULATION_SERVICES[k]
}

/// `~/simulate_steps`.
pub const SIMULATE_STEPS: Topic = Topic {
    name: ACTION.0,
    kind: Kind::Action,
    ty: Type { package: SIMULATION_INTERFACES, interface: "action", name: ACTION.1 },
    scope: Scope::Private,
    qos: Qos::Action,
    when: When::Always,
    note: "",
};

/// Every endpoint of the node, in the order the docs list them: a line's, the node's, the absolute
/// ones, the private ones.
pub const TOPICS: [Topic; 28] = [
    INPUT,
    BELT_OCCUPANCY,
    SENSORS_RATIO,
    STATE,
    RESET_EVENT,
    EVOLUTION_EVENT,
    SPEED_CMD,
    SORT_MODE_CMD,
    RESET,
    BATCH_CMD,
    BATCH_STATE,
    BATCH_RESET,
    CLOCK,
    DIAGNOSTICS,
    ROSOUT,
    PARAMETER_EVENTS,
    parameter_service("describe_parameters", "DescribeParameters"),
    parameter_service("get_parameters", "GetParameters"),
    parameter_service("get_parameter_types", "GetParameterTypes"),
    parameter_service("list_parameters", "ListParameters"),
    parameter_service("set_parameters", "SetParameters"),
    parameter_service("set_parameters_atomically", "SetParametersAtomically"),
    SIMULATION_SERVICES[0],
    SIMULATION_SERVICES[1],
    SIMULATION_SERVICES[2],
    SIMULATION_SERVICES[3],
    SIMULATION_SERVICES[4],
    SIMULATE_STEPS,
];

/// The table as `vocabulary` prints it: `{"topics": [{name, kind, type, scope, qos, when, note}],
/// "qos_profiles": {key: words}}`.
pub fn vocabulary() -> serde_json::Value {
    let topics: Vec<serde_json::Value> = TOPICS
        .iter()
        .map(|t| {
            serde_json::json!({
                "name": t.name, "kind": t.kind, "type": t.ty.to_string(), "scope": t.scope,
                "qos": t.qos, "when": t.when, "note": t.note,
            })
        })
        .collect();
    let profiles: serde_json::Map<String, serde_json::Value> =
        Qos::ALL.iter().map(|q| (q.key(), q.describe().into())).collect();
    serde_json::json!({"topics": topics, "qos_profiles": profiles})
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::messages::*;
    use crate::ros::simulation_interfaces::action_type;

    fn message<M: Typed>(topic: &Topic) {
        let t = M::type_name();
        assert_eq!((topic.ty.package, topic.ty.name), (t.package_name(), t.type_name()), "{}", topic.name);
        assert_eq!(topic.ty.interface, "msg", "{}", topic.name);
    }

    /// The types named here are the mirrors' the node creates the endpoints with.
    #[test]
    fn types_are_the_mirrors() {
        message::<MaterialInput>(&INPUT);
        message::<BeltOccupancy>(&BELT_OCCUPANCY);
        message::<MaterialRatio>(&SENSORS_RATIO);
        message::<LineState>(&STATE);
        message::<ResetEvent>(&RESET_EVENT);
        message::<EvolutionEvent>(&EVOLUTION_EVENT);
        message::<SpeedCommand>(&SPEED_CMD);
        message::<SortModeCommand>(&SORT_MODE_CMD);
        message::<LineCommands>(&BATCH_CMD);
        message::<LineStates>(&BATCH_STATE);
        message::<Clock>(&CLOCK);
        message::<DiagnosticArray>(&DIAGNOSTICS);
        for (topic, ty) in [(RESET, reset_service_type()), (BATCH_RESET, batch_reset_service_type())] {
            assert_eq!(
                (topic.ty.package, topic.ty.name, topic.ty.interface),
                (ty.package_name(), ty.type_name(), "srv")
            );
        }
        let action = action_type();
        assert_eq!((SIMULATE_STEPS.ty.package, SIMULATE_STEPS.ty.name), (action.package_name(), action.type_name()));
        for service in SimService::ALL {
            let row = simulation_service(service);
            assert_eq!((row.name, row.scope), (service.name(), Scope::Private));
            let ty = service.service_type();
            assert_eq!((row.ty.package, row.ty.name, row.ty.interface), (ty.package_name(), ty.type_name(), "srv"));
            assert!(TOPICS.contains(row));
        }
    }

    /// Names are unique within a scope, absolute exactly when global, and valid ROS names.
    #[test]
    fn names_are_unique_and_well_formed() {
        let mut seen = std::collections::BTreeSet::new();
        for t in TOPICS {
            assert!(seen.insert((format!("{:?}", t.scope), t.name)), "{} twice", t.name);
            assert_eq!(t.name.starts_with('/'), t.scope == Scope::Global, "{}", t.name);
            let relative = t.name.trim_start_matches('/');
            assert!(
                relative
                    .split('/')
                    .all(|token| !token.is_empty() && token.chars().all(|c| c.is_ascii_lowercase() || c == '_')),
                "{}",
                t.name
            );
        }
    }
}
