//! Position noise like an ultra-wideband (Pozyx-class) system: Gaussian
//! jitter of a few centimetres plus occasional outliers of 100-500 mm, the
//! error profile the 2017 robots' moving-median filter was built for.

use mech_proto::Pose;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use mech_proto::wrap_angle;

/// Parameters of [`UwbNoise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UwbNoiseModel {
    /// Standard deviation of x and y, m.
    pub sigma: f64,
    /// Standard deviation of heading, rad.
    pub heading_sigma: f64,
    /// Chance that a sample is an outlier.
    pub outlier_probability: f64,
    /// Outlier distance range, m.
    pub outlier_min: f64,
    pub outlier_max: f64,
}

impl Default for UwbNoiseModel {
    fn default() -> Self {
        UwbNoiseModel {
            sigma: 0.03,
            heading_sigma: 0.02,
            outlier_probability: 0.05,
            outlier_min: 0.1,
            outlier_max: 0.5,
        }
    }
}

/// A seeded noise generator.
#[derive(Debug, Clone)]
pub struct UwbNoise {
    model: UwbNoiseModel,
    rng: SmallRng,
}

impl UwbNoise {
    pub fn new(model: UwbNoiseModel, seed: u64) -> UwbNoise {
        UwbNoise {
            model,
            rng: SmallRng::seed_from_u64(seed),
        }
    }

    /// A measurement of `truth`.
    pub fn measure(&mut self, truth: &Pose) -> Pose {
        let m = &self.model;
        let gauss = |rng: &mut SmallRng, sd: f64| {
            Normal::new(0.0, sd.max(0.0)).map_or(0.0, |n| n.sample(rng))
        };
        let mut p = Pose {
            x: truth.x + gauss(&mut self.rng, m.sigma),
            y: truth.y + gauss(&mut self.rng, m.sigma),
            z: truth.z + gauss(&mut self.rng, m.sigma),
            heading: wrap_angle(truth.heading + gauss(&mut self.rng, m.heading_sigma)),
        };
        if m.outlier_max > m.outlier_min
            && self.rng.random_bool(m.outlier_probability.clamp(0.0, 1.0))
        {
            let r = self.rng.random_range(m.outlier_min..m.outlier_max);
            let a = self.rng.random_range(0.0..std::f64::consts::TAU);
            p.x += r * a.cos();
            p.y += r * a.sin();
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn has_jitter_and_outliers() {
        let mut n = UwbNoise::new(UwbNoiseModel::default(), 1);
        let errs: Vec<f64> = (0..5000)
            .map(|_| {
                let p = n.measure(&Pose::default());
                p.x.hypot(p.y)
            })
            .collect();
        let outliers = errs.iter().filter(|e| **e > 0.15).count() as f64 / errs.len() as f64;
        assert!((0.02..0.08).contains(&outliers), "{outliers}");
        let mut sorted = errs.clone();
        sorted.sort_by(f64::total_cmp);
        assert!(
            (0.02..0.05).contains(&sorted[sorted.len() / 2]),
            "median {}",
            sorted[sorted.len() / 2]
        );
    }
}
