//! Pose fusion for a robot with wheel encoders: between position fixes
//! (UWB, GPS, an external tracker) the pose advances by wheel odometry; each
//! fix corrects it. A three-state extended Kalman filter (x, y, heading), in
//! the form of `robot_localization`'s planar EKF, reduced to what a robot
//! agent needs; `docs/odometry.md` says why an EKF rather than a
//! complementary filter.
//!
//! - Predict: the body displacement measured by the encoders since the last
//!   reading, with a covariance that grows with each wheel's travel.
//! - Correct: a fix's position (and heading, when measured), weighted by
//!   the fix's standard deviation and quality against the covariance
//!   odometry has grown since.
//! - Outliers: a fix whose Mahalanobis distance from the prediction is
//!   beyond the 99% gate is dropped, as the median filter drops a reading
//!   far from its neighbours. A run of dropped fixes as long as the median
//!   window means the estimate, not the fixes, is wrong (a wheel slipped, the
//!   robot was carried): the filter restarts from the median of the recent
//!   fixes.
//! - Latency: a fix is compared with the pose at the fix's own time (a
//!   short history of predicted poses is kept), so a fix that took 30 ms to
//!   arrive does not pull a moving robot 30 ms back.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{Pose, wrap_angle};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use crate::hal::PositionSample;

/// 99% gate of a chi-square with 2 degrees of freedom (a position fix).
const GATE_POSITION: f64 = 9.21;
/// 99% gate of a chi-square with 1 degree of freedom (a heading).
const GATE_HEADING: f64 = 6.63;
/// Predicted poses kept to meet late fixes.
const HISTORY: Duration = Duration::from_secs(1);
/// Random walk of the pose over time not covered by odometry (m/√s,
/// rad/√s), so the filter keeps following fixes if the encoders stop
/// answering.
const WANDER: f64 = 0.05;

/// Noise figures of the filter, from `[encoders]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionSettings {
    /// Standard deviation of one position fix at quality 1, m.
    pub position_sigma: f64,
    /// Standard deviation of one measured heading at quality 1, rad.
    pub heading_sigma: f64,
    /// Standard deviation of a wheel's travel as a fraction of it (slip,
    /// wheel radius error).
    pub odometry_sigma: f64,
    /// Dropped fixes in a row after which the filter restarts from the
    /// median of recent fixes (the median window).
    pub restart_after: usize,
}

impl Default for FusionSettings {
    fn default() -> Self {
        FusionSettings {
            position_sigma: 0.05,
            heading_sigma: 0.05,
            // Wheel slip and radius error are mostly systematic, which a
            // white-noise model under-states: 10% keeps the fixes pulling
            // hard enough to take out a percent or two of bias (the
            // simulated waypoint runs were best between 10% and 30%).
            odometry_sigma: 0.1,
            restart_after: 9,
        }
    }
}

/// What the filter did with a fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FixUse {
    /// The first fix, or a restart: the estimate is the median of the fixes.
    Started,
    Used,
    /// Beyond the gate: dropped.
    Dropped,
}

/// Counters of the fixes the filter saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FusionCounters {
    pub used: u64,
    pub dropped: u64,
    pub restarts: u64,
}

/// The estimate: mean and covariance of (x, y, heading).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Belief {
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
}

/// Odometry and fixes fused into one pose.
#[derive(Debug, Clone)]
pub struct PoseFusion {
    settings: FusionSettings,
    belief: Option<Belief>,
    /// When the belief was last moved on in time.
    at: Duration,
    /// Predicted means, oldest first, for late fixes.
    history: VecDeque<(Duration, Vector3<f64>)>,
    dropped_in_row: usize,
    pub counters: FusionCounters,
}

impl PoseFusion {
    pub fn new(settings: FusionSettings) -> PoseFusion {
        PoseFusion {
            settings,
            belief: None,
            at: Duration::ZERO,
            history: VecDeque::new(),
            dropped_in_row: 0,
            counters: FusionCounters::default(),
        }
    }

    /// The fused pose (`z` is left at 0: odometry is planar), `None` before
    /// the first fix.
    pub fn pose(&self) -> Option<Pose> {
        self.belief.map(|b| Pose {
            x: b.mean[0],
            y: b.mean[1],
            z: 0.0,
            heading: wrap_angle(b.mean[2]),
        })
    }

    /// Standard deviations of x, y and heading now.
    pub fn sigmas(&self) -> Option<(f64, f64, f64)> {
        self.belief.map(|b| {
            (
                b.cov[(0, 0)].sqrt(),
                b.cov[(1, 1)].sqrt(),
                b.cov[(2, 2)].sqrt(),
            )
        })
    }

    /// The standard deviation of the position along its worst direction,
    /// m: the square root of the largest eigenvalue of the x-y covariance.
    pub fn position_sigma(&self) -> Option<f64> {
        self.belief.map(|b| {
            let (a, c, off) = (b.cov[(0, 0)], b.cov[(1, 1)], b.cov[(0, 1)]);
            let largest = (a + c) / 2.0 + ((a - c) / 2.0).hypot(off);
            largest.max(0.0).sqrt()
        })
    }

    /// Moves the pose on by a body-frame displacement (`dx` forward, `dy`
    /// left, m; `dheading`, rad) measured by the encoders up to `now`;
    /// `cov` is its covariance.
    pub fn predict(&mut self, displacement: Vector3<f64>, cov: Matrix3<f64>, now: Duration) {
        let Some(b) = self.belief.as_mut() else {
            return;
        };
        let (dx, dy, dh) = (displacement[0], displacement[1], displacement[2]);
        let mid = b.mean[2] + dh / 2.0;
        let (s, c) = mid.sin_cos();
        b.mean[0] += c * dx - s * dy;
        b.mean[1] += s * dx + c * dy;
        b.mean[2] = wrap_angle(b.mean[2] + dh);
        // Jacobians with respect to the state and to the displacement.
        let f = Matrix3::new(
            1.0,
            0.0,
            -s * dx - c * dy,
            0.0,
            1.0,
            c * dx - s * dy,
            0.0,
            0.0,
            1.0,
        );
        let g = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        b.cov = f * b.cov * f.transpose() + g * cov * g.transpose();
        let mean = b.mean;
        self.at = self.at.max(now);
        self.history.push_back((now, mean));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| now.saturating_sub(*t) > HISTORY)
        {
            self.history.pop_front();
        }
    }

    /// Corrects the pose with a fix. `median` is the median filter's
    /// estimate including this fix: where the filter starts, and restarts
    /// after a run of dropped fixes.
    pub fn correct(
        &mut self,
        fix: &PositionSample,
        median: &PositionSample,
        now: Duration,
    ) -> FixUse {
        let quality = fix.quality.clamp(0.05, 1.0);
        let sp = self.settings.position_sigma / quality;
        let sh = self.settings.heading_sigma / quality;
        if self.belief.is_none() || self.dropped_in_row >= self.settings.restart_after.max(1) {
            let restart = self.belief.is_some();
            self.start(median, sp, sh, now);
            if restart {
                self.counters.restarts += 1;
            }
            return FixUse::Started;
        }
        self.wander(now);
        let then = self.mean_at(fix.stamp);
        let Some(b) = self.belief.as_mut() else {
            return FixUse::Dropped;
        };
        // Position: the innovation against the pose at the fix's time,
        // applied to the pose now.
        let innovation = Vector2::new(fix.pose.x - then[0], fix.pose.y - then[1]);
        let s = b.cov.fixed_view::<2, 2>(0, 0).into_owned() + Matrix2::identity() * (sp * sp);
        let Some(s_inv) = s.try_inverse() else {
            return FixUse::Dropped;
        };
        if (innovation.transpose() * s_inv * innovation)[0] > GATE_POSITION {
            self.dropped_in_row += 1;
            self.counters.dropped += 1;
            return FixUse::Dropped;
        }
        let before = b.mean;
        let gain = b.cov.fixed_view::<3, 2>(0, 0) * s_inv;
        b.mean += gain * innovation;
        let mut kh = Matrix3::zeros();
        kh.fixed_view_mut::<3, 2>(0, 0).copy_from(&gain);
        joseph(&mut b.cov, &kh, &(gain * gain.transpose() * (sp * sp)));
        if fix.has_heading {
            let innovation = wrap_angle(fix.pose.heading - then[2]);
            let s = b.cov[(2, 2)] + sh * sh;
            if innovation * innovation / s <= GATE_HEADING {
                let gain = b.cov.column(2) / s;
                b.mean += gain * innovation;
                let mut kh = Matrix3::zeros();
                kh.set_column(2, &gain);
                joseph(&mut b.cov, &kh, &(gain * gain.transpose() * (sh * sh)));
            }
        }
        b.mean[2] = wrap_angle(b.mean[2]);
        // The kept trajectory moves with the estimate, so a later late fix
        // is not compared with a pose this fix already corrected.
        let shift = b.mean - before;
        for (_, m) in self.history.iter_mut() {
            *m += shift;
        }
        self.dropped_in_row = 0;
        self.counters.used += 1;
        FixUse::Used
    }

    fn start(&mut self, median: &PositionSample, sp: f64, sh: f64, now: Duration) {
        // An unmeasured heading is unknown until motion makes it observable.
        let heading_var = if median.has_heading {
            sh * sh
        } else {
            std::f64::consts::PI.powi(2)
        };
        let p = median.pose;
        self.belief = Some(Belief {
            mean: Vector3::new(p.x, p.y, p.heading),
            cov: Matrix3::from_diagonal(&Vector3::new(sp * sp, sp * sp, heading_var)),
        });
        self.at = now;
        self.history.clear();
        self.dropped_in_row = 0;
    }

    /// Grows the covariance by the random walk since the belief was last
    /// moved on (by a prediction or a fix): nothing while odometry comes
    /// every period, enough to keep following fixes when it stops.
    fn wander(&mut self, now: Duration) {
        let dt = now.saturating_sub(self.at).as_secs_f64();
        self.at = self.at.max(now);
        if let Some(b) = self.belief.as_mut() {
            let q = WANDER * WANDER * dt;
            b.cov += Matrix3::from_diagonal(&Vector3::new(q, q, q));
        }
    }

    /// The predicted mean at `stamp`: the newest kept at or before it, or
    /// the current one for a fix as new as the last prediction.
    fn mean_at(&self, stamp: Duration) -> Vector3<f64> {
        let now = self.belief.map_or(Vector3::zeros(), |b| b.mean);
        match self.history.back() {
            Some((t, _)) if stamp < *t => self
                .history
                .iter()
                .rev()
                .find(|(t, _)| *t <= stamp)
                .or(self.history.front())
                .map_or(now, |(_, m)| *m),
            _ => now,
        }
    }
}

/// Covariance update in Joseph form, `(I - KH) P (I - KH)' + K R K'`: stays
/// symmetric and positive with rounding, which the short form does not.
fn joseph(cov: &mut Matrix3<f64>, kh: &Matrix3<f64>, krk: &Matrix3<f64>) {
    let a = Matrix3::identity() - kh;
    *cov = a * *cov * a.transpose() + krk;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::median::MedianFilter;
    use crate::sim::{UwbNoise, UwbNoiseModel};

    fn fix(x: f64, y: f64, heading: f64, ms: u64) -> PositionSample {
        PositionSample {
            pose: Pose {
                x,
                y,
                z: 0.0,
                heading,
            },
            stamp: Duration::from_millis(ms),
            quality: 1.0,
            has_heading: true,
        }
    }

    fn odometry_cov(d: f64) -> Matrix3<f64> {
        let v = (0.05 * d).powi(2) + 1e-10;
        Matrix3::from_diagonal(&Vector3::new(v, v, v))
    }

    #[test]
    fn odometry_moves_the_pose_between_fixes_and_a_fix_corrects_it() {
        let mut f = PoseFusion::new(FusionSettings::default());
        let start = fix(1.0, 2.0, std::f64::consts::FRAC_PI_2, 0);
        assert_eq!(f.correct(&start, &start, Duration::ZERO), FixUse::Started);
        // 10 cm forward, facing +y.
        f.predict(
            Vector3::new(0.1, 0.0, 0.0),
            odometry_cov(0.1),
            Duration::from_millis(100),
        );
        let p = f.pose().unwrap();
        assert!(
            (p.x - 1.0).abs() < 1e-12 && (p.y - 2.1).abs() < 1e-12,
            "{p:?}"
        );
        // A fix 2 cm further on pulls the estimate toward it, not all the way.
        let ahead = fix(1.0, 2.12, std::f64::consts::FRAC_PI_2, 100);
        assert_eq!(
            f.correct(&ahead, &ahead, Duration::from_millis(100)),
            FixUse::Used
        );
        let y = f.pose().unwrap().y;
        assert!(y > 2.1 && y < 2.12, "{y}");
    }

    #[test]
    fn the_position_sigma_is_the_worst_direction_s() {
        let mut f = PoseFusion::new(FusionSettings::default());
        assert_eq!(f.position_sigma(), None);
        let start = fix(0.0, 0.0, 0.0, 0);
        f.correct(&start, &start, Duration::ZERO);
        let at_fix = f.position_sigma().unwrap();
        assert!((at_fix - 0.05).abs() < 1e-9, "a fix's sigma: {at_fix}");
        // Odometry along x only: x's variance grows, y's does not.
        let along_x = Matrix3::from_diagonal(&Vector3::new(0.04, 0.0, 0.0));
        f.predict(Vector3::zeros(), along_x, Duration::from_millis(20));
        let (sx, sy, _) = f.sigmas().unwrap();
        let worst = f.position_sigma().unwrap();
        assert!(sx > sy && (worst - sx).abs() < 1e-6, "{sx} {sy} {worst}");
    }

    #[test]
    fn a_late_fix_is_compared_with_the_pose_at_its_own_time() {
        let mut f = PoseFusion::new(FusionSettings::default());
        let start = fix(0.0, 0.0, 0.0, 0);
        f.correct(&start, &start, Duration::ZERO);
        let mut now = Duration::ZERO;
        for _ in 0..10 {
            now += Duration::from_millis(20);
            f.predict(Vector3::new(0.01, 0.0, 0.0), odometry_cov(0.01), now);
        }
        // A fix taken at 100 ms (x = 0.05, exactly where the robot was)
        // arriving at 200 ms agrees with the estimate: nothing moves.
        let x_before = f.pose().unwrap().x;
        let late = fix(0.05, 0.0, 0.0, 100);
        assert_eq!(f.correct(&late, &late, now), FixUse::Used);
        assert!((f.pose().unwrap().x - x_before).abs() < 1e-9);
    }

    #[test]
    fn heading_is_learnt_from_positions_alone() {
        // A fix without a heading (GPS without a compass) leaves the heading
        // unknown; driving straight while positions come in reveals it.
        let truth = 0.8f64;
        let mut f = PoseFusion::new(FusionSettings::default());
        let mut start = fix(0.0, 0.0, 0.0, 0);
        start.has_heading = false;
        f.correct(&start, &start, Duration::ZERO);
        let mut now = Duration::ZERO;
        let mut travelled = 0.0;
        for _ in 0..100 {
            now += Duration::from_millis(20);
            travelled += 0.006;
            f.predict(Vector3::new(0.006, 0.0, 0.0), odometry_cov(0.006), now);
            let mut p = fix(
                travelled * truth.cos(),
                travelled * truth.sin(),
                0.0,
                now.as_millis() as u64,
            );
            p.has_heading = false;
            f.correct(&p, &p, now);
        }
        let h = f.pose().unwrap().heading;
        assert!((h - truth).abs() < 0.05, "{h}");
    }

    #[test]
    fn outliers_the_median_filter_drops_are_dropped() {
        // A robot at rest, fixes with UWB-like noise: 3 cm jitter and 5%
        // outliers of 100-500 mm. Odometry says it does not move.
        let model = UwbNoiseModel {
            outlier_probability: 0.2,
            ..UwbNoiseModel::default()
        };
        let mut noise = UwbNoise::new(model, 3);
        let mut median = MedianFilter::new(9);
        let settings = FusionSettings {
            position_sigma: 0.03,
            heading_sigma: 0.02,
            ..FusionSettings::default()
        };
        let mut f = PoseFusion::new(settings);
        let (mut worst, mut worst_median) = (0.0f64, 0.0f64);
        for i in 0..2000u64 {
            let now = Duration::from_millis(20 * i);
            f.predict(Vector3::zeros(), Matrix3::zeros(), now);
            let measured = PositionSample {
                pose: noise.measure(&Pose::default()),
                stamp: now,
                quality: 1.0,
                has_heading: true,
            };
            let m = median.push(measured);
            f.correct(&measured, &m, now);
            if i > 50 {
                let p = f.pose().unwrap();
                worst = worst.max(p.x.hypot(p.y));
                worst_median = worst_median.max(m.pose.x.hypot(m.pose.y));
            }
        }
        assert!(f.counters.dropped > 200, "{:?}", f.counters);
        assert_eq!(f.counters.restarts, 0);
        // No outlier ever pulls the estimate further than the median's own
        // worst excursion, and it stays within a centimetre.
        assert!(
            worst < 0.01 && worst < worst_median,
            "{worst} vs {worst_median}"
        );
    }

    #[test]
    fn a_run_of_dropped_fixes_restarts_from_the_median() {
        // The robot was carried 1 m while odometry saw nothing.
        let mut f = PoseFusion::new(FusionSettings::default());
        let mut median = MedianFilter::new(9);
        let mut now = Duration::ZERO;
        let mut feed = |f: &mut PoseFusion, x: f64, now: Duration| {
            let s = fix(x, 0.0, 0.0, now.as_millis() as u64);
            let m = median.push(s);
            f.correct(&s, &m, now)
        };
        for _ in 0..20 {
            now += Duration::from_millis(20);
            feed(&mut f, 0.0, now);
        }
        let mut outcomes = vec![];
        for _ in 0..20 {
            now += Duration::from_millis(20);
            outcomes.push(feed(&mut f, 1.0, now));
        }
        assert_eq!(outcomes[..9], [FixUse::Dropped; 9]);
        assert_eq!(outcomes[9], FixUse::Started);
        assert_eq!(f.counters.restarts, 1);
        assert!((f.pose().unwrap().x - 1.0).abs() < 0.01);
    }
}
