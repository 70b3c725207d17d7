//! One wheel's speed and travel from its edge count.
//!
//! Speed is the edges counted over the time between the newest edge of the
//! previous reading and the newest edge of this one, not over the control
//! period: at low speed a wheel gives an edge every few periods, and
//! edges-per-period would read 0, 0, 1/period, 0... where edges-over-edge-time
//! reads the true speed. With no new edge, the speed can be no more than one
//! edge over the time since the last one, so it decays toward zero instead
//! of holding the last value.
//!
//! A single-channel encoder counts up whichever way the wheel turns: the
//! direction is the sign of the output driven meanwhile, or, while that
//! output is zero (the wheel coasting), of the last non-zero one.

use std::time::Duration;

use crate::hal::{Counting, EdgeCount};

/// One wheel's speed estimate.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WheelSpeed {
    previous: Option<(EdgeCount, Duration)>,
    /// Rim speed, m/s.
    speed: f64,
    /// +1 or -1: the direction a single-channel encoder's edges count in.
    direction: f64,
}

impl WheelSpeed {
    /// Rim speed, m/s (signed, forward positive).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Takes a reading at `now`, `output` having been driven since the
    /// previous one; returns the signed edges since then.
    pub fn update(
        &mut self,
        count: EdgeCount,
        output: f64,
        now: Duration,
        counting: Counting,
        metres_per_edge: f64,
    ) -> i64 {
        if output != 0.0 {
            self.direction = output.signum();
        } else if self.direction == 0.0 {
            self.direction = 1.0;
        }
        let Some((previous, previous_at)) = self.previous.replace((count, now)) else {
            return 0;
        };
        let raw = count.edges.wrapping_sub(previous.edges);
        let edges = match counting {
            Counting::Quadrature => raw,
            // Counts only go up; a fall means the counter restarted.
            Counting::SingleChannel => raw.max(0) * self.direction as i64,
        };
        if edges != 0 {
            // `edges` edges happened after the previous newest edge, the last
            // of them at this reading's newest edge.
            let from = previous.last_edge.unwrap_or(previous_at);
            let to = count.last_edge.unwrap_or(now).min(now);
            let span = to.saturating_sub(from);
            let span = if span.is_zero() {
                now.saturating_sub(previous_at)
            } else {
                span
            };
            if !span.is_zero() {
                self.speed = edges as f64 * metres_per_edge / span.as_secs_f64();
            }
        } else {
            // No edge: at most one edge's travel since the newest edge.
            let bound = match count.last_edge {
                Some(last) if now > last => {
                    metres_per_edge / now.saturating_sub(last).as_secs_f64()
                }
                _ => 0.0,
            };
            self.speed = self.speed.signum() * self.speed.abs().min(bound);
        }
        edges
    }
}

#[cfg(test)]
mod tests {
    //! Fake edge sources: a wheel turning at a known speed, edges at exactly
    //! the times its rim passes each edge's travel.
    use super::*;

    const PER_EDGE: f64 = 0.001; // 1 mm of rim per edge
    const PERIOD: Duration = Duration::from_millis(20);

    /// A wheel whose rim travel at time `t` is `travel(t)` (m), read through
    /// an encoder of `PER_EDGE` resolution counting as `counting` does.
    struct FakeWheel<F: Fn(f64) -> f64> {
        travel: F,
        counting: Counting,
    }

    impl<F: Fn(f64) -> f64> FakeWheel<F> {
        /// The reading at `now`: edges of the travel so far (every edge the
        /// rim crossed), and when the newest was crossed (found by bisection
        /// on the travel function, to 1 µs).
        fn read(&self, now: Duration) -> EdgeCount {
            let t = now.as_secs_f64();
            let edges_at = |t: f64| ((self.travel)(t) / PER_EDGE).trunc() as i64;
            let signed = edges_at(t);
            if signed == 0 {
                return EdgeCount::default();
            }
            let (mut lo, mut hi) = (0.0, t);
            while hi - lo > 1e-6 {
                let mid = (lo + hi) / 2.0;
                if edges_at(mid) == signed {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let edges = match self.counting {
                Counting::Quadrature => signed,
                Counting::SingleChannel => signed.abs(),
            };
            EdgeCount {
                edges,
                last_edge: Some(Duration::from_secs_f64(hi)),
            }
        }
    }

    /// Reads `wheel` every period for `seconds` with `output` driven;
    /// returns the speeds and the total signed edges.
    fn run<F: Fn(f64) -> f64>(wheel: &FakeWheel<F>, output: f64, seconds: f64) -> (Vec<f64>, i64) {
        let mut w = WheelSpeed::default();
        let (mut speeds, mut total) = (vec![], 0);
        let mut now = Duration::ZERO;
        while now.as_secs_f64() < seconds {
            total += w.update(wheel.read(now), output, now, wheel.counting, PER_EDGE);
            speeds.push(w.speed());
            now += PERIOD;
        }
        (speeds, total)
    }

    #[test]
    fn counts_become_the_rim_speed() {
        let wheel = FakeWheel {
            travel: |t| 0.3 * t,
            counting: Counting::Quadrature,
        };
        let (speeds, _) = run(&wheel, 0.6, 2.0);
        for v in &speeds[2..] {
            assert!((v - 0.3).abs() < 0.3 * 0.01, "{v}");
        }
    }

    #[test]
    fn quadrature_counts_down_in_reverse_whatever_the_output() {
        let wheel = FakeWheel {
            travel: |t| -0.2 * t,
            counting: Counting::Quadrature,
        };
        // The output says forward; the counts say reverse, and win.
        let (speeds, total) = run(&wheel, 0.5, 1.0);
        assert!(total < 0);
        assert!((speeds.last().unwrap() + 0.2).abs() < 0.002);
    }

    #[test]
    fn single_channel_direction_comes_from_the_output_and_holds_while_coasting() {
        let wheel = FakeWheel {
            travel: |t| -0.2 * t,
            counting: Counting::SingleChannel,
        };
        let (speeds, total) = run(&wheel, -0.4, 1.0);
        assert!(total < 0, "{total}");
        assert!((speeds.last().unwrap() + 0.2).abs() < 0.002);

        // Driven backwards, then coasting with the output at zero: the edges
        // still count backwards.
        let mut w = WheelSpeed::default();
        let counting = Counting::SingleChannel;
        let e = |edges, ms| EdgeCount {
            edges,
            last_edge: Some(Duration::from_millis(ms)),
        };
        w.update(e(0, 0), -0.4, Duration::ZERO, counting, PER_EDGE);
        assert_eq!(w.update(e(10, 19), -0.4, PERIOD, counting, PER_EDGE), -10);
        assert_eq!(w.update(e(14, 39), 0.0, PERIOD * 2, counting, PER_EDGE), -4);
        assert!(w.speed() < 0.0);
    }

    #[test]
    fn fewer_edges_than_periods_still_read_the_true_speed() {
        // 0.02 m/s on a 1 mm encoder: one edge every 50 ms, 2.5 periods.
        // Edges per period would read 0 or 0.05 m/s; edge timing reads 0.02.
        let wheel = FakeWheel {
            travel: |t| 0.02 * t,
            counting: Counting::Quadrature,
        };
        let (speeds, total) = run(&wheel, 0.1, 3.0);
        let settled = &speeds[10..];
        let mean = settled.iter().sum::<f64>() / settled.len() as f64;
        assert!((mean - 0.02).abs() < 0.002, "mean {mean}");
        // Between edges the estimate never exceeds the true speed by more
        // than the bisection error, and never reads zero while turning.
        for v in settled {
            assert!(*v > 0.01 && *v < 0.0201, "{v}");
        }
        // Quantisation: the travel is the edges crossed, never more than
        // one edge behind the truth.
        let truth = 0.02 * (speeds.len() - 1) as f64 * PERIOD.as_secs_f64();
        let measured = total as f64 * PER_EDGE;
        assert!(
            measured <= truth + 1e-9 && truth - measured < PER_EDGE,
            "{measured} vs {truth}"
        );
    }

    #[test]
    fn a_wheel_that_stops_reads_zero_soon_after() {
        let wheel = FakeWheel {
            travel: |t: f64| 0.3 * t.min(1.0),
            counting: Counting::Quadrature,
        };
        let (speeds, _) = run(&wheel, 0.6, 2.0);
        // 0.5 s after stopping, at most one edge in 0.5 s (to the fake's
        // 1 µs edge timing).
        assert!(speeds[75].abs() <= PER_EDGE / 0.5 + 1e-5, "{}", speeds[75]);
        assert!(speeds.last().unwrap().abs() < 0.002);
    }
}
