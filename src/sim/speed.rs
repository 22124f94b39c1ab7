//! The belt: its ten speeds and the occupancy each speed can sort without loss.
//!
//! The values are the reference's literals, not `1.1 - speed` computed in floating point:
//! `1.1 - 0.4` is `0.7000000000000001`, and an occupancy of exactly 0.7 must count as
//! "within the limit" at speed 0.4, as it does in the reference.

/// Number of belt speeds (speed index 0..=9).
pub const SPEED_COUNT: usize = 10;

/// Belt speed by index: index `i` is speed `(i + 1) / 10`.
pub const SPEEDS: [f64; SPEED_COUNT] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];

/// Highest belt occupancy that still gives base accuracy 1.0, by speed index (`1.1 - speed`).
pub const OCCUPANCY_LIMITS: [f64; SPEED_COUNT] = [1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1];

/// Speed index of the start speed 0.6, set by every reset.
pub const START_SPEED_INDEX: usize = 5;

/// How far a commanded speed may be from one of the ten speeds and still count as that speed.
/// Commands arrive as `float64` over ROS; `0.30000000000000004` (0.1 * 3) must mean 0.3.
pub const SPEED_TOLERANCE: f64 = 1e-6;

/// The speed index for a commanded belt speed, or `None` when it is not one of the ten speeds
/// (NaN, infinite, out of 0.1..=1.0, or between two speeds).
pub fn index_of_speed(speed: f64) -> Option<usize> {
    if !speed.is_finite() {
        return None;
    }
    let index = (speed * 10.0).round() - 1.0;
    if !(0.0..SPEED_COUNT as f64).contains(&index) {
        return None;
    }
    let index = index as usize;
    ((speed - SPEEDS[index]).abs() <= SPEED_TOLERANCE).then_some(index)
}

/// The speed term of the reward: `0.5 * (speed - 0.1) / 0.9`, in 0..=0.5.
pub fn speed_reward(speed_index: usize) -> f64 {
    (SPEEDS[speed_index] - 0.1) / 0.9 * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_speed_maps_back_to_its_index() {
        for (i, &s) in SPEEDS.iter().enumerate() {
            assert_eq!(index_of_speed(s), Some(i));
        }
        assert_eq!(index_of_speed(0.1 * 3.0), Some(2));
    }

    #[test]
    fn off_grid_and_non_finite_speeds_are_rejected() {
        for bad in [f64::NAN, f64::INFINITY, -0.1, 0.0, 0.05, 0.55, 1.1, 1.0001, 7.0] {
            assert_eq!(index_of_speed(bad), None, "{bad}");
        }
    }

    #[test]
    fn limits_are_one_point_one_minus_speed() {
        for i in 0..SPEED_COUNT {
            assert!((OCCUPANCY_LIMITS[i] - (1.1 - SPEEDS[i])).abs() < 1e-12);
        }
        assert_eq!(speed_reward(0), 0.0);
        assert_eq!(speed_reward(9), 0.5);
    }
}
