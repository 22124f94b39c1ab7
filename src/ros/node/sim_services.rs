//! The simulation_interfaces services in the node's private namespace (`~/...`, as Gazebo serves
//! them under its node's name): state, step, reset and features. The rules live in
//! `ros::simulation`; here requests are decoded, applied to the lines and answered.

use std::ops::ControlFlow;
use std::rc::Rc;

use futures::stream::{LocalBoxStream, StreamExt};
use ros2_client::{Node, ReadResult, RmwRequestId, Server as ServiceServer};

use super::super::names::Names;
use super::super::simulation::Transition;
use super::super::simulation::{self, code, reset_scope, step_request, transition, ResetScope, SimState};
use super::super::simulation_interfaces::*;
use super::endpoints::{requests, service};
use super::server::Server;
use super::stepping::StepReply;
use super::{log, Event};

/// The servers, one per [`SimService`].
pub(super) struct SimulationServers {
    features: Rc<ServiceServer<GetSimulatorFeaturesRequest, GetSimulatorFeaturesResponse>>,
    get_state: Rc<ServiceServer<GetSimulationStateRequest, GetSimulationStateResponse>>,
    set_state: Rc<ServiceServer<SetSimulationStateRequest, SetSimulationStateResponse>>,
    step: Rc<ServiceServer<StepSimulationRequest, StepSimulationResponse>>,
    reset: Rc<ServiceServer<ResetSimulationRequest, ResetSimulationResponse>>,
}

/// A request to one of the [`SimulationServers`], decoded.
#[derive(Clone, Copy, Debug)]
pub(super) enum SimRequest {
    Features,
    GetState,
    SetState(u8),
    Step(u64),
    Reset(u8),
}

impl SimRequest {
    fn service(self) -> SimService {
        match self {
            SimRequest::Features => SimService::Features,
            SimRequest::GetState => SimService::GetState,
            SimRequest::SetState(_) => SimService::SetState,
            SimRequest::Step(_) => SimService::Step,
            SimRequest::Reset(_) => SimService::Reset,
        }
    }

    fn describe(self) -> String {
        match self {
            SimRequest::Features | SimRequest::GetState => "the request".to_string(),
            SimRequest::SetState(state) => format!("state {state}"),
            SimRequest::Step(steps) => format!("steps {steps}"),
            SimRequest::Reset(scope) => format!("scope {scope}"),
        }
    }
}

pub(super) fn ok() -> SimResult {
    SimResult { result: code::OK, error_message: String::new() }
}

impl SimulationServers {
    pub(super) fn new(node: &mut Node, names: &Names) -> Result<Self, String> {
        let at = |s: SimService| names.private(s.name());
        Ok(SimulationServers {
            features: service(node, &at(SimService::Features), SimService::Features.service_type())?,
            get_state: service(node, &at(SimService::GetState), SimService::GetState.service_type())?,
            set_state: service(node, &at(SimService::SetState), SimService::SetState.service_type())?,
            step: service(node, &at(SimService::Step), SimService::Step.service_type())?,
            reset: service(node, &at(SimService::Reset), SimService::Reset.service_type())?,
        })
    }

    /// The requests of every service, decoded, each stream holding its server.
    pub(super) fn events(&self) -> Vec<LocalBoxStream<'static, Event>> {
        fn tag<R>(request: fn(R) -> SimRequest) -> impl Fn(ReadResult<(RmwRequestId, R)>) -> Event {
            move |r| Event::Sim(r.map(|(id, req)| (id, request(req))).map_err(|e| format!("{e:?}")))
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
        let err = |e| format!("{e:?}");
        let sent = match request {
            SimRequest::Features => {
                let features = SimulatorFeatures {
                    features: simulation::features(),
                    spawn_formats: Vec::new(),
                    custom_info: "sorting_line: PAUSED is lock-step (commands or StepSimulation advance the lines), \
                                  PLAYING is realtime at the rate parameter; one step is one tick of every line"
                        .to_string(),
                };
                self.features.async_send_response(id, GetSimulatorFeaturesResponse { features }).await.map_err(err)
            }
            SimRequest::GetState => {
                let response = GetSimulationStateResponse { state: SimulationState { state: state.code() }, result };
                self.get_state.async_send_response(id, response).await.map_err(err)
            }
            SimRequest::SetState(_) => {
                self.set_state.async_send_response(id, SetSimulationStateResponse { result }).await.map_err(err)
            }
            SimRequest::Step(_) => {
                self.step.async_send_response(id, StepSimulationResponse { result }).await.map_err(err)
            }
            SimRequest::Reset(_) => {
                self.reset.async_send_response(id, ResetSimulationResponse { result }).await.map_err(err)
            }
        };
        if let Err(error) = sent {
            log("WARN", format!("{}: cannot send the response: {error}", request.service().name()));
        }
    }
}

impl Server {
    /// A simulation_interfaces request: applied and answered, except a StepSimulation of some
    /// steps (answered when they are done) and QUITTING (answered, then the node leaves).
    pub(super) async fn on_sim_request(&mut self, id: RmwRequestId, request: SimRequest) -> ControlFlow<()> {
        let stepping = self.stepping();
        let outcome: Result<(), simulation::Refusal> = match request {
            SimRequest::Features | SimRequest::GetState => Ok(()),
            SimRequest::SetState(target) => match transition(self.sim, target, stepping) {
                Ok(Transition::To { to, reset }) => {
                    self.enter(to, reset);
                    Ok(())
                }
                Ok(Transition::Quit) => {
                    self.sim_counters.answered_ok += 1;
                    self.graph.sim.reply(id, request, ok(), self.sim).await;
                    log("INFO", "simulation QUITTING (SetSimulationState): leaving the graph");
                    return ControlFlow::Break(());
                }
                Err(refusal) => Err(refusal),
            },
            SimRequest::Step(steps) => match step_request(self.sim, steps, stepping) {
                Ok(0) => Ok(()),
                Ok(steps) => {
                    self.start_job(StepReply::Service(id), steps);
                    return ControlFlow::Continue(()); // answered when the steps are done
                }
                Err(refusal) => Err(refusal),
            },
            SimRequest::Reset(scope) => reset_scope(scope, stepping).map(|scope| self.reset_simulation(scope)),
        };
        let result = match outcome {
            Ok(()) => {
                self.sim_counters.answered_ok += 1;
                ok()
            }
            Err(refusal) => {
                if let Some(line) = self.sim_counters.refuse(request.service().name(), &request.describe(), &refusal) {
                    log("WARN", line);
                }
                SimResult { result: refusal.code, error_message: refusal.message }
            }
        };
        self.graph.sim.reply(id, request, result, self.sim).await;
        ControlFlow::Continue(())
    }

    /// SetSimulationState's transition to `to` (resetting the simulation first if it asks).
    fn enter(&mut self, to: SimState, reset: bool) {
        if reset {
            self.reset_simulation(ResetScope::ALL);
        }
        self.sim = to;
        for line in &mut self.lines {
            line.host.set_mode(to.tick_mode());
            line.host.set_halted(to.halted());
        }
        if to == SimState::Playing {
            self.timer.get_mut().set_interval(self.period);
        } else {
            *self.timer.get_mut() = smol::Timer::never();
        }
        log("INFO", format!("simulation {}", to.name()));
    }
}
