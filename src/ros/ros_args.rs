//! `--ros-args` as rcl parses it, which ros2-client does not: remaps (`-r`, with `__ns` and
//! `__node`), parameters (`-p name:=value`), `--params-file`, and the logging flags (accepted and
//! ignored: this node logs to stderr). Anything else fails at start with the flag named, rather
//! than being silently dropped.

use std::path::PathBuf;

/// The parsed ROS arguments of one process.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RosArgs {
    /// `-r __ns:=/plant`.
    pub namespace: Option<String>,
    /// `-r __node:=name`.
    pub node_name: Option<String>,
    /// Topic and service remaps `from:=to`, in order (node-targeted rules already filtered).
    pub remaps: Vec<(String, String)>,
    /// `-p name:=value`, the value as YAML.
    pub params: Vec<(String, serde_yaml::Value)>,
    pub params_files: Vec<PathBuf>,
}

/// Flags that take a value we do not use (logging); accepted so launch files work unchanged.
const IGNORED_WITH_VALUE: &[&str] = &["--log-level", "--log-config-file", "--log-file-name"];
const IGNORED_FLAGS: &[&str] = &[
    "--enable-rosout-logs",
    "--disable-rosout-logs",
    "--enable-stdout-logs",
    "--disable-stdout-logs",
    "--enable-external-lib-logs",
    "--disable-external-lib-logs",
];

impl RosArgs {
    /// Parses the arguments between `--ros-args` and `--`. Rules addressed to another node
    /// (`other:from:=to`) are skipped; `default_node` is the name rules are matched against
    /// unless a `__node` remap renames it.
    pub fn parse(args: &[String], default_node: &str) -> Result<RosArgs, String> {
        let mut parsed = RosArgs::default();
        let mut rules: Vec<(Option<String>, String, String, bool)> = Vec::new(); // (node, from, to, is_param)
        let mut it = args.iter();
        while let Some(flag) = it.next() {
            let mut value =
                |what: &str| it.next().cloned().ok_or_else(|| format!("--ros-args: {flag} needs {what} after it"));
            match flag.as_str() {
                "-r" | "--remap" => {
                    let (node, from, to) = split_rule(&value("a rule from:=to")?, flag)?;
                    rules.push((node, from, to, false));
                }
                "-p" | "--param" => {
                    let (node, name, v) = split_rule(&value("a rule name:=value")?, flag)?;
                    rules.push((node, name, v, true));
                }
                "--params-file" => parsed.params_files.push(PathBuf::from(value("a file")?)),
                f if IGNORED_WITH_VALUE.contains(&f) => {
                    value("a value")?;
                }
                f if IGNORED_FLAGS.contains(&f) => {}
                other => {
                    return Err(format!(
                        "--ros-args: unknown argument '{other}': allowed -r/--remap from:=to, -p/--param name:=value, \
                         --params-file FILE, --log-level LEVEL and the --enable/--disable-*-logs flags"
                    ))
                }
            }
        }
        // `__node` decides which node-targeted rules are ours, so find it first.
        for (node, from, to, is_param) in &rules {
            if !is_param && from == "__node" && node.as_deref().is_none_or(|n| n == default_node) {
                parsed.node_name = Some(to.clone());
            }
        }
        let ours = parsed.node_name.clone().unwrap_or_else(|| default_node.to_string());
        for (node, from, to, is_param) in rules {
            if node.as_ref().is_some_and(|n| *n != ours && *n != default_node) {
                continue;
            }
            match (is_param, from.as_str()) {
                (true, _) => {
                    let v: serde_yaml::Value = serde_yaml::from_str(&to)
                        .map_err(|e| format!("--ros-args: value of -p {from}:={to} is not valid YAML: {e}"))?;
                    parsed.params.push((from, v));
                }
                (false, "__ns") => parsed.namespace = Some(to),
                (false, "__node") => {}
                (false, other) if other.starts_with("__") => {
                    return Err(format!("--ros-args: unsupported special remap '{other}': allowed __ns, __node"))
                }
                (false, _) => parsed.remaps.push((from, to)),
            }
        }
        Ok(parsed)
    }
}

/// Splits `[node:]left:=right`.
fn split_rule(rule: &str, flag: &str) -> Result<(Option<String>, String, String), String> {
    let (left, right) =
        rule.split_once(":=").ok_or_else(|| format!("--ros-args: {flag} '{rule}' is not of the form name:=value"))?;
    let (node, left) = match left.split_once(':') {
        Some((node, left)) => (Some(node.to_string()), left),
        None => (None, left),
    };
    if left.is_empty() {
        return Err(format!("--ros-args: {flag} '{rule}' has an empty name"));
    }
    Ok((node, left.to_string(), right.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn launch_ros_style_arguments() {
        let a = RosArgs::parse(
            &args(
                "-r __ns:=/plant -r __node:=sorter -p seed:=7 -p threshold:=0.8 --params-file f.yaml \
                   -r state:=status --log-level debug -r other:cmd/speed:=x -p sorter:lines:=2",
            ),
            "sorting_line",
        )
        .unwrap();
        assert_eq!(a.namespace.as_deref(), Some("/plant"));
        assert_eq!(a.node_name.as_deref(), Some("sorter"));
        assert_eq!(a.remaps, vec![("state".to_string(), "status".to_string())]);
        let names: Vec<&str> = a.params.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(names, ["seed", "threshold", "lines"]);
        assert_eq!(a.params[0].1, serde_yaml::Value::from(7));
        assert_eq!(a.params_files, vec![PathBuf::from("f.yaml")]);
    }

    #[test]
    fn unknown_and_malformed_arguments_are_named() {
        let e = RosArgs::parse(&args("--bogus"), "n").unwrap_err();
        assert!(e.contains("unknown argument '--bogus'"), "{e}");
        let e = RosArgs::parse(&args("-p seed"), "n").unwrap_err();
        assert!(e.contains("'seed' is not of the form name:=value"), "{e}");
        let e = RosArgs::parse(&args("-r"), "n").unwrap_err();
        assert!(e.contains("-r needs a rule"), "{e}");
        let e = RosArgs::parse(&args("-r __fancy:=1"), "n").unwrap_err();
        assert!(e.contains("unsupported special remap '__fancy'"), "{e}");
    }
}
