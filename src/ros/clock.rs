//! Simulated time: tick k of a line is stamped k * tick_period. Stamps are how a command says
//! which tick it answers, so they never repeat: the tick counter runs on across resets.

use super::messages::Time;

/// Converts between tick numbers and stamps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SimClock {
    period_ns: u64,
}

impl SimClock {
    pub fn new(tick_period_s: f64) -> Self {
        SimClock { period_ns: (tick_period_s * 1e9).round().max(1.0) as u64 }
    }

    pub fn stamp(&self, tick: u64) -> Time {
        Time::from_nanos(tick * self.period_ns)
    }

    /// The tick a stamp names, or `None` when it falls between ticks or before zero.
    pub fn tick_of(&self, stamp: Time) -> Option<u64> {
        let nanos = u64::try_from(stamp.nanos()).ok()?;
        (nanos % self.period_ns == 0).then_some(nanos / self.period_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_and_ticks_round_trip() {
        let clock = SimClock::new(0.1);
        for tick in [0, 1, 9, 10, 12_345_678] {
            assert_eq!(clock.tick_of(clock.stamp(tick)), Some(tick));
        }
        assert_eq!(clock.tick_of(Time { sec: 0, nanosec: 150_000_000 }), None);
        assert_eq!(clock.tick_of(Time { sec: -1, nanosec: 0 }), None);
    }
}
