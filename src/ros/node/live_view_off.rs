//! The live view's stand-in in a node built without the `foxglove` cargo feature: asking for it
//! (`--foxglove`, parameter `foxglove`) fails at start, saying how to build it in.

use std::convert::Infallible;
use std::net::SocketAddr;

use serde::Serialize;

use super::parameters::ParameterValues;
use crate::ros::messages::{DiagnosticStatus, ResetLineResponse};
use crate::ros::protocol::HostedLine;

/// Never made: there is no live view to call.
pub(super) struct ResetCall {
    pub(super) line: usize,
    pub(super) seed: Option<u64>,
    never: Infallible,
}

impl ResetCall {
    pub(super) fn answer(self, _response: &ResetLineResponse) {
        match self.never {}
    }
}

/// Never yields.
pub(super) type ResetCalls = futures::stream::Pending<ResetCall>;

/// Never built: [`LiveView::start`] refuses.
pub(super) struct LiveView(Infallible);

impl LiveView {
    pub(super) fn start(
        address: SocketAddr,
        _name: &str,
        _parameters: ParameterValues,
        _lines: &[String],
    ) -> Result<(Self, ResetCalls), String> {
        Err(format!(
            "parameter foxglove = {address}: this sorting_line was built without the live view \
             (cargo build --release --features foxglove)"
        ))
    }

    pub(super) fn address(&self) -> SocketAddr {
        match self.0 {}
    }

    pub(super) fn offer<M: Serialize>(&self, _topic: &str, _ros_type: &str, _message: &M) {
        match self.0 {}
    }

    pub(super) fn offer_scene(&self, _topic: &str, _host: &HostedLine, _index: usize, _namespace: &str) {
        match self.0 {}
    }

    pub(super) fn status(&self) -> DiagnosticStatus {
        match self.0 {}
    }
}
