//! What the node reports about itself: per-line counters (ticks, episodes, commands accepted and
//! rejected by reason) and the simulation's (its state, simulation_interfaces requests answered and
//! refused by result code) published on /diagnostics, and logging of rejections that says each
//! reason once and then at most once per interval, so a flood of bad requests cannot flood the log.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use super::messages::{DiagnosticStatus, KeyValue, DIAGNOSTIC_OK, DIAGNOSTIC_WARN};
use super::protocol::{Rejection, REJECTIONS};
use super::simulation::{code, Refusal, SimState};

/// How often a repeated rejection reason may be logged again.
pub const LOG_INTERVAL: Duration = Duration::from_secs(5);

/// Counters of one line.
#[derive(Debug)]
pub struct LineCounters {
    pub namespace: String,
    pub ticks: u64,
    pub episodes: u64,
    pub accepted: u64,
    pub rejected: BTreeMap<Rejection, u64>,
    /// Messages of the line's own topics sent, and skipped because the topic had no reader.
    pub published: u64,
    pub unread: u64,
    /// For the tick rate and the warning level: values at the last report.
    last_report: (Instant, u64, u64),
    log: LogThrottle<Rejection>,
}

/// Logs each kind of rejection once, then at most once per [`LOG_INTERVAL`], counting the rest.
#[derive(Debug, Default)]
struct LogThrottle<K: Ord> {
    /// Per kind: when it was last logged and how many were not logged since.
    state: BTreeMap<K, (Instant, u64)>,
}

impl<K: Ord + Copy> LogThrottle<K> {
    /// None when this kind was logged less than LOG_INTERVAL ago; otherwise the suffix to log
    /// ("" or " (N more like it since the last report)").
    fn due(&mut self, kind: K) -> Option<String> {
        let now = Instant::now();
        match self.state.get_mut(&kind) {
            Some((last, suppressed)) if now.duration_since(*last) < LOG_INTERVAL => {
                *suppressed += 1;
                None
            }
            entry => {
                let suppressed = entry.map(|(_, s)| *s).unwrap_or(0);
                self.state.insert(kind, (now, 0));
                Some(if suppressed > 0 {
                    format!(" ({suppressed} more like it since the last report)")
                } else {
                    String::new()
                })
            }
        }
    }
}

impl LineCounters {
    pub fn new(namespace: String) -> Self {
        LineCounters {
            namespace,
            ticks: 0,
            episodes: 0,
            accepted: 0,
            rejected: BTreeMap::new(),
            published: 0,
            unread: 0,
            last_report: (Instant::now(), 0, 0),
            log: LogThrottle { state: BTreeMap::new() },
        }
    }

    /// Counts a message of the line's topics: sent, or skipped (no reader).
    pub fn count_published(&mut self, sent: bool) {
        if sent {
            self.published += 1;
        } else {
            self.unread += 1;
        }
    }

    pub fn total_rejected(&self) -> u64 {
        self.rejected.values().sum()
    }

    /// Counts a rejection and returns the log line to print, if this reason is due one.
    pub fn reject(&mut self, reason: Rejection, topic: &str, detail: &str) -> Option<String> {
        *self.rejected.entry(reason).or_default() += 1;
        let more = self.log.due(reason)?;
        Some(format!(
            "{}/{topic}: rejected {detail}: {} [{}]{more}; the line keeps its last valid command",
            self.namespace.trim_end_matches('/'),
            reason.explain(),
            reason.key()
        ))
    }

    /// The DiagnosticStatus of this line; `extra` adds node-wide values (seed, mode, ...).
    pub fn status(&mut self, extra: Vec<KeyValue>) -> DiagnosticStatus {
        let now = Instant::now();
        let (then, ticks_then, rejected_then) = self.last_report;
        let elapsed = now.duration_since(then).as_secs_f64().max(1e-9);
        let rate = (self.ticks - ticks_then) as f64 / elapsed;
        let recent_rejections = self.total_rejected() - rejected_then;
        self.last_report = (now, self.ticks, self.total_rejected());
        let kv = |key: &str, value: String| KeyValue { key: key.to_string(), value };
        let mut values = vec![
            kv("tick_rate", format!("{rate:.1}")),
            kv("ticks", self.ticks.to_string()),
            kv("episodes", self.episodes.to_string()),
            kv("commands_accepted", self.accepted.to_string()),
            kv("commands_rejected", self.total_rejected().to_string()),
            kv("messages_published", self.published.to_string()),
            kv("messages_unread_skipped", self.unread.to_string()),
        ];
        for reason in REJECTIONS {
            values.push(kv(
                &format!("rejected_{}", reason.key()),
                self.rejected.get(&reason).copied().unwrap_or(0).to_string(),
            ));
        }
        values.extend(extra);
        let (level, message) = if recent_rejections > 0 {
            (DIAGNOSTIC_WARN, format!("{recent_rejections} commands rejected since the last report"))
        } else {
            (DIAGNOSTIC_OK, "running".to_string())
        };
        DiagnosticStatus {
            level,
            name: format!("sorting_line: {}", self.namespace),
            message,
            hardware_id: self.namespace.clone(),
            values,
        }
    }
}

/// Counters of the simulation_interfaces services (node-wide: they act on every line).
#[derive(Debug)]
pub struct SimulationCounters {
    /// The node's private namespace (`<ns>/<node name>`), where the services are.
    pub node: String,
    pub answered_ok: u64,
    /// Requests refused, per result code.
    pub refused: BTreeMap<u8, u64>,
    /// Simulation steps run by StepSimulation.
    pub steps: u64,
    refused_at_last_report: u64,
    log: LogThrottle<u8>,
}

impl SimulationCounters {
    pub fn new(node: String) -> Self {
        SimulationCounters {
            node,
            answered_ok: 0,
            refused: BTreeMap::new(),
            steps: 0,
            refused_at_last_report: 0,
            log: LogThrottle { state: BTreeMap::new() },
        }
    }

    pub fn total_refused(&self) -> u64 {
        self.refused.values().sum()
    }

    /// Counts a refused request of `service` and returns the log line, if this code is due one.
    pub fn refuse(&mut self, service: &str, request: &str, refusal: &Refusal) -> Option<String> {
        *self.refused.entry(refusal.code).or_default() += 1;
        let more = self.log.due(refusal.code)?;
        Some(format!(
            "{}/{service}: refused {request}: {} [{}]{more}",
            self.node.trim_end_matches('/'),
            refusal.message,
            code::name(refusal.code)
        ))
    }

    /// The DiagnosticStatus "sorting_line: simulation" (hardware_id: the node's private namespace).
    pub fn status(&mut self, state: SimState, stepping: Option<(u64, u64)>) -> DiagnosticStatus {
        let kv = |key: &str, value: String| KeyValue { key: key.to_string(), value };
        let mut values = vec![
            kv("simulation_state", state.name().to_string()),
            kv("step_in_progress", stepping.map_or_else(|| "none".to_string(), |(done, n)| format!("{done}/{n}"))),
            kv("steps_stepped", self.steps.to_string()),
            kv("requests_ok", self.answered_ok.to_string()),
            kv("requests_refused", self.total_refused().to_string()),
        ];
        for c in code::REFUSALS {
            values.push(kv(
                &format!("refused_{}", code::name(c)),
                self.refused.get(&c).copied().unwrap_or(0).to_string(),
            ));
        }
        let recent = self.total_refused() - self.refused_at_last_report;
        self.refused_at_last_report = self.total_refused();
        let (level, message) = if recent > 0 {
            (DIAGNOSTIC_WARN, format!("{recent} simulation_interfaces requests refused since the last report"))
        } else {
            (DIAGNOSTIC_OK, state.name().to_string())
        };
        DiagnosticStatus {
            level,
            name: "sorting_line: simulation".to_string(),
            message,
            hardware_id: self.node.clone(),
            values,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_every_rejection_but_logs_each_reason_once_per_interval() {
        let mut c = LineCounters::new("/plant".into());
        let first = c.reject(Rejection::InvalidSpeed, "cmd/speed", "speed NaN");
        assert!(first.unwrap().contains("/plant/cmd/speed: rejected speed NaN"));
        for _ in 0..99 {
            assert!(c.reject(Rejection::InvalidSpeed, "cmd/speed", "speed NaN").is_none());
        }
        assert!(c.reject(Rejection::Stale, "cmd/speed", "stamp 0").is_some(), "another reason logs at once");
        assert_eq!(c.rejected[&Rejection::InvalidSpeed], 100);
        let status = c.status(vec![]);
        assert_eq!(status.level, DIAGNOSTIC_WARN);
        let get = |k: &str| status.values.iter().find(|v| v.key == k).unwrap().value.clone();
        assert_eq!(get("commands_rejected"), "101");
        assert_eq!(get("rejected_invalid_speed"), "100");
        assert_eq!(c.status(vec![]).level, DIAGNOSTIC_OK, "no new rejections since");
    }

    #[test]
    fn counts_refused_simulation_requests_per_result_code() {
        let mut c = SimulationCounters::new("/plant/sorting_line".into());
        let refusal = Refusal { code: code::INCORRECT_STATE, message: "the simulation is PLAYING".into() };
        let line = c.refuse("step_simulation", "steps 50", &refusal).unwrap();
        assert_eq!(
            line,
            "/plant/sorting_line/step_simulation: refused steps 50: the simulation is PLAYING [incorrect_state]"
        );
        assert!(c.refuse("step_simulation", "steps 50", &refusal).is_none(), "once per interval");
        let status = c.status(SimState::Playing, None);
        let get = |k: &str| status.values.iter().find(|v| v.key == k).unwrap().value.clone();
        assert_eq!(
            (get("refused_incorrect_state"), get("requests_refused"), get("simulation_state")),
            ("2".into(), "2".into(), "PLAYING".into())
        );
        assert_eq!(status.level, DIAGNOSTIC_WARN);
        assert_eq!(c.status(SimState::Playing, None).level, DIAGNOSTIC_OK);
    }
}
