//! Where the robot's own motion took it: the velocities it drove (measured
//! by its encoders, or following from its outputs), integrated each
//! control period over the last seconds, so that a position estimate that
//! refers to the past (a median of fixes lags by half its window) can be
//! moved on to now, with a bound on the error that adds.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::Velocity;

/// How far back the track reaches: an estimate older than this is moved
/// on only by this much of the robot's motion, and its error bound keeps
/// growing with its age.
const KEPT: Duration = Duration::from_secs(2);

/// The robot's displacement (x, y, heading) since an arbitrary start, at
/// each control period of the last [`KEPT`].
#[derive(Debug, Clone)]
pub(crate) struct Track {
    points: VecDeque<(Duration, [f64; 3])>,
    /// The position source's own error at rest, m (`safety.position_error`).
    source_error: f64,
    /// How fast the velocity may change, m/s² (`safety.max_deceleration`).
    acceleration: f64,
}

impl Track {
    pub(crate) fn new(source_error: f64, acceleration: f64) -> Track {
        Track {
            points: VecDeque::new(),
            source_error,
            acceleration,
        }
    }

    /// The robot moved at `velocity` (world frame) from the last period
    /// until `now`.
    pub(crate) fn advance(&mut self, velocity: &Velocity, now: Duration) {
        let (last, p) = self.points.back().copied().unwrap_or((now, [0.0; 3]));
        let dt = now.saturating_sub(last).as_secs_f64();
        let next = [
            p[0] + velocity.vx * dt,
            p[1] + velocity.vy * dt,
            p[2] + velocity.wz * dt,
        ];
        if next.iter().all(|v| v.is_finite()) && now >= last {
            self.points.push_back((now, next));
        }
        while self
            .points
            .front()
            .is_some_and(|(t, _)| *t + KEPT < now && self.points.len() > 1)
        {
            self.points.pop_front();
        }
    }

    /// The displacement from `then` to `now` (what the track holds of it),
    /// and how far an estimate of `then` moved on by it may be from the
    /// truth: the source's error, plus `a·t²/2` for the `t` it was moved
    /// on (the velocity may have changed by up to `a·t` in that time).
    pub(crate) fn since(&self, then: Duration, now: Duration) -> ([f64; 3], f64) {
        let t = now.saturating_sub(then).as_secs_f64();
        let error = self.source_error + self.acceleration * t * t / 2.0;
        let (Some(newest), Some(oldest)) = (self.points.back(), self.points.front()) else {
            return ([0.0; 3], error);
        };
        let at = self
            .points
            .iter()
            .rev()
            .find(|(time, _)| *time <= then)
            .unwrap_or(oldest);
        let moved = [
            newest.1[0] - at.1[0],
            newest.1[1] - at.1[1],
            newest.1[2] - at.1[2],
        ];
        (moved, error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn moving(vx: f64, vy: f64, wz: f64) -> Velocity {
        Velocity {
            vx,
            vy,
            vz: 0.0,
            wz,
        }
    }

    #[test]
    fn an_estimate_of_the_past_moves_on_by_the_motion_since() {
        let mut t = Track::new(0.04, 1.0);
        let (moved, error) = t.since(ms(0), ms(0));
        assert_eq!((moved, error), ([0.0; 3], 0.04), "nothing driven yet");
        for i in 0..=20 {
            t.advance(&moving(0.5, -0.1, 0.2), ms(50 * i));
        }
        // From 800 ms to 1000 ms at (0.5, -0.1) m/s, turning at 0.2 rad/s.
        let (moved, error) = t.since(ms(800), ms(1000));
        let want = [0.1, -0.02, 0.04];
        for (m, w) in moved.iter().zip(want) {
            assert!((m - w).abs() < 1e-12, "{moved:?}");
        }
        assert!((error - (0.04 + 0.02)).abs() < 1e-12, "{error}");
        // A time between two periods: from the one before it.
        let (between, _) = t.since(ms(825), ms(1000));
        assert_eq!(between, moved);
    }

    #[test]
    fn the_track_keeps_two_seconds_and_the_bound_keeps_growing() {
        let mut t = Track::new(0.0, 1.0);
        for i in 0..=100 {
            t.advance(&moving(1.0, 0.0, 0.0), ms(50 * i));
        }
        let (moved, error) = t.since(ms(0), ms(5000));
        assert!((moved[0] - 2.0).abs() < 1e-9, "two seconds kept: {moved:?}");
        assert!((error - 12.5).abs() < 1e-9, "a·t²/2 over 5 s: {error}");
        // A velocity that is not a number is not driven.
        t.advance(&moving(f64::NAN, 0.0, 0.0), ms(5050));
        assert!(t.since(ms(4000), ms(5050)).0.iter().all(|v| v.is_finite()));
    }
}
