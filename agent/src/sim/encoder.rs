//! Simulated wheel encoders: the simulated robot's wheel travel, counted as
//! a real encoder counts it.
//!
//! - Quantisation: only whole edges are counted (a 1440-count encoder on a
//!   33 mm wheel resolves 0.14 mm; a 40-slot optical disc 5.2 mm).
//! - Slip: the rim travels a little more than the ground (the wheel spins
//!   on the floor), by a mean fraction and a random part per step; the
//!   robot moves by the ground travel, the encoder counts the rim's.
//! - Scale: each wheel's radius differs from the nominal one by a fixed
//!   fraction (tyre wear, manufacturing), so odometry drifts as it does on a
//!   real robot.
//! - Edge timing noise: each reported edge time is off by a random few tens
//!   of microseconds, as interrupt latency on a Pi makes it.

use std::time::Duration;

use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand_distr::{Distribution, Normal};

use crate::hal::{Counting, EdgeCount, HalError, WheelEncoders};

/// Parameters of [`SimEncoders`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimEncoderModel {
    pub counting: Counting,
    /// Edges per wheel revolution.
    pub counts_per_revolution: f64,
    /// Nominal wheel radius, m.
    pub wheel_radius: f64,
    /// Mean extra rim travel as a fraction of the ground travel.
    pub slip: f64,
    /// Standard deviation of the extra rim travel per step, as a fraction.
    pub slip_sigma: f64,
    /// Standard deviation of each wheel's fixed radius error, as a fraction.
    pub scale_sigma: f64,
    /// Standard deviation of an edge's reported time, s.
    pub timing_sigma: f64,
}

impl Default for SimEncoderModel {
    /// A 360-line quadrature encoder (1440 edges) on a 33 mm wheel, 1% mean
    /// slip, 2% random slip, 1% radius error, 50 µs interrupt jitter.
    fn default() -> Self {
        SimEncoderModel {
            counting: Counting::Quadrature,
            counts_per_revolution: 1440.0,
            wheel_radius: 0.033,
            slip: 0.01,
            slip_sigma: 0.02,
            scale_sigma: 0.01,
            timing_sigma: 50e-6,
        }
    }
}

/// One wheel's simulated encoder.
#[derive(Debug, Clone, PartialEq)]
struct Wheel {
    /// Rim travel counted so far, m (signed).
    rim: f64,
    /// This wheel's true radius over the nominal one.
    scale: f64,
    count: EdgeCount,
}

/// The encoders of a simulated robot's wheels.
#[derive(Debug, Clone)]
pub struct SimEncoders {
    model: SimEncoderModel,
    wheels: Vec<Wheel>,
    rng: SmallRng,
    time: Duration,
}

impl SimEncoders {
    /// Encoders on `wheels` wheels, seeded.
    pub fn new(model: SimEncoderModel, wheels: usize, seed: u64) -> SimEncoders {
        let mut rng = SmallRng::seed_from_u64(seed);
        let wheels = (0..wheels)
            .map(|_| Wheel {
                rim: 0.0,
                scale: 1.0 + gauss(&mut rng, model.scale_sigma),
                count: EdgeCount::default(),
            })
            .collect();
        SimEncoders {
            model,
            wheels,
            rng,
            time: Duration::ZERO,
        }
    }

    pub fn model(&self) -> &SimEncoderModel {
        &self.model
    }

    /// The wheels travelled `ground` metres each (signed) on the floor
    /// between the previous call and `now`; counts the edges their rims
    /// crossed.
    pub fn advance(&mut self, ground: &[f64], now: Duration) {
        let m = self.model;
        let per_edge = std::f64::consts::TAU * m.wheel_radius / m.counts_per_revolution;
        let from = self.time;
        let span = now.saturating_sub(from).as_secs_f64();
        self.time = now;
        for (wheel, g) in self.wheels.iter_mut().zip(ground) {
            let slip = 1.0 + m.slip + gauss(&mut self.rng, m.slip_sigma);
            // The encoder turns with the wheel: a larger wheel turns less
            // for the same rim travel, so it counts fewer edges.
            let before = wheel.rim;
            wheel.rim += g * slip.max(0.0) / wheel.scale;
            let crossed = |rim: f64| (rim / per_edge).floor() as i64;
            let (a, b) = (crossed(before), crossed(wheel.rim));
            if a == b {
                continue;
            }
            let edges = match m.counting {
                Counting::Quadrature => b - a,
                Counting::SingleChannel => (b - a).abs(),
            };
            wheel.count.edges += edges;
            // When the newest boundary was crossed, by linear interpolation
            // over the step, plus interrupt jitter.
            let boundary = if b > a { b } else { b + 1 } as f64 * per_edge;
            let fraction = if wheel.rim != before {
                ((boundary - before) / (wheel.rim - before)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let at = from.as_secs_f64() + fraction * span + gauss(&mut self.rng, m.timing_sigma);
            let at = at.clamp(from.as_secs_f64(), now.as_secs_f64());
            wheel.count.last_edge = Some(Duration::from_secs_f64(at));
        }
    }
}

impl WheelEncoders for SimEncoders {
    fn read_all(&mut self, _now: Duration) -> Result<Vec<EdgeCount>, HalError> {
        Ok(self.wheels.iter().map(|w| w.count).collect())
    }
}

fn gauss(rng: &mut SmallRng, sd: f64) -> f64 {
    Normal::new(0.0, sd.max(0.0)).map_or(0.0, |n| n.sample(rng))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exact(counting: Counting) -> SimEncoderModel {
        SimEncoderModel {
            counting,
            counts_per_revolution: 100.0,
            wheel_radius: 0.1 / std::f64::consts::TAU, // 1 mm per edge
            slip: 0.0,
            slip_sigma: 0.0,
            scale_sigma: 0.0,
            timing_sigma: 0.0,
        }
    }

    #[test]
    fn whole_edges_of_the_travel_with_the_time_of_the_newest() {
        let mut e = SimEncoders::new(exact(Counting::Quadrature), 2, 1);
        let ms = Duration::from_millis;
        // 2.5 mm forward and 1.5 mm back in 20 ms.
        e.advance(&[0.0025, -0.0015], ms(20));
        let c = e.read_all(ms(20)).unwrap();
        assert_eq!((c[0].edges, c[1].edges), (2, -2));
        // The 2nd edge (2 mm) was crossed at 16 ms.
        let t = c[0].last_edge.unwrap().as_secs_f64();
        assert!((t - 0.016).abs() < 1e-9, "{t}");
        let mut single = SimEncoders::new(exact(Counting::SingleChannel), 1, 1);
        single.advance(&[0.0005], ms(20));
        single.advance(&[-0.003], ms(40));
        single.advance(&[0.003], ms(60));
        // Back then forward across the same three edges: counted up both
        // ways.
        assert_eq!(single.read_all(ms(60)).unwrap()[0].edges, 6);
    }

    #[test]
    fn slip_makes_the_rim_count_more_than_the_ground() {
        let model = SimEncoderModel {
            slip: 0.05,
            ..exact(Counting::Quadrature)
        };
        let mut e = SimEncoders::new(model, 1, 1);
        for i in 1..=100u64 {
            e.advance(&[0.01], Duration::from_millis(20 * i));
        }
        // 1 m on the ground, 1.05 m at the rim.
        let edges = e.read_all(Duration::from_secs(2)).unwrap()[0].edges;
        assert!((1049..=1050).contains(&edges), "{edges}");
    }
}
