//! The input generators: what enters the line each tick, as in the reference's
//! `RandomInputGenerator`, `SeasonalInputGenerator` (9 patterns) and
//! `SimpleSeasonalInputGenerator` (3 patterns).
//!
//! Order of draws from the input stream (`rng::Stream::Input`):
//! - random: total = integer 5..=95, then A = integer 0..=total; B = total - A.
//! - seasonal (9): on (re)seeding, pattern = integer 1..=9 then length = integer 10..=12.
//!   Each batch: if the pattern has run its length, draw a new pattern and length first;
//!   then total (10..=29, 40..=59 or 70..=89 by pattern), then the ratio
//!   r = U(0.4, 2.0), U(3, 10) or U(0.1, 0.3) rounded to 2 decimals; B = ceil(total / (1 + r)),
//!   A = total - B.
//! - seasonal (3): as seasonal (9) with patterns 1..=3 (little, medium, much input) choosing only
//!   the total; then A = integer 0..=total.
//!
//! [`prior`] gives the exact long-run distribution of (total, ratio category) of each generator,
//! which the rule-based agent uses to interpret a noisy input reading.

use super::config::InputKind;
use super::material::Batch;
use super::rng::{integer, stream, uniform, SimRng, Stream};
use super::round::round2;

/// Largest total a batch can have, in units (an occupancy of 1.0).
pub const MAX_TOTAL: usize = 100;

/// Totals of random input: a uniform integer in `low..high` (5..=95).
const RANDOM_TOTAL: (u32, u32) = (5, 96);

/// Length of a seasonal pattern in batches: a uniform integer in `low..high` (10, 11 or 12).
pub const PATTERN_LENGTH: (u32, u32) = (10, 13);

/// A seeded input generator of one line.
#[derive(Clone, Debug)]
pub struct InputGenerator {
    kind: InputKind,
    rng: SimRng,
    pattern: u8,
    pattern_length: u32,
    step_in_pattern: u32,
}

impl InputGenerator {
    pub fn new(kind: InputKind, seed: u64) -> Self {
        let mut generator = InputGenerator {
            kind,
            rng: stream(seed, Stream::Input),
            pattern: 0,
            pattern_length: 0,
            step_in_pattern: 0,
        };
        generator.reseed(seed);
        generator
    }

    /// Restarts the stream from `seed`; seasonal generators choose their first pattern at once.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = stream(seed, Stream::Input);
        self.pattern = 0;
        if self.kind != InputKind::Random {
            self.select_pattern();
        }
    }

    /// The seasonal pattern in force (1..=9 or 1..=3), 0 for random input.
    pub fn pattern(&self) -> u8 {
        self.pattern
    }

    fn pattern_count(&self) -> u32 {
        match self.kind {
            InputKind::Random => 0,
            InputKind::Seasonal => 9,
            InputKind::Seasonal3 => 3,
        }
    }

    fn select_pattern(&mut self) {
        let count = self.pattern_count();
        self.pattern = integer(&mut self.rng, 1, count + 1) as u8;
        self.pattern_length = integer(&mut self.rng, PATTERN_LENGTH.0, PATTERN_LENGTH.1);
        self.step_in_pattern = 0;
    }

    /// Draws the next batch.
    pub fn next_batch(&mut self) -> Batch {
        match self.kind {
            InputKind::Random => {
                let total = integer(&mut self.rng, RANDOM_TOTAL.0, RANDOM_TOTAL.1);
                let a = integer(&mut self.rng, 0, total + 1);
                Batch::new(a, total - a)
            }
            InputKind::Seasonal | InputKind::Seasonal3 => {
                if self.step_in_pattern >= self.pattern_length {
                    self.select_pattern();
                }
                self.step_in_pattern += 1;
                let (low, high) = total_band(self.kind, self.pattern);
                let total = integer(&mut self.rng, low, high);
                if self.kind == InputKind::Seasonal3 {
                    let a = integer(&mut self.rng, 0, total + 1);
                    return Batch::new(a, total - a);
                }
                let (r_low, r_high) = ratio_band(self.pattern);
                let ratio = round2(uniform(&mut self.rng, r_low, r_high));
                split_by_ratio(total, ratio)
            }
        }
    }
}

/// The amount classes of a generator: the bands of batch totals (`low..high`) its patterns draw
/// from, one per class. Random input is one class (5..=95); the seasonal generators have three
/// (little, medium, much input) and a new pattern falls in each with probability 1/3.
pub fn amount_bands(kind: InputKind) -> Vec<(u32, u32)> {
    match kind {
        InputKind::Random => vec![RANDOM_TOTAL],
        InputKind::Seasonal => [1, 4, 7].map(|p| total_band(kind, p)).to_vec(),
        InputKind::Seasonal3 => [1, 2, 3].map(|p| total_band(kind, p)).to_vec(),
    }
}

/// Totals of a seasonal pattern: `low..high`, upper bound excluded.
fn total_band(kind: InputKind, pattern: u8) -> (u32, u32) {
    let amount_class = match kind {
        InputKind::Seasonal => (pattern - 1) / 3,
        _ => pattern - 1,
    };
    match amount_class {
        0 => (10, 30),
        1 => (40, 60),
        _ => (70, 90),
    }
}

/// A/B ratio range of a 9-pattern seasonal pattern: 1/4/7 mixed, 2/5/8 A-rich, 3/6/9 B-rich.
fn ratio_band(pattern: u8) -> (f64, f64) {
    match (pattern - 1) % 3 {
        0 => (0.4, 2.0),
        1 => (3.0, 10.0),
        _ => (0.1, 0.3),
    }
}

/// B = ceil(total / (1 + r)), A = total - B (so the realised ratio is a little below r).
fn split_by_ratio(total: u32, ratio: f64) -> Batch {
    let b = (f64::from(total) / (1.0 + ratio)).ceil() as u32;
    Batch::new(total - b, b)
}

/// Joint long-run probability of (total, category) for a generator: `prior[total][category]`.
///
/// Exact, not sampled: it enumerates every total, every A (random, seasonal-3) or every rounded
/// ratio (seasonal-9, where `round(U(lo, hi), 2)` puts half weight on the two end values).
/// Seasonal patterns are equally likely in the long run (uniform choice, same length law).
pub fn prior(kind: InputKind) -> [[f64; 3]; MAX_TOTAL + 1] {
    let mut p = [[0.0; 3]; MAX_TOTAL + 1];
    let add_uniform_split = |p: &mut [[f64; 3]; MAX_TOTAL + 1], total: u32, weight: f64| {
        let share = weight / f64::from(total + 1);
        for a in 0..=total {
            p[total as usize][Batch::new(a, total - a).category().index()] += share;
        }
    };
    match kind {
        InputKind::Random => {
            for total in 5..=95 {
                add_uniform_split(&mut p, total, 1.0 / 91.0);
            }
        }
        InputKind::Seasonal3 => {
            for pattern in 1..=3u8 {
                let (low, high) = total_band(kind, pattern);
                for total in low..high {
                    add_uniform_split(&mut p, total, 1.0 / 3.0 / f64::from(high - low));
                }
            }
        }
        InputKind::Seasonal => {
            for pattern in 1..=9u8 {
                let (low, high) = total_band(kind, pattern);
                let (r_low, r_high) = ratio_band(pattern);
                let (first, last) = ((r_low * 100.0).round() as u32, (r_high * 100.0).round() as u32);
                let steps = f64::from(last - first);
                for total in low..high {
                    let weight = 1.0 / 9.0 / f64::from(high - low);
                    for hundredths in first..=last {
                        let ends = hundredths == first || hundredths == last;
                        let w = if ends { 0.5 } else { 1.0 } / steps;
                        let batch = split_by_ratio(total, f64::from(hundredths) / 100.0);
                        p[total as usize][batch.category().index()] += weight * w;
                    }
                }
            }
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::material::CATEGORIES;

    fn shares(kind: InputKind, n: usize) -> [f64; 3] {
        let mut g = InputGenerator::new(kind, 11);
        let mut counts = [0usize; 3];
        for _ in 0..n {
            counts[g.next_batch().category().index()] += 1;
        }
        counts.map(|c| c as f64 / n as f64)
    }

    #[test]
    fn random_input_stays_in_range_and_matches_reference_shares() {
        let mut g = InputGenerator::new(InputKind::Random, 3);
        for _ in 0..10_000 {
            let b = g.next_batch();
            assert!((5..=95).contains(&b.total()));
        }
        // Reference: basic 0.478, positive 0.261, negative 0.261 over 100k samples.
        let s = shares(InputKind::Random, 100_000);
        assert!((s[0] - 0.478).abs() < 0.01 && (s[1] - 0.261).abs() < 0.01, "{s:?}");
    }

    #[test]
    fn seasonal_patterns_run_ten_to_twelve_steps_within_their_bands() {
        let mut g = InputGenerator::new(InputKind::Seasonal, 5);
        let mut runs = vec![];
        let (mut current, mut run) = (g.pattern(), 0);
        for _ in 0..5_000 {
            let before = g.step_in_pattern >= g.pattern_length;
            let b = g.next_batch();
            let (lo, hi) = total_band(InputKind::Seasonal, g.pattern());
            assert!((lo..hi).contains(&b.total()));
            if before {
                runs.push(run);
                run = 0;
            }
            current = g.pattern();
            run += 1;
        }
        assert!((1..=9).contains(&current));
        assert!(runs.iter().all(|r| (10..=12).contains(r)), "{runs:?}");
    }

    #[test]
    fn prior_is_a_distribution_and_matches_sampling() {
        for kind in [InputKind::Random, InputKind::Seasonal, InputKind::Seasonal3] {
            let p = prior(kind);
            let total: f64 = p.iter().flatten().sum();
            assert!((total - 1.0).abs() < 1e-9, "{kind:?} sums to {total}");
            let s = shares(kind, 200_000);
            for c in CATEGORIES {
                let exact: f64 = p.iter().map(|row| row[c.index()]).sum();
                assert!((exact - s[c.index()]).abs() < 0.01, "{kind:?} {c:?}: {exact} vs {}", s[c.index()]);
            }
        }
    }

    #[test]
    fn reseeding_repeats_the_stream() {
        let mut g = InputGenerator::new(InputKind::Seasonal, 42);
        let first: Vec<Batch> = (0..30).map(|_| g.next_batch()).collect();
        g.reseed(42);
        let again: Vec<Batch> = (0..30).map(|_| g.next_batch()).collect();
        assert_eq!(first, again);
    }
}
