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
//! ([`lines::Line::fit_hardware`]); each point at which events apply is announced on
//! `events/evolution` before the state it concerns, and the parameters they change (line 0's) are
//! updated through `/parameter_events`.
//!
//! - here: [`run`], the node's set-up, and [`Graph`], what the node holds of the ROS graph.
//! - `server`: [`server::Server`], the node's state as fields and its loop, one method per kind of
//!   event.
//! - `endpoints`: creating publishers, subscriptions and servers, and the input streams that own them.
//! - `lines`: one hosted line: its endpoints and state, its hardware endpoints at upgrades, what it
//!   publishes per tick; `evolution`: its evolution announcements.
//! - `commands`: speed and sort-mode commands (per-line topics, `batch/cmd`) and resets (per line,
//!   `batch/reset`).
//! - `sim_services`: the simulation_interfaces services; `stepping`: StepSimulation jobs, the
//!   realtime tick, ResetSimulation and /clock; `action`: the SimulateSteps action.
//! - `parameters`: the declared parameters and their updates by the evolution schedule.
//! - `diagnostics`: what the node publishes on /diagnostics.

mod action;
mod commands;
mod diagnostics;
mod endpoints;
mod evolution;
mod lines;
mod parameters;
mod server;
mod sim_services;
mod stepping;

use std::rc::Rc;

use async_signal::{Signal, Signals};
use futures::stream::{LocalBoxStream, SelectAll};
use ros2_client::action::{CancelHandle, NewGoalHandle};
use ros2_client::{Context, Message, MessageInfo, Node, NodeName, Publisher, RmwRequestId, Server as ServiceServer};
use serde::Serialize;

use super::discovery::Discovery;
use super::messages::{Clock, DiagnosticArray, LineCommands, LineStates, ResetLineRequest, ResetLinesRequest};
use super::messages::{ResetLinesResponse, Time};
use super::names::{Names, NODE_NAME};
use super::options::{NodeArgs, TickMode};
use super::params::NodeParams;
use super::protocol::{Client, Command};
use super::ros_args::RosArgs;
use super::simulation_interfaces::SimulateStepsGoal;
use action::SimulateStepsServer;
use lines::Line;
use parameters::{node_options, ParameterValues};
use server::Server;
use sim_services::{SimRequest, SimulationServers};

fn log(level: &str, message: impl AsRef<str>) {
    eprintln!("[{level}] [{NODE_NAME}]: {}", message.as_ref());
}

/// Runs the node until SIGINT or SIGTERM.
pub fn run(args: NodeArgs, ros_args: Vec<String>) -> Result<(), String> {
    let ros = RosArgs::parse(&ros_args, NODE_NAME)?;
    let names = Names::new(&ros)?;
    let params = NodeParams::resolve(&args, &ros.params, &ros.params_files, &names)?;
    let discovery = Discovery::from_env()?;
    for warning in &discovery.warnings {
        log("WARN", warning);
    }
    // Before any DDS thread exists, so a signal during start-up is ours to handle.
    let signals = Signals::new([Signal::Int, Signal::Term]).map_err(|e| format!("cannot catch signals: {e}"))?;

    // Whatever the environment asks, as any rcl node would: keeping a test on this machine is
    // the test's business (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, network namespaces).
    let participant = discovery.participant()?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| format!("cannot create the ROS context: {e:?}"))?;
    let node_name = NodeName::new(&names.namespace, &names.node_name).map_err(|e| format!("bad node name: {e:?}"))?;
    let (options, parameter_values) = node_options(&params);
    let node = context.new_node(node_name, options).map_err(|e| format!("cannot create the node: {e:?}"))?;
    let mut server = Server::new(node, &names, &params, parameter_values, signals)?;
    let spinner = server.spinner()?;

    log("INFO", started_message(&names, &discovery, &params));
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

/// Everything from DDS that can wake the node.
enum Event {
    Batch(Result<(LineCommands, MessageInfo), String>),
    BatchReset(Result<(RmwRequestId, ResetLinesRequest), String>),
    /// A command on line k's own topic (named), with its sender and stamp.
    Command(usize, &'static str, Result<(Client, Time, Command), String>),
    Reset(usize, Result<(RmwRequestId, ResetLineRequest), String>),
    /// A simulation_interfaces request.
    Sim(Result<(RmwRequestId, SimRequest), String>),
    /// A new SimulateSteps goal, or a request to cancel goals.
    Goal(Result<NewGoalHandle<SimulateStepsGoal>, String>),
    Cancel(Result<CancelHandle, String>),
}

/// The node's inputs, one stream per endpoint, each holding its endpoint.
type Events = SelectAll<LocalBoxStream<'static, Event>>;

/// What the node holds of the ROS graph: every input stream, the node-wide endpoints, and the ROS
/// node they live on. `batch/cmd` and `batch/state` (in the node's namespace) carry every line at
/// once: a vectorised client exchanges two messages per round trip instead of two per line, which
/// is what lets one rclpy process drive many lines.
struct Graph {
    /// Every input the node waits on; endpoints created while serving (the line's hardware,
    /// [`Line::fit_hardware`]) join it at once.
    events: Events,
    clock_pub: Publisher<Clock>,
    diagnostics_pub: Publisher<DiagnosticArray>,
    batch_state: Publisher<LineStates>,
    batch_reset: Rc<ServiceServer<ResetLinesRequest, ResetLinesResponse>>,
    sim: SimulationServers,
    simulate_steps: Rc<SimulateStepsServer>,
    parameter_values: ParameterValues,
    /// Last: the endpoints above are dropped before the node.
    node: Node,
}

impl Graph {
    /// Publishes the message `build` makes if the publisher has a matched reader; returns whether
    /// it did. Topics nobody reads are skipped: a node hosting 16 lines for a vectorised client
    /// (which reads `batch/state` only) would otherwise build, serialise and queue 64 unread
    /// per-line messages per round trip, most of the node's time per tick
    /// (benches/bridge_throughput.py). Nothing is lost that a volatile reader could have had:
    /// samples written before a reader matches never reach it anyway, and the node's count
    /// follows the DDS writer's own matching (the spinner records each match the writer reports).
    fn offer<M>(&self, publisher: &Publisher<M>, topic: &dyn Fn() -> String, build: impl FnOnce() -> M) -> bool
    where
        M: Message + Serialize + std::fmt::Debug,
    {
        if publisher.get_subscription_count(&self.node) == 0 {
            return false;
        }
        if let Err(e) = publisher.publish(build()) {
            log("WARN", format!("cannot publish {}: {e:?}", topic()));
        }
        true
    }

    /// `batch/state`, when a vectorised client reads it (per-line clients and realtime lines
    /// without one would otherwise get every line's state built and sent each tick for nothing).
    fn publish_batch_state(&self, lines: &[Line]) {
        self.offer(&self.batch_state, &|| "batch/state".to_string(), || batch_states(lines));
    }
}

/// Every line's current state, as arrays.
fn batch_states(lines: &[Line]) -> LineStates {
    LineStates::of(lines.iter().map(|line| &line.host))
}
