//! The node's ROS parameters: every setting declared with its value and described, fixed for the
//! run (set requests are refused with a reason), except that the node's own evolution schedule
//! moves the values it changes.

use std::sync::{Arc, Mutex};

use ros2_client::{Node, NodeOptions, ParameterValue};

use super::log::log;
use crate::ros::param_descriptors::{descriptors, EVOLVING_PARAMETERS};
use crate::ros::params::NodeParams;
use crate::sim::evolution::Settings;

/// The values the parameter validator accepts: the current ones. The node itself moves them
/// when its evolution schedule changes a setting ([`update_parameters`]).
pub(super) type ParameterValues = Arc<Mutex<Vec<(&'static str, ParameterValue)>>>;

/// Declares every parameter with its value. They are fixed for the run: changing the dynamics
/// mid-run would silently break every trajectory, so set requests are refused with a reason
/// (only the node's own evolution schedule moves the values it names).
pub(super) fn node_options(params: &NodeParams) -> (NodeOptions, ParameterValues) {
    let mut options = NodeOptions::new().enable_rosout(true).start_parameter_services(true);
    let mut declared = Vec::new();
    for (name, value) in params.as_values() {
        let value = match value {
            serde_yaml::Value::Bool(b) => ParameterValue::Boolean(b),
            serde_yaml::Value::Number(n) if n.is_f64() => ParameterValue::Double(n.as_f64().unwrap_or_default()),
            serde_yaml::Value::Number(n) => {
                // Every integer parameter fits an i64: NodeParams::validate keeps the seed within it.
                ParameterValue::Integer(n.as_i64().unwrap_or(i64::MAX))
            }
            other => ParameterValue::String(other.as_str().unwrap_or_default().to_string()),
        };
        declared.push((name, value.clone()));
        options = options.declare_parameter(name, value);
    }
    for descriptor in descriptors() {
        options = options.describe_parameter(descriptor);
    }
    let current = Arc::new(Mutex::new(declared));
    let accepted = Arc::clone(&current);
    // The validator also sees the declarations themselves: those pass, any change is refused.
    let options = options.parameter_validator(Box::new(move |name: &str, value: &ParameterValue| {
        let values = accepted.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        match values.iter().find(|(n, _)| *n == name) {
            Some((_, v)) if v == value => Ok(()),
            _ => Err(format!("parameter {name} is fixed for the run: restart the node with the new value")),
        }
    }));
    (options, current)
}

/// Moves the parameters an evolution event changed (line 0's settings) to their new values: the
/// validator (which reads `parameter_values`) accepts them first, then `node` sets them, which
/// publishes them on `/parameter_events`.
pub(super) fn update_parameters(node: &Node, parameter_values: &ParameterValues, settings: &Settings) {
    let now = [
        ("obs_noise", ParameterValue::Double(settings.obs_noise)),
        ("action_penalty", ParameterValue::Double(settings.action_penalty)),
        ("threshold", ParameterValue::Double(settings.threshold)),
        ("input", ParameterValue::String(settings.input.to_string())),
    ];
    debug_assert!(now.iter().map(|(n, _)| *n).eq(EVOLVING_PARAMETERS));
    let mut changed = Vec::new();
    {
        let mut values = parameter_values.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        for (name, value) in now {
            if let Some(slot) = values.iter_mut().find(|(n, _)| *n == name) {
                if slot.1 != value {
                    slot.1 = value.clone();
                    changed.push((name, value));
                }
            }
        }
    }
    for (name, value) in changed {
        if let Err(e) = node.set_parameter(name, value) {
            log("WARN", format!("cannot update parameter {name}: {e}"));
        }
    }
}
