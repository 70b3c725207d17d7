//! Stall detection: a wheel driven at or above a threshold output that has
//! not given a single encoder edge for the stall time is stuck (a jammed
//! gearbox, a wheel against a wall, a cut encoder wire). A stalled DC motor
//! draws its stall current and heats; the agent zeroes the outputs and
//! reports a driver fault.
//!
//! "Not a single edge" rather than "slower than expected": a weak battery or
//! a slope makes a wheel slow, not still, and must not trip it. The
//! threshold keeps low outputs, which may not overcome static friction
//! (below an L298's minimum duty), from counting as a stall.

use std::time::Duration;

/// When a wheel counts as stalled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StallSettings {
    /// Smallest output magnitude (fraction of full) that must turn a wheel.
    pub output: f64,
    /// How long such an output may give no edge.
    pub time: Duration,
}

impl Default for StallSettings {
    fn default() -> Self {
        StallSettings {
            output: 0.3,
            time: Duration::from_millis(500),
        }
    }
}

/// A stalled wheel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stall {
    /// Motor index.
    pub wheel: usize,
    /// The output it was driven at when found stalled.
    pub output: f64,
    /// How long it had been driven without an edge.
    pub for_time: Duration,
}

/// Watches every wheel for a stall.
#[derive(Debug, Clone, PartialEq)]
pub struct StallDetector {
    settings: StallSettings,
    /// Per wheel: since when it has been driven at or above the threshold
    /// without an edge.
    stuck_since: Vec<Option<Duration>>,
    found: Option<Stall>,
}

impl StallDetector {
    pub fn new(settings: StallSettings, wheels: usize) -> StallDetector {
        StallDetector {
            settings,
            stuck_since: vec![None; wheels],
            found: None,
        }
    }

    /// One reading: between `previous` and `now` each wheel was driven at
    /// `applied[i]` and gave an edge or not (`turned[i]`).
    pub fn observe(&mut self, applied: &[f64], turned: &[bool], previous: Duration, now: Duration) {
        for (i, since) in self.stuck_since.iter_mut().enumerate() {
            let output = applied.get(i).copied().unwrap_or(0.0);
            let driven = output.abs() >= self.settings.output;
            if !driven || turned.get(i).copied().unwrap_or(true) {
                *since = None;
                continue;
            }
            let from = *since.get_or_insert(previous);
            let for_time = now.saturating_sub(from);
            if for_time >= self.settings.time && self.found.is_none() {
                self.found = Some(Stall {
                    wheel: i,
                    output,
                    for_time,
                });
            }
        }
    }

    /// The stall found, once; the watch starts afresh.
    pub fn take(&mut self) -> Option<Stall> {
        let found = self.found.take();
        if found.is_some() {
            self.stuck_since.iter_mut().for_each(|s| *s = None);
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: Duration = Duration::from_millis(20);

    /// Drives wheel 1 of 2 at `output`; it turns until `jam`, then not.
    /// Returns when the stall was reported.
    fn jam_at(output: f64, jam: Duration, until: Duration) -> Option<Stall> {
        let mut d = StallDetector::new(StallSettings::default(), 2);
        let mut now = Duration::ZERO;
        while now < until {
            let next = now + PERIOD;
            d.observe(&[0.5, output], &[true, next <= jam], now, next);
            now = next;
            if let Some(s) = d.take() {
                return Some(Stall {
                    for_time: now.saturating_sub(jam),
                    ..s
                });
            }
        }
        None
    }

    #[test]
    fn a_driven_wheel_without_edges_stalls_within_the_stall_time() {
        let jam = Duration::from_secs(1);
        let s = jam_at(0.6, jam, Duration::from_secs(3)).unwrap();
        assert_eq!(s.wheel, 1);
        // Reported after the stall time, and no later than one period after.
        let limit = StallSettings::default().time;
        assert!(s.for_time >= limit && s.for_time <= limit + PERIOD, "{s:?}");
    }

    #[test]
    fn a_low_output_or_a_turning_wheel_never_stalls() {
        assert!(jam_at(0.2, Duration::ZERO, Duration::from_secs(5)).is_none());
        assert!(jam_at(1.0, Duration::from_secs(10), Duration::from_secs(5)).is_none());
    }
}
