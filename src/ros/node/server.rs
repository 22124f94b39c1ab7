//! The node's one task as a type: [`Server`] is composed of the node's parts (the lines, simulation
//! control, stepping, diagnostics), each owning its state and endpoints; it waits on every input at
//! once and hands each event to the part it concerns, until a signal (or a SetSimulationState to
//! QUITTING).

use std::ops::ControlFlow;

use async_signal::{Signal, Signals};
use futures::future::{FutureExt, LocalBoxFuture};
use futures::stream::{Fuse, StreamExt};
use ros2_client::Node;

use super::action::NAME;
use super::control::{SimFlow, SimulationControl};
use super::diagnostics::Diagnostics;
use super::events::Event;
use super::graph::Graph;
use super::line_set::{ClockPublisher, LineSet};
use super::lines::Line;
use super::live_view::{LiveView, ResetCalls};
use super::log::log;
use super::parameters::ParameterValues;
use super::stepping::{StepReply, Stepping};
use crate::ros::names::Names;
use crate::ros::params::NodeParams;
use crate::ros::topics;

/// The running node: its parts, its signals, and the ROS graph they share.
pub(super) struct Server {
    lines: LineSet,
    control: SimulationControl,
    stepping: Stepping,
    diagnostics: Diagnostics,
    signals: Fuse<Signals>,
    /// Last: its input streams and node outlive every endpoint above.
    graph: Graph,
}

/// What woke the node.
enum Wake {
    Event(Event),
    /// The next step of the StepSimulation in progress.
    Step,
    /// A SimulateSteps result went out.
    Finished,
    Timer,
    Diagnostics,
    Signal(std::io::Result<Signal>),
}

impl Server {
    /// Creates every endpoint: each line's, then the node-wide ones (in that order, as announced
    /// to the graph: /clock, /diagnostics, the batch topics, the simulation services, the action).
    pub(super) fn new(
        mut node: Node,
        names: &Names,
        params: &NodeParams,
        parameter_values: ParameterValues,
        (signals, live): (Signals, Option<(LiveView, ResetCalls)>),
    ) -> Result<Self, String> {
        let mut lines = Vec::new();
        let mut inputs = Vec::new();
        for k in 0..params.lines {
            let (line, streams) = Line::new(&mut node, names, params, k)?;
            lines.push(line);
            inputs.extend(streams);
        }
        let clock = ClockPublisher::new(&mut node, names)?;
        let diagnostics = Diagnostics::new(&mut node, names, params)?;
        let lines = LineSet::new(&mut node, names, params, (lines, clock), &mut inputs)?;
        let (control, sim_inputs) = SimulationControl::new(&mut node, names, params)?;
        let stepping = Stepping::new(&mut node, names, &mut inputs)?;
        inputs.extend(sim_inputs);
        let live = live.map(|(live, calls)| {
            inputs.push(calls.map(Event::LiveReset).boxed_local());
            live
        });
        let graph = Graph::new(node, parameter_values, inputs, live);
        Ok(Server { lines, control, stepping, diagnostics, signals: signals.fuse(), graph })
    }

    pub(super) fn spinner(&mut self) -> Result<ros2_client::Spinner, String> {
        self.graph.node.spinner().map_err(|e| format!("cannot start the node's spinner: {e:?}"))
    }

    /// Serves until a signal (or a SetSimulationState to QUITTING).
    pub(super) async fn serve(&mut self) {
        self.lines.start(&mut self.graph);
        self.control.start();
        self.diagnostics.start();
        loop {
            let flow = match self.next_wake().await {
                Wake::Event(event) => self.on_event(event).await,
                Wake::Step => {
                    self.stepping.on_step((&mut self.lines, &mut self.graph), &mut self.control).await;
                    ControlFlow::Continue(())
                }
                Wake::Finished => ControlFlow::Continue(()),
                Wake::Timer => {
                    self.lines.tick_all(&mut self.graph);
                    ControlFlow::Continue(())
                }
                Wake::Diagnostics => {
                    let simulation = self.control.status(self.stepping.progress());
                    self.diagnostics.publish(&self.graph, &mut self.lines.lines, simulation);
                    ControlFlow::Continue(())
                }
                Wake::Signal(signal) => {
                    let name = match signal {
                        Ok(Signal::Int) => "SIGINT",
                        Ok(Signal::Term) => "SIGTERM",
                        _ => "a signal",
                    };
                    log("INFO", format!("received {name}: leaving the graph"));
                    ControlFlow::Break(())
                }
            };
            if flow.is_break() {
                break;
            }
        }
    }

    async fn next_wake(&mut self) -> Wake {
        // A StepSimulation in progress runs one step per turn of the loop, so other requests,
        // commands and signals are served between its steps.
        let mut step_now: futures::future::Fuse<LocalBoxFuture<'static, ()>> = if self.stepping.progress().is_some() {
            futures::future::ready(()).boxed_local().fuse()
        } else {
            futures::future::pending().boxed_local().fuse()
        };
        // Fair (random among ready inputs): a biased order would let a flood of commands starve
        // the realtime timer and /diagnostics.
        futures::select! {
            event = self.graph.events.select_next_some() => Wake::Event(event),
            () = step_now => Wake::Step,
            () = self.stepping.action.finishing.select_next_some() => Wake::Finished,
            _ = self.control.timer.select_next_some() => Wake::Timer,
            _ = self.diagnostics.timer.select_next_some() => Wake::Diagnostics,
            signal = self.signals.select_next_some() => Wake::Signal(signal),
        }
    }

    /// Hands an event to the part it concerns.
    async fn on_event(&mut self, event: Event) -> ControlFlow<()> {
        let (lines, graph) = (&mut self.lines, &mut self.graph);
        match event {
            Event::Batch(received) => lines.on_batch(graph, received),
            Event::Command(k, topic, received) => lines.on_command(graph, (k, topic), received),
            Event::BatchReset(Ok((id, request))) => lines.on_batch_reset(graph, id, request).await,
            Event::BatchReset(Err(error)) => {
                log("WARN", format!("{}: unreadable request: {error}", topics::BATCH_RESET.name))
            }
            Event::Reset(k, Ok((id, request))) => lines.on_reset(graph, k, id, request).await,
            Event::Reset(k, Err(error)) => {
                log("WARN", format!("{}/reset: unreadable request: {error}", lines.lines[k].namespace));
            }
            Event::Sim(Ok(request)) => {
                let stepping = self.stepping.progress();
                match self.control.on_request((lines, graph), request, stepping).await {
                    SimFlow::Answered => {}
                    SimFlow::Steps(steps) => self.stepping.start(lines, StepReply::Service(request.0), steps),
                    SimFlow::Quit => return ControlFlow::Break(()),
                }
            }
            Event::Sim(Err(error)) => log("WARN", format!("simulation_interfaces: unreadable request: {error}")),
            Event::Goal(Ok(handle)) => self.stepping.on_goal(lines, &mut self.control, handle).await,
            Event::Goal(Err(error)) => log("WARN", format!("{}: unreadable goal: {error}", NAME)),
            Event::Cancel(Ok(cancel)) => self.stepping.on_cancel(lines, cancel).await,
            Event::LiveReset(call) => lines.on_live_reset(graph, call),
            Event::Cancel(Err(error)) => {
                log("WARN", format!("{}: unreadable cancel request: {error}", NAME));
            }
        }
        ControlFlow::Continue(())
    }
}
