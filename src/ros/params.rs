//! The node's parameters: one validated set, filled in order from the defaults, `--params-file`
//! (ours, then those in `--ros-args`), `--ros-args -p`, and finally explicit command-line flags.
//! Every value goes through one setter, so a wrong type or an out-of-range value fails at start
//! with the parameter, the value, where it came from and what is allowed.
//!
//! `setup` (A..D) is a preset, not a value of its own: it is applied first, from whichever source
//! gives it with the highest precedence, and `input`, `obs_noise` and `action_penalty` given
//! explicitly anywhere override it. So `--setup B --obs-noise 0.1` and a file with `setup: B`
//! plus `-p obs_noise:=0.1` mean the same line.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::Path;

use serde_yaml::Value;

use super::names::Names;
use super::options::{NodeArgs, TickMode};
use crate::sim::config::{
    ACTION_PENALTY_ALLOWED, MAX_NODE_LINES, MAX_STEPS_ALLOWED, NODE_LINES_ALLOWED, OBS_NOISE_ALLOWED, THRESHOLD_ALLOWED,
};
use crate::sim::evolution::Schedule;
use crate::sim::{LineConfig, Setup};

/// Everything the node needs to know before it starts.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeParams {
    /// The paper's setup the line started from, if one was named (see the module's doc).
    pub setup: Option<Setup>,
    pub line: LineConfig,
    /// Seed of line 0; line k uses seed + k.
    pub seed: u64,
    pub mode: TickMode,
    /// Ticks per second of wall time (realtime mode).
    pub rate: f64,
    pub lines: u32,
    /// Simulated seconds per tick.
    pub tick_period: f64,
    /// The evolution schedule's file as given ("" for none) and the schedule read from it.
    pub evolution_file: String,
    pub evolution: Schedule,
    /// Where the Foxglove live view listens, if it is on (`foxglove`).
    pub foxglove: Option<SocketAddr>,
}

impl Default for NodeParams {
    fn default() -> Self {
        NodeParams {
            setup: None,
            line: LineConfig::default(),
            seed: 42,
            mode: TickMode::Lockstep,
            rate: 10.0,
            lines: 1,
            tick_period: 1.0,
            evolution_file: String::new(),
            evolution: Schedule::default(),
            foxglove: None,
        }
    }
}

/// Highest realtime rate, ticks per second (the lower bound, 0, is open).
pub const MAX_RATE: f64 = 100_000.0;

/// Simulated seconds per tick, inclusive bounds.
pub const TICK_PERIOD_RANGE: (f64, f64) = (1e-6, 3600.0);

/// Highest seed: a ROS integer parameter is an int64.
pub const MAX_SEED: u64 = i64::MAX as u64;

/// Every parameter the node declares, with what it accepts.
pub const PARAMETERS: &[(&str, &str)] = &[
    ("variant", "basic or advanced"),
    ("input", "random, seasonal or seasonal3"),
    ("obs_noise", OBS_NOISE_ALLOWED),
    ("action_penalty", ACTION_PENALTY_ALLOWED),
    ("threshold", THRESHOLD_ALLOWED),
    ("max_steps", MAX_STEPS_ALLOWED),
    ("seed", "0 ..= 9223372036854775807 (a ROS integer parameter is 64-bit signed; seed + k for k < lines included)"),
    ("mode", "lockstep or realtime"),
    ("rate", "0.0 <.. 100000.0 (ticks per second)"),
    ("lines", NODE_LINES_ALLOWED),
    ("tick_period", "0.000001 ..= 3600.0 (seconds)"),
    ("setup", "A, B, C or D, or empty for none (sets input, obs_noise and action_penalty; those given explicitly override it)"),
    ("use_sim_time", "true or false (ignored: this node is the clock)"),
    ("evolution_file", "a readable evolution schedule (YAML, see src/sim/evolution.rs), or empty for none"),
    ("foxglove", FOXGLOVE_ALLOWED),
];

/// What the `foxglove` parameter accepts.
pub const FOXGLOVE_ALLOWED: &str = "empty for off, or [ADDR:]PORT: PORT 0 ..= 65535 (0: any free port, logged), \
     ADDR an IP address of this host or localhost (default 127.0.0.1; 0.0.0.0 or [::] for every interface)";

/// The address the Foxglove live view listens on, from `[ADDR:]PORT` (see [`FOXGLOVE_ALLOWED`]);
/// `None` for "" (off); the error says what is allowed. Whether ADDR belongs to this host shows
/// when the node binds it.
pub fn listen_address(text: &str) -> Result<Option<SocketAddr>, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    let invalid = || format!("is not valid: allowed {FOXGLOVE_ALLOWED}");
    let port = |p: &str| p.parse::<u16>().map_err(|_| invalid());
    if text.bytes().all(|b| b.is_ascii_digit()) {
        return Ok(Some(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port(text)?)));
    }
    if let Some(p) = text.strip_prefix("localhost:") {
        return Ok(Some(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port(p)?)));
    }
    text.parse::<SocketAddr>().map(Some).map_err(|_| invalid())
}

fn allowed(name: &str) -> &'static str {
    PARAMETERS.iter().find(|(n, _)| *n == name).map(|(_, a)| *a).unwrap_or("")
}

impl NodeParams {
    /// Resolves the parameters from every source, in precedence order.
    pub fn resolve(
        args: &NodeArgs,
        ros_params: &[(String, Value)],
        ros_files: &[impl AsRef<Path>],
        names: &Names,
    ) -> Result<Self, String> {
        // (name, value, source), lowest precedence first.
        let mut given: Vec<(String, Value, String)> = Vec::new();
        for file in args.params_file.iter().map(|f| f.as_path()).chain(ros_files.iter().map(|f| f.as_ref())) {
            let source = format!("params file {}", file.display());
            given.extend(load_params_file(file, names)?.into_iter().map(|(n, v)| (n, v, source.clone())));
        }
        given.extend(ros_params.iter().map(|(n, v)| (n.clone(), v.clone(), "--ros-args -p".to_string())));
        given.extend(explicit_flags(args).into_iter().map(|(n, v)| (n.to_string(), v, flag_of(n))));
        // The preset first, so that every explicit value overrides it whatever its source.
        let (presets, values): (Vec<_>, Vec<_>) = given.iter().partition(|(name, _, _)| name == "setup");
        let mut p = NodeParams::default();
        for (name, value, source) in presets.into_iter().chain(values) {
            p.set(name, value, source)?;
        }
        p.validate()?;
        Ok(p)
    }

    /// Sets one parameter from a YAML value.
    pub fn set(&mut self, name: &str, value: &Value, source: &str) -> Result<(), String> {
        let bad =
            || format!("parameter {name} = {} (from {source}) is not valid: allowed {}", show(value), allowed(name));
        let float = || value.as_f64().filter(|v| v.is_finite()).ok_or_else(bad);
        let text = || value.as_str().ok_or_else(bad);
        match name {
            // Empty names no setup, as the node declares it then: a `ros2 param dump` reads back.
            "setup" if text()?.is_empty() => {}
            "setup" => {
                let setup: Setup = text()?.parse().map_err(|_| bad())?;
                let preset = LineConfig::for_setup(setup, self.line.variant);
                self.line = LineConfig {
                    input: preset.input,
                    obs_noise: preset.obs_noise,
                    action_penalty: preset.action_penalty,
                    ..self.line.clone()
                };
                self.setup = Some(setup);
            }
            "variant" => self.line.variant = text()?.parse().map_err(|_| bad())?,
            "input" => self.line.input = text()?.parse().map_err(|_| bad())?,
            "obs_noise" => self.line.obs_noise = float()?,
            "action_penalty" => self.line.action_penalty = float()?,
            "threshold" => self.line.threshold = float()?,
            "max_steps" => self.line.max_steps = value.as_u64().and_then(|v| u32::try_from(v).ok()).ok_or_else(bad)?,
            "seed" => self.seed = value.as_u64().ok_or_else(bad)?,
            "mode" => {
                self.mode = match text()? {
                    "lockstep" => TickMode::Lockstep,
                    "realtime" => TickMode::Realtime,
                    _ => return Err(bad()),
                }
            }
            "rate" => self.rate = float()?,
            "lines" => self.lines = value.as_u64().and_then(|v| u32::try_from(v).ok()).ok_or_else(bad)?,
            "tick_period" => self.tick_period = float()?,
            "evolution_file" => {
                let file = text()?;
                self.evolution =
                    load_schedule(file).map_err(|e| format!("parameter {name} = {file} (from {source}): {e}"))?;
                self.evolution_file = file.to_string();
            }
            "foxglove" => {
                // A port alone reads as a YAML integer (`-p foxglove:=8765`).
                let given = match value {
                    Value::Number(n) => n.to_string(),
                    _ => text()?.to_string(),
                };
                self.foxglove =
                    listen_address(&given).map_err(|e| format!("parameter {name} = {given} (from {source}) {e}"))?;
            }
            "use_sim_time" => {
                value.as_bool().ok_or_else(bad)?;
            }
            _ => {
                let known: Vec<&str> = PARAMETERS.iter().map(|(n, _)| *n).collect();
                return Err(format!("unknown parameter '{name}' (from {source}): allowed {}", known.join(", ")));
            }
        }
        // Range errors name the source at once, not at the end.
        self.validate().map_err(|e| format!("{e} (from {source})"))
    }

    /// Checks every range; the message names the parameter, its value and what is allowed.
    pub fn validate(&self) -> Result<(), String> {
        self.line.validate().map_err(|e| format!("parameter {e}"))?;
        let out_of_range = |name: &str, value: String| {
            Err(format!("parameter {name} = {value} is out of range: allowed {}", allowed(name)))
        };
        if !(self.rate > 0.0 && self.rate <= MAX_RATE) {
            return out_of_range("rate", self.rate.to_string());
        }
        if !(1..=MAX_NODE_LINES).contains(&self.lines) {
            return out_of_range("lines", self.lines.to_string());
        }
        if !(self.tick_period >= TICK_PERIOD_RANGE.0 && self.tick_period <= TICK_PERIOD_RANGE.1) {
            return out_of_range("tick_period", self.tick_period.to_string());
        }
        // The seed is declared as a ROS parameter, an int64: a larger one would read back negative.
        match self.seed.checked_add(u64::from(self.lines - 1)) {
            Some(last) if last <= MAX_SEED => {}
            _ if self.lines > 1 => {
                return out_of_range(
                    "seed",
                    format!("{} (with {} lines, up to seed + {})", self.seed, self.lines, self.lines - 1),
                )
            }
            _ => return out_of_range("seed", self.seed.to_string()),
        }
        Ok(())
    }

    /// The parameters as (name, YAML value), for declaring them on the node.
    pub fn as_values(&self) -> Vec<(&'static str, Value)> {
        let l = &self.line;
        vec![
            // Empty when no setup was named; the three values it set are declared on their own.
            ("setup", Value::from(self.setup.map(|s| s.to_string()).unwrap_or_default())),
            ("variant", Value::from(l.variant.to_string())),
            ("input", Value::from(l.input.to_string())),
            ("obs_noise", Value::from(l.obs_noise)),
            ("action_penalty", Value::from(l.action_penalty)),
            ("threshold", Value::from(l.threshold)),
            ("max_steps", Value::from(l.max_steps)),
            ("seed", Value::from(self.seed)),
            ("mode", Value::from(if self.mode == TickMode::Lockstep { "lockstep" } else { "realtime" })),
            ("rate", Value::from(self.rate)),
            ("lines", Value::from(self.lines)),
            ("tick_period", Value::from(self.tick_period)),
            ("evolution_file", Value::from(self.evolution_file.clone())),
            ("foxglove", Value::from(self.foxglove.map(|a| a.to_string()).unwrap_or_default())),
        ]
    }
}

fn show(value: &Value) -> String {
    serde_yaml::to_string(value).map(|s| s.trim().to_string()).unwrap_or_else(|_| format!("{value:?}"))
}

/// The flags given on the command line, as parameter values.
fn explicit_flags(a: &NodeArgs) -> Vec<(&'static str, Value)> {
    let mut v = Vec::new();
    let mut push = |name, value: Option<Value>| {
        if let Some(value) = value {
            v.push((name, value));
        }
    };
    push("setup", a.setup.map(|x| Value::from(x.to_string())));
    push("variant", a.variant.map(|x| Value::from(x.to_string())));
    push("input", a.input.map(|x| Value::from(x.to_string())));
    push("obs_noise", a.obs_noise.map(Value::from));
    push("action_penalty", a.action_penalty.map(Value::from));
    push("threshold", a.threshold.map(Value::from));
    push("max_steps", a.max_steps.map(Value::from));
    push("seed", a.seed.map(Value::from));
    push("mode", a.mode.map(|m| Value::from(if m == TickMode::Lockstep { "lockstep" } else { "realtime" })));
    push("rate", a.rate.map(Value::from));
    push("lines", a.lines.map(Value::from));
    push("tick_period", a.tick_period.map(Value::from));
    push("evolution_file", a.evolution.as_ref().map(|p| Value::from(p.display().to_string())));
    push("foxglove", a.foxglove.clone().map(Value::from));
    v
}

/// The command-line flag of a parameter.
fn flag_of(name: &str) -> String {
    match name {
        "evolution_file" => "--evolution".to_string(),
        _ => format!("--{}", name.replace('_', "-")),
    }
}

/// Reads and validates an evolution schedule file; "" is the empty schedule. The validation is
/// the library's, so the error names the event, the field, the value and the allowed range.
fn load_schedule(file: &str) -> Result<Schedule, String> {
    if file.is_empty() {
        return Ok(Schedule::default());
    }
    let text = std::fs::read_to_string(file).map_err(|e| format!("cannot read it: {e}"))?;
    Schedule::from_yaml(&text)
}

/// Reads a parameter file: either a flat mapping of parameters, or the launch_ros form
/// `<node key>: {ros__parameters: {...}}` where the node key is `/**`, the node's name or its
/// fully qualified name (sections for other nodes are skipped).
pub fn load_params_file(path: &Path, names: &Names) -> Result<Vec<(String, Value)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read params file {}: {e}", path.display()))?;
    let doc: Value =
        serde_yaml::from_str(&text).map_err(|e| format!("params file {} is not valid YAML: {e}", path.display()))?;
    let Some(top) = doc.as_mapping() else {
        return Err(format!("params file {} must be a mapping of parameters", path.display()));
    };
    let launch_form = top.values().any(|v| v.get("ros__parameters").is_some());
    let mut out = Vec::new();
    let flatten = |out: &mut Vec<(String, Value)>, map: &serde_yaml::Mapping| -> Result<(), String> {
        for (k, v) in map {
            let key = k.as_str().ok_or_else(|| format!("params file {}: key {k:?} is not a string", path.display()))?;
            out.push((key.to_string(), v.clone()));
        }
        Ok(())
    };
    if !launch_form {
        flatten(&mut out, top)?;
        return Ok(out);
    }
    let fqn = if names.namespace == "/" {
        format!("/{}", names.node_name)
    } else {
        format!("{}/{}", names.namespace, names.node_name)
    };
    let ours = ["/**", "**", names.node_name.as_str(), fqn.as_str(), fqn.trim_start_matches('/')];
    for (key, section) in top {
        let key = key.as_str().unwrap_or_default();
        if !ours.contains(&key) {
            continue;
        }
        let params = section
            .get("ros__parameters")
            .and_then(Value::as_mapping)
            .ok_or_else(|| format!("params file {}: section '{key}' has no ros__parameters mapping", path.display()))?;
        flatten(&mut out, params)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::ros_args::RosArgs;
    use crate::sim::Variant;

    fn names(ns: &str) -> Names {
        Names::new(&RosArgs { namespace: Some(ns.into()), ..RosArgs::default() }).unwrap()
    }

    fn write(text: &str) -> tempfile::TempPath {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut f, text.as_bytes()).unwrap();
        f.into_temp_path()
    }

    #[test]
    fn precedence_is_file_then_ros_p_then_flags() {
        let f = write("/**:\n  ros__parameters:\n    seed: 1\n    threshold: 0.8\n    lines: 3\n");
        let ros = vec![("seed".to_string(), Value::from(2))];
        let args = NodeArgs { lines: Some(4), ..NodeArgs::default() };
        let p = NodeParams::resolve(&args, &ros, &[&f], &names("/plant")).unwrap();
        assert_eq!((p.seed, p.line.threshold, p.lines), (2, 0.8, 4));
    }

    #[test]
    fn launch_form_takes_only_our_sections() {
        let f = write(
            "/plant/sorting_line:\n  ros__parameters:\n    variant: advanced\nother_node:\n  ros__parameters:\n    variant: nonsense\n",
        );
        let p = NodeParams::resolve(&NodeArgs::default(), &[], &[&f], &names("/plant")).unwrap();
        assert_eq!(p.line.variant, Variant::Advanced);
    }

    #[test]
    fn errors_name_parameter_value_source_and_range() {
        let f = write("threshold: 1.5\n");
        let e = NodeParams::resolve(&NodeArgs::default(), &[], &[&f], &names("/")).unwrap_err();
        assert!(e.contains("threshold = 1.5 is out of range: allowed 0.0 ..< 1.0"), "{e}");
        assert!(e.contains("params file"), "{e}");
        let e =
            NodeParams::resolve(&NodeArgs { lines: Some(0), ..NodeArgs::default() }, &[], &[] as &[&Path], &names("/"))
                .unwrap_err();
        assert!(e.contains("lines = 0 is out of range: allowed 1 ..= 64"), "{e}");
        let bad_type = vec![("max_steps".to_string(), Value::from("many"))];
        let e = NodeParams::resolve(&NodeArgs::default(), &bad_type, &[] as &[&Path], &names("/")).unwrap_err();
        assert!(e.contains("max_steps = many (from --ros-args -p) is not valid: allowed 1 ..= 1000000"), "{e}");
        let unknown = vec![("speed".to_string(), Value::from(1))];
        let e = NodeParams::resolve(&NodeArgs::default(), &unknown, &[] as &[&Path], &names("/")).unwrap_err();
        assert!(e.contains("unknown parameter 'speed'"), "{e}");
        let f = write("a: [unclosed\n");
        let e = NodeParams::resolve(&NodeArgs::default(), &[], &[&f], &names("/")).unwrap_err();
        assert!(e.contains("is not valid YAML"), "{e}");
        let e =
            NodeParams::resolve(&NodeArgs::default(), &[], &[Path::new("/nonexistent.yaml")], &names("/")).unwrap_err();
        assert!(e.contains("cannot read params file /nonexistent.yaml"), "{e}");
    }

    #[test]
    fn a_setup_is_the_papers_and_explicit_values_override_it_from_any_source() {
        use crate::sim::InputKind;
        let none = &[] as &[&Path];
        let flags = |setup, obs_noise| NodeArgs { setup, obs_noise, ..NodeArgs::default() };
        let d = NodeParams::resolve(&flags(Some(Setup::D), None), &[], none, &names("/")).unwrap();
        assert_eq!(d.line, LineConfig::for_setup(Setup::D, Variant::Basic));
        assert_eq!(d.setup, Some(Setup::D));
        assert!(d.as_values().contains(&("setup", Value::from("D"))));
        // A flag overrides the setup, and so does a value of lower precedence than the setup's own.
        let p = NodeParams::resolve(&flags(Some(Setup::D), Some(0.1)), &[], none, &names("/")).unwrap();
        assert_eq!((p.line.input, p.line.obs_noise, p.line.action_penalty), (InputKind::Seasonal, 0.1, 0.5));
        let f = write("obs_noise: 0.2\nvariant: advanced\n");
        let p = NodeParams::resolve(&flags(Some(Setup::B), None), &[], &[&f], &names("/")).unwrap();
        assert_eq!((p.line.input, p.line.obs_noise, p.line.variant), (InputKind::Seasonal, 0.2, Variant::Advanced));
        // As a parameter: the highest-precedence setup is the preset.
        let f = write("setup: C\n");
        let ros = vec![("setup".to_string(), Value::from("B")), ("input".to_string(), Value::from("random"))];
        let p = NodeParams::resolve(&NodeArgs::default(), &ros, &[&f], &names("/")).unwrap();
        assert_eq!(
            (p.setup, p.line.input, p.line.obs_noise, p.line.action_penalty),
            (Some(Setup::B), InputKind::Random, 0.0, 0.5)
        );
        // None named: the defaults, declared as an empty setup.
        let p = NodeParams::resolve(&NodeArgs::default(), &[], none, &names("/")).unwrap();
        assert_eq!((p.setup, &p.line), (None, &LineConfig::default()));
        assert!(p.as_values().contains(&("setup", Value::from(""))));
        let bad = vec![("setup".to_string(), Value::from("E"))];
        let e = NodeParams::resolve(&NodeArgs::default(), &bad, none, &names("/")).unwrap_err();
        assert!(e.contains("parameter setup = E (from --ros-args -p) is not valid: allowed A, B, C or D"), "{e}");
    }

    #[test]
    fn the_foxglove_address_is_a_port_or_an_address_and_port() {
        let resolve = |ros: Vec<(String, Value)>, flag: Option<&str>| {
            let args = NodeArgs { foxglove: flag.map(String::from), ..NodeArgs::default() };
            NodeParams::resolve(&args, &ros, &[] as &[&Path], &names("/")).map(|p| p.foxglove.map(|a| a.to_string()))
        };
        assert_eq!(resolve(vec![], None).unwrap(), None);
        assert_eq!(resolve(vec![], Some("8765")).unwrap().as_deref(), Some("127.0.0.1:8765"));
        assert_eq!(resolve(vec![], Some("0.0.0.0:0")).unwrap().as_deref(), Some("0.0.0.0:0"));
        assert_eq!(resolve(vec![], Some("[::1]:9")).unwrap().as_deref(), Some("[::1]:9"));
        assert_eq!(resolve(vec![], Some("localhost:9")).unwrap().as_deref(), Some("127.0.0.1:9"));
        let as_int = vec![("foxglove".to_string(), Value::from(8765))];
        assert_eq!(resolve(as_int, None).unwrap().as_deref(), Some("127.0.0.1:8765"));
        let off = vec![("foxglove".to_string(), Value::from(""))];
        assert_eq!(resolve(off, None).unwrap(), None);
        for bad in ["65536", "-1", "host.example:80", "127.0.0.1", "1.2.3.4:99999", "::1:80"] {
            let e = resolve(vec![], Some(bad)).unwrap_err();
            assert!(
                e.contains(&format!("parameter foxglove = {bad} (from --foxglove) is not valid: allowed empty")),
                "{e}"
            );
        }
    }

    #[test]
    fn seeds_stay_within_a_ros_integer_parameter() {
        let resolve = |seed: u64, lines: u32| {
            let args = NodeArgs { seed: Some(seed), lines: Some(lines), ..NodeArgs::default() };
            NodeParams::resolve(&args, &[], &[] as &[&Path], &names("/"))
        };
        let max = i64::MAX as u64;
        assert_eq!(resolve(max, 1).unwrap().seed, max);
        assert_eq!(resolve(max - 3, 4).unwrap().seed, max - 3);
        let e = resolve(max + 1, 1).unwrap_err();
        assert!(e.contains("seed = 9223372036854775808 is out of range: allowed 0 ..= 9223372036854775807"), "{e}");
        let e = resolve(max - 2, 4).unwrap_err();
        assert!(e.contains("(with 4 lines, up to seed + 3)"), "{e}");
    }
}
