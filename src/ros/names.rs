//! Names in the ROS graph: the node's namespace and name, each line's namespace, and topic
//! names with remaps applied. Topics are always created with absolute names (ros2-client turns a
//! relative name in the root namespace into `rt//name`, which matches no ROS peer).

use super::ros_args::RosArgs;

/// The node's name as ROS sees it, and the remap rules that rename its topics.
#[derive(Clone, Debug, PartialEq)]
pub struct Names {
    /// Absolute namespace: "/" or "/plant".
    pub namespace: String,
    pub node_name: String,
    remaps: Vec<(String, String)>,
}

/// The default node name.
pub const NODE_NAME: &str = "sorting_line";

/// A name token as rcl validates it: letters, digits and `_`, not starting with a digit, and no
/// repeated `__` (reserved for ROS's own special names such as `__ns`).
fn valid_token(t: &str) -> bool {
    !t.is_empty()
        && !t.starts_with(|c: char| c.is_ascii_digit())
        && !t.contains("__")
        && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl Names {
    pub fn new(ros: &RosArgs) -> Result<Names, String> {
        let raw = ros.namespace.clone().unwrap_or_else(|| "/".into());
        let namespace = if raw.starts_with('/') { raw.clone() } else { format!("/{raw}") };
        let namespace = if namespace.len() > 1 { namespace.trim_end_matches('/').to_string() } else { namespace };
        if namespace != "/" && !namespace[1..].split('/').all(valid_token) {
            return Err(format!(
                "namespace '{raw}' is not valid: allowed '/' or /-separated tokens of letters, digits and single _"
            ));
        }
        let node_name = ros.node_name.clone().unwrap_or_else(|| NODE_NAME.into());
        if !valid_token(&node_name) {
            return Err(format!(
                "node name '{node_name}' is not valid: allowed letters, digits and single _, not starting with a digit"
            ));
        }
        Ok(Names { namespace, node_name, remaps: ros.remaps.clone() })
    }

    /// Where line `k` of `lines` lives: the node's namespace for one line, `<ns>/line_<k>` otherwise.
    pub fn line_namespace(&self, k: u32, lines: u32) -> String {
        if lines == 1 {
            self.namespace.clone()
        } else {
            join(&self.namespace, &format!("line_{k}"))
        }
    }

    /// The absolute name of `relative` in `line_ns`, after remaps. Remap rules are resolved
    /// against the node's namespace and matched on the full name, as rcl does.
    pub fn topic(&self, line_ns: &str, relative: &str) -> String {
        self.remapped(join(line_ns, relative))
    }

    /// The absolute name of `relative` in the node's private namespace (`~/relative`:
    /// `<namespace>/<node name>/relative`), after remaps.
    pub fn private(&self, relative: &str) -> String {
        self.remapped(join(&self.fully_qualified(), relative))
    }

    /// The node's fully qualified name, `<namespace>/<node name>`.
    pub fn fully_qualified(&self) -> String {
        join(&self.namespace, &self.node_name)
    }

    /// An absolute name such as "/clock", after remaps.
    pub fn global(&self, absolute: &str) -> String {
        self.remapped(absolute.to_string())
    }

    fn remapped(&self, name: String) -> String {
        for (from, to) in &self.remaps {
            if self.resolve(from) == name {
                return self.resolve(to);
            }
        }
        name
    }

    fn resolve(&self, name: &str) -> String {
        if let Some(private) = name.strip_prefix("~/") {
            join(&join(&self.namespace, &self.node_name), private)
        } else if name.starts_with('/') {
            name.to_string()
        } else {
            join(&self.namespace, name)
        }
    }
}

fn join(ns: &str, name: &str) -> String {
    if ns == "/" {
        format!("/{name}")
    } else {
        format!("{ns}/{name}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(ns: Option<&str>, remaps: &[(&str, &str)]) -> Names {
        let ros = RosArgs {
            namespace: ns.map(String::from),
            remaps: remaps.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect(),
            ..RosArgs::default()
        };
        Names::new(&ros).unwrap()
    }

    #[test]
    fn lines_and_topics() {
        let n = names(Some("/plant"), &[]);
        assert_eq!(n.line_namespace(0, 1), "/plant");
        assert_eq!(n.line_namespace(3, 4), "/plant/line_3");
        assert_eq!(n.topic("/plant/line_3", "cmd/speed"), "/plant/line_3/cmd/speed");
        let root = names(None, &[]);
        assert_eq!(root.topic(&root.line_namespace(0, 1), "state"), "/state");
        assert_eq!(names(Some("plant/"), &[]).namespace, "/plant");
    }

    #[test]
    fn remaps_match_resolved_names() {
        let n = names(Some("/plant"), &[("state", "status"), ("/clock", "/sim/clock"), ("line_1/input", "/raw")]);
        assert_eq!(n.topic("/plant", "state"), "/plant/status");
        assert_eq!(n.global("/clock"), "/sim/clock");
        assert_eq!(n.topic("/plant/line_1", "input"), "/raw");
        assert_eq!(n.topic("/plant/line_0", "input"), "/plant/line_0/input");
    }

    #[test]
    fn bad_namespaces_and_node_names_are_refused() {
        for bad in ["/pla nt", "/a__b", "/plant/line__x", "/1st"] {
            let ros = RosArgs { namespace: Some(bad.into()), ..RosArgs::default() };
            assert!(Names::new(&ros).unwrap_err().contains(&format!("namespace '{bad}' is not valid")), "{bad}");
        }
        for bad in ["a__b", "9lives", "sort-line"] {
            let ros = RosArgs { node_name: Some(bad.into()), ..RosArgs::default() };
            assert!(Names::new(&ros).unwrap_err().contains(&format!("node name '{bad}' is not valid")), "{bad}");
        }
        assert!(Names::new(&RosArgs { namespace: Some("/a_".into()), ..RosArgs::default() }).is_ok());
    }
}
