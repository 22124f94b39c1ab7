//! A line's evolution announcements: each point at which events of its schedule apply is announced
//! on `events/evolution` before the state it concerns (at the start, at every reset, and before
//! the step that brings them), counted once, and line 0's changed settings move the node's
//! parameters.

use super::super::messages::EvolutionEvent;
use super::lines::Line;
use super::{log, Graph};
use crate::sim::evolution::{At, Settings};

impl Line {
    /// On an evolving line: the announcement of the line as built (its episode-0 events), as the
    /// node starts and after a ResetSimulation rebuilt it.
    pub(super) fn announce_start(&mut self, graph: &Graph) {
        if self.host.evolving() {
            let settings = self.host.line().settings();
            let indices: Vec<usize> = self.host.line().evolution().events_at(At::Episode(0)).map(|(i, _)| i).collect();
            self.announce(graph, true, &indices, &settings);
        }
    }

    /// On an evolving line: the setup a new episode starts with, naming the episode's events.
    pub(super) fn announce_reset(&mut self, graph: &Graph) {
        if self.host.evolving() {
            self.announced_tick = None;
            let line = self.host.line();
            let indices: Vec<usize> = line.evolution().events_at(At::Episode(line.episode())).map(|(i, _)| i).collect();
            let settings = line.settings();
            self.announce(graph, true, &indices, &settings);
        }
    }

    /// Announces the events due at the start of the step the line waits for, once.
    pub(super) fn announce_tick_events(&mut self, graph: &Graph) {
        let tick = self.host.line().tick();
        if self.announced_tick == Some(tick) {
            return;
        }
        if let Some((indices, settings)) = self.host.line().pending_tick_events() {
            self.announced_tick = Some(tick);
            self.announce(graph, false, &indices, &settings);
        }
    }

    fn announce(&mut self, graph: &Graph, at_reset: bool, indices: &[usize], settings: &Settings) {
        let Some(publisher) = &self.evolution else { return };
        let message = EvolutionEvent::of(&self.host, at_reset, indices, settings);
        if !indices.is_empty() {
            let changes: Vec<String> =
                message.changed.iter().zip(&message.values).map(|(c, v)| format!("{c} = {v}")).collect();
            log(
                "INFO",
                format!(
                    "{}: evolution at episode {} tick {}: {}",
                    self.namespace.trim_end_matches('/'),
                    message.episode,
                    message.tick,
                    changes.join(", ")
                ),
            );
        }
        let tick = self.host.line().tick();
        if at_reset || self.counted_tick != Some(tick) {
            self.evolution_events += indices.len() as u64;
        }
        if !at_reset {
            self.counted_tick = Some(tick);
        }
        let sent = graph.offer(publisher, &|| self.show("events/evolution"), || message);
        self.counters.count_published(sent);
        if self.index == 0 {
            graph.update_parameters(settings);
        }
    }
}
