//! Line commands and resets as the node receives them: speed and sort-mode commands on each line's
//! topics and on `batch/cmd` (every line at once), per-line `reset` and `batch/reset`. The rules
//! live in `ros::protocol`; here each command's fate is applied, counted and logged.

use ros2_client::{Gid, MessageInfo, RmwRequestId};

use super::super::messages::{LineCommands, ResetLineRequest, ResetLineResponse, ResetLinesRequest};
use super::super::messages::{ResetLinesResponse, Time};
use super::super::protocol::Rejection;
use super::super::protocol::{batch_commands, batch_resets, Accepted, BatchModes, Client, Command, HostedLine};
use super::lines::Line;
use super::server::Server;
use super::{batch_states, log, Graph};

/// A rejected command: why, and what it said (for the log).
type Refusal = (Rejection, String);

impl Server {
    /// `batch/cmd`: applied line by line; the batch state and /clock follow if any line stepped.
    pub(super) fn on_batch(&mut self, received: Result<(LineCommands, MessageInfo), String>) {
        if self.handle_batch(received) {
            self.graph.publish_batch_state(&self.lines);
            self.publish_clock();
        }
    }

    /// A command on line k's own topic.
    pub(super) fn on_command(&mut self, k: usize, topic: &str, received: Result<(Client, Time, Command), String>) {
        let line = &mut self.lines[k];
        let result = match received {
            Ok((client, stamp, command)) => line.apply(client, stamp, command),
            Err(error) => Err(malformed(&error)),
        };
        if line.settle(&mut self.graph, topic, result) {
            self.publish_clock();
        }
    }

    /// Applies a batch command line by line, through the same rules as the per-line topics
    /// (`protocol::batch_commands`). Returns whether any line stepped.
    fn handle_batch(&mut self, received: Result<(LineCommands, MessageInfo), String>) -> bool {
        let (cmd, client) = match received {
            Ok((cmd, info)) => (cmd, client_of(&info)),
            Err(error) => {
                self.lines[0].settle(&mut self.graph, "batch/cmd", Err(malformed(&error)));
                return false;
            }
        };
        let modes = BatchModes::of(self.params.line.variant, !self.params.evolution.is_empty());
        let entries = match batch_commands(&cmd, self.lines.len(), modes) {
            Ok(entries) => entries,
            Err(detail) => {
                self.lines[0].settle(&mut self.graph, "batch/cmd", Err((Rejection::Malformed, detail)));
                return false;
            }
        };
        let mut stepped = false;
        for (line, entry) in self.lines.iter_mut().zip(entries) {
            for command in entry.commands() {
                let result = line.apply(client, entry.stamp, command);
                stepped |= line.settle(&mut self.graph, "batch/cmd", result);
            }
        }
        stepped
    }

    /// `batch/reset`: resets the lines it names, or refuses the whole request if it is malformed
    /// (`protocol::batch_resets`); answers with every line's state either way.
    pub(super) async fn on_batch_reset(&mut self, id: RmwRequestId, request: ResetLinesRequest) {
        let response = match batch_resets(&request, self.lines.len()) {
            Ok(resets) => {
                for reset in &resets {
                    self.lines[reset.line].reset(&mut self.graph, reset.seed);
                }
                let message = format!("{} line(s) reset", resets.len());
                ResetLinesResponse { success: true, message, states: batch_states(&self.lines) }
            }
            Err(message) => {
                // Counted like a malformed batch/cmd (on line 0), logged by the counters.
                let refusal = (Rejection::Malformed, format!("request ({message})"));
                self.lines[0].settle(&mut self.graph, "batch/reset", Err(refusal));
                ResetLinesResponse { success: false, message, states: batch_states(&self.lines) }
            }
        };
        if let Err(error) = self.graph.batch_reset.async_send_response(id, response).await {
            log("WARN", format!("batch/reset: cannot send the response: {error:?}"));
        }
        self.graph.publish_batch_state(&self.lines);
        self.publish_clock();
    }

    /// Line k's `reset` service.
    pub(super) async fn on_reset(&mut self, k: usize, id: RmwRequestId, request: ResetLineRequest) {
        let line = &mut self.lines[k];
        let observation = line.reset(&mut self.graph, request.has_seed.then_some(request.seed));
        let response = ResetLineResponse::of(&line.host, observation, request.has_seed);
        if let Err(error) = line.reset.async_send_response(id, response).await {
            log("WARN", format!("{}/reset: cannot send the response: {error:?}", line.namespace));
        }
        self.graph.publish_batch_state(&self.lines);
        self.publish_clock();
    }
}

impl Line {
    fn apply(&mut self, client: Client, stamp: Time, command: Command) -> Result<Accepted, Refusal> {
        let result = self.host.command_from(client, stamp, command);
        result.map_err(|reason| {
            (reason, command_detail(&self.host, client, format!("{command} for stamp {}", show_stamp(stamp))))
        })
    }

    /// Counts and logs a command's fate; publishes the new tick if it completed one. Returns
    /// whether the line stepped.
    fn settle(&mut self, graph: &mut Graph, topic: &str, result: Result<Accepted, Refusal>) -> bool {
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

/// The participant that wrote a command (the GUID prefix of its writer).
pub(super) fn client_of(info: &MessageInfo) -> Client {
    let gid: Gid = info.publisher_gid();
    let mut client = Client::default();
    let n = client.len();
    client.copy_from_slice(&gid.as_bytes()[..n]);
    client
}

pub(super) fn show_client(client: Option<Client>) -> String {
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

fn malformed(error: &str) -> Refusal {
    (Rejection::Malformed, format!("message ({error})"))
}

pub(super) fn show_stamp(t: Time) -> String {
    format!("{}.{:09}", t.sec, t.nanosec)
}
