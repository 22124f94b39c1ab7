//! The clairvoyant oracle: for one episode seed, the highest total reward that any action sequence
//! reaches when the seed's random streams are known in advance, and a sequence that reaches it.
//! It is the ceiling an agent's score on that seed is measured against (the optimality gap): no
//! policy can beat it, and one that sees only observations usually cannot reach it.
//!
//! # Why a small dynamic programme is exact
//! A step's reward depends on the batch on the belt, the commanded speed and mode, the previous
//! speed (the switching penalty) and the accuracy noise drawn for that step; on nothing else (not
//! the containers, the sorter's accuracy or the observation). See `line.rs`, steps 3 to 5.
//! - **Belt batches do not depend on the actions.** The belt holds [`START_INPUT`] at step 0 and
//!   the input generator's batch `t - 1` at step `t`; the generator draws only from the input
//!   stream, which nothing else touches.
//! - **Noise values do not depend on the actions; which one a step uses does, by a count.** The
//!   noise stream feeds both the accuracy noise and the sensor. A reset draws 1 value (the first
//!   reading). A step draws 1 value for the accuracy, 1 more when the sort mode matches the belt
//!   batch (advanced line; the first is then discarded), then 1 for the reading, always (also
//!   with no sensor noise). So before step `t` the stream has given `1 + 2t + m` values, where `m`
//!   is the number of matched steps so far; step `t`'s accuracy noise is value `1 + 2t + m`, or
//!   the next one when the mode matches.
//!
//! So step `t`'s reward is a function of (previous speed, `m`, action) and the next state is
//! (speed, `m` + matched). The programme runs over those states: 10 per step on the basic line
//! (`m` is always 0), at most `10 (t + 1)` on the advanced one. On the advanced line the two modes
//! that do not match the belt batch have the same effect and use the same draws, so one of them
//! stands for both.
//!
//! # Exact in floating point too
//! The library sums an episode's rewards forwards from 0.0 (`Line::cumulative_reward`, `eval`).
//! The programme also runs forwards and keeps, for each state, the best such partial sum. Float
//! rounding is monotone (`a <= b` implies `fl(a + r) <= fl(b + r)`), so the best partial sum at a
//! state leads to the best at the next one. The result is therefore the maximum, over all
//! action sequences, of the exact `f64` the library reports. Replaying the returned actions
//! reproduces it bit for bit; [`replay`] does that, and `eval::evaluate_oracle` checks every episode.
//!
//! Cost of a 50-step episode: 5,000 transitions (basic), at most 255,000 (advanced).

use serde::Serialize;

use super::accuracy::{noiseless_accuracy, with_noise, ModeEffect};
use super::config::{LineConfig, Variant};
use super::input::InputGenerator;
use super::line::{Action, Line, START_INPUT};
use super::material::{Batch, SortMode, SORT_MODES};
use super::reward::reward;
use super::rng::{scale, stream, unit, Stream};
use super::speed::{SPEED_COUNT, START_SPEED_INDEX};

/// Longest advanced episode the oracle solves: its states grow with the square of the length
/// (2,000 steps: 20 million states, 40 MB of back-pointers, about a second).
pub const MAX_ADVANCED_STEPS: u32 = 2_000;

/// Noise values a reset draws (the first reading).
const RESET_DRAWS: usize = 1;
/// Noise values a step draws besides the matched mode's extra one: accuracy and reading.
const STEP_DRAWS: usize = 2;

/// The optimum of one episode seed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OracleEpisode {
    pub seed: u64,
    /// The highest episode reward, as the library sums it.
    pub reward: f64,
    /// An action sequence that reaches it, one per step.
    pub actions: Vec<Action>,
}

/// How the best partial sum of a state was reached.
#[derive(Clone, Copy)]
struct Back {
    previous_speed: u8,
    mode: u8,
}

/// The batches on the belt at steps 0..steps of an episode seeded `seed`.
fn belt_batches(config: &LineConfig, seed: u64, steps: usize) -> Vec<Batch> {
    let mut generator = InputGenerator::new(config.input, seed);
    std::iter::once(START_INPUT).chain(std::iter::repeat_with(|| generator.next_batch())).take(steps).collect()
}

/// The first `count` raw values of the episode's noise stream.
fn noise_values(seed: u64, count: usize) -> Vec<f64> {
    let mut rng = stream(seed, Stream::Noise);
    (0..count).map(|_| unit(&mut rng)).collect()
}

/// The modes worth trying on a batch: basic line none; advanced the matching one and one that
/// does not match (the two mismatching modes are interchangeable).
fn distinct_modes(variant: Variant, batch: Batch) -> Vec<SortMode> {
    match variant {
        Variant::Basic => vec![SortMode::Basic],
        Variant::Advanced => {
            let matching = SortMode::for_category(batch.category());
            let other = SORT_MODES.into_iter().find(|&m| m != matching).expect("three modes");
            vec![matching, other]
        }
    }
}

/// The clairvoyant optimum of the episode that a reset with `seed` starts.
pub fn solve(config: &LineConfig, seed: u64) -> Result<OracleEpisode, String> {
    config.validate().map_err(|e| e.to_string())?;
    if config.variant == Variant::Advanced && config.max_steps > MAX_ADVANCED_STEPS {
        return Err(format!(
            "max_steps = {} is out of range for the advanced oracle: allowed 1 ..= {MAX_ADVANCED_STEPS}",
            config.max_steps
        ));
    }
    let steps = config.max_steps as usize;
    let belts = belt_batches(config, seed, steps);
    let noise = noise_values(seed, RESET_DRAWS + (STEP_DRAWS + 1) * steps);
    // States (speed, m) at index speed * width + m; the basic line never matches, so m = 0.
    let width = match config.variant {
        Variant::Basic => 1,
        Variant::Advanced => steps + 1,
    };
    let mut best = vec![f64::NEG_INFINITY; SPEED_COUNT * width];
    best[START_SPEED_INDEX * width] = 0.0;
    let mut backs: Vec<Vec<Back>> = Vec::with_capacity(steps);
    for (t, &belt) in belts.iter().enumerate() {
        let mut next = vec![f64::NEG_INFINITY; SPEED_COUNT * width];
        let mut back = vec![Back { previous_speed: u8::MAX, mode: 0 }; SPEED_COUNT * width];
        let occupancy = belt.occupancy();
        let modes = distinct_modes(config.variant, belt);
        for m in 0..width.min(t + 1) {
            let drawn = RESET_DRAWS + STEP_DRAWS * t + m;
            for &mode in &modes {
                let effect = ModeEffect::of(config.variant, mode, belt.category());
                let matched = usize::from(effect == ModeEffect::Matched);
                let (low, high) = effect.noise_range();
                let noise_value = scale(noise[drawn + matched], low, high);
                for speed in 0..SPEED_COUNT {
                    let accuracy = with_noise(noiseless_accuracy(occupancy, speed, effect), noise_value);
                    let kept = reward(accuracy, config.threshold, speed, 0.0);
                    let changed = reward(accuracy, config.threshold, speed, config.action_penalty);
                    let target = speed * width + m + matched;
                    for previous in 0..SPEED_COUNT {
                        let candidate = best[previous * width + m] + if previous == speed { kept } else { changed };
                        if candidate > next[target] {
                            next[target] = candidate;
                            back[target] = Back { previous_speed: previous as u8, mode: mode.index() as u8 };
                        }
                    }
                }
            }
        }
        best = next;
        backs.push(back);
    }
    let (mut state, &total) =
        best.iter().enumerate().fold((0, &f64::NEG_INFINITY), |acc, (i, v)| if *v > *acc.1 { (i, v) } else { acc });
    let mut actions = Vec::with_capacity(steps);
    for (t, back) in backs.iter().enumerate().rev() {
        let (speed, m) = (state / width, state % width);
        let step = back[state];
        let mode = SortMode::from_index(step.mode).expect("a recorded mode");
        let matched = usize::from(ModeEffect::of(config.variant, mode, belts[t].category()) == ModeEffect::Matched);
        actions.push(Action::new(speed, mode));
        state = usize::from(step.previous_speed) * width + m - matched;
    }
    actions.reverse();
    Ok(OracleEpisode { seed, reward: total, actions })
}

/// The episode reward the library gives `actions` after a reset with `seed`.
pub fn replay(config: &LineConfig, seed: u64, actions: &[Action]) -> f64 {
    let mut line = Line::new(config.clone(), seed);
    for &action in actions {
        line.step(action);
    }
    line.cumulative_reward()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::config::{Setup, SETUPS, VARIANTS};

    #[test]
    fn belt_batches_are_the_lines() {
        for setup in SETUPS {
            let config = LineConfig::for_setup(setup, Variant::Basic);
            let mut line = Line::new(config.clone(), 9);
            let belts = belt_batches(&config, 9, 30);
            for (t, belt) in belts.iter().enumerate() {
                line.step(Action::new((t * 3) % SPEED_COUNT, SortMode::Basic));
                assert_eq!(line.belt(), *belt, "{setup:?} step {t}");
            }
        }
    }

    #[test]
    fn solution_replays_to_its_reward_exactly() {
        for setup in SETUPS {
            for variant in VARIANTS {
                let config = LineConfig::for_setup(setup, variant);
                let best = solve(&config, 42).unwrap();
                assert_eq!(best.actions.len(), 50);
                assert_eq!(replay(&config, 42, &best.actions), best.reward, "{setup:?} {variant}");
            }
        }
    }

    #[test]
    fn long_advanced_episodes_are_refused_with_the_range() {
        let config =
            LineConfig { max_steps: MAX_ADVANCED_STEPS + 1, ..LineConfig::for_setup(Setup::A, Variant::Advanced) };
        let err = solve(&config, 1).unwrap_err();
        assert_eq!(err, "max_steps = 2001 is out of range for the advanced oracle: allowed 1 ..= 2000");
        let basic = LineConfig { max_steps: 5_000, ..LineConfig::for_setup(Setup::B, Variant::Basic) };
        let best = solve(&basic, 1).unwrap();
        assert_eq!(replay(&basic, 1, &best.actions), best.reward);
    }
}
