//! One hosted line in the node: its simulation with the protocol and counters, its endpoints, the
//! commands it takes, and what it publishes for each tick and reset. The fixed endpoints live as
//! long as the node; those of the line's hardware (ratio sensor, sort modes) come and go with it
//! ([`Line::fit_hardware`]).

use std::rc::Rc;

use futures::channel::oneshot;
use futures::stream::StreamExt;
use ros2_client::{MessageInfo, Node, Publisher, Server as ServiceServer};

use super::endpoints::{messages, publisher, requests, service, subscription};
use super::events::{client_of, Event, Input};
use super::evolution::LineEvolution;
use super::graph::Graph;
use super::line_messages;
use super::log::{log, show_client, show_stamp, show_topic};
use crate::ros::clock::SimClock;
use crate::ros::diagnostics::LineCounters;
use crate::ros::messages::*;
use crate::ros::names::Names;
use crate::ros::params::NodeParams;
use crate::ros::protocol::{Accepted, Client, Command, HostedLine, Rejection};
use crate::ros::topics::{self, Topic};
use crate::sim::Observation;

/// A rejected command: why, and what it said (for the log).
pub(super) type Refusal = (Rejection, String);

/// One line: the simulation with its protocol, its counters and evolution bookkeeping, and its
/// endpoints.
pub(super) struct Line {
    /// Its index among the node's lines (k in `line_k/`).
    pub(super) index: usize,
    pub(super) namespace: String,
    pub(super) host: HostedLine,
    pub(super) counters: LineCounters,
    /// Its evolution announcements (`events/evolution`, on an evolving line).
    pub(super) evolution: LineEvolution,
    input: Publisher<MaterialInput>,
    belt: Publisher<BeltOccupancy>,
    state: Publisher<LineState>,
    reset_event: Publisher<ResetEvent>,
    /// The `reset` service (its requests come through the node's events).
    pub(super) reset: Rc<ServiceServer<ResetLineRequest, ResetLineResponse>>,
    /// `sensors/ratio`, while the line has its ratio sensor.
    ratio: Option<Publisher<MaterialRatio>>,
    /// While `cmd/sort_mode` is subscribed: its stream (in the node's events) owns the
    /// subscription and ends, dropping it, when this sender is dropped.
    mode_cmd: Option<oneshot::Sender<()>>,
    ratio_topic: String,
    mode_topic: String,
    /// The live view's scene of the line (no DDS topic).
    scene_topic: String,
}

impl Line {
    /// Line k with its fixed endpoints, and the input streams of those (`cmd/speed`, `reset`).
    pub(super) fn new(
        node: &mut Node,
        names: &Names,
        params: &NodeParams,
        k: u32,
    ) -> Result<(Self, Vec<Input>), String> {
        let namespace = names.line_namespace(k, params.lines);
        let t = |topic: &Topic| names.topic(&namespace, topic.name);
        let reset = service(node, &topics::RESET, &t(&topics::RESET), reset_service_type())?;
        let input = publisher(node, &topics::INPUT, &t(&topics::INPUT))?;
        let belt = publisher(node, &topics::BELT_OCCUPANCY, &t(&topics::BELT_OCCUPANCY))?;
        let state = publisher(node, &topics::STATE, &t(&topics::STATE))?;
        let reset_event = publisher(node, &topics::RESET_EVENT, &t(&topics::RESET_EVENT))?;
        let evolving = !params.evolution.is_empty();
        let evolution = if evolving {
            Some(publisher(node, &topics::EVOLUTION_EVENT, &t(&topics::EVOLUTION_EVENT))?)
        } else {
            None
        };
        let speed_cmd = subscription::<SpeedCommand>(node, &topics::SPEED_CMD, &t(&topics::SPEED_CMD))?;
        let clock = SimClock::new(params.tick_period);
        let seed = params.seed + u64::from(k);
        let index = k as usize;
        let host = HostedLine::with_evolution(params.line.clone(), seed, params.evolution.clone(), clock, params.mode);
        let err = |e| format!("{e:?}");
        let speed =
            |(cmd, info): (SpeedCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Speed(cmd.speed));
        let streams = vec![
            messages(speed_cmd)
                .map(move |r| Event::Command(index, topics::SPEED_CMD.name, r.map(speed).map_err(err)))
                .boxed_local(),
            requests(&reset).map(move |r| Event::Reset(index, r.map_err(err))).boxed_local(),
        ];
        let line = Line {
            index,
            counters: LineCounters::new(namespace.clone()),
            host,
            evolution: LineEvolution::new(evolution, namespace.clone(), index == 0),
            input,
            belt,
            state,
            reset_event,
            reset,
            ratio: None,
            mode_cmd: None,
            ratio_topic: t(&topics::SENSORS_RATIO),
            mode_topic: t(&topics::SORT_MODE_CMD),
            scene_topic: show_topic(&namespace, "scene"),
            namespace,
        };
        Ok((line, streams))
    }

    /// How many readers the `input` writer has matched (a tick's input is sent only to these).
    pub(super) fn input_readers(&self, node: &Node) -> usize {
        self.input.get_subscription_count(node)
    }

    pub(super) fn show(&self, relative: &str) -> String {
        show_topic(&self.namespace, relative)
    }

    /// Makes the hardware endpoints match the line: `sensors/ratio` while its observation comes
    /// with a ratio reading, `cmd/sort_mode` while the step it waits for runs with sort modes
    /// (an upgrade due at that tick included, so a client can command the first upgraded step).
    pub(super) fn fit_hardware(&mut self, graph: &mut Graph) {
        let sensor = self.host.line().ratio_sensor();
        if sensor != self.ratio.is_some() {
            self.ratio = None;
            if sensor {
                match publisher(&mut graph.node, &topics::SENSORS_RATIO, &self.ratio_topic) {
                    Ok(p) => self.ratio = Some(p),
                    Err(e) => log("ERROR", e),
                }
            }
            if self.host.evolving() {
                let how = if sensor { "appears (ratio sensor fitted)" } else { "goes (ratio sensor removed)" };
                log("INFO", format!("{} {how}", self.show(topics::SENSORS_RATIO.name)));
            }
        }
        let modes = self.host.takes_modes();
        if modes != self.mode_cmd.is_some() {
            self.mode_cmd = None; // ends the old stream, which drops its subscription
            if modes {
                match subscription::<SortModeCommand>(&mut graph.node, &topics::SORT_MODE_CMD, &self.mode_topic) {
                    Ok(sub) => {
                        let (stop, stopped) = oneshot::channel();
                        graph.events.push(mode_commands(self.index, sub, stopped));
                        self.mode_cmd = Some(stop);
                    }
                    Err(e) => log("ERROR", e),
                }
            }
            if self.host.evolving() {
                let how = if modes { "appears (machine upgrade: sort modes)" } else { "goes (sort modes removed)" };
                log("INFO", format!("{} {how}", self.show(topics::SORT_MODE_CMD.name)));
            }
        }
    }

    /// Publishes everything that describes the current tick to the topics that have a reader
    /// (see [`Graph::offer`]); `state` last, because clients wait for it and by then the sensors
    /// of the same tick are out. Before them: the hardware is fitted to the line and evolution
    /// events due at the start of the coming step are announced.
    pub(super) fn publish_tick(&mut self, graph: &mut Graph) {
        self.fit_hardware(graph);
        self.evolution.announce_tick_events(&self.host, &mut self.counters, graph);
        let host = &self.host;
        let namespace = &self.namespace;
        let topic = |topic: Topic| move || show_topic(namespace, topic.name);
        let counters = &mut self.counters;
        let input = graph.offer(&self.input, &topic(topics::INPUT), || line_messages::material_input(host));
        counters.count_published(input);
        let belt = graph.offer(&self.belt, &topic(topics::BELT_OCCUPANCY), || line_messages::belt_occupancy(host));
        counters.count_published(belt);
        if let Some(ratio) = &self.ratio {
            let sent = graph.offer(ratio, &topic(topics::SENSORS_RATIO), || line_messages::material_ratio(host));
            counters.count_published(sent);
        }
        counters.count_published(graph.offer(&self.state, &topic(topics::STATE), || line_messages::line_state(host)));
        if let Some(live) = &graph.live {
            live.offer_scene(&self.scene_topic, &self.host, self.index, &self.namespace);
        }
    }

    /// `events/reset`, for bags: the line's new episode (`seeded`: whether the reset named a seed).
    pub(super) fn publish_reset_event(&mut self, graph: &Graph, seeded: bool) {
        let sent = graph.offer(&self.reset_event, &|| self.show(topics::RESET_EVENT.name), || {
            line_messages::reset_event(&self.host, seeded)
        });
        self.counters.count_published(sent);
    }

    /// A reset's `events/reset`, and on an evolving line its `events/evolution`: every reset
    /// announces the setup the episode starts with, naming the episode's events (if any).
    pub(super) fn publish_reset_events(&mut self, graph: &mut Graph, seeded: bool) {
        self.publish_reset_event(graph, seeded);
        self.evolution.announce_reset(&self.host, &mut self.counters, graph);
    }

    /// Resets the line and publishes its new tick (and the reset event, for bags).
    pub(super) fn reset(&mut self, graph: &mut Graph, seed: Option<u64>) -> Observation {
        let observation = self.host.reset(seed);
        self.counters.episodes += 1;
        self.publish_reset_events(graph, seed.is_some());
        self.publish_tick(graph);
        observation
    }

    /// On an evolving line: the announcement of the line as built (its episode-0 events).
    pub(super) fn announce_start(&mut self, graph: &Graph) {
        self.evolution.announce_start(&self.host, &mut self.counters, graph);
    }

    /// A command from `client` for the tick stamped `stamp`, through the protocol's rules.
    pub(super) fn apply(&mut self, client: Client, stamp: Time, command: Command) -> Result<Accepted, Refusal> {
        let result = self.host.command_from(client, stamp, command);
        result.map_err(|reason| {
            (reason, command_detail(&self.host, client, format!("{command} for stamp {}", show_stamp(stamp))))
        })
    }

    /// Counts and logs a command's fate; publishes the new tick if it completed one. Returns
    /// whether the line stepped.
    pub(super) fn settle(&mut self, graph: &mut Graph, topic: &str, result: Result<Accepted, Refusal>) -> bool {
        match result {
            Ok(Accepted::Stored) => {
                self.counters.accepted += 1;
                false
            }
            Ok(Accepted::Stepped(_)) => {
                self.counters.accepted += 1;
                self.counters.ticks += 1;
                self.publish_tick(graph);
                true
            }
            Err((reason, detail)) => {
                if let Some(line) = self.counters.reject(reason, topic, &detail) {
                    log("WARN", line);
                }
                false
            }
        }
    }
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

/// Line k's `cmd/sort_mode` commands, from a stream that owns the subscription and ends (dropping
/// it, so the subscription leaves the graph) when `stop` fires or its sender is dropped.
fn mode_commands(k: usize, sub: ros2_client::Subscription<SortModeCommand>, stop: oneshot::Receiver<()>) -> Input {
    let mode =
        |(cmd, info): (SortModeCommand, MessageInfo)| (client_of(&info), cmd.header.stamp, Command::Mode(cmd.mode));
    messages(sub)
        .map(move |r| Event::Command(k, topics::SORT_MODE_CMD.name, r.map(mode).map_err(|e| format!("{e:?}"))))
        .take_until(stop)
        .boxed_local()
}
