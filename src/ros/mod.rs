//! The ROS 2 node: the line's topics, services, action, clock and diagnostics on DDS (ros2-client), and
//! the ROS conventions ros2-client leaves to us (`--ros-args`, parameters, `ROS_DOMAIN_ID`).
//!
//! - `options`: the `node` subcommand's flags; `ros_args`: `--ros-args`; `params`: all of them
//!   merged and validated; `param_descriptors`: what `ros2 param describe` says; `names`:
//!   namespaces and remaps.
//! - `discovery`: the DDS participant as ROS 2's discovery variables ask; `type_hash`: the
//!   RIHS01 type hashes every endpoint announces.
//! - `protocol`: lock-step/realtime command handling of one line, without I/O.
//! - `simulation`: the node as a standard simulator (simulation_interfaces: state, step, reset,
//!   features), as rules without I/O; `simulation_interfaces`: the standard's types on the wire.
//! - `messages`, `qos`, `clock`, `diagnostics`: what goes on the wire; `ros2msg`: the types'
//!   schemas as Foxglove reads them (the live view); `topics`: the table of every endpoint's
//!   name, type, direction and QoS (what `sorting_line vocabulary` prints).
//! - `node`: the running node: the DDS participant, the endpoints, and the server whose loop
//!   handles every event (one module per concern, listed there).

pub mod clock;
pub mod diagnostics;
pub mod discovery;
pub mod messages;
pub mod names;
pub mod node;
pub mod options;
pub mod param_descriptors;
pub mod params;
pub mod protocol;
pub mod qos;
pub mod ros2msg;
pub mod ros_args;
pub mod simulation;
pub mod simulation_interfaces;
pub mod topics;
pub mod type_hash;
pub mod type_hash_table;

pub use node::run;
