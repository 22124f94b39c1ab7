//! /diagnostics as a part of the node: published once a second (wall time), one status per line
//! (its counters, where it is, and on an evolving line its setup and how far its schedule has
//! come), one for the simulation_interfaces side, and with the live view on, one for it
//! (`live_view`), which also shows the array itself.

use std::time::{Duration, Instant};

use futures::stream::{Fuse, StreamExt};
use ros2_client::{Node, Publisher};

use super::endpoints::publisher;
use super::graph::{ros_type, Graph};
use super::lines::Line;
use super::log::{log, show_client, show_stamp};
use crate::ros::messages::{DiagnosticArray, DiagnosticStatus, Header, KeyValue};
use crate::ros::names::Names;
use crate::ros::params::NodeParams;
use crate::ros::topics::DIAGNOSTICS;

/// How often /diagnostics is published (wall time).
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// The /diagnostics publisher, its timer, and what the statuses say besides the counters.
pub(super) struct Diagnostics {
    publisher: Publisher<DiagnosticArray>,
    pub(super) timer: Fuse<smol::Timer>,
    started: Instant,
    params: NodeParams,
}

fn kv(key: &str, value: String) -> KeyValue {
    KeyValue { key: key.to_string(), value }
}

impl Diagnostics {
    pub(super) fn new(node: &mut Node, names: &Names, params: &NodeParams) -> Result<Self, String> {
        Ok(Diagnostics {
            publisher: publisher(node, &DIAGNOSTICS, &names.global(DIAGNOSTICS.name))?,
            timer: StreamExt::fuse(smol::Timer::never()),
            started: Instant::now(),
            params: params.clone(),
        })
    }

    /// The timer starts, and the uptime counts from now.
    pub(super) fn start(&mut self) {
        self.timer = StreamExt::fuse(smol::Timer::interval(DIAGNOSTICS_PERIOD));
        self.started = Instant::now();
    }

    /// Every line's status, then `simulation`'s, then the live view's if it is on (the graph's
    /// node: whose matches the statuses count).
    pub(super) fn publish(&mut self, graph: &Graph, lines: &mut [Line], simulation: DiagnosticStatus) {
        let uptime = format!("{:.0}", self.started.elapsed().as_secs_f64());
        let params = &self.params;
        let node = &graph.node;
        let live = graph.live.as_ref().map(|live| live.status());
        let status = lines
            .iter_mut()
            .map(|line| line_status(line, node, params, &uptime))
            .chain([simulation])
            .chain(live)
            .collect();
        let stamp = lines.iter().map(|line| line.host.stamp()).max().unwrap_or_default();
        let array = DiagnosticArray { header: Header { stamp, frame_id: String::new() }, status };
        if let Some(live) = &graph.live {
            live.offer(DIAGNOSTICS.name, &ros_type::<DiagnosticArray>(), &array);
        }
        if let Err(e) = self.publisher.publish(array) {
            log("WARN", format!("cannot publish {}: {e:?}", DIAGNOSTICS.name));
        }
    }
}

fn line_status(line: &mut Line, node: &Node, p: &NodeParams, uptime: &str) -> DiagnosticStatus {
    let host = &line.host;
    let model = host.line();
    let mut extra = vec![
        kv("seed", model.seed().to_string()),
        kv("episode", model.episode().to_string()),
        kv("step", model.step_count().to_string()),
        kv("sim_time", show_stamp(host.stamp())),
        kv("variant", p.line.variant.to_string()),
        kv("input", model.config().input.to_string()),
        kv("mode", format!("{:?}", host.mode()).to_lowercase()),
        kv("uptime_s", uptime.to_string()),
        kv("owner", show_client(host.owner())),
        // The readers the node's `input` writer has matched: a tick's input reaches these, and
        // only these (a reader seen in the graph but not yet matched here misses it).
        kv("input_readers", line.input_readers(node).to_string()),
    ];
    if host.evolving() {
        // The evolution state: the setup now and how far the schedule has come.
        let s = model.settings();
        let fault = s
            .input_fault
            .map_or_else(|| "none".to_string(), |f| format!("{:?} {} ticks left", f.kind, f.remaining).to_lowercase());
        extra.extend([
            kv("evolution_file", p.evolution_file.clone()),
            kv("evolution_events_applied", line.evolution.applied().to_string()),
            kv("evolution_events_total", model.evolution().events.len().to_string()),
            kv("tick", model.tick().to_string()),
            kv("sort_modes", s.sort_modes.to_string()),
            kv("ratio_sensor", s.ratio_sensor.to_string()),
            kv("obs_noise", s.obs_noise.to_string()),
            kv("action_penalty", s.action_penalty.to_string()),
            kv("threshold", s.threshold.to_string()),
            kv("input_fault", fault),
        ]);
    }
    line.counters.status(extra)
}
