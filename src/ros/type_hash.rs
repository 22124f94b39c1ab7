//! The RIHS01 type hash every endpoint announces, as rcl does: `typehash=RIHS01_<hex>;` in the
//! endpoint's USER_DATA. Jazzy tools show it (`ros2 topic info -v`), rosbag2 records it, and
//! Jazzy subscribers warn about endpoints without one. The hashes are rosidl's
//! ([`super::type_hash_table`], generated and checked against rosidl's output); this module maps
//! a DDS type name to the ROS type it belongs to. A service's request and reply endpoints carry
//! the hashes of `<Service>_Request` and `<Service>_Response`, as an rclpy service does; an action's
//! those of `<Action>_SendGoal_Request` ... and `<Action>_FeedbackMessage`.

use super::type_hash_table::TYPE_HASHES;

/// The ROS type name (`pkg/msg/Type`, `pkg/srv/Type_Request`) of a DDS type name
/// (`pkg::msg::dds_::Type_`, `pkg::srv::dds_::Type_Request_` / `_Response_`).
pub fn ros_type_name(dds_type_name: &str) -> Option<String> {
    let mut parts = dds_type_name.split("::");
    let (pkg, kind, dds, name) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    if dds != "dds_" || parts.next().is_some() {
        return None;
    }
    let name = name.strip_suffix('_')?;
    let name = match kind {
        "msg" => name,
        "srv" if name.ends_with("_Request") || name.ends_with("_Response") => name,
        // An action's goal and result services and its feedback topic.
        "action" if name.ends_with("_Request") || name.ends_with("_Response") || name.ends_with("_FeedbackMessage") => {
            name
        }
        _ => return None,
    };
    Some(format!("{pkg}/{kind}/{name}"))
}

/// rosidl's RIHS01 hash of a ROS type, if the node uses it.
pub fn type_hash(ros_type_name: &str) -> Option<&'static str> {
    TYPE_HASHES.iter().find(|(name, _)| *name == ros_type_name).map(|(_, hash)| *hash)
}

/// The USER_DATA of an endpoint of this DDS type: `typehash=RIHS01_<hex>;`, or nothing for a type
/// the table does not know (DDS-internal topics).
pub fn endpoint_user_data(dds_type_name: &str) -> Vec<u8> {
    ros_type_name(dds_type_name)
        .and_then(|name| type_hash(&name))
        .map(|hash| format!("typehash={hash};").into_bytes())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::messages::{
        batch_reset_service_type, reset_service_type, Clock, DiagnosticArray, LineState, Typed,
    };

    #[test]
    fn dds_names_map_to_ros_types() {
        assert_eq!(ros_type_name("rosgraph_msgs::msg::dds_::Clock_").as_deref(), Some("rosgraph_msgs/msg/Clock"));
        assert_eq!(
            ros_type_name("sorting_line_interfaces::srv::dds_::ResetLine_Request_").as_deref(),
            Some("sorting_line_interfaces/srv/ResetLine_Request")
        );
        assert_eq!(
            ros_type_name("rcl_interfaces::srv::dds_::GetParameters_Response_").as_deref(),
            Some("rcl_interfaces/srv/GetParameters_Response")
        );
        assert_eq!(
            ros_type_name("simulation_interfaces::action::dds_::SimulateSteps_FeedbackMessage_").as_deref(),
            Some("simulation_interfaces/action/SimulateSteps_FeedbackMessage")
        );
        assert!(!endpoint_user_data("simulation_interfaces::action::dds_::SimulateSteps_SendGoal_Request_").is_empty());
        assert!(!endpoint_user_data("action_msgs::msg::dds_::GoalStatusArray_").is_empty());
        assert_eq!(ros_type_name("DCPSParticipant"), None);
        assert_eq!(ros_type_name("a::srv::dds_::X_"), None);
    }

    #[test]
    fn user_data_is_rcls_format() {
        let data = String::from_utf8(endpoint_user_data("rosgraph_msgs::msg::dds_::Clock_")).unwrap();
        assert!(data.starts_with("typehash=RIHS01_") && data.ends_with(';'), "{data}");
        assert_eq!(data.len(), "typehash=RIHS01_;".len() + 64);
        assert!(endpoint_user_data("unknown::msg::dds_::X_").is_empty());
    }

    /// Every type the node's own endpoints use has a hash (ros2-client's are checked by
    /// test_type_hash.py against the running node).
    #[test]
    fn the_nodes_types_are_in_the_table() {
        let dds = |t: ros2_client::MessageTypeName| t.dds_msg_type();
        for name in [dds(LineState::type_name()), dds(Clock::type_name()), dds(DiagnosticArray::type_name())] {
            assert!(!endpoint_user_data(&name).is_empty(), "{name}");
        }
        for service in [reset_service_type(), batch_reset_service_type()] {
            for part in ["Request", "Response"] {
                let name = format!("{}::srv::dds_::{}_{part}_", service.package_name(), service.type_name());
                assert!(!endpoint_user_data(&name).is_empty(), "{name}");
            }
        }
    }
}
