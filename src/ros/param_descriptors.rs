//! What `ros2 param describe` (the DescribeParameters service) says about each parameter:
//! a description, read-only (the values are fixed for the run), and the numeric range the
//! validator enforces, taken from the same constants the validator uses
//! (`crate::sim::config` for the line, [`super::params`] for the node).

use ros2_client::parameters::{NumericRange, ParameterDescriptor, ParameterType};

use super::params::{MAX_RATE, MAX_SEED, PARAMETERS, TICK_PERIOD_RANGE};
use super::topics::{CLOCK, DIAGNOSTICS, PARAMETER_EVENTS};
use crate::sim::config::{ACTION_PENALTY_RANGE, MAX_EPISODE_STEPS, MAX_NODE_LINES, OBS_NOISE_RANGE, THRESHOLD_RANGE};

/// What parameter `name` is for (empty for a name that is no parameter). The topics it names are
/// the topic table's ([`super::topics`]).
fn description(name: &str) -> String {
    let (clock, diagnostics, parameter_events) = (CLOCK.name, DIAGNOSTICS.name, PARAMETER_EVENTS.name);
    match name {
        "variant" => "Line variant: basic (belt speed only) or advanced (speed and sort mode, ratio sensor)".into(),
        "input" => "Input material stream: random, seasonal (9 patterns) or seasonal3".into(),
        "obs_noise" => "Noise of the observed input quantity (0 = exact)".into(),
        "action_penalty" => "Reward penalty per change of the belt speed".into(),
        "threshold" => "Sorting accuracy below which a step earns the flat -0.1 reward".into(),
        "max_steps" => "Episode length in ticks".into(),
        "seed" => "Seed of line 0's random streams; line k uses seed + k".into(),
        "mode" => "lockstep (a tick when its commands have arrived) or realtime (ticks at `rate`)".into(),
        "rate" => "Realtime mode: ticks per second of wall time".into(),
        "lines" => "Lines hosted by this node (more than one: <namespace>/line_<k>)".into(),
        "tick_period" => format!("Simulated seconds per tick (the step of {clock} and of every stamp)"),
        "setup" => "The paper's setup A, B, C or D (empty: none); sets input, obs_noise and action_penalty unless given explicitly".into(),
        "use_sim_time" => format!("Ignored: this node is the clock, it publishes {clock}"),
        "evolution_file" => format!("Evolution schedule every line follows (upgrades, drifts, sensor faults; empty: none); the values it changes are updated on {parameter_events}"),
        "foxglove" => format!("Where the Foxglove WebSocket live view listens ([ADDR:]PORT; empty: off): every topic, {clock}'s time, {diagnostics} and the line as a scene (docs/foxglove.md)"),
        _ => String::new(),
    }
}

/// The parameters an evolution schedule changes while the node runs (on /parameter_events).
pub const EVOLVING_PARAMETERS: [&str; 4] = ["obs_noise", "action_penalty", "threshold", "input"];

/// The numeric range of a parameter, if it has one.
fn range(name: &str) -> NumericRange {
    let float =
        |(from_value, to_value): (f64, f64)| NumericRange::FloatingPointRange { from_value, to_value, step: 0.0 };
    let int = |from_value: i64, to_value: i64| NumericRange::IntegerRange { from_value, to_value, step: 1 };
    match name {
        "obs_noise" => float(OBS_NOISE_RANGE),
        "action_penalty" => float(ACTION_PENALTY_RANGE),
        // Upper bound open: stated in additional_constraints ("0.0 ..< 1.0").
        "threshold" => float(THRESHOLD_RANGE),
        "max_steps" => int(1, i64::from(MAX_EPISODE_STEPS)),
        "seed" => int(0, MAX_SEED as i64),
        // Lower bound open: stated in additional_constraints ("0.0 <.. 100000.0").
        "rate" => float((0.0, MAX_RATE)),
        "lines" => int(1, i64::from(MAX_NODE_LINES)),
        "tick_period" => float(TICK_PERIOD_RANGE),
        _ => NumericRange::NotSpecified,
    }
}

/// The descriptor of every parameter the node declares.
pub fn descriptors() -> Vec<ParameterDescriptor> {
    PARAMETERS
        .iter()
        .map(|(name, allowed)| ParameterDescriptor {
            name: name.to_string(),
            // ros2-client answers with the type of the current value.
            param_type: ParameterType::NotSet,
            description: description(name),
            additional_constraints: if EVOLVING_PARAMETERS.contains(name) {
                format!("{allowed}; fixed for the run but for the node's evolution schedule (evolution_file), which updates it")
            } else {
                format!("{allowed}; fixed for the run: restart the node to change it")
            },
            read_only: true,
            dynamic_typing: false,
            range: range(name),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::params::NodeParams;
    use crate::ros::topics;
    use serde_yaml::Value;

    fn accepts(name: &str, value: Value) -> bool {
        NodeParams::default().set(name, &value, "test").is_ok()
    }

    #[test]
    fn every_parameter_is_described_and_read_only() {
        let all = descriptors();
        assert_eq!(all.len(), PARAMETERS.len());
        for d in &all {
            assert!(!d.description.is_empty(), "{} has no description", d.name);
            assert!(d.read_only, "{}", d.name);
        }
    }

    /// Every absolute name a description mentions is one of the node's topics, as the topic
    /// table spells it; the three descriptions that name one name it.
    #[test]
    fn the_descriptions_name_the_topic_tables_topics() {
        let globals: Vec<&str> = topics::TOPICS.iter().map(|t| t.name).filter(|n| n.starts_with('/')).collect();
        let mut named = Vec::new();
        for d in descriptors() {
            for word in d.description.split(|c: char| c.is_whitespace() || matches!(c, ',' | ';' | '(' | ')' | '\'')) {
                if word.starts_with('/') {
                    assert!(
                        globals.contains(&word),
                        "{}'s description names {word}, which is no topic of the node",
                        d.name
                    );
                    named.push((d.name.clone(), word.to_string()));
                }
            }
        }
        let named: Vec<(&str, &str)> = named.iter().map(|(p, t)| (p.as_str(), t.as_str())).collect();
        assert_eq!(
            named,
            [
                ("tick_period", CLOCK.name),
                ("use_sim_time", CLOCK.name),
                ("evolution_file", PARAMETER_EVENTS.name),
                ("foxglove", CLOCK.name),
                ("foxglove", DIAGNOSTICS.name),
            ]
        );
    }

    /// The advertised range is the enforced one: its bounds pass (unless stated open) and the
    /// values just beyond them are refused.
    #[test]
    fn ranges_are_what_the_validator_enforces() {
        let mut checked = 0;
        for d in descriptors() {
            let name = d.name.as_str();
            match d.range {
                NumericRange::FloatingPointRange { from_value, to_value, .. } => {
                    let open_low = d.additional_constraints.contains(" <..");
                    let open_high = d.additional_constraints.contains("..<");
                    assert_eq!(accepts(name, Value::from(from_value)), !open_low, "{name} = {from_value}");
                    assert_eq!(accepts(name, Value::from(to_value)), !open_high, "{name} = {to_value}");
                    assert!(!accepts(name, Value::from(from_value.next_down())), "{name} below {from_value}");
                    assert!(!accepts(name, Value::from(to_value.next_up())), "{name} above {to_value}");
                    checked += 1;
                }
                NumericRange::IntegerRange { from_value, to_value, .. } => {
                    assert!(accepts(name, Value::from(from_value)), "{name} = {from_value}");
                    assert!(accepts(name, Value::from(to_value)), "{name} = {to_value}");
                    if from_value > 0 {
                        assert!(!accepts(name, Value::from(from_value - 1)), "{name} below {from_value}");
                    }
                    assert!(!accepts(name, Value::from(to_value as u64 + 1)), "{name} above {to_value}");
                    checked += 1;
                }
                NumericRange::NotSpecified => {}
            }
        }
        assert_eq!(checked, 8, "every numeric parameter has a range");
    }
}
