//! The Bayes-optimal policy of the basic line with exact readings (setups A and B): of all
//! policies that know only what an agent knows (the readings so far, the belt speed, the step),
//! and not the seed's streams, the one with the highest *expected* episode reward. The clairvoyant
//! oracle (`oracle.rs`) bounds what any policy gets on a seed; this is the best a policy can get on
//! average, so `oracle - bayes` is the value of knowing the future and `bayes - agent` is what a
//! policy leaves on the table.
//!
//! # Why the belief is small here
//! With exact readings the agent knows the total of the batch it acts on, so the immediate
//! reward's expectation is known in closed form (`accuracy::accuracy_law`; the accuracy noise is
//! a fresh independent draw each step, and the basic line has no sort mode). The future depends on
//! the input generator's hidden state. For seasonal input, the hidden state is the pattern and its
//! age and length. On the basic line, only the pattern's *amount class* matters (its band of totals),
//! and within a class the totals are uniform whatever the pattern, so they tell nothing more.
//! A change of class can only happen where a new pattern starts, so the belief about the hidden age and length
//! is a function of the run age `d`: the number of batches since the class last changed (or since
//! the first batch, which also starts a pattern). A new pattern keeps the class with probability
//! 1/3, unseen, and the filter over (age, length) includes that. So the information state is
//! (step, speed, reading, run age), and backward induction over it is exact. Random input
//! is independent from batch to batch, so the run age plays no part.
//!
//! # Where it is not tractable
//! - Sensor noise (C, D): the reading no longer fixes the total or the class; the belief over the
//!   297 hidden generator states (9 patterns x ages 1..=L, L = 10, 11, 12), and over the current
//!   total, becomes a continuous distribution. The rewards seen (accuracy above the threshold
//!   reveals the total) also feed it. Random input with zero penalty (C) needs no belief: batches are
//!   independent and a policy's decisions do not interact, so the myopic `rba` (exact posterior
//!   expected reward of the reading) already is the Bayes-optimal policy.
//! - Advanced line on seasonal input (B advanced): the ratio category tells which pattern runs, and
//!   also where a pattern changes within a class (e.g. mixed -> A-rich). But patterns leak categories
//!   (pattern 2 gives "basic" 6.1 % of the time), so the belief depends on the whole category
//!   sequence since the last class change, up to 9^d histories, and is no longer a function of a
//!   few counters.

use super::accuracy::{accuracy_law, noiseless_accuracy, ModeEffect};
use super::config::{InputKind, LineConfig, Variant};
use super::input::{amount_bands, MAX_TOTAL, PATTERN_LENGTH};
use super::line::{Action, Observation, START_INPUT};
use super::material::{Category, SortMode};
use super::observation::level;
use super::reward::expected_reward;
use super::speed::{SPEED_COUNT, START_SPEED_INDEX};

/// Longest episode the policy is planned for: its table grows with the square of the length
/// (200 steps: 40 MB).
pub const MAX_STEPS: u32 = 200;

/// Reading levels (totals 0..=100).
const TOTALS: usize = MAX_TOTAL + 1;

/// The planned policy: a decision for every (step, speed, reading, run age).
#[derive(Clone, Debug)]
pub struct BayesPolicy {
    steps: usize,
    /// Run ages 1..ages (index 0 unused).
    ages: usize,
    bands: Vec<(u32, u32)>,
    seasonal: bool,
    /// Speed index per `((t * SPEED_COUNT + speed) * TOTALS + total) * ages + age`.
    decisions: Vec<u8>,
    /// Expected episode reward from the reset.
    expected: f64,
}

/// How the input regime moves on, seen from a run of one class that is `d` batches old.
struct RunModel {
    /// P(the next batch keeps the class), by run age.
    stay: Vec<f64>,
    /// P(the next batch is of one given other class), by run age.
    to_other: Vec<f64>,
}

/// The filter over the current pattern's (age, length) given that its class has held for `d`
/// batches since it last changed. New patterns are uniform over `classes` amount classes.
fn run_model(classes: usize, ages: usize) -> RunModel {
    let (low, high) = (PATTERN_LENGTH.0 as usize, PATTERN_LENGTH.1 as usize);
    let p_length = 1.0 / (high - low) as f64;
    let p_class = 1.0 / classes as f64;
    // belief[length - low][age - 1]
    let mut belief: Vec<Vec<f64>> =
        (low..high).map(|l| (0..l).map(|a| if a == 0 { p_length } else { 0.0 }).collect()).collect();
    let (mut stay, mut to_other) = (vec![0.0; ages + 1], vec![0.0; ages + 1]);
    for d in 1..=ages {
        let ends: f64 = belief.iter().map(|b| b[b.len() - 1]).sum();
        stay[d] = 1.0 - ends * (1.0 - p_class);
        to_other[d] = ends * p_class;
        let mut next: Vec<Vec<f64>> = belief.iter().map(|b| vec![0.0; b.len()]).collect();
        for (b, n) in belief.iter().zip(&mut next) {
            for age in 1..b.len() {
                n[age] = b[age - 1] / stay[d];
            }
            n[0] = ends * p_class * p_length / stay[d];
        }
        belief = next;
    }
    RunModel { stay, to_other }
}

/// Expected reward of moving to `speed` (from `current`) on a batch of `total` units.
fn immediate(config: &LineConfig, total: usize, speed: usize, current: usize) -> f64 {
    let c = noiseless_accuracy(total as f64 / 100.0, speed, ModeEffect::NoMode);
    let law = accuracy_law(c, ModeEffect::NoMode, config.threshold);
    let penalty = if speed == current { 0.0 } else { config.action_penalty };
    expected_reward(&law, config.threshold, speed, penalty)
}

/// The amount class of a total: its band, or the nearest one (for readings no band produces).
fn class_of(bands: &[(u32, u32)], total: usize) -> usize {
    let distance = |&(low, high): &(u32, u32)| {
        let t = total as i64;
        if t < i64::from(low) {
            i64::from(low) - t
        } else {
            (t - i64::from(high) + 1).max(0)
        }
    };
    (0..bands.len()).min_by_key(|&c| distance(&bands[c])).expect("at least one band")
}

/// Which configurations this policy is exact for, and why not the others.
fn check(config: &LineConfig) -> Result<(), String> {
    config.validate().map_err(|e| e.to_string())?;
    if config.variant != Variant::Basic {
        return Err("the Bayes-optimal policy is solved for the basic line only: on the advanced line the ratio categories make the belief over seasonal patterns depend on the whole category history (see sim/bayes.rs)".into());
    }
    if config.obs_noise != 0.0 {
        return Err(format!(
            "obs_noise = {} is out of range for the Bayes-optimal policy: allowed 0.0 (with a noisy sensor the belief is continuous; on random input with no penalty, rba already is Bayes-optimal)",
            config.obs_noise
        ));
    }
    if config.max_steps > MAX_STEPS {
        return Err(format!(
            "max_steps = {} is out of range for the Bayes-optimal policy: allowed 1 ..= {MAX_STEPS}",
            config.max_steps
        ));
    }
    Ok(())
}

impl BayesPolicy {
    /// Plans the Bayes-optimal policy by backward induction.
    pub fn build(config: &LineConfig) -> Result<Self, String> {
        check(config)?;
        Ok(plan(config, |_, _, _, _, values| argmax(values)))
    }

    /// Expected episode reward of the policy from a reset (the model's value, not a sample).
    pub fn expected_reward(&self) -> f64 {
        self.expected
    }

    fn decision(&self, t: usize, speed: usize, total: usize, age: usize) -> usize {
        let t = t.min(self.steps - 1);
        usize::from(self.decisions[((t * SPEED_COUNT + speed) * TOTALS + total) * self.ages + age.min(self.ages - 1)])
    }
}

/// The best speed; ties go to the slowest.
fn argmax(values: &[f64; SPEED_COUNT]) -> usize {
    (0..SPEED_COUNT).fold(0, |best, a| if values[a] > values[best] { a } else { best })
}

/// Backward induction over (step, speed, reading, run age) with `pick(t, speed, total, age,
/// values)` choosing the speed from the action values: the argmax plans the optimal policy;
/// a fixed choice evaluates another policy exactly under the same model.
fn plan(
    config: &LineConfig,
    mut pick: impl FnMut(usize, usize, usize, usize, &[f64; SPEED_COUNT]) -> usize,
) -> BayesPolicy {
    let steps = config.max_steps as usize;
    let bands = amount_bands(config.input);
    let seasonal = config.input != InputKind::Random;
    let ages = if seasonal { steps + 1 } else { 2 };
    let model = run_model(bands.len(), ages);
    let immediate: Vec<[[f64; SPEED_COUNT]; SPEED_COUNT]> = (0..TOTALS)
        .map(|n| std::array::from_fn(|current| std::array::from_fn(|speed| immediate(config, n, speed, current))))
        .collect();
    let mut decisions = vec![0u8; steps * SPEED_COUNT * TOTALS * ages];
    // mean_next[(speed * classes + class) * ages + age]: the expected value of the next step's state
    // (its total uniform over the class band) when this step ends at `speed`.
    let classes = bands.len();
    let mut mean_next = vec![0.0; SPEED_COUNT * classes * ages];
    let mut expected = 0.0;
    for t in (0..steps).rev() {
        let mut values_here = vec![0.0; SPEED_COUNT * TOTALS * ages];
        let age_range = if t == 0 || !seasonal { 1..2 } else { 1..t.min(ages - 1) + 1 };
        // Expected continuation after moving to `speed` now, from a batch of `class`, run age `d`.
        let continuation = |speed: usize, class: usize, d: usize| -> f64 {
            if t + 1 >= steps {
                return 0.0;
            }
            let at = |c: usize, a: usize| mean_next[(speed * classes + c) * ages + a];
            if t == 0 {
                // The first generator batch starts a pattern of a uniform class.
                return (0..classes).map(|c| at(c, 1)).sum::<f64>() / classes as f64;
            }
            if !seasonal {
                return at(0, 1);
            }
            let others: f64 = (0..classes).filter(|&c| c != class).map(|c| at(c, 1)).sum();
            model.stay[d] * at(class, (d + 1).min(ages - 1)) + model.to_other[d] * others
        };
        let mut future = vec![0.0; SPEED_COUNT * classes * ages];
        for a in 0..SPEED_COUNT {
            for class in 0..classes {
                for d in age_range.clone() {
                    future[(a * classes + class) * ages + d] = continuation(a, class, d);
                }
            }
        }
        for speed in 0..SPEED_COUNT {
            for total in 0..TOTALS {
                let class = class_of(&bands, total);
                for d in age_range.clone() {
                    let values: [f64; SPEED_COUNT] =
                        std::array::from_fn(|a| immediate[total][speed][a] + future[(a * classes + class) * ages + d]);
                    let chosen = pick(t, speed, total, d, &values);
                    decisions[((t * SPEED_COUNT + speed) * TOTALS + total) * ages + d] = chosen as u8;
                    values_here[(speed * TOTALS + total) * ages + d] = values[chosen];
                }
            }
        }
        if t == 0 {
            expected = values_here[(START_SPEED_INDEX * TOTALS + START_INPUT.total() as usize) * ages + 1];
        }
        for speed in 0..SPEED_COUNT {
            for (class, &(low, high)) in bands.iter().enumerate() {
                for d in age_range.clone() {
                    let sum: f64 = (low..high).map(|n| values_here[(speed * TOTALS + n as usize) * ages + d]).sum();
                    mean_next[(speed * classes + class) * ages + d] = sum / f64::from(high - low);
                }
            }
        }
    }
    BayesPolicy { steps, ages, bands, seasonal, decisions, expected }
}

/// The exact expected episode reward of a policy that decides from (reading, current speed)
/// alone, such as `rba` and `rba-hold`, under the same model: what [`BayesPolicy`] is held
/// against.
pub fn expected_reward_of(
    config: &LineConfig,
    mut policy: impl FnMut(Observation, usize) -> Action,
) -> Result<f64, String> {
    check(config)?;
    Ok(plan(config, |_, speed, total, _, _| {
        let observation = Observation { quantity: total as f64 / 100.0, category: Category::Basic };
        policy(observation, speed).speed_index
    })
    .expected)
}

/// The policy acting in an episode: it follows the run age of the amount class from the readings.
#[derive(Clone, Debug)]
pub struct BayesAgent {
    policy: Box<BayesPolicy>,
    step: usize,
    class: usize,
    age: usize,
}

impl BayesAgent {
    pub fn new(config: &LineConfig) -> Result<Self, String> {
        Ok(BayesAgent { policy: Box::new(BayesPolicy::build(config)?), step: 0, class: 0, age: 1 })
    }

    /// Starts an episode (the step and run age restart).
    pub fn restart(&mut self) {
        (self.step, self.class, self.age) = (0, 0, 1);
    }

    pub fn policy(&self) -> &BayesPolicy {
        &self.policy
    }

    pub fn act(&mut self, observation: Observation, current_speed: usize) -> Action {
        let total = level(observation.quantity);
        if self.step >= 1 {
            // From step 1 on the reading is a generator batch: track its class's run age.
            let class = class_of(&self.policy.bands, total);
            self.age = if self.step > 1 && class == self.class && self.policy.seasonal { self.age + 1 } else { 1 };
            self.class = class;
        }
        let speed = self.policy.decision(self.step, current_speed, total, self.age);
        self.step += 1;
        Action::new(speed, SortMode::Basic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::config::Setup;

    #[test]
    fn run_model_is_a_distribution_and_changes_only_at_pattern_ends() {
        let model = run_model(3, 40);
        for d in 1..=40 {
            let total = model.stay[d] + 2.0 * model.to_other[d];
            assert!((total - 1.0).abs() < 1e-12, "d = {d}: {total}");
        }
        // A pattern lasts at least 10 batches: no change before the tenth.
        assert!((1..10).all(|d| model.to_other[d] == 0.0));
        // After 10: one in three patterns end there, and two in three of those change class.
        assert!((model.to_other[10] - 1.0 / 3.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn unsupported_lines_are_refused_with_the_reason() {
        let err = BayesPolicy::build(&LineConfig::for_setup(Setup::D, Variant::Basic)).unwrap_err();
        assert!(err.starts_with("obs_noise = 0.3 is out of range for the Bayes-optimal policy: allowed 0.0"), "{err}");
        let err = BayesPolicy::build(&LineConfig::for_setup(Setup::B, Variant::Advanced)).unwrap_err();
        assert!(err.contains("basic line only"), "{err}");
        let long = LineConfig { max_steps: 201, ..LineConfig::for_setup(Setup::B, Variant::Basic) };
        assert!(BayesPolicy::build(&long).unwrap_err().contains("allowed 1 ..= 200"));
    }
}
