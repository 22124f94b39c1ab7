//! Everything from DDS that can wake the node, as one type: each input stream (one per endpoint,
//! each holding its endpoint) yields [`Event`]s, and the node waits on all of them at once.

use futures::stream::{LocalBoxStream, SelectAll};
use ros2_client::action::{CancelHandle, NewGoalHandle};
use ros2_client::{Gid, MessageInfo, RmwRequestId};

use super::live_view::ResetCall;
use crate::ros::messages::{LineCommands, ResetLineRequest, ResetLinesRequest, Time};
use crate::ros::protocol::{Client, Command};
use crate::ros::simulation_interfaces::{SimService, SimulateStepsGoal};

/// Everything from DDS that can wake the node.
pub(super) enum Event {
    Batch(Result<(LineCommands, MessageInfo), String>),
    BatchReset(Result<(RmwRequestId, ResetLinesRequest), String>),
    /// A command on line k's own topic (named), with its sender and stamp.
    Command(usize, &'static str, Result<(Client, Time, Command), String>),
    Reset(usize, Result<(RmwRequestId, ResetLineRequest), String>),
    /// A simulation_interfaces request.
    Sim(Result<(RmwRequestId, SimRequest), String>),
    /// A new SimulateSteps goal, or a request to cancel goals.
    Goal(Result<NewGoalHandle<SimulateStepsGoal>, String>),
    Cancel(Result<CancelHandle, String>),
    /// A viewer of the live view called a line's `reset`.
    LiveReset(ResetCall),
}

/// One input of the node.
pub(super) type Input = LocalBoxStream<'static, Event>;

/// The node's inputs, one stream per endpoint, each holding its endpoint.
pub(super) type Events = SelectAll<Input>;

/// The participant that wrote a command (the GUID prefix of its writer).
pub(super) fn client_of(info: &MessageInfo) -> Client {
    let gid: Gid = info.publisher_gid();
    let mut client = Client::default();
    let n = client.len();
    client.copy_from_slice(&gid.as_bytes()[..n]);
    client
}

/// A request to one of the simulation_interfaces services, decoded.
#[derive(Clone, Copy, Debug)]
pub(super) enum SimRequest {
    Features,
    GetState,
    SetState(u8),
    Step(u64),
    Reset(u8),
}

/// A decoded request as it comes in, or why it could not be read.
pub(super) type SimInput = Result<(RmwRequestId, SimRequest), String>;

impl SimRequest {
    pub(super) fn service(self) -> SimService {
        match self {
            SimRequest::Features => SimService::Features,
            SimRequest::GetState => SimService::GetState,
            SimRequest::SetState(_) => SimService::SetState,
            SimRequest::Step(_) => SimService::Step,
            SimRequest::Reset(_) => SimService::Reset,
        }
    }

    pub(super) fn describe(self) -> String {
        match self {
            SimRequest::Features | SimRequest::GetState => "the request".to_string(),
            SimRequest::SetState(state) => format!("state {state}"),
            SimRequest::Step(steps) => format!("steps {steps}"),
            SimRequest::Reset(scope) => format!("scope {scope}"),
        }
    }
}
