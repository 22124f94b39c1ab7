//! The sorting line model: configuration, input generators, accuracy, reward, the line's step,
//! its evolution schedule and the rule-based agent's expected-reward table. Pure functions and
//! plain structs: no I/O, no clocks, no global state, so the ROS node, the CLI and the tests all
//! run the same dynamics.

pub mod accuracy;
pub mod agent;
pub mod bayes;
pub mod config;
pub mod evolution;
pub mod input;
pub mod line;
pub mod material;
pub mod observation;
pub mod oracle;
pub mod rba;
pub mod report;
pub mod reward;
pub mod rng;
pub mod round;
pub mod speed;

pub use config::{InputKind, LineConfig, Setup, Variant};
pub use line::{Action, Containers, Line, Observation, StepOutcome};
pub use material::{Batch, Category, SortMode};
pub use report::Report;
