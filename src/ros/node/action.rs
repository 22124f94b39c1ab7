//! The SimulateSteps action (simulation_interfaces) in the node's private namespace, as endpoints:
//! its server with rcl_action's QoS, the goals and cancel requests as inputs, feedback, and the
//! results that go out beside the node's loop. What a goal does (a step job like
//! StepSimulation's) is the stepping part's.

use std::rc::Rc;

use futures::future::{FutureExt, LocalBoxFuture};
use futures::stream::{self, FuturesUnordered, StreamExt};
use ros2_client::action::{
    ActionServerQosPolicies, AsyncActionServer, CancelHandle, ExecutingGoalHandle, GoalEndStatus, NewGoalHandle,
};
use ros2_client::{Node, ServiceMapping};

use super::endpoints::topic_name;
use super::events::{Event, Input};
use super::log::log;
use crate::ros::names::Names;
use crate::ros::qos::{action_status_profile, default_profile};
use crate::ros::simulation_interfaces::SimulateStepsResult;
use crate::ros::simulation_interfaces::{action_type, SimResult, SimulateStepsFeedback, SimulateStepsGoal};
use crate::ros::topics::SIMULATE_STEPS;

/// The action's name in the private namespace.
pub(super) const NAME: &str = SIMULATE_STEPS.name;

type SimulateStepsServer = AsyncActionServer<SimulateStepsGoal, SimulateStepsResult, SimulateStepsFeedback>;
pub(super) type StepsGoal = ExecutingGoalHandle<SimulateStepsGoal>;

/// The action server, and the results on their way out.
pub(super) struct SimulateSteps {
    server: Rc<SimulateStepsServer>,
    /// SimulateSteps results waiting for their client to ask for them.
    pub(super) finishing: FuturesUnordered<LocalBoxFuture<'static, ()>>,
}

impl SimulateSteps {
    /// The server, in the node's private namespace (`~/simulate_steps`), with rcl_action's QoS
    /// (the status topic is transient-local); its goals and cancel requests go to `inputs`.
    pub(super) fn new(node: &mut Node, names: &Names, inputs: &mut Vec<Input>) -> Result<Self, String> {
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
        let server = Rc::new(AsyncActionServer::new(server));
        let err = |e| format!("{e:?}");
        let (goals, cancels) = (Rc::clone(&server), Rc::clone(&server));
        inputs.extend([
            stream::unfold(goals, move |action| async move {
                Some((Event::Goal(action.receive_new_goal().await.map_err(err)), action))
            })
            .boxed_local(),
            stream::unfold(cancels, move |action| async move {
                Some((Event::Cancel(action.receive_cancel_request().await.map_err(err)), action))
            })
            .boxed_local(),
        ]);
        Ok(SimulateSteps { server, finishing: FuturesUnordered::new() })
    }

    /// A new goal, accepted and executing (every goal is accepted; a refused one ends at once),
    /// with what it asks; `None` (logged) if it vanished or could not be accepted.
    pub(super) async fn accept(
        &self,
        handle: NewGoalHandle<SimulateStepsGoal>,
    ) -> Option<(SimulateStepsGoal, StepsGoal)> {
        let Some(goal) = self.server.get_new_goal(handle) else {
            log("WARN", format!("{NAME}: a new goal vanished before it was read"));
            return None;
        };
        let executing = match self.server.accept_goal(handle).await {
            Ok(accepted) => self.server.start_executing_goal(accepted).await,
            Err(e) => Err(e),
        };
        match executing {
            Ok(executing) => Some((goal, executing)),
            Err(e) => {
                log("WARN", format!("{NAME}: cannot accept a goal: {e:?}"));
                None
            }
        }
    }

    /// Answers a cancel request, canceling `goal` (the one in progress, if the request names it).
    pub(super) async fn answer_cancel(&self, cancel: &CancelHandle, goal: Option<&StepsGoal>) {
        let canceling = goal.map(|goal| goal.goal_id());
        if let Err(e) = self.server.respond_to_cancel_requests(cancel, canceling.into_iter()).await {
            log("WARN", format!("{NAME}: cannot answer a cancel request: {e:?}"));
        }
    }

    pub(super) async fn feedback(&self, goal: StepsGoal, feedback: SimulateStepsFeedback) {
        if let Err(e) = self.server.publish_feedback(goal, feedback).await {
            log("WARN", format!("{NAME}: cannot publish feedback: {e:?}"));
        }
    }

    /// Ends a goal: the result goes out when the client asks for it (ros2-client's
    /// `send_result_response` waits for that request), so it runs beside the node's loop.
    pub(super) fn finish(&mut self, goal: StepsGoal, status: GoalEndStatus, result: SimResult) {
        let server = Rc::clone(&self.server);
        self.finishing.push(
            async move {
                if let Err(e) = server.send_result_response(goal, status, SimulateStepsResult { result }).await {
                    log("WARN", format!("{NAME}: cannot send a goal's result: {e:?}"));
                }
            }
            .boxed_local(),
        );
    }
}
