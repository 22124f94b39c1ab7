//! Stepping as a part of the node: StepSimulation jobs and SimulateSteps goals, one step per turn
//! of the node's loop (so other requests, commands and signals are served between steps), with
//! the action's feedback, cancel after the step in progress, and refused goals ending aborted with
//! the reason.

use std::time::{Duration, Instant};

use ros2_client::action::{CancelHandle, GoalEndStatus, NewGoalHandle};
use ros2_client::{Node, RmwRequestId};

use super::action::{SimulateSteps, StepsGoal, NAME};
use super::control::SimulationControl;
use super::events::Input;
use super::events::SimRequest;
use super::graph::Graph;
use super::line_set::LineSet;
use super::log::log;
use super::sim_services::ok;
use crate::ros::names::Names;
use crate::ros::options::TickMode;
use crate::ros::simulation::{code, step_request};
use crate::ros::simulation_interfaces::{SimResult, SimulateStepsFeedback, SimulateStepsGoal};

/// Whom a finished StepSimulation answers: a service request, or a SimulateSteps goal.
#[derive(Clone, Copy)]
pub(super) enum StepReply {
    Service(RmwRequestId),
    Action(StepsGoal),
}

/// A StepSimulation (or SimulateSteps goal) in progress: whom to answer, steps done and asked.
struct StepJob {
    reply: StepReply,
    done: u64,
    steps: u64,
    /// When the action's last feedback went out (see [`FEEDBACK_PERIOD`]).
    last_feedback: Option<Instant>,
}

/// Shortest time between two SimulateSteps feedbacks. A paused line steps thousands of times a
/// second; one feedback per step outran the client's acknowledgements (the reliable writer then
/// refused every feedback with WouldBlock, and a client saw none for seconds). Feedback is
/// progress, not data: the first step, then at most one per period, and the last step always.
const FEEDBACK_PERIOD: Duration = Duration::from_millis(10);

/// The step job in progress (if any) and the SimulateSteps action.
pub(super) struct Stepping {
    job: Option<StepJob>,
    pub(super) action: SimulateSteps,
}

impl Stepping {
    pub(super) fn new(node: &mut Node, names: &Names, inputs: &mut Vec<Input>) -> Result<Self, String> {
        Ok(Stepping { job: None, action: SimulateSteps::new(node, names, inputs)? })
    }

    /// The step job in progress as (done, asked), for the rules and /diagnostics.
    pub(super) fn progress(&self) -> Option<(u64, u64)> {
        self.job.as_ref().map(|j| (j.done, j.steps))
    }

    /// Starts a StepSimulation (or SimulateSteps goal) of `steps` > 0. Realtime rules while
    /// stepping: a command updates the held command (the next step uses it) instead of completing
    /// a tick.
    pub(super) fn start(&mut self, lines: &mut LineSet, reply: StepReply, steps: u64) {
        lines.set_mode(TickMode::Realtime, None);
        self.job = Some(StepJob { reply, done: 0, steps, last_feedback: None });
    }

    /// Back to lock-step (PAUSED) after a step job.
    fn end(&mut self, lines: &mut LineSet) {
        lines.set_mode(TickMode::Lockstep, None);
        self.job = None;
    }

    /// One step of the job in progress; feedback to a SimulateSteps client at most every
    /// [`FEEDBACK_PERIOD`]; the answer once the last step is done.
    pub(super) async fn on_step(
        &mut self,
        (lines, graph): (&mut LineSet, &mut Graph),
        control: &mut SimulationControl,
    ) {
        if self.job.is_none() {
            return;
        }
        lines.tick_all(graph);
        let Some(job) = self.job.as_mut() else { return };
        job.done += 1;
        control.counters.steps += 1;
        let due = job.done == job.steps || job.last_feedback.is_none_or(|t| t.elapsed() >= FEEDBACK_PERIOD);
        if let (StepReply::Action(goal), true) = (job.reply, due) {
            job.last_feedback = Some(Instant::now());
            let feedback = SimulateStepsFeedback { completed_steps: job.done, remaining_steps: job.steps - job.done };
            self.action.feedback(goal, feedback).await;
        }
        if job.done == job.steps {
            let reply = job.reply;
            self.end(lines);
            control.counters.answered_ok += 1;
            match reply {
                StepReply::Service(id) => control.reply(id, SimRequest::Step(0), ok()).await,
                StepReply::Action(goal) => self.action.finish(goal, GoalEndStatus::Succeeded, ok()),
            }
        }
    }

    /// A new goal: accepted either way; a refused goal ends at once with the reason in its result.
    pub(super) async fn on_goal(
        &mut self,
        lines: &mut LineSet,
        control: &mut SimulationControl,
        handle: NewGoalHandle<SimulateStepsGoal>,
    ) {
        let stepping = self.progress();
        let Some((goal, executing)) = self.action.accept(handle).await else { return };
        match step_request(control.state, goal.steps, stepping) {
            Ok(0) => {
                control.counters.answered_ok += 1;
                self.action.finish(executing, GoalEndStatus::Succeeded, ok());
            }
            Ok(steps) => self.start(lines, StepReply::Action(executing), steps),
            Err(refusal) => {
                if let Some(line) = control.counters.refuse(NAME, &format!("steps {}", goal.steps), &refusal) {
                    log("WARN", line);
                }
                let result = SimResult { result: refusal.code, error_message: refusal.message };
                self.action.finish(executing, GoalEndStatus::Aborted, result);
            }
        }
    }

    /// A cancel request: only the goal in progress can be canceled (every other one has ended);
    /// it ends after the step in progress.
    pub(super) async fn on_cancel(&mut self, lines: &mut LineSet, cancel: CancelHandle) {
        let current = match self.job.as_ref().map(|j| (j.reply, j.done, j.steps)) {
            Some((StepReply::Action(goal), done, steps)) if cancel.contains_goal(&goal.goal_id()) => {
                Some((goal, done, steps))
            }
            _ => None,
        };
        self.action.answer_cancel(&cancel, current.as_ref().map(|(goal, _, _)| goal)).await;
        if let Some((goal, done, steps)) = current {
            self.end(lines);
            let result = SimResult {
                result: code::OPERATION_FAILED,
                error_message: format!("canceled after {done} of {steps} steps"),
            };
            self.action.finish(goal, GoalEndStatus::Canceled, result);
        }
    }
}
