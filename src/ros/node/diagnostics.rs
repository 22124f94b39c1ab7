//! What the node publishes on /diagnostics once a second: one status per line (its counters, where
//! it is, and on an evolving line its setup and how far its schedule has come), and one for the
//! simulation_interfaces side.

use super::super::messages::{DiagnosticArray, DiagnosticStatus, Header, KeyValue};
use super::super::params::NodeParams;
use super::commands::{show_client, show_stamp};
use super::lines::Line;
use super::log;
use super::server::Server;

fn kv(key: &str, value: String) -> KeyValue {
    KeyValue { key: key.to_string(), value }
}

impl Server {
    pub(super) fn publish_diagnostics(&mut self) {
        let simulation = self.sim_counters.status(self.sim, self.stepping());
        let uptime = format!("{:.0}", self.started.elapsed().as_secs_f64());
        let params = &self.params;
        let status = self.lines.iter_mut().map(|line| line_status(line, params, &uptime)).chain([simulation]).collect();
        let stamp = self.lines.iter().map(|line| line.host.stamp()).max().unwrap_or_default();
        let array = DiagnosticArray { header: Header { stamp, frame_id: String::new() }, status };
        if let Err(e) = self.graph.diagnostics_pub.publish(array) {
            log("WARN", format!("cannot publish /diagnostics: {e:?}"));
        }
    }
}

fn line_status(line: &mut Line, p: &NodeParams, uptime: &str) -> DiagnosticStatus {
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
    ];
    if host.evolving() {
        // The evolution state: the setup now and how far the schedule has come.
        let s = model.settings();
        let fault = s
            .input_fault
            .map_or_else(|| "none".to_string(), |f| format!("{:?} {} ticks left", f.kind, f.remaining).to_lowercase());
        extra.extend([
            kv("evolution_file", p.evolution_file.clone()),
            kv("evolution_events_applied", line.evolution_events.to_string()),
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
