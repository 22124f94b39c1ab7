//! The running node: one DDS participant (set up from ROS 2's discovery variables), one ROS node, and
//! for each hosted line its publishers, subscriptions and `reset` service. A single async task
//! waits on all inputs at once (commands, service requests, the realtime timer, the diagnostics
//! timer, SIGINT/SIGTERM), so an idle node in lock-step uses no CPU.
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
use futures::stream::{self, LocalBoxStream, StreamExt};
use ros2_client::{
    Context, Gid, Message, MessageInfo, Name, Node, NodeName, NodeOptions, ParameterValue, Publisher, RmwRequestId,
    Server, ServiceMapping, Subscription,
};
use serde::Serialize;

use super::clock::SimClock;
use super::diagnostics::LineCounters;
use super::discovery::Discovery;
use super::messages::*;
use super::names::{Names, NODE_NAME};
use super::options::{NodeArgs, TickMode};
use super::param_descriptors::{descriptors, EVOLVING_PARAMETERS};
use super::params::NodeParams;
use super::protocol::{batch_commands, batch_resets, Accepted, BatchModes, Client, Command, HostedLine, Rejection, TimerTick};
use super::qos::default_profile;
use super::ros_args::RosArgs;
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
    let context = Context::from_domain_participant(participant).map_err(|e| format!("cannot create the ROS context: {e:?}"))?;
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
    let spinner = node.spinner().map_err(|e| format!("cannot start the node's spinner: {e:?}"))?;
    let shared = Shared {
        clock_pub,
        diagnostics_pub,
        batch_cmd,
        batch_state,
        batch_reset,
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

fn subscription<M: Message + Typed + 'static>(node: &mut Node, absolute: &str) -> Result<Subscription<M>, String>
where
    M: for<'de> serde::Deserialize<'de>,
{
    let qos = default_profile();
    let topic = node
        .create_topic(&topic_name(absolute)?, M::type_name(), &qos)
        .map_err(|e| format!("cannot create topic {absolute}: {e:?}"))?;
    node.create_subscription(&topic, Some(qos)).map_err(|e| format!("cannot subscribe {absolute}: {e:?}"))
}

fn server<Req, Resp>(node: &mut Node, absolute: &str, service: ros2_client::ServiceTypeName) -> Result<Server<Req, Resp>, String>
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

    fn announce(&self, shared: &Shared, k: usize, r: &mut LineRuntime, at_reset: bool, indices: &[usize], settings: &Settings) {
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
                    message.changed.iter().zip(&message.values).map(|(c, v)| format!("{c} = {v}")).collect::<Vec<_>>().join(", ")
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
        let speed = |(cmd, info): (SpeedCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Speed(cmd.speed));
        vec![
            self.speed_cmd.async_stream().map(move |r| Event::Command(k, "cmd/speed", r.map(speed).map_err(err))).boxed_local(),
            self.reset.receive_request_stream().map(move |r| Event::Reset(k, r.map_err(err))).boxed_local(),
        ]
    }
}

/// Line k's `cmd/sort_mode` commands, from a stream that owns the subscription and ends (dropping
/// it, so the subscription leaves the graph) when `stop` fires or its sender is dropped.
fn mode_commands(k: usize, sub: Subscription<SortModeCommand>, stop: oneshot::Receiver<()>) -> LocalBoxStream<'static, Event> {
    let mode = |(cmd, info): (SortModeCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Mode(cmd.mode));
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
}

fn show_stamp(t: Time) -> String {
    format!("{}.{:09}", t.sec, t.nanosec)
}

/// The node's one task: waits on every input, handles each completely, repeats until a signal.
async fn serve(endpoints: &[LineEndpoints], runtimes: &mut [LineRuntime], shared: &Shared, signals: Signals) {
    let mut clock_time = Time::default();
    let mut publish_clock = |runtimes: &[LineRuntime]| {
        // With several lines, /clock follows the line that is furthest ahead and never goes back.
        let newest = runtimes.iter().map(|r| r.host.stamp()).max().unwrap_or_default();
        if newest > clock_time {
            clock_time = newest;
            shared.offer(&shared.clock_pub, &|| "/clock".to_string(), || Clock { clock: newest });
        }
    };
    for (k, (e, r)) in endpoints.iter().zip(runtimes.iter_mut()).enumerate() {
        // The line as built: its episode-0 events applied (announced, and line 0's parameters
        // set, like those of any later reset).
        if r.host.evolving() {
            let settings = r.host.line().settings();
            let indices: Vec<usize> = r.host.line().evolution().events_at(At::Episode(0)).map(|(i, _)| i).collect();
            e.announce(shared, k, r, true, &indices, &settings);
        }
        e.publish_tick(shared, k, r);
    }
    publish_clock(runtimes);

    let batch = shared.batch_cmd.async_stream().map(|r| Event::Batch(r.map_err(|e| format!("{e:?}")))).boxed_local();
    let resets =
        shared.batch_reset.receive_request_stream().map(|r| Event::BatchReset(r.map_err(|e| format!("{e:?}")))).boxed_local();
    let mut events =
        stream::select_all(endpoints.iter().enumerate().flat_map(|(k, e)| e.events(k)).chain([batch, resets]));
    let mut signals = signals.fuse();
    let realtime = shared.params.mode == TickMode::Realtime;
    let mut timer = StreamExt::fuse(if realtime {
        smol::Timer::interval(Duration::from_secs_f64(1.0 / shared.params.rate))
    } else {
        smol::Timer::never()
    });
    let mut diagnostics = StreamExt::fuse(smol::Timer::interval(DIAGNOSTICS_PERIOD));
    let started = Instant::now();

    loop {
        // Endpoints created since the last turn (the line's hardware) join the select.
        for new in shared.new_streams.borrow_mut().drain(..) {
            events.push(new);
        }
        // Fair (random among ready inputs): a biased order would let a flood of commands starve
        // the realtime timer and /diagnostics.
        futures::select! {
            event = events.select_next_some() => match event {
                Event::Batch(received) => {
                    if handle_batch(endpoints, runtimes, shared, received) {
                        shared.publish_batch_state(runtimes);
                        publish_clock(runtimes);
                    }
                }
                Event::Command(k, topic, received) => {
                    let result = match received {
                        Ok((client, stamp, command)) => apply(&mut runtimes[k], client, stamp, command),
                        Err(error) => Err(malformed(&error)),
                    };
                    if settle(&endpoints[k], k, &mut runtimes[k], shared, topic, result) {
                        publish_clock(runtimes);
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
                    publish_clock(runtimes);
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
                    publish_clock(runtimes);
                }
                Event::Reset(k, Err(error)) => {
                    log("WARN", format!("{}/reset: unreadable request: {error}", endpoints[k].namespace));
                }
            },
            _ = timer.select_next_some() => {
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
                publish_clock(runtimes);
            },
            _ = diagnostics.select_next_some() => publish_diagnostics(runtimes, shared, started),
            signal = signals.select_next_some() => {
                let name = match signal { Ok(Signal::Int) => "SIGINT", Ok(Signal::Term) => "SIGTERM", _ => "a signal" };
                log("INFO", format!("received {name}: leaving the graph"));
                break;
            },
        }
    }
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
            format!("{what} from client {} (the episode's owner is {})", show_client(Some(client)), show_client(Some(owner)))
        }
        _ => what,
    }
}

fn apply(r: &mut LineRuntime, client: Client, stamp: Time, command: Command) -> Result<Accepted, Refusal> {
    let result = r.host.command_from(client, stamp, command);
    result.map_err(|reason| (reason, command_detail(&r.host, client, format!("{command} for stamp {}", show_stamp(stamp)))))
}

fn malformed(error: &str) -> Refusal {
    (Rejection::Malformed, format!("message ({error})"))
}

/// Counts and logs a command's fate; publishes the new tick if it completed one. Returns
/// whether the line stepped.
fn settle(e: &LineEndpoints, k: usize, r: &mut LineRuntime, shared: &Shared, topic: &str, result: Result<Accepted, Refusal>) -> bool {
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

fn publish_diagnostics(runtimes: &mut [LineRuntime], shared: &Shared, started: Instant) {
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
                kv("mode", format!("{:?}", p.mode).to_lowercase()),
                kv("uptime_s", format!("{:.0}", started.elapsed().as_secs_f64())),
                kv("owner", show_client(r.host.owner())),
            ];
            if r.host.evolving() {
                // The evolution state: the setup now and how far the schedule has come.
                let s = line.settings();
                let fault = s.input_fault.map_or_else(|| "none".to_string(), |f| format!("{:?} {} ticks left", f.kind, f.remaining).to_lowercase());
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
        .collect();
    let stamp = runtimes.iter().map(|r| r.host.stamp()).max().unwrap_or_default();
    let array = DiagnosticArray { header: Header { stamp, frame_id: String::new() }, status };
    if let Err(e) = shared.diagnostics_pub.publish(array) {
        log("WARN", format!("cannot publish /diagnostics: {e:?}"));
    }
}
