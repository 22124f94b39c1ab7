//! What a hosted line's current tick looks like in each message the node publishes or answers
//! with: the fillers of the wire types (`ros::messages`, plain mirrors of the .msg files), kept
//! here beside their publishers so that the wire types import nothing of the line.

use crate::ros::messages::{
    BeltOccupancy, EvolutionEvent, Header, LineState, LineStates, MaterialInput, MaterialRatio, ResetEvent,
    ResetLineResponse,
};
use crate::ros::protocol::HostedLine;
use crate::sim::evolution::{event_changes, fault_name, Settings};
use crate::sim::{Observation, Report};

/// The header of a line's current tick.
pub(super) fn header(host: &HostedLine) -> Header {
    Header { stamp: host.stamp(), frame_id: String::new() }
}

/// `input`: the batch entering the line and the sensor's reading of it.
pub(super) fn material_input(host: &HostedLine) -> MaterialInput {
    let line = host.line();
    let input = line.input();
    MaterialInput {
        header: header(host),
        episode: line.episode(),
        step: line.step_count(),
        quantity: line.observation().quantity,
        amount_a: input.a,
        amount_b: input.b,
        occupancy: input.occupancy(),
    }
}

/// `belt/occupancy`.
pub(super) fn belt_occupancy(host: &HostedLine) -> BeltOccupancy {
    let line = host.line();
    let belt = line.belt();
    BeltOccupancy {
        header: header(host),
        episode: line.episode(),
        step: line.step_count(),
        occupancy: belt.occupancy(),
        speed: line.speed(),
        amount_a: belt.a,
        amount_b: belt.b,
    }
}

/// `sensors/ratio` (advanced line).
pub(super) fn material_ratio(host: &HostedLine) -> MaterialRatio {
    let line = host.line();
    let input = line.input();
    MaterialRatio {
        header: header(host),
        episode: line.episode(),
        step: line.step_count(),
        ratio: input.ratio(),
        category: input.category() as u8,
    }
}

/// `events/reset`: the episode that just started, and whether its reset named a seed.
pub(super) fn reset_event(host: &HostedLine, seeded: bool) -> ResetEvent {
    let line = host.line();
    ResetEvent { header: header(host), episode: line.episode(), seed: line.seed(), seeded }
}

/// `events/evolution`: the events `indices` of the line's schedule, at the reset that started
/// the current episode (`at_reset`) or at the start of the tick the line waits at, and the
/// line's `settings` once they applied.
pub(super) fn evolution_event(
    host: &HostedLine,
    at_reset: bool,
    indices: &[usize],
    settings: &Settings,
) -> EvolutionEvent {
    let line = host.line();
    let events = &line.evolution().events;
    let (mut changed, mut values) = (Vec::new(), Vec::new());
    for &i in indices {
        for (field, value) in event_changes(&events[i]) {
            changed.push(field.to_string());
            values.push(value);
        }
    }
    let fault = settings.input_fault;
    EvolutionEvent {
        header: header(host),
        episode: line.episode(),
        tick: line.tick(),
        at_reset,
        event_indices: indices.iter().map(|&i| i as u32).collect(),
        changed,
        values,
        obs_noise: settings.obs_noise,
        action_penalty: settings.action_penalty,
        threshold: settings.threshold,
        input: settings.input.to_string(),
        sort_modes: settings.sort_modes,
        ratio_sensor: settings.ratio_sensor,
        input_fault: fault.map(|f| fault_name(f.kind).to_string()).unwrap_or_default(),
        input_fault_ticks: fault.map_or(0, |f| f.remaining),
    }
}

/// The `state` message of a line's current tick. Right after a reset no step has happened: it
/// reports the start state with reward 0.
pub(super) fn line_state(host: &HostedLine) -> LineState {
    let line = host.line();
    let r = Report::of(line);
    let [container_a, container_a_false, container_b, container_b_false] = r.containers;
    LineState {
        header: header(host),
        episode: r.episode,
        step: r.step,
        seed: r.seed,
        speed: r.speed,
        speed_index: r.speed_index as u8,
        mode: r.mode as u8,
        occupancy: r.occupancy,
        accuracy: r.accuracy,
        reward: r.reward,
        cumulative_reward: r.cumulative_reward,
        purity: r.purity,
        recall_a: r.recall_a,
        recall_b: r.recall_b,
        container_a,
        container_a_false,
        container_b,
        container_b_false,
        speed_changes: r.speed_changes,
        observation_quantity: line.observation().quantity,
        observation_category: host.category_reading(),
        terminated: false,
        truncated: r.truncated,
    }
}

/// `batch/state`: every hosted line's current state, stamped with the newest line's stamp.
pub(super) fn line_states<'a>(hosts: impl Iterator<Item = &'a HostedLine>) -> LineStates {
    let states: Vec<LineState> = hosts.map(line_state).collect();
    let stamp = states.iter().map(|s| s.header.stamp).max().unwrap_or_default();
    LineStates::from_states(Header { stamp, frame_id: String::new() }, &states)
}

/// The answer of a line's `reset` service after the reset.
pub(super) fn reset_response(host: &HostedLine, observation: Observation, seeded: bool) -> ResetLineResponse {
    let line = host.line();
    let how = if seeded { "seeded with" } else { "continuing the streams of seed" };
    ResetLineResponse {
        success: true,
        message: format!("episode {} started, {how} {}", line.episode(), line.seed()),
        seed: line.seed(),
        episode: line.episode(),
        stamp: host.stamp(),
        quantity: observation.quantity,
        category: host.category_reading(),
    }
}
