//! The simulation_interfaces services in the node's private namespace (`~/...`, as Gazebo serves
//! them under its node's name): state, step, reset and features, as endpoints: their requests
//! decoded, their answers sent. The rules live in `ros::simulation`; what a request does to the
//! lines, in `control`.

use std::rc::Rc;
use std::time::Duration;

use futures::stream::{LocalBoxStream, StreamExt};
use ros2_client::{Node, ReadResult, RmwRequestId, Server as ServiceServer};

use super::endpoints::{requests, respond, service, within};
use super::events::{SimInput, SimRequest};
use crate::ros::names::Names;
use crate::ros::simulation::{self, code, SimState};
use crate::ros::simulation_interfaces::*;
use crate::ros::topics::simulation_service;

/// The server of `s`, at its row's name in the private namespace.
fn serve<Req, Resp>(node: &mut Node, names: &Names, s: SimService) -> Result<Rc<ServiceServer<Req, Resp>>, String>
where
    Req: ros2_client::Message + Clone + serde::de::DeserializeOwned + 'static,
    Resp: ros2_client::Message + serde::Serialize + 'static,
{
    let row = simulation_service(s);
    service(node, row, &names.private(row.name), s.service_type())
}

/// The servers, one per [`SimService`].
pub(super) struct SimulationServers {
    features: Rc<ServiceServer<GetSimulatorFeaturesRequest, GetSimulatorFeaturesResponse>>,
    get_state: Rc<ServiceServer<GetSimulationStateRequest, GetSimulationStateResponse>>,
    set_state: Rc<ServiceServer<SetSimulationStateRequest, SetSimulationStateResponse>>,
    step: Rc<ServiceServer<StepSimulationRequest, StepSimulationResponse>>,
    reset: Rc<ServiceServer<ResetSimulationRequest, ResetSimulationResponse>>,
}

pub(super) fn ok() -> SimResult {
    SimResult { result: code::OK, error_message: String::new() }
}

impl SimulationServers {
    pub(super) fn new(node: &mut Node, names: &Names) -> Result<Self, String> {
        Ok(SimulationServers {
            features: serve(node, names, SimService::Features)?,
            get_state: serve(node, names, SimService::GetState)?,
            set_state: serve(node, names, SimService::SetState)?,
            step: serve(node, names, SimService::Step)?,
            reset: serve(node, names, SimService::Reset)?,
        })
    }

    /// The requests of every service, decoded, each stream holding its server.
    pub(super) fn requests(&self) -> Vec<LocalBoxStream<'static, SimInput>> {
        fn tag<R>(request: fn(R) -> SimRequest) -> impl Fn(ReadResult<(RmwRequestId, R)>) -> SimInput {
            move |r| r.map(|(id, req)| (id, request(req))).map_err(|e| format!("{e:?}"))
        }
        vec![
            requests(&self.features).map(tag(|_| SimRequest::Features)).boxed_local(),
            requests(&self.get_state).map(tag(|_| SimRequest::GetState)).boxed_local(),
            requests(&self.set_state)
                .map(tag(|r: SetSimulationStateRequest| SimRequest::SetState(r.state.state)))
                .boxed_local(),
            requests(&self.step).map(tag(|r: StepSimulationRequest| SimRequest::Step(r.steps))).boxed_local(),
            requests(&self.reset).map(tag(|r: ResetSimulationRequest| SimRequest::Reset(r.scope))).boxed_local(),
        ]
    }

    /// Answers `request` with `result` (and the state, for GetSimulationState).
    pub(super) async fn reply(&self, id: RmwRequestId, request: SimRequest, result: SimResult, state: SimState) {
        let name = request.service().name();
        match request {
            SimRequest::Features => {
                let features = SimulatorFeatures {
                    features: simulation::features(),
                    spawn_formats: Vec::new(),
                    custom_info: "sorting_line: PAUSED is lock-step (commands or StepSimulation advance the lines), \
                                  PLAYING is realtime at the rate parameter; one step is one tick of every line"
                        .to_string(),
                };
                respond(&self.features, name, id, GetSimulatorFeaturesResponse { features }).await
            }
            SimRequest::GetState => {
                let response = GetSimulationStateResponse { state: SimulationState { state: state.code() }, result };
                respond(&self.get_state, name, id, response).await
            }
            SimRequest::SetState(_) => respond(&self.set_state, name, id, SetSimulationStateResponse { result }).await,
            SimRequest::Step(_) => respond(&self.step, name, id, StepSimulationResponse { result }).await,
            SimRequest::Reset(_) => respond(&self.reset, name, id, ResetSimulationResponse { result }).await,
        }
    }

    /// Waits until every reader of SetSimulationState replies has acknowledged the replies sent,
    /// at most `limit`; says why it gave up. For a node about to leave the graph: DDS repeats a
    /// lost sample only while its writer lives, so a reply in flight is lost with the participant.
    pub(super) async fn set_state_delivered(&self, limit: Duration) -> Result<(), String> {
        match within(limit, self.set_state.async_wait_for_acknowledgments()).await {
            Some(acknowledged) => acknowledged.map(|_| ()).map_err(|e| format!("{e:?}")),
            None => Err(format!("not acknowledged within {} s", limit.as_secs_f64())),
        }
    }
}
