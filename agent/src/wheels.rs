//! Wheel encoders in the agent core: each wheel's measured rim speed and
//! travel from its edge counts ([`speed`]), closed-loop wheel speed with a
//! PI controller per wheel ([`speed_loop`]) and stall detection ([`stall`]),
//! gathered in [`Wheels`], which the agent feeds one reading per control
//! period.
//!
//! Speeds are rim speeds in m/s, the unit of the platform's
//! `max_wheel_speed`: an output `u` asks for `u * max_wheel_speed`.

pub mod speed;
pub mod speed_loop;
pub mod stall;

use std::time::Duration;

use crate::hal::{Counting, EdgeCount};

pub use speed::WheelSpeed;
pub use speed_loop::{PiGains, SpeedLoop};
pub use stall::{Stall, StallDetector, StallSettings};

/// A reading older than this is not used to close the loop or to report
/// velocity: the agent falls back to open loop and commanded velocity.
pub const READING_FRESH_FOR: Duration = Duration::from_millis(200);

/// The `[encoders]` settings the agent core uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelSettings {
    pub counting: Counting,
    /// Edges counted per wheel revolution (every edge of every channel: a
    /// 360-line quadrature encoder gives 1440).
    pub counts_per_revolution: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// PI gains of the wheel speed loop; `None` keeps the outputs open loop
    /// (the encoders then only measure).
    pub speed_loop: Option<PiGains>,
    pub stall: StallSettings,
}

impl WheelSettings {
    /// Rim travel of one edge, m.
    pub fn metres_per_edge(&self) -> f64 {
        std::f64::consts::TAU * self.wheel_radius / self.counts_per_revolution
    }
}

/// What one reading of every wheel gave.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelStep {
    /// Rim travel of each wheel since the previous reading, m (signed).
    pub travel: Vec<f64>,
    /// Time since the previous reading, s (0 for the first).
    pub dt: f64,
}

/// A reading that does not fit the robot.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{got} encoder readings for {wheels} wheels")]
pub struct WrongCount {
    pub got: usize,
    pub wheels: usize,
}

/// Every wheel's speed estimate, speed loop and stall watch.
#[derive(Debug, Clone)]
pub struct Wheels {
    settings: WheelSettings,
    max_wheel_speed: f64,
    speeds: Vec<WheelSpeed>,
    loops: Vec<SpeedLoop>,
    stall: StallDetector,
    last_reading: Option<Duration>,
    last_loop: Option<Duration>,
}

impl Wheels {
    /// `wheels` encoders on a platform whose full output is
    /// `max_wheel_speed` m/s at the rim.
    pub fn new(settings: WheelSettings, wheels: usize, max_wheel_speed: f64) -> Wheels {
        Wheels {
            settings,
            max_wheel_speed,
            speeds: vec![WheelSpeed::default(); wheels],
            loops: vec![SpeedLoop::default(); wheels],
            stall: StallDetector::new(settings.stall, wheels),
            last_reading: None,
            last_loop: None,
        }
    }

    pub fn settings(&self) -> &WheelSettings {
        &self.settings
    }

    /// Takes one reading of every wheel. `applied` are the outputs driven
    /// since the previous reading: a single-channel encoder's direction, and
    /// what the stall watch compares against.
    pub fn observe(
        &mut self,
        counts: &[EdgeCount],
        applied: &[f64],
        now: Duration,
    ) -> Result<WheelStep, WrongCount> {
        if counts.len() != self.speeds.len() {
            return Err(WrongCount {
                got: counts.len(),
                wheels: self.speeds.len(),
            });
        }
        let per_edge = self.settings.metres_per_edge();
        let counting = self.settings.counting;
        let dt = self
            .last_reading
            .map_or(0.0, |t| now.saturating_sub(t).as_secs_f64());
        let mut travel = Vec::with_capacity(counts.len());
        let mut turned = Vec::with_capacity(counts.len());
        for (i, (wheel, count)) in self.speeds.iter_mut().zip(counts).enumerate() {
            let output = applied.get(i).copied().unwrap_or(0.0);
            let edges = wheel.update(*count, output, now, counting, per_edge);
            travel.push(edges as f64 * per_edge);
            turned.push(edges != 0);
        }
        if let Some(previous) = self.last_reading {
            self.stall.observe(applied, &turned, previous, now);
        }
        self.last_reading = Some(now);
        Ok(WheelStep { travel, dt })
    }

    /// Each wheel's rim speed, m/s, if the newest reading is fresh.
    pub fn speeds(&self, now: Duration) -> Option<Vec<f64>> {
        self.fresh(now)
            .then(|| self.speeds.iter().map(WheelSpeed::speed).collect())
    }

    /// Whether the newest reading is recent enough to act on.
    pub fn fresh(&self, now: Duration) -> bool {
        self.last_reading
            .is_some_and(|t| now.saturating_sub(t) <= READING_FRESH_FOR)
    }

    /// The outputs that make each wheel turn at the speed `open_loop` asks
    /// for (`open_loop[i] * max_wheel_speed`): the PI loops' outputs when
    /// configured and the reading is fresh, `open_loop` itself otherwise.
    pub fn close_loop(&mut self, open_loop: &[f64], now: Duration) -> Vec<f64> {
        let dt = self
            .last_loop
            .map_or(0.0, |t| now.saturating_sub(t).as_secs_f64())
            .min(READING_FRESH_FOR.as_secs_f64());
        self.last_loop = Some(now);
        let Some(gains) = self.settings.speed_loop.filter(|_| self.fresh(now)) else {
            self.reset_loops();
            return open_loop.to_vec();
        };
        open_loop
            .iter()
            .zip(self.loops.iter_mut().zip(&self.speeds))
            .map(|(&u, (pi, wheel))| {
                let error = (u * self.max_wheel_speed - wheel.speed()) / self.max_wheel_speed;
                pi.update(u, error, dt, &gains)
            })
            .collect()
    }

    /// Forgets the integrators (the robot was stopped by something else
    /// than its command: failsafe, fault, e-stop).
    pub fn reset_loops(&mut self) {
        self.loops.iter_mut().for_each(SpeedLoop::reset);
        self.last_loop = None;
    }

    /// A wheel that stalled, once: the watch starts afresh after reporting.
    pub fn take_stall(&mut self) -> Option<Stall> {
        self.stall.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hal::Counting;

    fn settings(counting: Counting) -> WheelSettings {
        WheelSettings {
            counting,
            counts_per_revolution: 1000.0,
            wheel_radius: 0.05,
            speed_loop: Some(PiGains::default()),
            stall: StallSettings::default(),
        }
    }

    fn at(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    #[test]
    fn a_reading_of_the_wrong_length_is_refused() {
        let mut w = Wheels::new(settings(Counting::Quadrature), 2, 0.5);
        assert_eq!(
            w.observe(&[EdgeCount::default()], &[0.0, 0.0], at(0)),
            Err(WrongCount { got: 1, wheels: 2 })
        );
    }

    #[test]
    fn travel_is_edges_times_the_rim_length_of_one_edge() {
        let s = settings(Counting::Quadrature);
        let mut w = Wheels::new(s, 2, 0.5);
        let count = |edges: i64, ms: u64| EdgeCount {
            edges,
            last_edge: Some(at(ms)),
        };
        w.observe(&[count(0, 0), count(0, 0)], &[0.0, 0.0], at(0))
            .unwrap();
        let step = w
            .observe(&[count(100, 19), count(-50, 18)], &[0.5, -0.5], at(20))
            .unwrap();
        let per_edge = std::f64::consts::TAU * 0.05 / 1000.0;
        assert!((step.travel[0] - 100.0 * per_edge).abs() < 1e-12);
        assert!((step.travel[1] + 50.0 * per_edge).abs() < 1e-12);
        assert!((step.dt - 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_stale_reading_falls_back_to_open_loop() {
        let mut w = Wheels::new(settings(Counting::Quadrature), 1, 0.5);
        w.observe(&[EdgeCount::default()], &[0.0], at(0)).unwrap();
        // Fresh and at rest while 0.4 is asked for: the loop pushes harder.
        assert!(w.close_loop(&[0.4], at(20))[0] > 0.4);
        assert!(w.speeds(at(20)).is_some());
        // No reading for longer than READING_FRESH_FOR: open loop.
        assert_eq!(w.close_loop(&[0.4], at(500)), vec![0.4]);
        assert!(w.speeds(at(500)).is_none());
    }
}
