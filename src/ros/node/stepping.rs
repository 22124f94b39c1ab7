//! How the simulation moves outside lock-step commands: StepSimulation jobs (one step per turn of
//! the node's loop), the realtime tick of every line, ResetSimulation, and /clock.

use std::time::{Duration, Instant};

use super::super::messages::{Clock, Time};
use super::super::options::TickMode;
use super::super::protocol::TimerTick;
use super::super::simulation::ResetScope;
use super::super::simulation_interfaces::SimulateStepsFeedback;
use super::action::{finish_goal, StepsGoal, NAME};
use super::server::Server;
use super::sim_services::{ok, SimRequest};
use super::{log, Graph, Line};
use ros2_client::action::GoalEndStatus;
use ros2_client::RmwRequestId;
use std::rc::Rc;

/// Whom a finished StepSimulation answers: a service request, or a SimulateSteps goal.
#[derive(Clone, Copy)]
pub(super) enum StepReply {
    Service(RmwRequestId),
    Action(StepsGoal),
}

/// A StepSimulation (or SimulateSteps goal) in progress: whom to answer, steps done and asked.
pub(super) struct StepJob {
    pub(super) reply: StepReply,
    pub(super) done: u64,
    pub(super) steps: u64,
    /// When the action's last feedback went out (see [`FEEDBACK_PERIOD`]).
    last_feedback: Option<Instant>,
}

/// Shortest time between two SimulateSteps feedbacks. A paused line steps thousands of times a
/// second; one feedback per step outran the client's acknowledgements (the reliable writer then
/// refused every feedback with WouldBlock, and a client saw none for seconds). Feedback is
/// progress, not data: the first step, then at most one per period, and the last step always.
const FEEDBACK_PERIOD: Duration = Duration::from_millis(10);

/// /clock: follows the line that is furthest ahead and goes back only when the simulation's time
/// is reset.
#[derive(Default)]
pub(super) struct ClockState {
    last: Option<Time>,
}

impl ClockState {
    fn publish(&mut self, graph: &Graph, lines: &[Line]) {
        let newest = lines.iter().map(|line| line.host.stamp()).max().unwrap_or_default();
        if self.last.is_none_or(|last| newest > last) {
            self.last = Some(newest);
            graph.offer(&graph.clock_pub, &|| "/clock".to_string(), || Clock { clock: newest });
        }
    }
}

impl Server {
    pub(super) fn publish_clock(&mut self) {
        self.clock.publish(&self.graph, &self.lines);
    }

    /// The step job in progress as (done, asked), for the rules and /diagnostics.
    pub(super) fn stepping(&self) -> Option<(u64, u64)> {
        self.job.as_ref().map(|j| (j.done, j.steps))
    }

    /// Starts a StepSimulation (or SimulateSteps goal) of `steps` > 0. Realtime rules while
    /// stepping: a command updates the held command (the next step uses it) instead of completing
    /// a tick.
    pub(super) fn start_job(&mut self, reply: StepReply, steps: u64) {
        for line in &mut self.lines {
            line.host.set_mode(TickMode::Realtime);
        }
        self.job = Some(StepJob { reply, done: 0, steps, last_feedback: None });
    }

    /// Back to lock-step (PAUSED) after a step job.
    pub(super) fn end_job(&mut self) {
        for line in &mut self.lines {
            line.host.set_mode(TickMode::Lockstep);
        }
        self.job = None;
    }

    /// One step of the job in progress; feedback to a SimulateSteps client at most every
    /// [`FEEDBACK_PERIOD`]; the answer once the last step is done.
    pub(super) async fn on_step(&mut self) {
        if self.job.is_none() {
            return;
        }
        self.tick_all();
        let Some(job) = self.job.as_mut() else { return };
        job.done += 1;
        self.sim_counters.steps += 1;
        let due = job.done == job.steps || job.last_feedback.is_none_or(|t| t.elapsed() >= FEEDBACK_PERIOD);
        if let (StepReply::Action(goal), true) = (job.reply, due) {
            job.last_feedback = Some(Instant::now());
            let feedback = SimulateStepsFeedback { completed_steps: job.done, remaining_steps: job.steps - job.done };
            if let Err(e) = self.graph.simulate_steps.publish_feedback(goal, feedback).await {
                log("WARN", format!("{NAME}: cannot publish feedback: {e:?}"));
            }
        }
        if job.done == job.steps {
            let reply = job.reply;
            self.end_job();
            self.sim_counters.answered_ok += 1;
            match reply {
                StepReply::Service(id) => self.graph.sim.reply(id, SimRequest::Step(0), ok(), self.sim).await,
                StepReply::Action(goal) => {
                    let action = Rc::clone(&self.graph.simulate_steps);
                    self.finishing.push(finish_goal(action, goal, GoalEndStatus::Succeeded, ok()));
                }
            }
        }
    }

    /// One tick of every line on its held command, as the realtime timer and StepSimulation run
    /// it: a line at its time limit starts a new episode instead (its random streams carry on).
    pub(super) fn tick_all(&mut self) {
        for line in &mut self.lines {
            match line.host.timer_tick() {
                TimerTick::Stepped(_) => {
                    line.counters.ticks += 1;
                    line.publish_tick(&mut self.graph);
                }
                TimerTick::Reset(_) => {
                    line.counters.episodes += 1;
                    line.publish_reset_events(&mut self.graph, false);
                    line.publish_tick(&mut self.graph);
                }
            }
        }
        self.graph.publish_batch_state(&self.lines);
        self.publish_clock();
    }

    /// ResetSimulation (and stopping): every line back to how it was built (state), the stamps and
    /// /clock back to 0 (time), or both; then each line's tick is published again (with the reset
    /// event, seeded, when the state was reset).
    pub(super) fn reset_simulation(&mut self, scope: ResetScope) {
        for line in &mut self.lines {
            if scope.state {
                line.host.restart();
                line.counters.episodes += 1;
                // The line as built again: its schedule starts over.
                (line.announced_tick, line.counted_tick, line.evolution_events) = (None, None, 0);
            }
            if scope.time {
                line.host.rewind_time();
            }
            if scope.state {
                line.publish_reset_event(&self.graph, true);
                line.announce_start(&self.graph);
            }
            line.publish_tick(&mut self.graph);
        }
        if scope.time {
            self.clock = ClockState::default();
        }
        self.graph.publish_batch_state(&self.lines);
        self.publish_clock();
    }
}
