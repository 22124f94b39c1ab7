//! What every part of the node shares of the ROS graph: the ROS node the endpoints live on, the
//! set of inputs the node waits on, and the declared parameters' values. `batch/cmd` and
//! `batch/state` (in the node's namespace) carry every line at once: a vectorised client exchanges
//! two messages per round trip instead of two per line, which is what lets one rclpy process
//! drive many lines.

use ros2_client::{Message, Node, Publisher};
use serde::Serialize;

use super::events::{Events, Input};
use super::live_view::LiveView;
use super::log::log;
use super::parameters::{update_parameters, ParameterValues};
use crate::ros::messages::Typed;
use crate::sim::evolution::Settings;

/// The ROS node with every input stream and the parameters' values.
pub(super) struct Graph {
    /// Every input the node waits on; endpoints created while serving (the line's hardware,
    /// [`super::lines::Line::fit_hardware`]) join it at once.
    pub(super) events: Events,
    parameter_values: ParameterValues,
    /// The Foxglove live view, when it is on: every message offered goes to it too.
    pub(super) live: Option<LiveView>,
    /// Last: the endpoints above are dropped before the node.
    pub(super) node: Node,
}

impl Graph {
    pub(super) fn new(
        node: Node,
        parameter_values: ParameterValues,
        inputs: Vec<Input>,
        live: Option<LiveView>,
    ) -> Self {
        Graph { events: futures::stream::select_all(inputs), parameter_values, live, node }
    }

    /// Publishes the message `build` makes if the publisher has a matched reader; returns whether
    /// it did. Topics nobody reads are skipped: a node hosting 16 lines for a vectorised client
    /// (which reads `batch/state` only) would otherwise build, serialise and queue 64 unread
    /// per-line messages per round trip, most of the node's time per tick
    /// (benches/bridge_throughput.py). Nothing is lost that a volatile reader could have had:
    /// samples written before a reader matches never reach it anyway, and the node's count
    /// follows the DDS writer's own matching (the spinner records each match the writer reports).
    /// With the live view on, every message is built and offered to it as well (it keeps each
    /// topic's latest for viewers that subscribe later); the result still says whether DDS got it.
    pub(super) fn offer<M>(
        &self,
        publisher: &Publisher<M>,
        topic: &dyn Fn() -> String,
        build: impl FnOnce() -> M,
    ) -> bool
    where
        M: Message + Serialize + Typed + std::fmt::Debug,
    {
        let read = publisher.get_subscription_count(&self.node) > 0;
        if let Some(live) = &self.live {
            let message = build();
            live.offer(&topic(), &ros_type::<M>(), &message);
            if read {
                self.publish(publisher, topic, message);
            }
            return read;
        }
        if !read {
            return false;
        }
        self.publish(publisher, topic, build());
        true
    }

    fn publish<M>(&self, publisher: &Publisher<M>, topic: &dyn Fn() -> String, message: M)
    where
        M: Message + Serialize + std::fmt::Debug,
    {
        if let Err(e) = publisher.publish(message) {
            log("WARN", format!("cannot publish {}: {e:?}", topic()));
        }
    }

    /// Moves the parameters an evolution event changed (line 0's settings) to their new values.
    pub(super) fn update_parameters(&self, settings: &Settings) {
        update_parameters(&self.node, &self.parameter_values, settings);
    }
}

/// The ROS type name of a message mirror, `pkg/msg/Type`.
pub(super) fn ros_type<M: Typed>() -> String {
    let t = M::type_name();
    format!("{}/msg/{}", t.package_name(), t.type_name())
}
