//! The live view's stand-in in a node built without the `foxglove` cargo feature: asking for it
//! (`--foxglove`, parameter `foxglove`) fails at start, saying how to build it in.

use std::convert::Infallible;
use std::net::SocketAddr;

use serde::Serialize;

use super::lines::Line;
use crate::ros::messages::{DiagnosticStatus, Time};

/// Never built: [`LiveView::start`] refuses.
pub(super) struct LiveView(Infallible);

impl LiveView {
    pub(super) fn start(address: SocketAddr, _name: &str) -> Result<Self, String> {
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

    pub(super) fn offer_scene(&self, _topic: &str, _lines: &[Line], _stamp: Time) {
        match self.0 {}
    }

    pub(super) fn status(&self) -> DiagnosticStatus {
        match self.0 {}
    }
}
