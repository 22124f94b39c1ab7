//! The node's one task as a type: [`Server`] holds everything the node knows and owns as fields,
//! waits on every input at once and handles each event completely with the method for its kind,
//! until a signal (or a SetSimulationState to QUITTING).

use std::ops::ControlFlow;
use std::rc::Rc;
use std::time::{Duration, Instant};

use async_signal::{Signal, Signals};
use futures::future::{FutureExt, LocalBoxFuture};
use futures::stream::{self, Fuse, FuturesUnordered, LocalBoxStream, StreamExt};
use ros2_client::Node;

use super::super::diagnostics::SimulationCounters;
use super::super::messages::batch_reset_service_type;
use super::super::names::Names;
use super::super::params::NodeParams;
use super::super::simulation::SimState;
use super::action::simulate_steps_server;
use super::endpoints::{messages, publisher, requests, service, subscription};
use super::lines::Line;
use super::parameters::ParameterValues;
use super::sim_services::SimulationServers;
use super::stepping::{ClockState, StepJob};
use super::{log, Event, Graph};

/// How often /diagnostics is published (wall time).
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// The running node: its lines, the simulation's state, its timers and what it owes clients.
pub(super) struct Server {
    pub(super) lines: Vec<Line>,
    pub(super) params: NodeParams,
    /// The simulation_interfaces state (PAUSED is lock-step, PLAYING realtime).
    pub(super) sim: SimState,
    /// The realtime tick period, and its timer (never fires unless PLAYING).
    pub(super) period: Duration,
    pub(super) timer: Fuse<smol::Timer>,
    /// A StepSimulation (or SimulateSteps goal) in progress.
    pub(super) job: Option<StepJob>,
    pub(super) sim_counters: SimulationCounters,
    pub(super) clock: ClockState,
    diagnostics: Fuse<smol::Timer>,
    pub(super) started: Instant,
    signals: Fuse<Signals>,
    /// SimulateSteps results waiting for their client to ask for them.
    pub(super) finishing: FuturesUnordered<LocalBoxFuture<'static, ()>>,
    /// Last: its endpoints and node outlive everything above.
    pub(super) graph: Graph,
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
    /// to the graph).
    pub(super) fn new(
        mut node: Node,
        names: &Names,
        params: &NodeParams,
        parameter_values: ParameterValues,
        signals: Signals,
    ) -> Result<Self, String> {
        let mut lines = Vec::new();
        let mut inputs: Vec<LocalBoxStream<'static, Event>> = Vec::new();
        for k in 0..params.lines {
            let (line, streams) = Line::new(&mut node, names, params, k)?;
            lines.push(line);
            inputs.extend(streams);
        }
        let graph = Self::graph(node, names, parameter_values, inputs)?;
        let sim = SimState::initial(params.mode);
        Ok(Server {
            lines,
            params: params.clone(),
            sim,
            period: Duration::from_secs_f64(1.0 / params.rate),
            timer: StreamExt::fuse(smol::Timer::never()),
            job: None,
            sim_counters: SimulationCounters::new(names.fully_qualified()),
            clock: ClockState::default(),
            diagnostics: StreamExt::fuse(smol::Timer::never()),
            started: Instant::now(),
            signals: signals.fuse(),
            finishing: FuturesUnordered::new(),
            graph,
        })
    }

    /// The node-wide endpoints, with every input stream.
    fn graph(
        mut node: Node,
        names: &Names,
        parameter_values: ParameterValues,
        mut inputs: Vec<LocalBoxStream<'static, Event>>,
    ) -> Result<Graph, String> {
        let err = |e| format!("{e:?}");
        let clock_pub = publisher(&mut node, &names.global("/clock"))?;
        let diagnostics_pub = publisher(&mut node, &names.global("/diagnostics"))?;
        let batch_cmd = subscription(&mut node, &names.topic(&names.namespace, "batch/cmd"))?;
        let batch_state = publisher(&mut node, &names.topic(&names.namespace, "batch/state"))?;
        let batch_reset =
            service(&mut node, &names.topic(&names.namespace, "batch/reset"), batch_reset_service_type())?;
        let sim = SimulationServers::new(&mut node, names)?;
        let simulate_steps = Rc::new(simulate_steps_server(&mut node, names)?);
        let (goals, cancels) = (Rc::clone(&simulate_steps), Rc::clone(&simulate_steps));
        inputs.extend([
            messages(batch_cmd).map(move |r| Event::Batch(r.map_err(err))).boxed_local(),
            requests(&batch_reset).map(move |r| Event::BatchReset(r.map_err(err))).boxed_local(),
            stream::unfold(goals, move |action| async move {
                Some((Event::Goal(action.receive_new_goal().await.map_err(err)), action))
            })
            .boxed_local(),
            stream::unfold(cancels, move |action| async move {
                Some((Event::Cancel(action.receive_cancel_request().await.map_err(err)), action))
            })
            .boxed_local(),
        ]);
        inputs.extend(sim.events());
        Ok(Graph {
            events: stream::select_all(inputs),
            clock_pub,
            diagnostics_pub,
            batch_state,
            batch_reset,
            sim,
            simulate_steps,
            parameter_values,
            node,
        })
    }

    pub(super) fn spinner(&mut self) -> Result<ros2_client::Spinner, String> {
        self.graph.node.spinner().map_err(|e| format!("cannot start the node's spinner: {e:?}"))
    }

    /// Serves until a signal (or a SetSimulationState to QUITTING).
    pub(super) async fn serve(&mut self) {
        self.start();
        loop {
            let flow = match self.next_wake().await {
                Wake::Event(event) => self.on_event(event).await,
                Wake::Step => {
                    self.on_step().await;
                    ControlFlow::Continue(())
                }
                Wake::Finished => ControlFlow::Continue(()),
                Wake::Timer => {
                    self.tick_all();
                    ControlFlow::Continue(())
                }
                Wake::Diagnostics => {
                    self.publish_diagnostics();
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

    /// The lines as built: their episode-0 events applied (announced, and line 0's parameters
    /// set, like those of any later reset) and their first tick out; the timers start.
    fn start(&mut self) {
        for line in &mut self.lines {
            line.announce_start(&self.graph);
            line.publish_tick(&mut self.graph);
        }
        self.publish_clock();
        if self.sim == SimState::Playing {
            self.timer = StreamExt::fuse(smol::Timer::interval(self.period));
        }
        self.diagnostics = StreamExt::fuse(smol::Timer::interval(DIAGNOSTICS_PERIOD));
        self.started = Instant::now();
    }

    async fn next_wake(&mut self) -> Wake {
        // A StepSimulation in progress runs one step per turn of the loop, so other requests,
        // commands and signals are served between its steps.
        let mut step_now: futures::future::Fuse<LocalBoxFuture<'static, ()>> = if self.job.is_some() {
            futures::future::ready(()).boxed_local().fuse()
        } else {
            futures::future::pending().boxed_local().fuse()
        };
        // Fair (random among ready inputs): a biased order would let a flood of commands starve
        // the realtime timer and /diagnostics.
        futures::select! {
            event = self.graph.events.select_next_some() => Wake::Event(event),
            () = step_now => Wake::Step,
            () = self.finishing.select_next_some() => Wake::Finished,
            _ = self.timer.select_next_some() => Wake::Timer,
            _ = self.diagnostics.select_next_some() => Wake::Diagnostics,
            signal = self.signals.select_next_some() => Wake::Signal(signal),
        }
    }

    async fn on_event(&mut self, event: Event) -> ControlFlow<()> {
        match event {
            Event::Batch(received) => self.on_batch(received),
            Event::Command(k, topic, received) => self.on_command(k, topic, received),
            Event::BatchReset(Ok((id, request))) => self.on_batch_reset(id, request).await,
            Event::BatchReset(Err(error)) => log("WARN", format!("batch/reset: unreadable request: {error}")),
            Event::Reset(k, Ok((id, request))) => self.on_reset(k, id, request).await,
            Event::Reset(k, Err(error)) => {
                log("WARN", format!("{}/reset: unreadable request: {error}", self.lines[k].namespace));
            }
            Event::Sim(Ok((id, request))) => return self.on_sim_request(id, request).await,
            Event::Sim(Err(error)) => log("WARN", format!("simulation_interfaces: unreadable request: {error}")),
            Event::Goal(Ok(handle)) => self.on_goal(handle).await,
            Event::Goal(Err(error)) => log("WARN", format!("{}: unreadable goal: {error}", super::action::NAME)),
            Event::Cancel(Ok(cancel)) => self.on_cancel(cancel).await,
            Event::Cancel(Err(error)) => {
                log("WARN", format!("{}: unreadable cancel request: {error}", super::action::NAME));
            }
        }
        ControlFlow::Continue(())
    }
}
