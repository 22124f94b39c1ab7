//! The ROS 2 node: the line's topics, service, clock and diagnostics on DDS (ros2-client).

pub mod options;

use options::NodeArgs;

/// Runs the node until SIGINT/SIGTERM.
pub fn run(_args: NodeArgs, _ros_args: Vec<String>) -> Result<(), String> {
    Err("the ROS 2 node is not built yet (see the node issue)".into())
}
