//! Moving-median filter for position outliers. The 2017 robots needed one
//! for Pozyx UWB: occasional readings hundreds of millimetres off pushed the
//! raw standard deviation past 180 mm; after a moving median it fell under
//! 10 mm. A median ignores a minority of outliers in its window entirely,
//! where a mean would be dragged by them.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{Pose, wrap_angle};

use crate::hal::PositionSample;

/// Median over the last `window` samples, per axis. Heading is filtered as
/// offsets from the newest heading so the wrap at ±π does not split the
/// window.
#[derive(Debug, Clone)]
pub struct MedianFilter {
    window: usize,
    samples: VecDeque<PositionSample>,
    /// Scratch buffer, reused to keep the filter allocation-free.
    scratch: Vec<f64>,
}

impl MedianFilter {
    /// A filter over `window` samples (`window` = 1 passes samples through).
    pub fn new(window: usize) -> MedianFilter {
        let window = window.max(1);
        MedianFilter {
            window,
            samples: VecDeque::with_capacity(window),
            scratch: Vec::with_capacity(window),
        }
    }

    pub fn window(&self) -> usize {
        self.window
    }

    /// Whether the window holds all its samples: before that the median
    /// of a few fixes is no protection from an outlier among them.
    pub fn full(&self) -> bool {
        self.samples.len() == self.window
    }

    /// Forgets every sample (after a teleport in simulation, or a new origin).
    pub fn reset(&mut self) {
        self.samples.clear();
    }

    /// Adds a sample and returns the filtered estimate.
    pub fn push(&mut self, sample: PositionSample) -> PositionSample {
        if self.samples.len() == self.window {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
        self.estimate().unwrap_or(sample)
    }

    /// The time the estimate refers to: the median of the samples' stamps.
    /// A median of fixes of a moving robot lags its newest fix by about
    /// half the window (each fix being the median's in turn as the robot
    /// moves on), so the estimate is where the robot was then. `None`
    /// before the first sample.
    pub fn middle_stamp(&self) -> Option<Duration> {
        let n = self.samples.len();
        let (a, b) = (
            self.samples.get((n.checked_sub(1)?) / 2)?,
            self.samples.get(n / 2)?,
        );
        Some((a.stamp + b.stamp) / 2)
    }

    /// The current estimate, `None` before the first sample.
    pub fn estimate(&mut self) -> Option<PositionSample> {
        let newest = *self.samples.back()?;
        let x = self.median(|s| s.pose.x);
        let y = self.median(|s| s.pose.y);
        let z = self.median(|s| s.pose.z);
        let quality = self.median(|s| s.quality);
        let heading = if newest.has_heading {
            let h0 = newest.pose.heading;
            let offset = self.median_of(|s| s.has_heading, |s| wrap_angle(s.pose.heading - h0));
            wrap_angle(h0 + offset)
        } else {
            newest.pose.heading
        };
        Some(PositionSample {
            pose: Pose { x, y, z, heading },
            stamp: newest.stamp,
            quality,
            has_heading: newest.has_heading,
        })
    }

    fn median(&mut self, f: impl Fn(&PositionSample) -> f64) -> f64 {
        self.median_of(|_| true, f)
    }

    fn median_of(
        &mut self,
        keep: impl Fn(&PositionSample) -> bool,
        f: impl Fn(&PositionSample) -> f64,
    ) -> f64 {
        self.scratch.clear();
        self.scratch
            .extend(self.samples.iter().filter(|s| keep(s)).map(f));
        self.scratch.sort_by(f64::total_cmp);
        let n = self.scratch.len();
        match n {
            0 => 0.0,
            _ if n % 2 == 1 => self.scratch[n / 2],
            _ => (self.scratch[n / 2 - 1] + self.scratch[n / 2]) / 2.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(x: f64, y: f64, heading: f64) -> PositionSample {
        PositionSample {
            pose: Pose {
                x,
                y,
                z: 0.0,
                heading,
            },
            stamp: Duration::ZERO,
            quality: 1.0,
            has_heading: true,
        }
    }

    #[test]
    fn rejects_isolated_outliers() {
        let mut f = MedianFilter::new(5);
        let mut out = vec![];
        for i in 0..20 {
            let s = if i % 5 == 2 {
                at(1.0 + 0.4, 2.0 - 0.3, 0.0)
            } else {
                at(1.0, 2.0, 0.0)
            };
            out.push(f.push(s));
        }
        for o in &out[4..] {
            assert_eq!((o.pose.x, o.pose.y), (1.0, 2.0));
        }
    }

    #[test]
    fn shrinks_spread_of_outlier_laden_noise() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::SmallRng::seed_from_u64(7);
        let mut f = MedianFilter::new(9);
        let (mut raw, mut filtered) = (vec![], vec![]);
        for _ in 0..2000 {
            let mut x = rng.random_range(-0.02..0.02);
            if rng.random_bool(0.08) {
                x += rng.random_range(0.1..0.5);
            }
            raw.push(x);
            filtered.push(f.push(at(x, 0.0, 0.0)).pose.x);
        }
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        assert!(sd(&raw) > 0.05, "raw sd {}", sd(&raw));
        assert!(
            sd(&filtered[9..]) < 0.02,
            "filtered sd {}",
            sd(&filtered[9..])
        );
    }

    #[test]
    fn the_estimate_refers_to_the_middle_of_the_window() {
        let mut f = MedianFilter::new(9);
        assert_eq!(f.middle_stamp(), None);
        for i in 0..20u64 {
            f.push(PositionSample {
                stamp: Duration::from_millis(50 * i),
                ..at(0.01 * i as f64, 0.0, 0.0)
            });
            let n = (i + 1).min(9);
            let middle = Duration::from_millis(50 * (i + 1 - n) + 25 * (n - 1));
            assert_eq!(f.middle_stamp(), Some(middle), "after {} samples", i + 1);
        }
        // A robot moving steadily: the median is where it was 200 ms ago.
        let x = f.estimate().unwrap().pose.x;
        assert!((x - 0.15).abs() < 1e-9, "{x}");
    }

    #[test]
    fn heading_median_survives_the_wrap() {
        let mut f = MedianFilter::new(3);
        f.push(at(0.0, 0.0, 3.1));
        f.push(at(0.0, 0.0, -3.1));
        let h = f.push(at(0.0, 0.0, 3.12)).pose.heading;
        assert!((h.abs() - 3.12).abs() < 1e-9, "{h}");
    }
}
