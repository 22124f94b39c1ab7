//! What a line reports of itself at a tick, read once from a [`Line`]: the values of the node's
//! `state` message (`ros::node::line_messages::line_state`) and of the native env's info dict
//! (`native/src/info.rs`), so the two backends cannot report a line differently.

use super::line::Line;

/// A line's report after its last step; right after a reset (no step yet), the start state with
/// reward 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report {
    pub episode: u32,
    /// Steps taken in this episode.
    pub step: u32,
    pub seed: u64,
    pub speed: f64,
    pub speed_index: usize,
    /// The sort mode's index (`SortMode as usize`).
    pub mode: usize,
    /// Occupancy of the batch on the belt.
    pub occupancy: f64,
    /// Accuracy set for the batch on the belt.
    pub accuracy: f64,
    pub reward: f64,
    pub cumulative_reward: f64,
    pub purity: f64,
    pub recall_a: f64,
    pub recall_b: f64,
    /// The container counters `(a, a_false, b, b_false)`, each capped at `u32::MAX` (the
    /// messages' field type).
    pub containers: [u32; 4],
    pub speed_changes: u32,
    pub truncated: bool,
}

impl Report {
    /// The report of `line` as it stands.
    pub fn of(line: &Line) -> Self {
        let c = line.containers();
        let count = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
        let (occupancy, accuracy, reward) = match line.last_step() {
            Some(o) => (o.occupancy, o.accuracy, o.reward),
            None => (line.belt().occupancy(), line.belt_accuracy(), 0.0),
        };
        Report {
            episode: line.episode(),
            step: line.step_count(),
            seed: line.seed(),
            speed: line.speed(),
            speed_index: line.speed_index(),
            mode: line.mode() as usize,
            occupancy,
            accuracy,
            reward,
            cumulative_reward: line.cumulative_reward(),
            purity: c.purity(),
            recall_a: c.recall_a(),
            recall_b: c.recall_b(),
            containers: [count(c.a), count(c.a_false), count(c.b), count(c.b_false)],
            speed_changes: line.speed_changes(),
            truncated: line.truncated(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Action, LineConfig, Setup, SortMode, Variant};

    #[test]
    fn a_fresh_line_reports_its_start_state_with_reward_zero() {
        let line = Line::new(LineConfig::for_setup(Setup::A, Variant::Basic), 1);
        let r = Report::of(&line);
        assert_eq!((r.step, r.reward, r.containers, r.speed_changes), (0, 0.0, [0; 4], 0));
        assert_eq!((r.occupancy, r.accuracy), (line.belt().occupancy(), line.belt_accuracy()));
        assert!(!r.truncated);
    }

    #[test]
    fn after_a_step_it_reports_that_step() {
        let mut line = Line::new(LineConfig::for_setup(Setup::B, Variant::Advanced), 9);
        line.step(Action::new(2, SortMode::Positive));
        let out = line.step(Action::new(7, SortMode::Negative));
        let r = Report::of(&line);
        assert_eq!((r.step, r.reward, r.accuracy, r.occupancy), (2, out.reward, out.accuracy, out.occupancy));
        assert_eq!((r.speed_index, r.mode, r.speed_changes), (7, SortMode::Negative as usize, 2));
        let c = line.containers();
        assert_eq!(r.containers, [c.a, c.a_false, c.b, c.b_false].map(|v| v as u32));
        assert_eq!((r.purity, r.seed, r.episode), (c.purity(), line.seed(), line.episode()));
    }
}
