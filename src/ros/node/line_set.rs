//! The node's lines as one part: every hosted line, the node-wide endpoints that carry them all
//! (`batch/cmd`, `batch/state`, `batch/reset`) and /clock. Here commands and resets (per line and
//! batched) are applied, counted and logged (the rules live in `ros::protocol`), and the lines
//! tick together (the realtime timer, StepSimulation) or go back to how they were built
//! (ResetSimulation).

use std::rc::Rc;

use futures::stream::StreamExt;
use ros2_client::{MessageInfo, Node, Publisher, RmwRequestId, Server as ServiceServer};

use super::endpoints::{messages, publisher, requests, respond, service, subscription};
use super::events::{client_of, Event, Input};
use super::graph::Graph;
use super::line_messages;
use super::lines::{Line, Refusal};
use super::live_view::ResetCall;
use super::log::show_topic;
use crate::ros::messages::{batch_reset_service_type, Clock, LineCommands, LineStates, ResetLineRequest};
use crate::ros::messages::{ResetLinesRequest, ResetLinesResponse, Time};
use crate::ros::names::Names;
use crate::ros::options::TickMode;
use crate::ros::params::NodeParams;
use crate::ros::protocol::{batch_commands, batch_resets, BatchModes, Client, Command, Rejection, TimerTick};
use crate::ros::simulation::ResetScope;
use crate::ros::topics::{self, Topic};

/// /clock: follows the line that is furthest ahead and goes back only when the simulation's time
/// is reset.
pub(super) struct ClockPublisher {
    publisher: Publisher<Clock>,
    last: Option<Time>,
}

impl ClockPublisher {
    pub(super) fn new(node: &mut Node, names: &Names) -> Result<Self, String> {
        let clock = publisher(node, &topics::CLOCK, &names.global(topics::CLOCK.name))?;
        Ok(ClockPublisher { publisher: clock, last: None })
    }

    fn publish(&mut self, graph: &Graph, lines: &[Line]) {
        let newest = lines.iter().map(|line| line.host.stamp()).max().unwrap_or_default();
        if self.last.is_none_or(|last| newest > last) {
            self.last = Some(newest);
            graph.offer(&self.publisher, &|| topics::CLOCK.name.to_string(), || Clock { clock: newest });
        }
    }
}

/// Every line, with the endpoints that carry them all.
pub(super) struct LineSet {
    pub(super) lines: Vec<Line>,
    /// Whether `batch/cmd` carries sort modes.
    modes: BatchModes,
    batch_state: Publisher<LineStates>,
    /// Its name, for the log and the live view.
    batch_state_topic: String,
    batch_reset: Rc<ServiceServer<ResetLinesRequest, ResetLinesResponse>>,
    clock: ClockPublisher,
}

impl LineSet {
    /// The lines with the batch endpoints (created here, after /clock and /diagnostics, in the
    /// order the node has always announced them); their input streams go to `inputs`.
    pub(super) fn new(
        node: &mut Node,
        names: &Names,
        params: &NodeParams,
        (lines, clock): (Vec<Line>, ClockPublisher),
        inputs: &mut Vec<Input>,
    ) -> Result<Self, String> {
        let err = |e| format!("{e:?}");
        let at = |topic: &Topic| names.topic(&names.namespace, topic.name);
        let batch_cmd = subscription(node, &topics::BATCH_CMD, &at(&topics::BATCH_CMD))?;
        let batch_state = publisher(node, &topics::BATCH_STATE, &at(&topics::BATCH_STATE))?;
        let batch_reset = service(node, &topics::BATCH_RESET, &at(&topics::BATCH_RESET), batch_reset_service_type())?;
        inputs.extend([
            messages(batch_cmd).map(move |r| Event::Batch(r.map_err(err))).boxed_local(),
            requests(&batch_reset).map(move |r| Event::BatchReset(r.map_err(err))).boxed_local(),
        ]);
        let modes = BatchModes::of(params.line.variant, !params.evolution.is_empty());
        let batch_state_topic = show_topic(&names.namespace, topics::BATCH_STATE.name);
        Ok(LineSet { lines, modes, batch_state, batch_state_topic, batch_reset, clock })
    }

    /// The lines as built: their episode-0 events applied (announced, and line 0's parameters
    /// set, like those of any later reset) and their first tick out.
    pub(super) fn start(&mut self, graph: &mut Graph) {
        for line in &mut self.lines {
            line.announce_start(graph);
            line.publish_tick(graph);
        }
        self.publish_clock(graph);
    }

    pub(super) fn publish_clock(&mut self, graph: &Graph) {
        self.clock.publish(graph, &self.lines);
    }

    /// `batch/state`, when a vectorised client reads it (per-line clients and realtime lines
    /// without one would otherwise get every line's state built and sent each tick for nothing).
    fn publish_batch_state(&self, graph: &Graph) {
        graph.offer(&self.batch_state, &|| self.batch_state_topic.clone(), || self.states());
    }

    /// Every line's current state, as arrays.
    fn states(&self) -> LineStates {
        line_messages::line_states(self.lines.iter().map(|line| &line.host))
    }

    /// Every line's tick mode, and whether the lines are halted (simulation_interfaces' STOPPED).
    pub(super) fn set_mode(&mut self, mode: TickMode, halted: Option<bool>) {
        for line in &mut self.lines {
            line.host.set_mode(mode);
            if let Some(halted) = halted {
                line.host.set_halted(halted);
            }
        }
    }

    /// `batch/cmd`: applied line by line; the batch state and /clock follow if any line stepped.
    pub(super) fn on_batch(&mut self, graph: &mut Graph, received: Result<(LineCommands, MessageInfo), String>) {
        if self.handle_batch(graph, received) {
            self.publish_batch_state(graph);
            self.publish_clock(graph);
        }
    }

    /// A command on line k's own topic.
    pub(super) fn on_command(
        &mut self,
        graph: &mut Graph,
        (k, topic): (usize, &str),
        received: Result<(Client, Time, Command), String>,
    ) {
        let line = &mut self.lines[k];
        let result = match received {
            Ok((client, stamp, command)) => line.apply(client, stamp, command),
            Err(error) => Err(malformed(&error)),
        };
        if line.settle(graph, topic, result) {
            self.publish_clock(graph);
        }
    }

    /// Applies a batch command line by line, through the same rules as the per-line topics
    /// (`protocol::batch_commands`). Returns whether any line stepped.
    fn handle_batch(&mut self, graph: &mut Graph, received: Result<(LineCommands, MessageInfo), String>) -> bool {
        let (cmd, client) = match received {
            Ok((cmd, info)) => (cmd, client_of(&info)),
            Err(error) => {
                self.lines[0].settle(graph, topics::BATCH_CMD.name, Err(malformed(&error)));
                return false;
            }
        };
        let entries = match batch_commands(&cmd, self.lines.len(), self.modes) {
            Ok(entries) => entries,
            Err(detail) => {
                self.lines[0].settle(graph, topics::BATCH_CMD.name, Err((Rejection::Malformed, detail)));
                return false;
            }
        };
        let mut stepped = false;
        for (line, entry) in self.lines.iter_mut().zip(entries) {
            for command in entry.commands() {
                let result = line.apply(client, entry.stamp, command);
                stepped |= line.settle(graph, topics::BATCH_CMD.name, result);
            }
        }
        stepped
    }

    /// `batch/reset`: resets the lines it names, or refuses the whole request if it is malformed
    /// (`protocol::batch_resets`); answers with every line's state either way.
    pub(super) async fn on_batch_reset(&mut self, graph: &mut Graph, id: RmwRequestId, request: ResetLinesRequest) {
        let response = match batch_resets(&request, self.lines.len()) {
            Ok(resets) => {
                for reset in &resets {
                    self.lines[reset.line].reset(graph, reset.seed);
                }
                let message = format!("{} line(s) reset", resets.len());
                ResetLinesResponse { success: true, message, states: self.states() }
            }
            Err(message) => {
                // Counted like a malformed batch/cmd (on line 0), logged by the counters.
                let refusal = (Rejection::Malformed, format!("request ({message})"));
                self.lines[0].settle(graph, topics::BATCH_RESET.name, Err(refusal));
                ResetLinesResponse { success: false, message, states: self.states() }
            }
        };
        respond(&self.batch_reset, topics::BATCH_RESET.name, id, response).await;
        self.publish_batch_state(graph);
        self.publish_clock(graph);
    }

    /// Line k's `reset` service.
    pub(super) async fn on_reset(&mut self, graph: &mut Graph, k: usize, id: RmwRequestId, request: ResetLineRequest) {
        let line = &mut self.lines[k];
        let observation = line.reset(graph, request.has_seed.then_some(request.seed));
        let response = line_messages::reset_response(&line.host, observation, request.has_seed);
        respond(&line.reset, &format!("{}/reset", line.namespace), id, response).await;
        self.publish_batch_state(graph);
        self.publish_clock(graph);
    }

    /// A live view viewer's call of line k's `reset`: done and answered as the ROS service is.
    pub(super) fn on_live_reset(&mut self, graph: &mut Graph, call: ResetCall) {
        let Some(line) = self.lines.get_mut(call.line) else { return };
        let observation = line.reset(graph, call.seed);
        let response = line_messages::reset_response(&line.host, observation, call.seed.is_some());
        call.answer(&response);
        self.publish_batch_state(graph);
        self.publish_clock(graph);
    }

    /// One tick of every line on its held command, as the realtime timer and StepSimulation run
    /// it: a line at its time limit starts a new episode instead (its random streams carry on).
    pub(super) fn tick_all(&mut self, graph: &mut Graph) {
        for line in &mut self.lines {
            match line.host.timer_tick() {
                TimerTick::Stepped(_) => {
                    line.counters.ticks += 1;
                    line.publish_tick(graph);
                }
                TimerTick::Reset(_) => {
                    line.counters.episodes += 1;
                    line.publish_reset_events(graph, false);
                    line.publish_tick(graph);
                }
            }
        }
        self.publish_batch_state(graph);
        self.publish_clock(graph);
    }

    /// ResetSimulation (and stopping): every line back to how it was built (state), the stamps and
    /// /clock back to 0 (time), or both; then each line's tick is published again (with the reset
    /// event, seeded, when the state was reset).
    pub(super) fn reset_simulation(&mut self, graph: &mut Graph, scope: ResetScope) {
        for line in &mut self.lines {
            if scope.state {
                line.host.restart();
                line.counters.episodes += 1;
                line.evolution.restart();
            }
            if scope.time {
                line.host.rewind_time();
            }
            if scope.state {
                line.publish_reset_event(graph, true);
                line.announce_start(graph);
            }
            line.publish_tick(graph);
        }
        if scope.time {
            self.clock.last = None;
        }
        self.publish_batch_state(graph);
        self.publish_clock(graph);
    }
}

fn malformed(error: &str) -> Refusal {
    (Rejection::Malformed, format!("message ({error})"))
}
