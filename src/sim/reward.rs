//! The reward of one step: accuracy above the threshold plus belt speed, minus the switching
//! penalty; a flat -0.1 (and no penalty) when the accuracy is below the threshold.
//!
//! R = 0.5 * (accuracy - thr) / (1 - thr) + 0.5 * (speed - 0.1) / 0.9 - penalty. The terms are
//! added in the reference's order so the result is the same double.

use super::accuracy::AccuracyLaw;
use super::speed::speed_reward;

/// Reward of a step whose accuracy is below the threshold (replaces the whole reward).
pub const BELOW_THRESHOLD_REWARD: f64 = -0.1;
/// Weight of the accuracy term.
pub const ACCURACY_WEIGHT: f64 = 0.5;

/// The accuracy term alone.
pub fn accuracy_reward(accuracy: f64, threshold: f64) -> f64 {
    (accuracy - threshold) / (1.0 - threshold) * ACCURACY_WEIGHT
}

/// The reward of a step.
pub fn reward(accuracy: f64, threshold: f64, speed_index: usize, penalty: f64) -> f64 {
    if accuracy < threshold {
        BELOW_THRESHOLD_REWARD
    } else {
        accuracy_reward(accuracy, threshold) + speed_reward(speed_index) - penalty
    }
}

/// The expected reward of a step whose accuracy follows `law`, with `penalty` charged when the
/// accuracy is above the threshold (a change of speed).
pub fn expected_reward(law: &AccuracyLaw, threshold: f64, speed_index: usize, penalty: f64) -> f64 {
    let above = if law.p_above > 0.0 {
        accuracy_reward(law.mean_above, threshold) + speed_reward(speed_index) - penalty
    } else {
        0.0
    };
    law.p_above * above + (1.0 - law.p_above) * BELOW_THRESHOLD_REWARD
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_threshold() {
        assert_eq!(reward(0.69, 0.7, 9, 0.5), -0.1);
        assert_eq!(reward(1.0, 0.7, 9, 0.0), 1.0);
        assert_eq!(reward(0.7, 0.7, 0, 0.0), 0.0);
        assert!((reward(0.85, 0.7, 4, 0.5) - (0.25 + 0.5 * 4.0 / 9.0 * 0.5 * 2.0 - 0.5)).abs() < 1e-12);
    }
}
