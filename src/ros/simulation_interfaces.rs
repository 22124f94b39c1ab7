//! Rust mirrors of the `simulation_interfaces` types the node serves: ROS 2's standard for
//! driving a simulator (msg/simulation_interfaces/, written to the Jazzy 1.5.x definitions). As in
//! `messages`, each struct lists its fields in .msg order (CDR is positional); the constants live
//! in `simulation` beside the rules that use them.

use ros2_client::{ActionTypeName, Message, ServiceTypeName};
use serde::{Deserialize, Serialize};

/// The standard's package name.
pub const PACKAGE: &str = "simulation_interfaces";

/// simulation_interfaces/Result.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimResult {
    pub result: u8,
    pub error_message: String,
}

/// simulation_interfaces/SimulationState.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulationState {
    pub state: u8,
}

/// simulation_interfaces/SimulatorFeatures.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulatorFeatures {
    pub features: Vec<u16>,
    pub spawn_formats: Vec<String>,
    pub custom_info: String,
}

/// simulation_interfaces/GetSimulatorFeatures request (no fields: one placeholder byte on the
/// wire, as rosidl generates for an empty structure).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetSimulatorFeaturesRequest {
    pub structure_needs_at_least_one_member: u8,
}

/// simulation_interfaces/GetSimulatorFeatures response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetSimulatorFeaturesResponse {
    pub features: SimulatorFeatures,
}

/// simulation_interfaces/GetSimulationState request (empty, see above).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetSimulationStateRequest {
    pub structure_needs_at_least_one_member: u8,
}

/// simulation_interfaces/GetSimulationState response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetSimulationStateResponse {
    pub state: SimulationState,
    pub result: SimResult,
}

/// simulation_interfaces/SetSimulationState request.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetSimulationStateRequest {
    pub state: SimulationState,
}

/// simulation_interfaces/SetSimulationState response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetSimulationStateResponse {
    pub result: SimResult,
}

/// simulation_interfaces/StepSimulation request.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepSimulationRequest {
    pub steps: u64,
}

/// simulation_interfaces/StepSimulation response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepSimulationResponse {
    pub result: SimResult,
}

/// simulation_interfaces/ResetSimulation request.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResetSimulationRequest {
    pub scope: u8,
}

/// simulation_interfaces/ResetSimulation response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResetSimulationResponse {
    pub result: SimResult,
}

/// simulation_interfaces/SimulateSteps goal (Copy: ros2-client's goal handles are Copy when it is).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulateStepsGoal {
    pub steps: u64,
}

/// simulation_interfaces/SimulateSteps result.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulateStepsResult {
    pub result: SimResult,
}

/// simulation_interfaces/SimulateSteps feedback.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimulateStepsFeedback {
    pub completed_steps: u64,
    pub remaining_steps: u64,
}

impl Message for SimulateStepsGoal {}
impl Message for SimulateStepsResult {}
impl Message for SimulateStepsFeedback {}

/// The action the node serves in its private namespace: (relative name, type).
pub const ACTION: (&str, &str) = ("simulate_steps", "SimulateSteps");

/// `simulation_interfaces/action/SimulateSteps`.
pub fn action_type() -> ActionTypeName {
    ActionTypeName::new(PACKAGE, ACTION.1)
}

impl Message for GetSimulatorFeaturesRequest {}
impl Message for GetSimulatorFeaturesResponse {}
impl Message for GetSimulationStateRequest {}
impl Message for GetSimulationStateResponse {}
impl Message for SetSimulationStateRequest {}
impl Message for SetSimulationStateResponse {}
impl Message for StepSimulationRequest {}
impl Message for StepSimulationResponse {}
impl Message for ResetSimulationRequest {}
impl Message for ResetSimulationResponse {}

/// The service type `simulation_interfaces/srv/<name>`.
pub fn service_type(name: &str) -> ServiceTypeName {
    ServiceTypeName::new(PACKAGE, name)
}

/// The services the node serves in its private namespace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimService {
    Features,
    GetState,
    SetState,
    Step,
    Reset,
}

impl SimService {
    pub const ALL: [SimService; 5] =
        [SimService::Features, SimService::GetState, SimService::SetState, SimService::Step, SimService::Reset];

    /// The service's name in the private namespace.
    pub const fn name(self) -> &'static str {
        match self {
            SimService::Features => "get_simulator_features",
            SimService::GetState => "get_simulation_state",
            SimService::SetState => "set_simulation_state",
            SimService::Step => "step_simulation",
            SimService::Reset => "reset_simulation",
        }
    }

    /// The type's name in `simulation_interfaces/srv`.
    pub const fn type_name(self) -> &'static str {
        match self {
            SimService::Features => "GetSimulatorFeatures",
            SimService::GetState => "GetSimulationState",
            SimService::SetState => "SetSimulationState",
            SimService::Step => "StepSimulation",
            SimService::Reset => "ResetSimulation",
        }
    }

    /// `simulation_interfaces/srv/<type>`.
    pub fn service_type(self) -> ServiceTypeName {
        service_type(self.type_name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Field order is the wire format: the mirrors list the fields of the .srv/.msg files.
    #[test]
    fn mirrors_list_the_standard_fields_in_order() {
        let root = format!("{}/msg/simulation_interfaces", env!("CARGO_MANIFEST_DIR"));
        let fields = |file: &str| -> Vec<String> {
            std::fs::read_to_string(format!("{root}/{file}"))
                .unwrap()
                .lines()
                .map(|l| l.split('#').next().unwrap().trim().to_string())
                .filter(|l| !l.is_empty() && !l.contains('='))
                .map(|l| if l == "---" { l } else { l.split_whitespace().nth(1).unwrap().to_string() })
                .collect()
        };
        let yaml = |y: serde_yaml::Value| -> Vec<String> {
            y.as_mapping().unwrap().keys().map(|k| k.as_str().unwrap().to_string()).collect()
        };
        let srv = |req: Vec<String>, resp: Vec<String>| {
            let req = req.into_iter().filter(|f| f != "structure_needs_at_least_one_member");
            req.chain(["---".to_string()]).chain(resp).collect::<Vec<_>>()
        };
        fn v<T: Serialize>(x: T) -> serde_yaml::Value {
            serde_yaml::to_value(x).unwrap()
        }
        assert_eq!(yaml(v(SimResult::default())), fields("msg/Result.msg"));
        assert_eq!(yaml(v(SimulationState::default())), fields("msg/SimulationState.msg"));
        assert_eq!(yaml(v(SimulatorFeatures::default())), fields("msg/SimulatorFeatures.msg"));
        let cases = [
            (
                "GetSimulatorFeatures",
                v(GetSimulatorFeaturesRequest::default()),
                v(GetSimulatorFeaturesResponse::default()),
            ),
            ("GetSimulationState", v(GetSimulationStateRequest::default()), v(GetSimulationStateResponse::default())),
            ("SetSimulationState", v(SetSimulationStateRequest::default()), v(SetSimulationStateResponse::default())),
            ("StepSimulation", v(StepSimulationRequest::default()), v(StepSimulationResponse::default())),
            ("ResetSimulation", v(ResetSimulationRequest::default()), v(ResetSimulationResponse::default())),
        ];
        for (name, req, resp) in cases {
            assert_eq!(srv(yaml(req), yaml(resp)), fields(&format!("srv/{name}.srv")), "{name}");
        }
        let action = [
            yaml(v(SimulateStepsGoal::default())),
            vec!["---".to_string()],
            yaml(v(SimulateStepsResult::default())),
            vec!["---".to_string()],
            yaml(v(SimulateStepsFeedback::default())),
        ]
        .concat();
        assert_eq!(action, fields("action/SimulateSteps.action"));
        let mut built: Vec<String> = std::fs::read_dir(format!("{root}/srv"))
            .unwrap()
            .map(|f| f.unwrap().file_name().to_string_lossy().trim_end_matches(".srv").to_string())
            .collect();
        built.sort();
        let mut served: Vec<String> = SimService::ALL.iter().map(|s| s.type_name().to_string()).collect();
        served.sort();
        assert_eq!(served, built, "the node serves every service of msg/simulation_interfaces/srv");
    }
}
