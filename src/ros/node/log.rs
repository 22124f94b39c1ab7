//! How the node writes its log lines (as rcl formats them, on stderr) and the values in them:
//! topics, clients, stamps.

use crate::ros::messages::Time;
use crate::ros::names::NODE_NAME;
use crate::ros::protocol::Client;

pub(super) fn log(level: &str, message: impl AsRef<str>) {
    eprintln!("[{level}] [{NODE_NAME}]: {}", message.as_ref());
}

/// A topic of the line in `namespace`, for messages.
pub(super) fn show_topic(namespace: &str, relative: &str) -> String {
    format!("{}/{relative}", namespace.trim_end_matches('/'))
}

pub(super) fn show_client(client: Option<Client>) -> String {
    client.map_or_else(|| "none".to_string(), |c| c.iter().map(|b| format!("{b:02x}")).collect())
}

pub(super) fn show_stamp(t: Time) -> String {
    format!("{}.{:09}", t.sec, t.nanosec)
}
