//! Simulation control as a part of the node: the simulation_interfaces state (PAUSED is
//! lock-step, PLAYING realtime), the realtime timer, the services' counters and servers. A request
//! is checked by the rules of `ros::simulation`, applied to the lines and answered, except a
//! StepSimulation of some steps (handed to the stepping part, answered when they are done) and
//! QUITTING (answered, then the node leaves once the reply is acknowledged, 2 s at most).

use std::time::Duration;

use futures::stream::{Fuse, StreamExt};
use ros2_client::{Node, RmwRequestId};

use super::events::SimRequest;
use super::events::{Event, Input};
use super::graph::Graph;
use super::line_set::LineSet;
use super::log::log;
use super::sim_services::{ok, SimulationServers};
use crate::ros::diagnostics::SimulationCounters;
use crate::ros::messages::DiagnosticStatus;
use crate::ros::names::Names;
use crate::ros::params::NodeParams;
use crate::ros::simulation::{self, reset_scope, step_request, transition, ResetScope, SimState, Transition};
use crate::ros::simulation_interfaces::SimResult;

/// How long a QUITTING node waits for its reply to be acknowledged before it leaves anyway (the
/// reply piggybacks a heartbeat, so a reader acknowledges at once; 2 s outlasts rustdds's slow
/// heartbeat period of 1 s, should the first acknowledgment be lost).
const QUIT_REPLY_WAIT: Duration = Duration::from_secs(2);

/// What the node does after a simulation_interfaces request.
pub(super) enum SimFlow {
    /// Answered; serve on.
    Answered,
    /// A StepSimulation of this many steps (> 0): answered when they are done.
    Steps(u64),
    /// QUITTING: answered; the node leaves the graph.
    Quit,
}

/// The simulation's state, its realtime timer, and the standard's services.
pub(super) struct SimulationControl {
    /// The simulation_interfaces state (PAUSED is lock-step, PLAYING realtime).
    pub(super) state: SimState,
    /// The realtime tick period, and its timer (never fires unless PLAYING).
    period: Duration,
    pub(super) timer: Fuse<smol::Timer>,
    pub(super) counters: SimulationCounters,
    servers: SimulationServers,
}

impl SimulationControl {
    /// The part, with its services' requests as inputs (for the node to add after the action's,
    /// the order it has always waited on them in).
    pub(super) fn new(node: &mut Node, names: &Names, params: &NodeParams) -> Result<(Self, Vec<Input>), String> {
        let servers = SimulationServers::new(node, names)?;
        let inputs = servers.requests().into_iter().map(|requests| requests.map(Event::Sim).boxed_local()).collect();
        let control = SimulationControl {
            state: SimState::initial(params.mode),
            period: Duration::from_secs_f64(1.0 / params.rate),
            timer: StreamExt::fuse(smol::Timer::never()),
            counters: SimulationCounters::new(names.fully_qualified()),
            servers,
        };
        Ok((control, inputs))
    }

    /// The realtime timer starts if the simulation starts PLAYING.
    pub(super) fn start(&mut self) {
        if self.state == SimState::Playing {
            self.timer = StreamExt::fuse(smol::Timer::interval(self.period));
        }
    }

    /// The simulation's status on /diagnostics (`stepping`: a step job's steps done and asked).
    pub(super) fn status(&mut self, stepping: Option<(u64, u64)>) -> DiagnosticStatus {
        self.counters.status(self.state, stepping)
    }

    /// Answers `request` with `result` (and the state, for GetSimulationState).
    pub(super) async fn reply(&self, id: RmwRequestId, request: SimRequest, result: SimResult) {
        self.servers.reply(id, request, result, self.state).await;
    }

    /// A simulation_interfaces request, given the step job in progress (`stepping`: done, asked).
    pub(super) async fn on_request(
        &mut self,
        (lines, graph): (&mut LineSet, &mut Graph),
        (id, request): (RmwRequestId, SimRequest),
        stepping: Option<(u64, u64)>,
    ) -> SimFlow {
        let outcome: Result<(), simulation::Refusal> = match request {
            SimRequest::Features | SimRequest::GetState => Ok(()),
            SimRequest::SetState(target) => match transition(self.state, target, stepping) {
                Ok(Transition::To { to, reset }) => {
                    self.enter(lines, graph, to, reset);
                    Ok(())
                }
                Ok(Transition::Quit) => {
                    self.counters.answered_ok += 1;
                    self.reply(id, request, ok()).await;
                    if let Err(why) = self.servers.set_state_delivered(QUIT_REPLY_WAIT).await {
                        log("WARN", format!("the QUITTING reply may be lost: {why}"));
                    }
                    log("INFO", "simulation QUITTING (SetSimulationState): leaving the graph");
                    return SimFlow::Quit;
                }
                Err(refusal) => Err(refusal),
            },
            SimRequest::Step(steps) => match step_request(self.state, steps, stepping) {
                Ok(0) => Ok(()),
                Ok(steps) => return SimFlow::Steps(steps), // answered when the steps are done
                Err(refusal) => Err(refusal),
            },
            SimRequest::Reset(scope) => reset_scope(scope, stepping).map(|scope| lines.reset_simulation(graph, scope)),
        };
        let result = match outcome {
            Ok(()) => {
                self.counters.answered_ok += 1;
                ok()
            }
            Err(refusal) => {
                if let Some(line) = self.counters.refuse(request.service().name(), &request.describe(), &refusal) {
                    log("WARN", line);
                }
                SimResult { result: refusal.code, error_message: refusal.message }
            }
        };
        self.reply(id, request, result).await;
        SimFlow::Answered
    }

    /// SetSimulationState's transition to `to` (resetting the simulation first if it asks).
    fn enter(&mut self, lines: &mut LineSet, graph: &mut Graph, to: SimState, reset: bool) {
        if reset {
            lines.reset_simulation(graph, ResetScope::ALL);
        }
        self.state = to;
        lines.set_mode(to.tick_mode(), Some(to.halted()));
        if to == SimState::Playing {
            self.timer.get_mut().set_interval(self.period);
        } else {
            *self.timer.get_mut() = smol::Timer::never();
        }
        log("INFO", format!("simulation {}", to.name()));
    }
}
