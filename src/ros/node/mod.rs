//! The running node: one DDS participant (set up from ROS 2's discovery variables), one ROS node, and
//! for each hosted line its publishers, subscriptions and `reset` service, plus the standard
//! simulator-control services and action (simulation_interfaces, rules in `ros::simulation`) in the
//! node's private namespace. A single async task waits on all inputs at once (commands, service
//! requests, the realtime timer, a StepSimulation in progress, the diagnostics timer,
//! SIGINT/SIGTERM), so an idle node in lock-step uses no CPU.
//!
//! The line's hardware shows in the graph: `sensors/ratio` is published while the line has its
//! ratio sensor, `cmd/sort_mode` subscribed while its machine has sort modes. On an evolving line
//! (`--evolution FILE`) they appear and go with the upgrades of its schedule
//! (`lines::Line::fit_hardware`); each point at which events apply is announced on
//! `events/evolution` before the state it concerns, and the parameters they change (line 0's) are
//! updated through `/parameter_events`.
//!
//! The node is a `server::Server` composed of owned parts, each with its state, endpoints and
//! methods in its own module; the server only waits and dispatches. From the parts down to what
//! they share (each module uses only those after it in this list; tests/layers.rs fails on any
//! circle among them):
//!
//! - here: [`run`], the node's set-up.
//! - `server`: the node's loop: what woke it, and which part handles it.
//! - `stepping`: StepSimulation jobs and SimulateSteps goals, one step per turn of the loop;
//!   `action`: the SimulateSteps action's server, feedback and results.
//! - `control`: the simulation_interfaces state, the realtime timer, and what each request does;
//!   `sim_services`: those services' servers, requests decoded and answers sent.
//! - `diagnostics`: what the node publishes on /diagnostics.
//! - `line_set`: every line with the batch topics and /clock: commands and resets (per line and
//!   batched), every line's tick, ResetSimulation.
//! - `lines`: one hosted line: its endpoints and state, the commands it takes, its hardware
//!   endpoints at upgrades, what it publishes per tick; `evolution`: its evolution announcements.
//! - `line_messages`: what a hosted line's tick looks like in each message (the wire types in
//!   `ros::messages` are plain mirrors of the .msg files).
//! - `graph`: what the parts share of the ROS graph: the ROS node, the inputs the node waits on,
//!   publishing only to topics with a reader; `parameters`: the declared parameters and their
//!   updates by the evolution schedule.
//! - `events`: everything that can wake the node, as one type; `endpoints`: creating publishers,
//!   subscriptions and servers, and the input streams that own them.
//! - `live_view`: the Foxglove live view (with the `foxglove` feature; a stand-in without it), which
//!   the graph, the lines and the events hand to; `scene`: a line drawn as a 3D scene for it (it
//!   uses `parameters`' shared values, nothing else of the parts).
//! - `log`: the node's log lines.

mod action;
mod control;
mod diagnostics;
mod endpoints;
mod events;
mod evolution;
mod graph;
mod line_messages;
mod line_set;
mod lines;
// Without the `foxglove` cargo feature, a stand-in that refuses `--foxglove` at start.
#[cfg_attr(not(feature = "foxglove"), path = "live_view_off.rs")]
mod live_view;
mod log;
mod parameters;
#[cfg(feature = "foxglove")]
mod scene;
mod server;
mod sim_services;
mod stepping;

use async_signal::{Signal, Signals};
use ros2_client::{Context, NodeName};

use crate::ros::discovery::Discovery;
use crate::ros::names::{Names, NODE_NAME};
use crate::ros::options::{NodeArgs, TickMode};
use crate::ros::params::NodeParams;
use crate::ros::ros_args::RosArgs;
use crate::ros::topics;
use live_view::LiveView;
use log::{install_records, log};
use parameters::node_options;
use server::Server;

/// Runs the node until SIGINT or SIGTERM.
pub fn run(args: NodeArgs, ros_args: Vec<String>) -> Result<(), String> {
    let ros = RosArgs::parse(&ros_args, NODE_NAME)?;
    let names = Names::new(&ros)?;
    let params = NodeParams::resolve(&args, &ros.params, &ros.params_files, &names)?;
    install_records(params.foxglove.is_some());
    let discovery = Discovery::from_env()?;
    for warning in &discovery.warnings {
        log("WARN", warning);
    }
    // Before any DDS thread exists, so a signal during start-up is ours to handle.
    let signals = Signals::new([Signal::Int, Signal::Term]).map_err(|e| format!("cannot catch signals: {e}"))?;
    let (options, parameter_values) = node_options(&params);
    // Before DDS too: a port in use (or an address not of this host) fails the start at once.
    let live = match params.foxglove {
        Some(address) => {
            let resets: Vec<String> = (0..params.lines)
                .map(|k| names.topic(&names.line_namespace(k, params.lines), topics::RESET.name))
                .collect();
            Some(LiveView::start(address, &names.node_name, parameter_values.clone(), &resets)?)
        }
        None => None,
    };
    let live_address = live.as_ref().map(|(live, _)| live.address());

    // Whatever the environment asks, as any rcl node would: keeping a test on this machine is
    // the test's business (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, network namespaces).
    let participant = discovery.participant()?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| format!("cannot create the ROS context: {e:?}"))?;
    let node_name = NodeName::new(&names.namespace, &names.node_name).map_err(|e| format!("bad node name: {e:?}"))?;
    let node = context.new_node(node_name, options).map_err(|e| format!("cannot create the node: {e:?}"))?;
    let mut server = Server::new(node, &names, &params, parameter_values, (signals, live))?;
    let spinner = server.spinner()?;

    log("INFO", started_message(&names, &discovery, &params));
    if let Some(address) = live_address {
        // Tests and launch files read the port from this line (port 0: the one the system chose).
        log("INFO", format!("foxglove live view on ws://{address}"));
    }
    let spin = async move {
        if let Err(e) = spinner.spin().await {
            log("ERROR", format!("node spinner stopped: {e:?}"));
        }
    };
    smol::block_on(smol::future::or(server.serve(), spin));
    // Drop order matters: entities, then the node (the last field of the server's graph), then the
    // context (the participant announces its departure, so peers see the node leave at once).
    drop(server);
    drop(context);
    log("INFO", "shut down cleanly");
    Ok(())
}

fn started_message(names: &Names, discovery: &Discovery, params: &NodeParams) -> String {
    format!(
        "{}/{} up on {}: {} {} line(s), {} input, {:?}, seed {}{}{}",
        names.namespace.trim_end_matches('/'),
        names.node_name,
        discovery.summary(),
        params.lines,
        params.line.variant,
        params.line.input,
        params.mode,
        params.seed,
        if params.mode == TickMode::Realtime { format!(", {} Hz", params.rate) } else { String::new() },
        if params.evolution.is_empty() {
            String::new()
        } else {
            format!(", evolving by {} ({} events)", params.evolution_file, params.evolution.events.len())
        }
    )
}
