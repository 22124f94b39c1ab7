//! The accuracy model: how well the batch on the belt will be sorted, given the belt speed,
//! its occupancy and (advanced line) whether the sorting mode matches the batch.
//!
//! accuracy = clamp(clamp(base + mode effect, 0, 1) - noise, 0, 1), where
//! base = 1 within the speed's occupancy limit and 1 - 3 * excess above it, and the noise is
//! *subtracted*: U(0.10, 0.15), or U(0, 0.05) when the mode matches. The clamp before the noise is
//! the reference's; it caps what the +0.15 match bonus can make up for at 0.05 of excess.

use super::config::Variant;
use super::material::{Category, SortMode};
use super::speed::OCCUPANCY_LIMITS;

/// Accuracy lost per unit of occupancy above the speed's limit.
pub const ABATEMENT_RATE: f64 = 3.0;
/// Subtracted noise without a matching mode: U(0.10, 0.15).
pub const NOISE: (f64, f64) = (0.1, 0.15);
/// Subtracted noise with a matching mode: U(0, 0.05).
pub const MATCHED_NOISE: (f64, f64) = (0.0, 0.05);
/// Base-accuracy bonus of a matching sort mode.
pub const MATCH_BONUS: f64 = 0.15;
/// Base-accuracy loss of a sort mode that does not match the batch.
pub const MISMATCH_MALUS: f64 = 0.1;
/// Accuracy of the two batches already in the line after a reset.
pub const START_ACCURACY: f64 = 0.75;

/// How the sorting mode acts on a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeEffect {
    /// Basic line: there is no sorting mode.
    NoMode,
    Matched,
    Mismatched,
}

impl ModeEffect {
    /// How a sort mode acts on a batch of `category` on a line of `variant`.
    pub fn of(variant: Variant, mode: SortMode, category: Category) -> Self {
        match variant {
            Variant::Basic => ModeEffect::NoMode,
            Variant::Advanced if mode.matches(category) => ModeEffect::Matched,
            Variant::Advanced => ModeEffect::Mismatched,
        }
    }

    /// The range of the subtracted noise under this effect.
    pub fn noise_range(self) -> (f64, f64) {
        match self {
            ModeEffect::Matched => MATCHED_NOISE,
            _ => NOISE,
        }
    }
}

/// Accuracy before noise, clamped to 0..=1.
pub fn noiseless_accuracy(occupancy: f64, speed_index: usize, effect: ModeEffect) -> f64 {
    let limit = OCCUPANCY_LIMITS[speed_index];
    let mut accuracy = if occupancy <= limit { 1.0 } else { 1.0 - (occupancy - limit) * ABATEMENT_RATE };
    match effect {
        ModeEffect::NoMode => {}
        ModeEffect::Matched => accuracy += MATCH_BONUS,
        ModeEffect::Mismatched => accuracy -= MISMATCH_MALUS,
    }
    accuracy.clamp(0.0, 1.0)
}

/// The accuracy after subtracting a drawn noise value.
pub fn with_noise(noiseless: f64, noise: f64) -> f64 {
    (noiseless - noise).clamp(0.0, 1.0)
}

/// Closed-form statistics of `max(c - N, 0)` for N ~ U(low, high), and of the event
/// `c - N >= threshold` that decides whether a step earns more than the flat -0.1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccuracyLaw {
    /// E\[accuracy\].
    pub mean: f64,
    /// P(accuracy >= threshold).
    pub p_above: f64,
    /// E[accuracy | accuracy >= threshold] (0 when that has probability 0).
    pub mean_above: f64,
}

/// The law of the accuracy for a noiseless accuracy `c` (in 0..=1) and the given effect.
pub fn accuracy_law(c: f64, effect: ModeEffect, threshold: f64) -> AccuracyLaw {
    let (low, high) = effect.noise_range();
    let width = high - low;
    let mean = if c >= high {
        c - (low + high) / 2.0
    } else if c <= low {
        0.0
    } else {
        (c - low) * (c - low) / (2.0 * width)
    };
    // accuracy >= threshold  <=>  N <= c - threshold (threshold > 0, so the clamp at 0 never passes).
    let cut = (c - threshold).min(high);
    let (p_above, mean_above) = if cut < low { (0.0, 0.0) } else { ((cut - low) / width, c - (low + cut) / 2.0) };
    AccuracyLaw { mean, p_above, mean_above }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base_accuracy_follows_limits() {
        assert_eq!(noiseless_accuracy(0.7, 3, ModeEffect::NoMode), 1.0); // exactly at the limit of 0.4
        let over = noiseless_accuracy(0.8, 3, ModeEffect::NoMode);
        assert!((over - 0.7).abs() < 1e-12);
        assert_eq!(noiseless_accuracy(1.0, 9, ModeEffect::NoMode), 0.0); // 1 - 2.7 clamps to 0
                                                                         // The clamp comes before the noise: a matched mode cannot exceed 1.
        assert_eq!(noiseless_accuracy(0.3, 5, ModeEffect::Matched), 1.0);
        assert!((noiseless_accuracy(0.52, 5, ModeEffect::Matched) - 1.0).abs() < 1e-12);
        assert!((noiseless_accuracy(0.3, 5, ModeEffect::Mismatched) - 0.9).abs() < 1e-12);
    }

    #[test]
    fn law_matches_numeric_integration() {
        for &c in &[0.0, 0.05, 0.12, 0.5, 0.8, 0.84, 0.86, 0.9, 0.97, 1.0] {
            for effect in [ModeEffect::NoMode, ModeEffect::Matched] {
                let (low, high) = effect.noise_range();
                let n = 100_000;
                let (mut mean, mut above, mut sum_above) = (0.0, 0.0, 0.0);
                for i in 0..n {
                    let noise = low + (high - low) * (i as f64 + 0.5) / n as f64;
                    let acc = with_noise(c, noise);
                    mean += acc / n as f64;
                    if acc >= 0.85 {
                        above += 1.0 / n as f64;
                        sum_above += acc / n as f64;
                    }
                }
                let law = accuracy_law(c, effect, 0.85);
                assert!((law.mean - mean).abs() < 1e-6, "mean c={c}");
                assert!((law.p_above - above).abs() < 1e-4, "p c={c}");
                if above > 0.0 {
                    assert!((law.mean_above - sum_above / above).abs() < 1e-4, "cond c={c}");
                }
            }
        }
    }
}
