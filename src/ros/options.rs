//! The node's command-line options. Each is also a ROS parameter of the same name (`-` as `_`),
//! so a value can come from a flag, `--params-file`, or `--ros-args -p name:=value`.

use clap::{Args, ValueEnum};
use std::path::PathBuf;

use crate::sim::{InputKind, Setup, Variant};

/// How the node advances time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TickMode {
    /// One tick when the commands answering the current tick have arrived.
    #[default]
    Lockstep,
    /// Ticks at `--rate` Hz of wall time, holding the last valid command.
    Realtime,
}

/// `sorting_line node` options. `None` means "not given": the parameter file or default decides.
#[derive(Args, Clone, Debug, Default)]
pub struct NodeArgs {
    /// One of the paper's setups, A..D: sets input, obs_noise and action_penalty
    /// (`LineConfig::for_setup`); any of those three given explicitly, from any source, overrides it.
    #[arg(long)]
    pub setup: Option<Setup>,
    /// The line: basic (belt speed only) or advanced (speed and sort mode, ratio sensor);
    /// default basic.
    #[arg(long)]
    pub variant: Option<Variant>,
    /// The material input: random (independent batches), seasonal (the paper's 9 patterns) or
    /// seasonal3 (the seasonal amounts with a random A/B split); default random, or --setup's.
    #[arg(long)]
    pub input: Option<InputKind>,
    /// Relative noise of the input sensor, 0.0..=1.0.
    #[arg(long)]
    pub obs_noise: Option<f64>,
    /// Reward subtracted for a change of belt speed, 0.0..=10.0.
    #[arg(long)]
    pub action_penalty: Option<f64>,
    /// Accuracy threshold of the reward, 0.0..<1.0 (default 0.7).
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Episode length in steps (default 50).
    #[arg(long)]
    pub max_steps: Option<u32>,
    /// Seed of line 0; line k uses seed + k.
    #[arg(long)]
    pub seed: Option<u64>,
    /// How time advances: lockstep (default; a tick when its commands arrived) or realtime
    /// (--rate ticks per second on the last valid command).
    #[arg(long, value_enum)]
    pub mode: Option<TickMode>,
    /// Ticks per second of wall time in realtime mode.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Number of lines hosted by this process.
    #[arg(long)]
    pub lines: Option<u32>,
    /// Simulated seconds per tick (the stamp step and the /clock step).
    #[arg(long)]
    pub tick_period: Option<f64>,
    /// An evolution schedule (YAML; format in src/sim/evolution.rs and docs/evolving.md): every
    /// hosted line evolves by it. Parameter `evolution_file`.
    #[arg(long, value_name = "FILE")]
    pub evolution: Option<PathBuf>,
    /// Serve the Foxglove WebSocket live view on `[ADDR:]PORT` (default address 127.0.0.1; port 0:
    /// any free port, logged); off unless given. Parameter `foxglove` (docs/foxglove.md).
    #[arg(long, value_name = "[ADDR:]PORT")]
    pub foxglove: Option<String>,
    /// A YAML parameter file (flat keys, or the launch_ros form with `/**:` / node-name keys).
    #[arg(long)]
    pub params_file: Option<PathBuf>,
}

/// Splits `argv` into the arguments for clap and the ROS arguments: everything between
/// `--ros-args` and an optional `--` (ROS allows several such sections).
pub fn split_ros_args(argv: Vec<String>) -> (Vec<String>, Vec<String>) {
    let (mut ours, mut ros) = (Vec::new(), Vec::new());
    let mut in_ros = false;
    for arg in argv {
        match (in_ros, arg.as_str()) {
            (_, "--ros-args") => in_ros = true,
            (true, "--") => in_ros = false,
            (true, _) => ros.push(arg),
            (false, _) => ours.push(arg),
        }
    }
    (ours, ros)
}

#[cfg(test)]
mod tests {
    use super::split_ros_args;

    fn v(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn ros_sections_are_split_off() {
        let (ours, ros) = split_ros_args(v("bin node --lines 2 --ros-args -r __ns:=/plant -p seed:=3 -- --seed 4"));
        assert_eq!(ours, v("bin node --lines 2 --seed 4"));
        assert_eq!(ros, v("-r __ns:=/plant -p seed:=3"));
    }
}
