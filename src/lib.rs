//! `sorting_line`: the SortingEnv industrial sorting line (Maus et al.) as a Rust library and
//! a ROS 2 node.
//!
//! - [`sim`]: the line model. Pure, deterministic, no I/O: this is what every other part runs.
//! - [`eval`]: offline evaluation of the built-in agents with the paper's protocol.
//! - `ros` (the `ros` feature, on by default): the ROS 2 node around the model (topics,
//!   services, an action, clock, parameters, diagnostics). Without the feature the crate builds
//!   with no DDS dependency.
//!
//! The `sorting_line` binary (src/main.rs) wraps these as commands: `eval`, `oracle`, `table`,
//! `policy`, `trace` and `vocabulary` run the library offline, `node` runs the ROS 2 node.

pub mod eval;
#[cfg(feature = "ros")]
pub mod ros;
pub mod sim;
