//! A line's evolution announcements: each point at which events of its schedule apply is announced
//! on `events/evolution` before the state it concerns (at the start, at every reset, and before
//! the step that brings them), counted once, and line 0's changed settings move the node's
//! parameters.

use ros2_client::Publisher;

use super::graph::Graph;
use super::line_messages;
use super::log::{log, show_topic};
use crate::ros::diagnostics::LineCounters;
use crate::ros::messages::EvolutionEvent;
use crate::ros::protocol::HostedLine;
use crate::ros::topics::EVOLUTION_EVENT;
use crate::sim::evolution::{At, Settings};

/// One line's announcements and the bookkeeping that says which were made and counted.
pub(super) struct LineEvolution {
    /// `events/evolution`, on an evolving line.
    publisher: Option<Publisher<EvolutionEvent>>,
    /// The line's namespace, for the log.
    namespace: String,
    /// Whether the line's settings move the node's parameters (line 0's do).
    moves_parameters: bool,
    /// The tick whose pending evolution events were announced since the last reset (a reset
    /// announces them again after its own, so a client that reset knows what its first step
    /// brings).
    announced_tick: Option<u64>,
    /// The newest tick whose events were counted (they are counted once however often announced).
    counted_tick: Option<u64>,
    /// Evolution events announced so far.
    applied: u64,
}

impl LineEvolution {
    pub(super) fn new(publisher: Option<Publisher<EvolutionEvent>>, namespace: String, moves_parameters: bool) -> Self {
        LineEvolution { publisher, namespace, moves_parameters, announced_tick: None, counted_tick: None, applied: 0 }
    }

    /// Evolution events announced so far (for /diagnostics).
    pub(super) fn applied(&self) -> u64 {
        self.applied
    }

    /// The line as built again (ResetSimulation): its schedule starts over.
    pub(super) fn restart(&mut self) {
        (self.announced_tick, self.counted_tick, self.applied) = (None, None, 0);
    }

    /// On an evolving line: the announcement of the line as built (its episode-0 events), as the
    /// node starts and after a ResetSimulation rebuilt it.
    pub(super) fn announce_start(&mut self, host: &HostedLine, counters: &mut LineCounters, graph: &Graph) {
        if host.evolving() {
            let settings = host.line().settings();
            let indices: Vec<usize> = host.line().evolution().events_at(At::Episode(0)).map(|(i, _)| i).collect();
            self.announce(host, counters, graph, true, &indices, &settings);
        }
    }

    /// On an evolving line: the setup a new episode starts with, naming the episode's events.
    pub(super) fn announce_reset(&mut self, host: &HostedLine, counters: &mut LineCounters, graph: &Graph) {
        if host.evolving() {
            self.announced_tick = None;
            let line = host.line();
            let indices: Vec<usize> = line.evolution().events_at(At::Episode(line.episode())).map(|(i, _)| i).collect();
            let settings = line.settings();
            self.announce(host, counters, graph, true, &indices, &settings);
        }
    }

    /// Announces the events due at the start of the step the line waits for, once.
    pub(super) fn announce_tick_events(&mut self, host: &HostedLine, counters: &mut LineCounters, graph: &Graph) {
        let tick = host.line().tick();
        if self.announced_tick == Some(tick) {
            return;
        }
        if let Some((indices, settings)) = host.line().pending_tick_events() {
            self.announced_tick = Some(tick);
            self.announce(host, counters, graph, false, &indices, &settings);
        }
    }

    fn announce(
        &mut self,
        host: &HostedLine,
        counters: &mut LineCounters,
        graph: &Graph,
        at_reset: bool,
        indices: &[usize],
        settings: &Settings,
    ) {
        let Some(publisher) = &self.publisher else { return };
        let message = line_messages::evolution_event(host, at_reset, indices, settings);
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
        let tick = host.line().tick();
        if at_reset || self.counted_tick != Some(tick) {
            self.applied += indices.len() as u64;
        }
        if !at_reset {
            self.counted_tick = Some(tick);
        }
        let sent = graph.offer(publisher, &|| show_topic(&self.namespace, EVOLUTION_EVENT.name), || message);
        counters.count_published(sent);
        if self.moves_parameters {
            graph.update_parameters(settings);
        }
    }
}
