//! The running node: one DDS participant (set up from ROS 2's discovery variables), one ROS node, and
//! for each hosted line its publishers, subscriptions and `reset` service, plus the standard
//! simulator-control services (simulation_interfaces, rules in `simulation`) in the node's private
//! namespace. A single async task waits on all inputs at once (commands, service requests, the
//! realtime timer, a StepSimulation in progress, the diagnostics timer, SIGINT/SIGTERM), so an
//! idle node in lock-step uses no CPU.
//!
//! The line's hardware shows in the graph: `sensors/ratio` is published while the line has its
//! ratio sensor, `cmd/sort_mode` subscribed while its machine has sort modes. On an evolving line
//! (`--evolution FILE`) they appear and go with the upgrades of its schedule
//! ([`LineEndpoints::fit_hardware`]); each point at which events apply is announced on
//! `events/evolution` before the state it concerns, and the parameters they change (line 0's) are
//! updated through `/parameter_events`.

use std::cell::RefCell;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use async_signal::{Signal, Signals};
use futures::channel::oneshot;
use futures::future::{FutureExt, LocalBoxFuture};
use futures::stream::{self, FuturesUnordered, LocalBoxStream, StreamExt};
use ros2_client::action::{
    ActionServerQosPolicies, AsyncActionServer, CancelHandle, ExecutingGoalHandle, GoalEndStatus, NewGoalHandle,
};
use ros2_client::{
    Context, Gid, Message, MessageInfo, Name, Node, NodeName, NodeOptions, ParameterValue, Publisher, RmwRequestId,
    Server, ServiceMapping, Subscription,
};
use serde::Serialize;

use super::clock::SimClock;
use super::diagnostics::{LineCounters, SimulationCounters};
use super::discovery::Discovery;
use super::messages::*;
use super::names::{Names, NODE_NAME};
use super::options::{NodeArgs, TickMode};
use super::param_descriptors::{descriptors, EVOLVING_PARAMETERS};
use super::params::NodeParams;
use super::protocol::{
    batch_commands, batch_resets, Accepted, BatchModes, Client, Command, HostedLine, Rejection, TimerTick,
};
use super::qos::{action_status_profile, default_profile};
use super::ros_args::RosArgs;
use super::simulation::{self, code, reset_scope, step_request, transition, ResetScope, SimState, Transition};
use super::simulation_interfaces::*;
use crate::sim::evolution::{At, Settings};
use crate::sim::Observation;

/// How often /diagnostics is published (wall time).
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

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
    let mut node = context.new_node(node_name, options).map_err(|e| format!("cannot create the node: {e:?}"))?;

    let clock = SimClock::new(params.tick_period);
    let mut endpoints = Vec::new();
    let mut runtimes = Vec::new();
    for k in 0..params.lines {
        let namespace = names.line_namespace(k, params.lines);
        let evolving = !params.evolution.is_empty();
        endpoints.push(LineEndpoints::new(&mut node, &names, &namespace, evolving)?);
        let seed = params.seed + u64::from(k);
        runtimes.push(LineRuntime {
            host: HostedLine::with_evolution(params.line.clone(), seed, params.evolution.clone(), clock, params.mode),
            counters: LineCounters::new(namespace),
            announced_tick: None,
            counted_tick: None,
            evolution_events: 0,
        });
    }
    let clock_pub = publisher::<Clock>(&mut node, &names.global("/clock"))?;
    let diagnostics_pub = publisher::<DiagnosticArray>(&mut node, &names.global("/diagnostics"))?;
    let batch_cmd = subscription::<LineCommands>(&mut node, &names.topic(&names.namespace, "batch/cmd"))?;
    let batch_state = publisher::<LineStates>(&mut node, &names.topic(&names.namespace, "batch/state"))?;
    let batch_reset = server(&mut node, &names.topic(&names.namespace, "batch/reset"), batch_reset_service_type())?;
    let sim = SimulationServers::new(&mut node, &names)?;
    let simulate_steps = simulate_steps_server(&mut node, &names)?;
    let spinner = node.spinner().map_err(|e| format!("cannot start the node's spinner: {e:?}"))?;
    let shared = Shared {
        clock_pub,
        diagnostics_pub,
        batch_cmd,
        batch_state,
        batch_reset,
        sim,
        simulate_steps,
        fully_qualified_name: names.fully_qualified(),
        params: params.clone(),
        parameter_values,
        new_streams: RefCell::new(Vec::new()),
        node: RefCell::new(node),
    };

    log(
        "INFO",
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
        ),
    );
    let spin = async move {
        if let Err(e) = spinner.spin().await {
            log("ERROR", format!("node spinner stopped: {e:?}"));
        }
    };
    smol::block_on(smol::future::or(serve(&endpoints, &mut runtimes, &shared, signals), spin));
    // Drop order matters: entities, then the node (the last field of `shared`), then the context
    // (the participant announces its departure, so peers see the node leave at once).
    drop(endpoints);
    drop(shared);
    drop(context);
    log("INFO", "shut down cleanly");
    Ok(())
}

/// The values the parameter validator accepts: the current ones. The node itself moves them
/// when its evolution schedule changes a setting ([`Shared::update_parameters`]).
type ParameterValues = Arc<Mutex<Vec<(&'static str, ParameterValue)>>>;

/// Declares every parameter with its value. They are fixed for the run: changing the dynamics
/// mid-run would silently break every trajectory, so set requests are refused with a reason
/// (only the node's own evolution schedule moves the values it names).
fn node_options(params: &NodeParams) -> (NodeOptions, ParameterValues) {
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

fn topic_name(absolute: &str) -> Result<Name, String> {
    Name::parse(absolute).map_err(|e| format!("'{absolute}' is not a valid topic name: {e:?}"))
}

fn publisher<M: Message + Serialize + Typed>(node: &mut Node, absolute: &str) -> Result<Publisher<M>, String> {
    let qos = default_profile();
    let topic = node
        .create_topic(&topic_name(absolute)?, M::type_name(), &qos)
        .map_err(|e| format!("cannot create topic {absolute}: {e:?}"))?;
    node.create_publisher(&topic, Some(qos)).map_err(|e| format!("cannot publish {absolute}: {e:?}"))
}

fn subscription<M>(node: &mut Node, absolute: &str) -> Result<Subscription<M>, String>
where
    M: Message + Typed + for<'de> serde::Deserialize<'de> + 'static,
{
    let qos = default_profile();
    let topic = node
        .create_topic(&topic_name(absolute)?, M::type_name(), &qos)
        .map_err(|e| format!("cannot create topic {absolute}: {e:?}"))?;
    node.create_subscription(&topic, Some(qos)).map_err(|e| format!("cannot subscribe {absolute}: {e:?}"))
}

fn server<Req, Resp>(
    node: &mut Node,
    absolute: &str,
    service: ros2_client::ServiceTypeName,
) -> Result<Server<Req, Resp>, String>
where
    Req: Message + Clone + for<'de> serde::Deserialize<'de> + 'static,
    Resp: Message + Serialize + 'static,
{
    let qos = default_profile();
    node.create_server(
        ServiceMapping::Enhanced, // what rmw_fastrtps_cpp (Jazzy's default) speaks
        &topic_name(absolute)?,
        &service,
        qos.clone(),
        qos,
    )
    .map_err(|e| format!("cannot serve {absolute}: {e:?}"))
}

/// The simulation_interfaces services, in the node's private namespace (`~/...`), as Gazebo
/// serves them under its node's name.
struct SimulationServers {
    features: Server<GetSimulatorFeaturesRequest, GetSimulatorFeaturesResponse>,
    get_state: Server<GetSimulationStateRequest, GetSimulationStateResponse>,
    set_state: Server<SetSimulationStateRequest, SetSimulationStateResponse>,
    step: Server<StepSimulationRequest, StepSimulationResponse>,
    reset: Server<ResetSimulationRequest, ResetSimulationResponse>,
}

/// A request to one of the [`SimulationServers`], decoded.
#[derive(Clone, Copy, Debug)]
enum SimRequest {
    Features,
    GetState,
    SetState(u8),
    Step(u64),
    Reset(u8),
}

impl SimRequest {
    /// The service's name in the private namespace.
    fn service(self) -> &'static str {
        let index = match self {
            SimRequest::Features => 0,
            SimRequest::GetState => 1,
            SimRequest::SetState(_) => 2,
            SimRequest::Step(_) => 3,
            SimRequest::Reset(_) => 4,
        };
        SERVICES[index].0
    }

    fn describe(self) -> String {
        match self {
            SimRequest::Features | SimRequest::GetState => "the request".to_string(),
            SimRequest::SetState(state) => format!("state {state}"),
            SimRequest::Step(steps) => format!("steps {steps}"),
            SimRequest::Reset(scope) => format!("scope {scope}"),
        }
    }
}

impl SimulationServers {
    fn new(node: &mut Node, names: &Names) -> Result<Self, String> {
        let at = |k: usize| names.private(SERVICES[k].0);
        let ty = |k: usize| service_type(SERVICES[k].1);
        Ok(SimulationServers {
            features: server(node, &at(0), ty(0))?,
            get_state: server(node, &at(1), ty(1))?,
            set_state: server(node, &at(2), ty(2))?,
            step: server(node, &at(3), ty(3))?,
            reset: server(node, &at(4), ty(4))?,
        })
    }

    fn events(&self) -> Vec<LocalBoxStream<'_, Event>> {
        fn tag<R>(request: fn(R) -> SimRequest) -> impl Fn(ros2_client::ReadResult<(RmwRequestId, R)>) -> Event {
            move |r| Event::Sim(r.map(|(id, req)| (id, request(req))).map_err(|e| format!("{e:?}")))
        }
        vec![
            self.features.receive_request_stream().map(tag(|_| SimRequest::Features)).boxed_local(),
            self.get_state.receive_request_stream().map(tag(|_| SimRequest::GetState)).boxed_local(),
            self.set_state
                .receive_request_stream()
                .map(tag(|r: SetSimulationStateRequest| SimRequest::SetState(r.state.state)))
                .boxed_local(),
            self.step
                .receive_request_stream()
                .map(tag(|r: StepSimulationRequest| SimRequest::Step(r.steps)))
                .boxed_local(),
            self.reset
                .receive_request_stream()
                .map(tag(|r: ResetSimulationRequest| SimRequest::Reset(r.scope)))
                .boxed_local(),
        ]
    }

    /// Answers `request` with `result` (and the state, for GetSimulationState).
    async fn reply(&self, id: RmwRequestId, request: SimRequest, result: SimResult, state: SimState) {
        let sent = match request {
            SimRequest::Features => {
                let features = SimulatorFeatures {
                    features: simulation::features(),
                    spawn_formats: Vec::new(),
                    custom_info: "sorting_line: PAUSED is lock-step (commands or StepSimulation advance the lines), \
                                  PLAYING is realtime at the rate parameter; one step is one tick of every line"
                        .to_string(),
                };
                self.features
                    .async_send_response(id, GetSimulatorFeaturesResponse { features })
                    .await
                    .map_err(|e| format!("{e:?}"))
            }
            SimRequest::GetState => {
                let response = GetSimulationStateResponse { state: SimulationState { state: state.code() }, result };
                self.get_state.async_send_response(id, response).await.map_err(|e| format!("{e:?}"))
            }
            SimRequest::SetState(_) => self
                .set_state
                .async_send_response(id, SetSimulationStateResponse { result })
                .await
                .map_err(|e| format!("{e:?}")),
            SimRequest::Step(_) => {
                self.step.async_send_response(id, StepSimulationResponse { result }).await.map_err(|e| format!("{e:?}"))
            }
            SimRequest::Reset(_) => self
                .reset
                .async_send_response(id, ResetSimulationResponse { result })
                .await
                .map_err(|e| format!("{e:?}")),
        };
        if let Err(error) = sent {
            log("WARN", format!("{}: cannot send the response: {error}", request.service()));
        }
    }
}

fn ok() -> SimResult {
    SimResult { result: code::OK, error_message: String::new() }
}

type SimulateStepsServer = AsyncActionServer<SimulateStepsGoal, SimulateStepsResult, SimulateStepsFeedback>;
type StepsGoal = ExecutingGoalHandle<SimulateStepsGoal>;

/// The SimulateSteps action server, in the node's private namespace (`~/simulate_steps`), with
/// rcl_action's QoS (the status topic is transient-local).
fn simulate_steps_server(node: &mut Node, names: &Names) -> Result<SimulateStepsServer, String> {
    let absolute = names.private(ACTION.0);
    let qos = ActionServerQosPolicies {
        goal_service: default_profile(),
        result_service: default_profile(),
        cancel_service: default_profile(),
        feedback_publisher: default_profile(),
        status_publisher: action_status_profile(),
    };
    let server = node
        .create_action_server(ServiceMapping::Enhanced, &topic_name(&absolute)?, &action_type(), qos)
        .map_err(|e| format!("cannot serve the action {absolute}: {e:?}"))?;
    Ok(AsyncActionServer::new(server))
}

/// Whom a finished StepSimulation answers: a service request, or a SimulateSteps goal.
#[derive(Clone, Copy)]
enum StepReply {
    Service(RmwRequestId),
    Action(StepsGoal),
}

/// A StepSimulation (or SimulateSteps goal) in progress: whom to answer, steps done and asked.
struct StepJob {
    reply: StepReply,
    done: u64,
    steps: u64,
    /// When the action's last feedback went out (see [`FEEDBACK_PERIOD`]).
    last_feedback: Option<std::time::Instant>,
}

/// Shortest time between two SimulateSteps feedbacks. A paused line steps thousands of times a
/// second; one feedback per step outran the client's acknowledgements (the reliable writer then
/// refused every feedback with WouldBlock, and a client saw none for seconds). Feedback is
/// progress, not data: the first step, then at most one per period, and the last step always.
const FEEDBACK_PERIOD: std::time::Duration = std::time::Duration::from_millis(10);

/// Ends a SimulateSteps goal: the result goes out when the client asks for it (ros2-client's
/// `send_result_response` waits for that request), so it runs beside the node's loop.
fn finish_goal<'a>(
    server: &'a SimulateStepsServer,
    goal: StepsGoal,
    status: GoalEndStatus,
    result: SimResult,
) -> LocalBoxFuture<'a, ()> {
    async move {
        if let Err(e) = server.send_result_response(goal, status, SimulateStepsResult { result }).await {
            log("WARN", format!("{}: cannot send a goal's result: {e:?}", ACTION.0));
        }
    }
    .boxed_local()
}

/// /clock: follows the line that is furthest ahead and goes back only when the simulation's time
/// is reset.
#[derive(Default)]
struct ClockState {
    last: Option<Time>,
}

impl ClockState {
    fn publish(&mut self, shared: &Shared, runtimes: &[LineRuntime]) {
        let newest = runtimes.iter().map(|r| r.host.stamp()).max().unwrap_or_default();
        if self.last.is_none_or(|last| newest > last) {
            self.last = Some(newest);
            shared.offer(&shared.clock_pub, &|| "/clock".to_string(), || Clock { clock: newest });
        }
    }
}

/// The ROS endpoints of one line. The fixed ones do not change while serving, so the input
/// streams can borrow them while the line's state ([`LineRuntime`]) is mutated; those of the
/// line's hardware (ratio sensor, sort modes) come and go with it ([`Self::fit_hardware`]).
struct LineEndpoints {
    namespace: String,
    input: Publisher<MaterialInput>,
    belt: Publisher<BeltOccupancy>,
    state: Publisher<LineState>,
    reset_event: Publisher<ResetEvent>,
    /// `events/evolution`, on an evolving line.
    evolution: Option<Publisher<EvolutionEvent>>,
    speed_cmd: Subscription<SpeedCommand>,
    reset: Server<ResetLineRequest, ResetLineResponse>,
    /// `sensors/ratio`, while the line has its ratio sensor.
    ratio: RefCell<Option<Publisher<MaterialRatio>>>,
    /// While `cmd/sort_mode` is subscribed: its stream (in the node's select) owns the
    /// subscription and ends, dropping it, when this sender is dropped.
    mode_cmd: RefCell<Option<oneshot::Sender<()>>>,
    ratio_topic: String,
    mode_topic: String,
}

/// The mutable part of one line: the simulation with its protocol, and its counters.
struct LineRuntime {
    host: HostedLine,
    counters: LineCounters,
    /// The tick whose pending evolution events were announced since the last reset (a reset
    /// announces them again after its own, so a client that reset knows what its first step
    /// brings).
    announced_tick: Option<u64>,
    /// The newest tick whose events were counted (they are counted once however often announced).
    counted_tick: Option<u64>,
    /// Evolution events announced so far.
    evolution_events: u64,
}

/// Node-wide endpoints and settings. `batch/cmd` and `batch/state` (in the node's namespace)
/// carry every line at once: a vectorised client exchanges two messages per round trip instead
/// of two per line, which is what lets one rclpy process drive many lines.
struct Shared {
    clock_pub: Publisher<Clock>,
    diagnostics_pub: Publisher<DiagnosticArray>,
    batch_cmd: Subscription<LineCommands>,
    batch_state: Publisher<LineStates>,
    batch_reset: Server<ResetLinesRequest, ResetLinesResponse>,
    sim: SimulationServers,
    simulate_steps: SimulateStepsServer,
    fully_qualified_name: String,
    params: NodeParams,
    parameter_values: ParameterValues,
    /// Input streams of endpoints created while serving, for the node's select to take in.
    new_streams: RefCell<Vec<LocalBoxStream<'static, Event>>>,
    /// Last: the endpoints above are dropped before the node. In a cell because endpoints are
    /// created while serving (the line's hardware, [`LineEndpoints::fit_hardware`]).
    node: RefCell<Node>,
}

impl Shared {
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
        if publisher.get_subscription_count(&self.node.borrow()) == 0 {
            return false;
        }
        if let Err(e) = publisher.publish(build()) {
            log("WARN", format!("cannot publish {}: {e:?}", topic()));
        }
        true
    }

    /// Moves the parameters an evolution event changed (line 0's settings) to their new values:
    /// the validator accepts them first, then the node sets them, which publishes them on
    /// `/parameter_events`.
    fn update_parameters(&self, settings: &Settings) {
        let now = [
            ("obs_noise", ParameterValue::Double(settings.obs_noise)),
            ("action_penalty", ParameterValue::Double(settings.action_penalty)),
            ("threshold", ParameterValue::Double(settings.threshold)),
            ("input", ParameterValue::String(settings.input.to_string())),
        ];
        debug_assert!(now.iter().map(|(n, _)| *n).eq(EVOLVING_PARAMETERS));
        let mut changed = Vec::new();
        {
            let mut values = self.parameter_values.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
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
            if let Err(e) = self.node.borrow().set_parameter(name, value) {
                log("WARN", format!("cannot update parameter {name}: {e}"));
            }
        }
    }

    /// `batch/state`, when a vectorised client reads it (per-line clients and realtime lines
    /// without one would otherwise get every line's state built and sent each tick for nothing).
    fn publish_batch_state(&self, runtimes: &[LineRuntime]) {
        self.offer(&self.batch_state, &|| "batch/state".to_string(), || batch_states(runtimes));
    }
}

impl LineEndpoints {
    fn new(node: &mut Node, names: &Names, namespace: &str, evolving: bool) -> Result<Self, String> {
        let t = |relative: &str| names.topic(namespace, relative);
        let reset = server(node, &t("reset"), reset_service_type())?;
        Ok(LineEndpoints {
            namespace: namespace.to_string(),
            input: publisher(node, &t("input"))?,
            belt: publisher(node, &t("belt/occupancy"))?,
            state: publisher(node, &t("state"))?,
            reset_event: publisher(node, &t("events/reset"))?,
            evolution: if evolving { Some(publisher(node, &t("events/evolution"))?) } else { None },
            speed_cmd: subscription(node, &t("cmd/speed"))?,
            reset,
            ratio: RefCell::new(None),
            mode_cmd: RefCell::new(None),
            ratio_topic: t("sensors/ratio"),
            mode_topic: t("cmd/sort_mode"),
        })
    }

    fn show(&self, relative: &str) -> String {
        format!("{}/{relative}", self.namespace.trim_end_matches('/'))
    }

    /// Makes the hardware endpoints match line k: `sensors/ratio` while its observation comes
    /// with a ratio reading, `cmd/sort_mode` while the step it waits for runs with sort modes
    /// (an upgrade due at that tick included, so a client can command the first upgraded step).
    fn fit_hardware(&self, shared: &Shared, k: usize, host: &HostedLine) {
        let sensor = host.line().ratio_sensor();
        let mut ratio = self.ratio.borrow_mut();
        if sensor != ratio.is_some() {
            *ratio = None;
            if sensor {
                match publisher(&mut shared.node.borrow_mut(), &self.ratio_topic) {
                    Ok(p) => *ratio = Some(p),
                    Err(e) => log("ERROR", e),
                }
            }
            if host.evolving() {
                let how = if sensor { "appears (ratio sensor fitted)" } else { "goes (ratio sensor removed)" };
                log("INFO", format!("{} {how}", self.show("sensors/ratio")));
            }
        }
        let modes = host.takes_modes();
        let mut mode_cmd = self.mode_cmd.borrow_mut();
        if modes != mode_cmd.is_some() {
            *mode_cmd = None; // ends the old stream, which drops its subscription
            if modes {
                match subscription::<SortModeCommand>(&mut shared.node.borrow_mut(), &self.mode_topic) {
                    Ok(sub) => {
                        let (stop, stopped) = oneshot::channel();
                        shared.new_streams.borrow_mut().push(mode_commands(k, sub, stopped));
                        *mode_cmd = Some(stop);
                    }
                    Err(e) => log("ERROR", e),
                }
            }
            if host.evolving() {
                let how = if modes { "appears (machine upgrade: sort modes)" } else { "goes (sort modes removed)" };
                log("INFO", format!("{} {how}", self.show("cmd/sort_mode")));
            }
        }
    }

    /// Publishes everything that describes the current tick to the topics that have a reader
    /// (see [`Shared::offer`]); `state` last, because clients wait for it and by then the sensors
    /// of the same tick are out. Before them: the hardware is fitted to the line and evolution
    /// events due at the start of the coming step are announced.
    fn publish_tick(&self, shared: &Shared, k: usize, r: &mut LineRuntime) {
        self.fit_hardware(shared, k, &r.host);
        self.announce_tick_events(shared, k, r);
        let host = &r.host;
        let topic = |relative: &'static str| move || self.show(relative);
        let counters = &mut r.counters;
        counters.count_published(shared.offer(&self.input, &topic("input"), || MaterialInput::of(host)));
        counters.count_published(shared.offer(&self.belt, &topic("belt/occupancy"), || BeltOccupancy::of(host)));
        if let Some(ratio) = &*self.ratio.borrow() {
            counters.count_published(shared.offer(ratio, &topic("sensors/ratio"), || MaterialRatio::of(host)));
        }
        counters.count_published(shared.offer(&self.state, &topic("state"), || LineState::of(host)));
    }

    /// A reset's `events/reset`, and on an evolving line its `events/evolution`: every reset
    /// announces the setup the episode starts with, naming the episode's events (if any).
    fn publish_reset_events(&self, shared: &Shared, k: usize, r: &mut LineRuntime, seeded: bool) {
        let sent = shared.offer(&self.reset_event, &|| self.show("events/reset"), || ResetEvent::of(&r.host, seeded));
        r.counters.count_published(sent);
        if r.host.evolving() {
            r.announced_tick = None;
            let line = r.host.line();
            let indices: Vec<usize> = line.evolution().events_at(At::Episode(line.episode())).map(|(i, _)| i).collect();
            let settings = line.settings();
            self.announce(shared, k, r, true, &indices, &settings);
        }
    }

    /// On an evolving line: the announcement of the line as built (its episode-0 events), as the
    /// node starts and after a ResetSimulation rebuilt it.
    fn announce_start(&self, shared: &Shared, k: usize, r: &mut LineRuntime) {
        if r.host.evolving() {
            let settings = r.host.line().settings();
            let indices: Vec<usize> = r.host.line().evolution().events_at(At::Episode(0)).map(|(i, _)| i).collect();
            self.announce(shared, k, r, true, &indices, &settings);
        }
    }

    /// Announces the events due at the start of the step line k waits for, once.
    fn announce_tick_events(&self, shared: &Shared, k: usize, r: &mut LineRuntime) {
        let tick = r.host.line().tick();
        if r.announced_tick == Some(tick) {
            return;
        }
        if let Some((indices, settings)) = r.host.line().pending_tick_events() {
            r.announced_tick = Some(tick);
            self.announce(shared, k, r, false, &indices, &settings);
        }
    }

    fn announce(
        &self,
        shared: &Shared,
        k: usize,
        r: &mut LineRuntime,
        at_reset: bool,
        indices: &[usize],
        settings: &Settings,
    ) {
        let Some(publisher) = &self.evolution else { return };
        let message = EvolutionEvent::of(&r.host, at_reset, indices, settings);
        if !indices.is_empty() {
            log(
                "INFO",
                format!(
                    "{}: evolution at episode {} tick {}: {}",
                    self.namespace.trim_end_matches('/'),
                    message.episode,
                    message.tick,
                    message
                        .changed
                        .iter()
                        .zip(&message.values)
                        .map(|(c, v)| format!("{c} = {v}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            );
        }
        let tick = r.host.line().tick();
        if at_reset || r.counted_tick != Some(tick) {
            r.evolution_events += indices.len() as u64;
        }
        if !at_reset {
            r.counted_tick = Some(tick);
        }
        r.counters.count_published(shared.offer(publisher, &|| self.show("events/evolution"), || message));
        if k == 0 {
            shared.update_parameters(settings);
        }
    }

    /// The tagged input streams of this line's fixed endpoints.
    fn events(&self, k: usize) -> Vec<LocalBoxStream<'_, Event>> {
        let err = |e| format!("{e:?}");
        let speed =
            |(cmd, info): (SpeedCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Speed(cmd.speed));
        vec![
            self.speed_cmd
                .async_stream()
                .map(move |r| Event::Command(k, "cmd/speed", r.map(speed).map_err(err)))
                .boxed_local(),
            self.reset.receive_request_stream().map(move |r| Event::Reset(k, r.map_err(err))).boxed_local(),
        ]
    }
}

/// Line k's `cmd/sort_mode` commands, from a stream that owns the subscription and ends (dropping
/// it, so the subscription leaves the graph) when `stop` fires or its sender is dropped.
fn mode_commands(
    k: usize,
    sub: Subscription<SortModeCommand>,
    stop: oneshot::Receiver<()>,
) -> LocalBoxStream<'static, Event> {
    let mode =
        |(cmd, info): (SortModeCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Mode(cmd.mode));
    stream::unfold(sub, |sub| async move {
        let received = sub.async_take().await;
        Some((received, sub))
    })
    .map(move |r| Event::Command(k, "cmd/sort_mode", r.map(mode).map_err(|e| format!("{e:?}"))))
    .take_until(stop)
    .boxed_local()
}

/// Every line's current state, as arrays.
fn batch_states(runtimes: &[LineRuntime]) -> LineStates {
    LineStates::of(runtimes.iter().map(|r| &r.host))
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

fn show_stamp(t: Time) -> String {
    format!("{}.{:09}", t.sec, t.nanosec)
}

/// The node's one task: waits on every input, handles each completely, repeats until a signal
/// (or a SetSimulationState to QUITTING).
async fn serve(endpoints: &[LineEndpoints], runtimes: &mut [LineRuntime], shared: &Shared, signals: Signals) {
    let mut clock = ClockState::default();
    for (k, (e, r)) in endpoints.iter().zip(runtimes.iter_mut()).enumerate() {
        // The line as built: its episode-0 events applied (announced, and line 0's parameters
        // set, like those of any later reset).
        e.announce_start(shared, k, r);
        e.publish_tick(shared, k, r);
    }
    clock.publish(shared, runtimes);

    let batch = shared.batch_cmd.async_stream().map(|r| Event::Batch(r.map_err(|e| format!("{e:?}")))).boxed_local();
    let resets = shared
        .batch_reset
        .receive_request_stream()
        .map(|r| Event::BatchReset(r.map_err(|e| format!("{e:?}"))))
        .boxed_local();
    let action = &shared.simulate_steps;
    let goals = stream::unfold((), move |()| async move {
        Some((Event::Goal(action.receive_new_goal().await.map_err(|e| format!("{e:?}"))), ()))
    })
    .boxed_local();
    let cancels = stream::unfold((), move |()| async move {
        Some((Event::Cancel(action.receive_cancel_request().await.map_err(|e| format!("{e:?}"))), ()))
    })
    .boxed_local();
    let mut events = stream::select_all(
        endpoints
            .iter()
            .enumerate()
            .flat_map(|(k, e)| e.events(k))
            .chain([batch, resets, goals, cancels])
            .chain(shared.sim.events()),
    );
    let mut finishing: FuturesUnordered<LocalBoxFuture<'_, ()>> = FuturesUnordered::new();
    let mut signals = signals.fuse();
    let period = Duration::from_secs_f64(1.0 / shared.params.rate);
    let mut sim = SimState::initial(shared.params.mode);
    let mut timer =
        StreamExt::fuse(if sim == SimState::Playing { smol::Timer::interval(period) } else { smol::Timer::never() });
    let mut job: Option<StepJob> = None;
    let mut sim_counters = SimulationCounters::new(shared.fully_qualified_name.clone());
    let mut diagnostics = StreamExt::fuse(smol::Timer::interval(DIAGNOSTICS_PERIOD));
    let started = Instant::now();

    loop {
        // Endpoints created since the last turn (the line's hardware) join the select.
        for new in shared.new_streams.borrow_mut().drain(..) {
            events.push(new);
        }
        // A StepSimulation in progress runs one step per turn of the loop, so other requests,
        // commands and signals are served between its steps.
        let mut step_now: futures::future::Fuse<LocalBoxFuture<'static, ()>> = if job.is_some() {
            futures::future::ready(()).boxed_local().fuse()
        } else {
            futures::future::pending().boxed_local().fuse()
        };
        // Fair (random among ready inputs): a biased order would let a flood of commands starve
        // the realtime timer and /diagnostics.
        futures::select! {
            event = events.select_next_some() => match event {
                Event::Batch(received) => {
                    if handle_batch(endpoints, runtimes, shared, received) {
                        shared.publish_batch_state(runtimes);
                        clock.publish(shared, runtimes);
                    }
                }
                Event::Command(k, topic, received) => {
                    let result = match received {
                        Ok((client, stamp, command)) => apply(&mut runtimes[k], client, stamp, command),
                        Err(error) => Err(malformed(&error)),
                    };
                    if settle(&endpoints[k], k, &mut runtimes[k], shared, topic, result) {
                        clock.publish(shared, runtimes);
                    }
                }
                Event::BatchReset(Ok((request_id, request))) => {
                    let response = match batch_reset(endpoints, runtimes, shared, &request) {
                        Ok(message) => ResetLinesResponse { success: true, message, states: batch_states(runtimes) },
                        Err(message) => {
                            // Counted like a malformed batch/cmd (on line 0), logged by the counters.
                            settle(&endpoints[0], 0, &mut runtimes[0], shared, "batch/reset", Err((Rejection::Malformed, format!("request ({message})"))));
                            ResetLinesResponse { success: false, message, states: batch_states(runtimes) }
                        }
                    };
                    if let Err(error) = shared.batch_reset.async_send_response(request_id, response).await {
                        log("WARN", format!("batch/reset: cannot send the response: {error:?}"));
                    }
                    shared.publish_batch_state(runtimes);
                    clock.publish(shared, runtimes);
                }
                Event::BatchReset(Err(error)) => log("WARN", format!("batch/reset: unreadable request: {error}")),
                Event::Reset(k, Ok((request_id, request))) => {
                    let (e, r) = (&endpoints[k], &mut runtimes[k]);
                    let observation = reset_line(e, k, r, shared, request.has_seed.then_some(request.seed));
                    let response = ResetLineResponse::of(&r.host, observation, request.has_seed);
                    if let Err(error) = e.reset.async_send_response(request_id, response).await {
                        log("WARN", format!("{}/reset: cannot send the response: {error:?}", e.namespace));
                    }
                    shared.publish_batch_state(runtimes);
                    clock.publish(shared, runtimes);
                }
                Event::Reset(k, Err(error)) => {
                    log("WARN", format!("{}/reset: unreadable request: {error}", endpoints[k].namespace));
                }
                Event::Sim(Ok((id, request))) => {
                    let stepping = job.as_ref().map(|j| (j.done, j.steps));
                    let outcome: Result<(), simulation::Refusal> = match request {
                        SimRequest::Features | SimRequest::GetState => Ok(()),
                        SimRequest::SetState(target) => match transition(sim, target, stepping) {
                            Ok(Transition::To { to, reset }) => {
                                if reset {
                                    reset_simulation(endpoints, runtimes, shared, ResetScope::ALL, &mut clock);
                                }
                                sim = to;
                                for r in runtimes.iter_mut() {
                                    r.host.set_mode(to.tick_mode());
                                    r.host.set_halted(to.halted());
                                }
                                if to == SimState::Playing {
                                    timer.get_mut().set_interval(period);
                                } else {
                                    *timer.get_mut() = smol::Timer::never();
                                }
                                log("INFO", format!("simulation {}", to.name()));
                                Ok(())
                            }
                            Ok(Transition::Quit) => {
                                sim_counters.answered_ok += 1;
                                shared.sim.reply(id, request, ok(), sim).await;
                                log("INFO", "simulation QUITTING (SetSimulationState): leaving the graph");
                                break;
                            }
                            Err(refusal) => Err(refusal),
                        },
                        SimRequest::Step(steps) => match step_request(sim, steps, stepping) {
                            Ok(0) => Ok(()),
                            Ok(steps) => {
                                job = Some(start_job(runtimes, StepReply::Service(id), steps));
                                continue; // answered when the steps are done
                            }
                            Err(refusal) => Err(refusal),
                        },
                        SimRequest::Reset(scope) => reset_scope(scope, stepping)
                            .map(|scope| reset_simulation(endpoints, runtimes, shared, scope, &mut clock)),
                    };
                    let result = match outcome {
                        Ok(()) => {
                            sim_counters.answered_ok += 1;
                            ok()
                        }
                        Err(refusal) => {
                            if let Some(line) = sim_counters.refuse(request.service(), &request.describe(), &refusal) {
                                log("WARN", line);
                            }
                            SimResult { result: refusal.code, error_message: refusal.message }
                        }
                    };
                    shared.sim.reply(id, request, result, sim).await;
                }
                Event::Sim(Err(error)) => log("WARN", format!("simulation_interfaces: unreadable request: {error}")),
                Event::Goal(Ok(handle)) => {
                    let stepping = job.as_ref().map(|j| (j.done, j.steps));
                    let Some(goal) = action.get_new_goal(handle) else {
                        log("WARN", format!("{}: a new goal vanished before it was read", ACTION.0));
                        continue;
                    };
                    // Accepted either way: a refused goal ends at once with the reason in its result.
                    let executing = match action.accept_goal(handle).await {
                        Ok(accepted) => action.start_executing_goal(accepted).await,
                        Err(e) => Err(e),
                    };
                    let executing = match executing {
                        Ok(executing) => executing,
                        Err(e) => {
                            log("WARN", format!("{}: cannot accept a goal: {e:?}", ACTION.0));
                            continue;
                        }
                    };
                    match step_request(sim, goal.steps, stepping) {
                        Ok(0) => {
                            sim_counters.answered_ok += 1;
                            finishing.push(finish_goal(action, executing, GoalEndStatus::Succeeded, ok()));
                        }
                        Ok(steps) => job = Some(start_job(runtimes, StepReply::Action(executing), steps)),
                        Err(refusal) => {
                            if let Some(line) = sim_counters.refuse(ACTION.0, &format!("steps {}", goal.steps), &refusal) {
                                log("WARN", line);
                            }
                            let result = SimResult { result: refusal.code, error_message: refusal.message };
                            finishing.push(finish_goal(action, executing, GoalEndStatus::Aborted, result));
                        }
                    }
                }
                Event::Goal(Err(error)) => log("WARN", format!("{}: unreadable goal: {error}", ACTION.0)),
                Event::Cancel(Ok(cancel)) => {
                    // Only the goal in progress can be canceled: every other one has ended.
                    let current = match job.as_ref().map(|j| (j.reply, j.done, j.steps)) {
                        Some((StepReply::Action(goal), done, steps)) if cancel.contains_goal(&goal.goal_id()) => Some((goal, done, steps)),
                        _ => None,
                    };
                    if let Err(e) = action.respond_to_cancel_requests(&cancel, current.map(|(g, _, _)| g.goal_id()).into_iter()).await {
                        log("WARN", format!("{}: cannot answer a cancel request: {e:?}", ACTION.0));
                    }
                    if let Some((goal, done, steps)) = current {
                        end_job(runtimes);
                        job = None;
                        let result = SimResult {
                            result: code::OPERATION_FAILED,
                            error_message: format!("canceled after {done} of {steps} steps"),
                        };
                        finishing.push(finish_goal(action, goal, GoalEndStatus::Canceled, result));
                    }
                }
                Event::Cancel(Err(error)) => log("WARN", format!("{}: unreadable cancel request: {error}", ACTION.0)),
            },
            _ = step_now => {
                if let Some(j) = job.as_mut() {
                    tick_all(endpoints, runtimes, shared, &mut clock);
                    j.done += 1;
                    sim_counters.steps += 1;
                    let due = j.done == j.steps || j.last_feedback.is_none_or(|t| t.elapsed() >= FEEDBACK_PERIOD);
                    if let (StepReply::Action(goal), true) = (j.reply, due) {
                        j.last_feedback = Some(std::time::Instant::now());
                        let feedback = SimulateStepsFeedback { completed_steps: j.done, remaining_steps: j.steps - j.done };
                        if let Err(e) = action.publish_feedback(goal, feedback).await {
                            log("WARN", format!("{}: cannot publish feedback: {e:?}", ACTION.0));
                        }
                    }
                    if j.done == j.steps {
                        let reply = j.reply;
                        end_job(runtimes);
                        job = None;
                        sim_counters.answered_ok += 1;
                        match reply {
                            StepReply::Service(id) => shared.sim.reply(id, SimRequest::Step(0), ok(), sim).await,
                            StepReply::Action(goal) => finishing.push(finish_goal(action, goal, GoalEndStatus::Succeeded, ok())),
                        }
                    }
                }
            },
            () = finishing.select_next_some() => {},
            _ = timer.select_next_some() => tick_all(endpoints, runtimes, shared, &mut clock),
            _ = diagnostics.select_next_some() => {
                let stepping = job.as_ref().map(|j| (j.done, j.steps));
                publish_diagnostics(runtimes, shared, started, sim_counters.status(sim, stepping));
            },
            signal = signals.select_next_some() => {
                let name = match signal { Ok(Signal::Int) => "SIGINT", Ok(Signal::Term) => "SIGTERM", _ => "a signal" };
                log("INFO", format!("received {name}: leaving the graph"));
                break;
            },
        }
    }
}

/// Starts a StepSimulation (or SimulateSteps goal) of `steps` > 0. Realtime rules while stepping:
/// a command updates the held command (the next step uses it) instead of completing a tick.
fn start_job(runtimes: &mut [LineRuntime], reply: StepReply, steps: u64) -> StepJob {
    for r in runtimes.iter_mut() {
        r.host.set_mode(TickMode::Realtime);
    }
    StepJob { reply, done: 0, steps, last_feedback: None }
}

/// Back to lock-step (PAUSED) after a step job.
fn end_job(runtimes: &mut [LineRuntime]) {
    for r in runtimes.iter_mut() {
        r.host.set_mode(TickMode::Lockstep);
    }
}

/// One tick of every line on its held command, as the realtime timer and StepSimulation run it:
/// a line at its time limit starts a new episode instead (its random streams carry on).
fn tick_all(endpoints: &[LineEndpoints], runtimes: &mut [LineRuntime], shared: &Shared, clock: &mut ClockState) {
    for (k, (e, r)) in endpoints.iter().zip(runtimes.iter_mut()).enumerate() {
        match r.host.timer_tick() {
            TimerTick::Stepped(_) => {
                r.counters.ticks += 1;
                e.publish_tick(shared, k, r);
            }
            TimerTick::Reset(_) => {
                r.counters.episodes += 1;
                e.publish_reset_events(shared, k, r, false);
                e.publish_tick(shared, k, r);
            }
        }
    }
    shared.publish_batch_state(runtimes);
    clock.publish(shared, runtimes);
}

/// ResetSimulation (and stopping): every line back to how it was built (state), the stamps and
/// /clock back to 0 (time), or both; then each line's tick is published again (with the reset
/// event, seeded, when the state was reset).
fn reset_simulation(
    endpoints: &[LineEndpoints],
    runtimes: &mut [LineRuntime],
    shared: &Shared,
    scope: ResetScope,
    clock: &mut ClockState,
) {
    for (k, (e, r)) in endpoints.iter().zip(runtimes.iter_mut()).enumerate() {
        if scope.state {
            r.host.restart();
            r.counters.episodes += 1;
            // The line as built again: its schedule starts over.
            (r.announced_tick, r.counted_tick, r.evolution_events) = (None, None, 0);
        }
        if scope.time {
            r.host.rewind_time();
        }
        if scope.state {
            let sent = shared.offer(&e.reset_event, &|| e.show("events/reset"), || ResetEvent::of(&r.host, true));
            r.counters.count_published(sent);
            e.announce_start(shared, k, r);
        }
        e.publish_tick(shared, k, r);
    }
    if scope.time {
        clock.last = None;
    }
    shared.publish_batch_state(runtimes);
    clock.publish(shared, runtimes);
}

/// Resets one line and publishes its new tick (and the reset event, for bags).
fn reset_line(e: &LineEndpoints, k: usize, r: &mut LineRuntime, shared: &Shared, seed: Option<u64>) -> Observation {
    let observation = r.host.reset(seed);
    r.counters.episodes += 1;
    e.publish_reset_events(shared, k, r, seed.is_some());
    e.publish_tick(shared, k, r);
    observation
}

/// Resets the lines a `batch/reset` request names; refuses the whole request if it is malformed
/// (`protocol::batch_resets`).
fn batch_reset(
    endpoints: &[LineEndpoints],
    runtimes: &mut [LineRuntime],
    shared: &Shared,
    request: &ResetLinesRequest,
) -> Result<String, String> {
    let resets = batch_resets(request, runtimes.len())?;
    for reset in &resets {
        reset_line(&endpoints[reset.line], reset.line, &mut runtimes[reset.line], shared, reset.seed);
    }
    Ok(format!("{} line(s) reset", resets.len()))
}

/// Applies a batch command line by line, through the same rules as the per-line topics
/// (`protocol::batch_commands`). Returns whether any line stepped.
fn handle_batch(
    endpoints: &[LineEndpoints],
    runtimes: &mut [LineRuntime],
    shared: &Shared,
    received: Result<(LineCommands, MessageInfo), String>,
) -> bool {
    let (cmd, client) = match received {
        Ok((cmd, info)) => (cmd, client_of(&info)),
        Err(error) => {
            settle(&endpoints[0], 0, &mut runtimes[0], shared, "batch/cmd", Err(malformed(&error)));
            return false;
        }
    };
    let modes = BatchModes::of(shared.params.line.variant, !shared.params.evolution.is_empty());
    let entries = match batch_commands(&cmd, runtimes.len(), modes) {
        Ok(entries) => entries,
        Err(detail) => {
            settle(&endpoints[0], 0, &mut runtimes[0], shared, "batch/cmd", Err((Rejection::Malformed, detail)));
            return false;
        }
    };
    let mut stepped = false;
    for (k, ((e, r), entry)) in endpoints.iter().zip(runtimes.iter_mut()).zip(entries).enumerate() {
        for command in entry.commands() {
            let result = apply(r, client, entry.stamp, command);
            stepped |= settle(e, k, r, shared, "batch/cmd", result);
        }
    }
    stepped
}

/// A rejected command: why, and what it said (for the log).
type Refusal = (Rejection, String);

/// The participant that wrote a command (the GUID prefix of its writer).
fn client_of(info: &MessageInfo) -> Client {
    let gid: Gid = info.publisher_gid();
    let mut client = Client::default();
    let n = client.len();
    client.copy_from_slice(&gid.as_bytes()[..n]);
    client
}

fn show_client(client: Option<Client>) -> String {
    client.map_or_else(|| "none".to_string(), |c| c.iter().map(|b| format!("{b:02x}")).collect())
}

/// What a rejected command said, and who sent it when that matters (ownership).
fn command_detail(host: &HostedLine, client: Client, what: String) -> String {
    match host.owner() {
        Some(owner) if owner != client => {
            format!(
                "{what} from client {} (the episode's owner is {})",
                show_client(Some(client)),
                show_client(Some(owner))
            )
        }
        _ => what,
    }
}

fn apply(r: &mut LineRuntime, client: Client, stamp: Time, command: Command) -> Result<Accepted, Refusal> {
    let result = r.host.command_from(client, stamp, command);
    result.map_err(|reason| {
        (reason, command_detail(&r.host, client, format!("{command} for stamp {}", show_stamp(stamp))))
    })
}

fn malformed(error: &str) -> Refusal {
    (Rejection::Malformed, format!("message ({error})"))
}

/// Counts and logs a command's fate; publishes the new tick if it completed one. Returns
/// whether the line stepped.
fn settle(
    e: &LineEndpoints,
    k: usize,
    r: &mut LineRuntime,
    shared: &Shared,
    topic: &str,
    result: Result<Accepted, Refusal>,
) -> bool {
    match result {
        Ok(Accepted::Stored) => {
            r.counters.accepted += 1;
            false
        }
        Ok(Accepted::Stepped(_)) => {
            r.counters.accepted += 1;
            r.counters.ticks += 1;
            e.publish_tick(shared, k, r);
            true
        }
        Err((reason, detail)) => {
            if let Some(line) = r.counters.reject(reason, topic, &detail) {
                log("WARN", line);
            }
            false
        }
    }
}

fn publish_diagnostics(runtimes: &mut [LineRuntime], shared: &Shared, started: Instant, simulation: DiagnosticStatus) {
    let p = &shared.params;
    let status = runtimes
        .iter_mut()
        .map(|r| {
            let line = r.host.line();
            let kv = |key: &str, value: String| KeyValue { key: key.to_string(), value };
            let mut extra = vec![
                kv("seed", line.seed().to_string()),
                kv("episode", line.episode().to_string()),
                kv("step", line.step_count().to_string()),
                kv("sim_time", show_stamp(r.host.stamp())),
                kv("variant", p.line.variant.to_string()),
                kv("input", line.config().input.to_string()),
                kv("mode", format!("{:?}", r.host.mode()).to_lowercase()),
                kv("uptime_s", format!("{:.0}", started.elapsed().as_secs_f64())),
                kv("owner", show_client(r.host.owner())),
            ];
            if r.host.evolving() {
                // The evolution state: the setup now and how far the schedule has come.
                let s = line.settings();
                let fault = s.input_fault.map_or_else(
                    || "none".to_string(),
                    |f| format!("{:?} {} ticks left", f.kind, f.remaining).to_lowercase(),
                );
                extra.extend([
                    kv("evolution_file", p.evolution_file.clone()),
                    kv("evolution_events_applied", r.evolution_events.to_string()),
                    kv("evolution_events_total", line.evolution().events.len().to_string()),
                    kv("tick", line.tick().to_string()),
                    kv("sort_modes", s.sort_modes.to_string()),
                    kv("ratio_sensor", s.ratio_sensor.to_string()),
                    kv("obs_noise", s.obs_noise.to_string()),
                    kv("action_penalty", s.action_penalty.to_string()),
                    kv("threshold", s.threshold.to_string()),
                    kv("input_fault", fault),
                ]);
            }
            r.counters.status(extra)
        })
        .chain([simulation])
        .collect();
    let stamp = runtimes.iter().map(|r| r.host.stamp()).max().unwrap_or_default();
    let array = DiagnosticArray { header: Header { stamp, frame_id: String::new() }, status };
    if let Err(e) = shared.diagnostics_pub.publish(array) {
        log("WARN", format!("cannot publish /diagnostics: {e:?}"));
    }
}
