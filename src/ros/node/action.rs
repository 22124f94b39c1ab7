//! The SimulateSteps action (simulation_interfaces) in the node's private namespace: goals are
//! step jobs like StepSimulation's, with feedback, cancel after the step in progress, and refused
//! goals ending aborted with the reason.

use std::rc::Rc;

use futures::future::{FutureExt, LocalBoxFuture};
use ros2_client::action::{
    ActionServerQosPolicies, AsyncActionServer, CancelHandle, ExecutingGoalHandle, GoalEndStatus, NewGoalHandle,
};
use ros2_client::{Node, ServiceMapping};

use super::super::names::Names;
use super::super::qos::{action_status_profile, default_profile};
use super::super::simulation::{code, step_request};
use super::super::simulation_interfaces::{action_type, SimResult, SimulateStepsFeedback, SimulateStepsGoal};
use super::super::simulation_interfaces::{SimulateStepsResult, ACTION};
use super::endpoints::topic_name;
use super::log;
use super::server::Server;
use super::sim_services::ok;
use super::stepping::StepReply;

/// The action's name in the private namespace.
pub(super) const NAME: &str = ACTION.0;

pub(super) type SimulateStepsServer = AsyncActionServer<SimulateStepsGoal, SimulateStepsResult, SimulateStepsFeedback>;
pub(super) type StepsGoal = ExecutingGoalHandle<SimulateStepsGoal>;

/// The SimulateSteps action server, in the node's private namespace (`~/simulate_steps`), with
/// rcl_action's QoS (the status topic is transient-local).
pub(super) fn simulate_steps_server(node: &mut Node, names: &Names) -> Result<SimulateStepsServer, String> {
    let absolute = names.private(NAME);
    let qos = ActionServerQosPolicies {
        goal_service: default_profile(),
        result_service: default_profile(),
        cancel_service: default_profile(),
        feedback_publisher: default_profile(),
        status_publisher: action_status_profile(),
    };
    let server = node
        .create_action_server(ServiceMapping::Enhanced, &topic_name(&absolute)?, &action_type(), qos)
        .map_err(|e| format!("cannot serve the action {absolute}: {e:?}"))?;
    Ok(AsyncActionServer::new(server))
}

/// Ends a SimulateSteps goal: the result goes out when the client asks for it (ros2-client's
/// `send_result_response` waits for that request), so it runs beside the node's loop.
pub(super) fn finish_goal(
    server: Rc<SimulateStepsServer>,
    goal: StepsGoal,
    status: GoalEndStatus,
    result: SimResult,
) -> LocalBoxFuture<'static, ()> {
    async move {
        if let Err(e) = server.send_result_response(goal, status, SimulateStepsResult { result }).await {
            log("WARN", format!("{NAME}: cannot send a goal's result: {e:?}"));
        }
    }
    .boxed_local()
}

impl Server {
    /// A new goal: accepted either way; a refused goal ends at once with the reason in its result.
    pub(super) async fn on_goal(&mut self, handle: NewGoalHandle<SimulateStepsGoal>) {
        let stepping = self.stepping();
        let action = Rc::clone(&self.graph.simulate_steps);
        let Some(goal) = action.get_new_goal(handle) else {
            log("WARN", format!("{NAME}: a new goal vanished before it was read"));
            return;
        };
        let executing = match action.accept_goal(handle).await {
            Ok(accepted) => action.start_executing_goal(accepted).await,
            Err(e) => Err(e),
        };
        let executing = match executing {
            Ok(executing) => executing,
            Err(e) => {
                log("WARN", format!("{NAME}: cannot accept a goal: {e:?}"));
                return;
            }
        };
        match step_request(self.sim, goal.steps, stepping) {
            Ok(0) => {
                self.sim_counters.answered_ok += 1;
                self.finishing.push(finish_goal(action, executing, GoalEndStatus::Succeeded, ok()));
            }
            Ok(steps) => self.start_job(StepReply::Action(executing), steps),
            Err(refusal) => {
                if let Some(line) = self.sim_counters.refuse(NAME, &format!("steps {}", goal.steps), &refusal) {
                    log("WARN", line);
                }
                let result = SimResult { result: refusal.code, error_message: refusal.message };
                self.finishing.push(finish_goal(action, executing, GoalEndStatus::Aborted, result));
            }
        }
    }

    /// A cancel request: only the goal in progress can be canceled (every other one has ended);
    /// it ends after the step in progress.
    pub(super) async fn on_cancel(&mut self, cancel: CancelHandle) {
        let current = match self.job.as_ref().map(|j| (j.reply, j.done, j.steps)) {
            Some((StepReply::Action(goal), done, steps)) if cancel.contains_goal(&goal.goal_id()) => {
                Some((goal, done, steps))
            }
            _ => None,
        };
        let action = Rc::clone(&self.graph.simulate_steps);
        let canceling = current.map(|(goal, _, _)| goal.goal_id());
        if let Err(e) = action.respond_to_cancel_requests(&cancel, canceling.into_iter()).await {
            log("WARN", format!("{NAME}: cannot answer a cancel request: {e:?}"));
        }
        if let Some((goal, done, steps)) = current {
            self.end_job();
            let result = SimResult {
                result: code::OPERATION_FAILED,
                error_message: format!("canceled after {done} of {steps} steps"),
            };
            self.finishing.push(finish_goal(action, goal, GoalEndStatus::Canceled, result));
        }
    }
}
