//! launch_scripts/sorting_line.yaml, the default parameter file that colcon installs in
//! share/sorting_line/ for users to copy, holds every parameter the node declares, each at the
//! node's own default: the file can neither drift from the node nor miss a parameter.

use std::path::Path;

use serde_yaml::Value;
use sorting_line::ros::names::Names;
use sorting_line::ros::options::NodeArgs;
use sorting_line::ros::params::NodeParams;
use sorting_line::ros::ros_args::RosArgs;

fn file() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts/sorting_line.yaml")
}

#[test]
fn the_default_parameter_file_gives_the_defaults() {
    let names = Names::new(&RosArgs { namespace: Some("/plant".into()), ..RosArgs::default() }).unwrap();
    let resolved = NodeParams::resolve(&NodeArgs::default(), &[], &[file()], &names).unwrap();
    assert_eq!(resolved, NodeParams::default());
}

#[test]
fn the_default_parameter_file_names_every_parameter() {
    let text = std::fs::read_to_string(file()).unwrap();
    let yaml: Value = serde_yaml::from_str(&text).unwrap();
    let params = yaml["/**"]["ros__parameters"].as_mapping().expect("a /**: ros__parameters: mapping");
    let mut in_file: Vec<&str> = params.keys().map(|k| k.as_str().unwrap()).collect();
    let mut declared: Vec<&str> = NodeParams::default().as_values().into_iter().map(|(name, _)| name).collect();
    in_file.sort_unstable();
    declared.sort_unstable();
    assert_eq!(in_file, declared);
}
