//! The input sensor as a probability model: which readings a true batch total can produce.
//!
//! The reading of a batch of occupancy o is round2(clamp(o * (1 + u), 0, 1)) with u ~ U(-n, n)
//! (see `line.rs`). With n = 0 it is o itself; otherwise o * (1 + u) is uniform on
//! [o(1 - n), o(1 + n)] and each reading level collects the part of that interval that rounds to
//! it. The rule-based agent weighs possible totals by this likelihood.

/// Reading levels 0.00, 0.01, ..., 1.00.
pub const LEVELS: usize = 101;

/// The level (0..=100) of a reading in 0..=1.
pub fn level(quantity: f64) -> usize {
    ((quantity * 100.0).round().clamp(0.0, 100.0)) as usize
}

/// P(reading level `level` | batch total `total` units) for relative noise `noise`.
pub fn likelihood(level: usize, total: usize, noise: f64) -> f64 {
    if noise == 0.0 || total == 0 {
        return f64::from(u8::from(level == total.min(100)));
    }
    let o = total as f64 / 100.0;
    let (low, high) = (o * (1.0 - noise), o * (1.0 + noise));
    let q = level as f64 / 100.0;
    let from = if level == 0 { f64::NEG_INFINITY } else { q - 0.005 };
    let to = if level == LEVELS - 1 { f64::INFINITY } else { q + 0.005 };
    let overlap = to.min(high) - from.max(low);
    overlap.max(0.0) / (high - low)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn likelihood_sums_to_one_over_readings() {
        for total in [1, 5, 37, 80, 95, 100] {
            for noise in [0.0, 0.1, 0.3, 1.0] {
                let sum: f64 = (0..LEVELS).map(|q| likelihood(q, total, noise)).sum();
                assert!((sum - 1.0).abs() < 1e-9, "total {total} noise {noise}: {sum}");
            }
        }
        assert_eq!(likelihood(42, 42, 0.0), 1.0);
        assert_eq!(likelihood(41, 42, 0.0), 0.0);
    }
}
