//! `sorting_line`: the SortingEnv industrial sorting line (Maus et al.) as a Rust library and
//! a ROS 2 node.
//!
//! - [`sim`]: the line model. Pure, deterministic, no I/O: this is what every other part runs.
//! - [`eval`]: offline evaluation of the built-in agents with the paper's protocol.
//! - [`ros`]: the ROS 2 node around the model (topics, service, clock, diagnostics).
//!
//! The `sorting_line` binary (src/main.rs) wraps these as the `eval`, `table` and `node`
//! commands.

pub mod eval;
pub mod ros;
pub mod sim;
