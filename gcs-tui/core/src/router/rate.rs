//! Message rate of a channel, measured over one-second windows.

use std::time::Duration;

use tokio::time::Instant;

/// Counts messages per window and keeps the rate of the last full window.
#[derive(Debug, Clone)]
pub(crate) struct RateMeter {
    window_start: Instant,
    count: u32,
    rate_hz: f64,
}

const WINDOW: Duration = Duration::from_secs(1);

impl RateMeter {
    pub(crate) fn new(now: Instant) -> RateMeter {
        RateMeter {
            window_start: now,
            count: 0,
            rate_hz: 0.0,
        }
    }

    pub(crate) fn record(&mut self, now: Instant) {
        self.roll(now);
        self.count += 1;
    }

    fn roll(&mut self, now: Instant) {
        let elapsed = now.saturating_duration_since(self.window_start);
        if elapsed >= WINDOW {
            // A window with a gap of several seconds averages over the gap.
            self.rate_hz = f64::from(self.count) / elapsed.as_secs_f64();
            self.count = 0;
            self.window_start = now;
        }
    }

    /// Messages per second; decays to zero once the channel falls silent.
    pub(crate) fn rate_hz(&self, now: Instant) -> f64 {
        let elapsed = now.saturating_duration_since(self.window_start);
        if elapsed >= WINDOW {
            f64::from(self.count) / elapsed.as_secs_f64()
        } else {
            self.rate_hz
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_of_a_steady_stream_and_its_decay() {
        let t0 = Instant::now();
        let mut m = RateMeter::new(t0);
        for i in 0..=40 {
            m.record(t0 + Duration::from_millis(i * 50));
        }
        let r = m.rate_hz(t0 + Duration::from_millis(2010));
        assert!((r - 20.0).abs() < 1.5, "{r}");
        let later = m.rate_hz(t0 + Duration::from_secs(30));
        assert!(later < 0.1, "{later}");
    }
}
