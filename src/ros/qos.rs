//! The QoS of every topic, set explicitly: ros2-client's defaults (publisher keep-last 1,
//! best-effort subscriptions) are not ROS's, and a mismatch silently delivers nothing.
//!
//! Everything the RL loop depends on is reliable, volatile, keep-last 10 (ROS's default profile,
//! what rclpy uses when given a depth of 10). The sensor topics use the same profile so that a
//! recorder or a lock-step client never misses a tick; a best-effort subscriber (such as rclpy's
//! default `/clock` subscription) still matches a reliable publisher.

use std::time::Duration;

use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::QosProfile;

/// How long a reliable write may block on a full history before it fails. A client that stops
/// reading must not stall the line for long.
const MAX_BLOCKING: Duration = Duration::from_millis(100);

/// Reliable, volatile, keep-last `depth`.
pub fn reliable(depth: usize) -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(MAX_BLOCKING))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// Commands (`cmd/speed`, `cmd/sort_mode`), `state`, the sensors, `events/reset`, `/clock`,
/// `/diagnostics` and the `reset` service: ROS's default profile.
pub fn default_profile() -> QosProfile {
    reliable(10)
}

/// An action's goal status topic, as rcl_action publishes it: reliable, transient-local,
/// keep-last 1 (a late client still gets the current statuses; rclpy asks for exactly this).
pub fn action_status_profile() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(MAX_BLOCKING))
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}
