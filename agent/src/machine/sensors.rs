//! What the robot senses of itself: the position estimate (the median of
//! the fixes, or, with wheel encoders, odometry fused with them), the wheel
//! encoders (measured speeds, the stall watch), the velocity it knows, its
//! health, and the [`faults`] of its drivers.

mod faults;
mod track;

use std::time::Duration;

use mech_proto::{Health, PositionFix, Twist, Velocity, VelocitySource};
use nalgebra::{DMatrix, Matrix3, Vector3};

use super::counters::Counters;
use super::settings::AgentSettings;
use super::step::Step;
use crate::control::Controller;
use crate::fusion::{FusionCounters, FusionSettings, PoseFusion};
use crate::hal::{EdgeCount, PositionSample};
use crate::median::MedianFilter;
use crate::platform::Platform;
use crate::wheels::Wheels;

pub(crate) use faults::Faults;
use track::Track;

/// What the robot knows of its own motion now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Motion {
    /// The position estimate, moved on to now by the robot's own motion
    /// since the time it refers to.
    pub(crate) estimate: Option<PositionSample>,
    /// How far `estimate` may be from the true position, m (see
    /// [`Sensors::motion`]); infinite without an estimate.
    pub(crate) position_error: f64,
    /// The velocity in the world frame (turned by the estimated heading).
    pub(crate) velocity: Velocity,
    /// Measured by the wheel encoders while their readings are fresh;
    /// otherwise what the outputs produce (the platform's forward
    /// kinematics, which is what a robot without encoders knows).
    pub(crate) velocity_source: VelocitySource,
}

/// The position estimate, the wheel encoders and the drivers' faults.
#[derive(Debug)]
pub(crate) struct Sensors {
    /// Whether the robot has any position source.
    has_position: bool,
    /// Whether `PositionFix` messages (relayed by the station) are the
    /// position source.
    external_position: bool,
    /// A position older than this marks health `Degraded`.
    position_stale_after: Duration,
    filter: MedianFilter,
    estimate: Option<PositionSample>,
    /// Encoders: speeds, speed loops, stall watch (with `[encoders]`).
    wheels: Option<Wheels>,
    /// Odometry fused with fixes (with encoders and a position source).
    fusion: Option<PoseFusion>,
    /// Each wheel's effect on the body displacement (the platform's
    /// odometry, one column per wheel), for the odometry covariance.
    wheel_jacobian: Option<DMatrix<f64>>,
    /// Odometry noise per metre of wheel travel.
    odometry_sigma: f64,
    /// The body twist the vehicle itself measures (a ROS 2 base's
    /// odometry), and when it came.
    measured: Option<(Twist, Duration)>,
    /// Where the robot's own motion took it, to move a lagging estimate on.
    track: Track,
    pub(crate) faults: Faults,
}

impl Sensors {
    pub(crate) fn new(settings: &AgentSettings, platform: &dyn Platform) -> Sensors {
        let wheels = settings
            .wheels
            .zip(platform.max_wheel_speed())
            .map(|(w, max)| Wheels::new(w, platform.motors(), max));
        let fusion = (wheels.is_some() && settings.has_position).then(|| {
            PoseFusion::new(FusionSettings {
                restart_after: settings.filter_window,
                ..settings.fusion
            })
        });
        let wheel_jacobian = wheels.as_ref().and_then(|_| wheel_jacobian(platform));
        Sensors {
            has_position: settings.has_position,
            external_position: settings.external_position,
            position_stale_after: settings.position_stale_after,
            filter: MedianFilter::new(settings.filter_window),
            estimate: None,
            wheels,
            fusion,
            wheel_jacobian,
            odometry_sigma: settings.fusion.odometry_sigma,
            measured: None,
            track: Track::new(
                settings.safety.position_error,
                settings.safety.max_deceleration,
            ),
            faults: Faults::default(),
        }
    }

    /// The position estimate: the median of the fixes, or, with encoders,
    /// odometry fused with them (its `stamp` is always the newest fix's).
    pub(crate) fn estimate(&self) -> Option<PositionSample> {
        self.estimate
    }

    /// What the odometry fusion did with the fixes (zero without encoders).
    pub(crate) fn fusion_counters(&self) -> FusionCounters {
        self.fusion.as_ref().map(|f| f.counters).unwrap_or_default()
    }

    /// Each wheel's measured rim speed (m/s), while encoder readings are
    /// fresh.
    pub(crate) fn wheel_speeds(&self, now: Duration) -> Option<Vec<f64>> {
        self.wheels.as_ref().and_then(|w| w.speeds(now))
    }

    /// The wheels' speed loops, for the outputs.
    pub(crate) fn wheels_mut(&mut self) -> Option<&mut Wheels> {
        self.wheels.as_mut()
    }

    /// A position measurement from the robot's own source: through the
    /// median filter, and with encoders, into the odometry fusion.
    pub(crate) fn observe_position(&mut self, sample: PositionSample, counters: &mut Counters) {
        counters.position_samples += 1;
        let median = self.filter.push(sample);
        self.estimate = Some(match self.fusion.as_mut() {
            None => median,
            Some(fusion) => {
                fusion.correct(&sample, &median, sample.stamp);
                fused(fusion, median)
            }
        });
    }

    /// A `PositionFix` relayed by the station: a position measurement when
    /// external positioning is this robot's source, ignored otherwise.
    pub(crate) fn position_fix(&mut self, fix: PositionFix, step: &mut Step) {
        if !self.external_position || fix.robot != step.robot() {
            return;
        }
        let sample = PositionSample {
            pose: fix.pose,
            stamp: step.now,
            quality: fix.quality.clamp(0.0, 1.0),
            has_heading: true,
        };
        self.observe_position(sample, step.counters);
    }

    /// One reading of every wheel encoder (motor order), `applied` being
    /// the outputs driven since the last one: measured speeds, odometry
    /// into the pose, the stall watch. A reading that does not fit the
    /// robot is a driver fault.
    pub(crate) fn observe_wheels(
        &mut self,
        counts: &[EdgeCount],
        applied: &[f64],
        platform: &dyn Platform,
        step: &mut Step,
    ) {
        let Some(wheels) = self.wheels.as_mut() else {
            return;
        };
        let step_taken = match wheels.observe(counts, applied, step.now) {
            Ok(taken) => taken,
            Err(e) => return self.faults.driver_fault(&format!("encoders: {e}"), step),
        };
        let sigma = wheels.settings().metres_per_edge() / 2.0;
        let (Some(fusion), Some(jacobian)) = (self.fusion.as_mut(), &self.wheel_jacobian) else {
            return;
        };
        // The platform's odometry is linear in the wheel speeds, so it turns
        // each wheel's travel into the body's displacement too.
        let Some(d) = platform.wheel_odometry(&step_taken.travel) else {
            return;
        };
        let relative = self.odometry_sigma;
        let variances: Vec<f64> = step_taken
            .travel
            .iter()
            .map(|t| (relative * t.abs() + sigma).powi(2))
            .collect();
        let wheel_cov = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(variances));
        let body = jacobian * wheel_cov * jacobian.transpose();
        let cov = Matrix3::from_fn(|r, c| body[(r, c)]);
        fusion.predict(Vector3::new(d.vx, d.vy, d.wz), cov, step.now);
        if let Some(e) = self.estimate {
            self.estimate = Some(fused(fusion, e));
        }
    }

    /// A wheel driven without turning for the stall time: an actuator
    /// fault (outputs held at zero), and the station told which wheel.
    pub(crate) fn watch_stall(&mut self, controller: &mut Controller, step: &mut Step) {
        let Some(stall) = self.wheels.as_mut().and_then(Wheels::take_stall) else {
            return;
        };
        step.counters.stalls += 1;
        let text = format!(
            "{} stalled: driven at {:.0}% for {:.2} s without an encoder edge; outputs zeroed",
            controller.platform().motor_name(stall.wheel),
            stall.output.abs() * 100.0,
            stall.for_time.as_secs_f64(),
        );
        tracing::error!(robot = %step.robot(), "{text}");
        self.faults.actuator_fault(&text, controller, step);
    }

    /// The body twist the vehicle measured at `now` (a ROS 2 base's
    /// odometry): the velocity while no older than the position's
    /// staleness, unless wheel encoders measure it.
    pub(crate) fn observe_velocity(&mut self, twist: Twist, now: Duration) {
        self.measured = Some((twist, now));
    }

    /// Once per control period, before the outputs are computed: the
    /// robot moved at the velocity `outputs` (the ones driven since the
    /// last period) give, or its encoders measured, until `now`.
    pub(crate) fn advance(&mut self, platform: &dyn Platform, outputs: &[f64], now: Duration) {
        let (velocity, _) = self.velocity(platform, outputs, now);
        self.track.advance(&velocity, now);
    }

    /// What the robot knows of its motion now, `outputs` being the outputs
    /// it drives.
    ///
    /// The estimate is moved on to `now`: a median of fixes is where the
    /// robot was at the middle of its window (200 ms ago for 9 fixes at
    /// 20 Hz: 10 cm at 0.5 m/s), so the robot's own motion since then (its
    /// [`Track`]) is added; odometry fused with the fixes is current. Its
    /// error bound: for fused odometry, 3 standard deviations along the
    /// worst direction (99% of a planar Gaussian); for a median, the
    /// configured `safety.position_error` plus `a·t²/2` for the time `t`
    /// moved on (the velocity may have changed by `a·t` meanwhile, `a`
    /// being `max_deceleration`, the rate the layer assumes of every
    /// robot), infinite until the median's window is full (the layer
    /// then holds the robot still, as it does without an estimate).
    pub(crate) fn motion(&self, platform: &dyn Platform, outputs: &[f64], now: Duration) -> Motion {
        let (velocity, velocity_source) = self.velocity(platform, outputs, now);
        let (estimate, position_error) = match (self.estimate, &self.fusion) {
            (None, _) => (None, f64::INFINITY),
            (Some(e), Some(fusion)) => {
                let sigma = fusion.position_sigma().unwrap_or(f64::INFINITY);
                (Some(e), FUSED_BOUND * sigma)
            }
            (Some(e), None) => {
                let since = self.filter.middle_stamp().unwrap_or(e.stamp);
                let (moved, error) = self.track.since(since, now);
                // Until the window is full an outlier can be the estimate.
                let error = if self.filter.full() {
                    error
                } else {
                    f64::INFINITY
                };
                (Some(moved_on(e, moved)), error)
            }
        };
        Motion {
            estimate,
            position_error,
            velocity,
            velocity_source,
        }
    }

    /// The velocity in the world frame (turned by the estimated heading):
    /// measured by the encoders or the vehicle while fresh, else what
    /// `outputs` give.
    fn velocity(
        &self,
        platform: &dyn Platform,
        outputs: &[f64],
        now: Duration,
    ) -> (Velocity, VelocitySource) {
        let vehicle = self
            .measured
            .filter(|(_, at)| now.saturating_sub(*at) <= self.position_stale_after)
            .map(|(twist, _)| twist);
        let (twist, velocity_source) = match self
            .wheel_speeds(now)
            .and_then(|speeds| platform.wheel_odometry(&speeds))
            .or(vehicle)
        {
            Some(measured) => (measured, VelocitySource::Measured),
            None => (platform.motion(outputs), VelocitySource::Commanded),
        };
        let heading = self.estimate.map_or(0.0, |e| e.pose.heading);
        let (sin, cos) = heading.sin_cos();
        let velocity = Velocity {
            vx: twist.vx * cos - twist.vy * sin,
            vy: twist.vx * sin + twist.vy * cos,
            vz: twist.vz,
            wz: twist.wz,
        };
        (velocity, velocity_source)
    }

    /// `Fault` for a second after a driver error, `Degraded` while the
    /// position (if the robot has a source) is stale.
    pub(crate) fn health(&self, now: Duration) -> Health {
        let stale = self.has_position
            && self
                .estimate
                .is_none_or(|e| now.saturating_sub(e.stamp) > self.position_stale_after);
        if self.faults.recent(now) {
            Health::Fault
        } else if stale {
            Health::Degraded
        } else {
            Health::Ok
        }
    }
}

/// Standard deviations of a fused position taken as its error bound: 99%
/// of a planar Gaussian lies within 3.03 of them.
const FUSED_BOUND: f64 = 3.03;

/// `estimate` moved on by the robot's own displacement `moved` (x, y,
/// heading) since the time it refers to.
fn moved_on(mut estimate: PositionSample, moved: [f64; 3]) -> PositionSample {
    estimate.pose.x += moved[0];
    estimate.pose.y += moved[1];
    estimate.pose.heading = mech_proto::wrap_angle(estimate.pose.heading + moved[2]);
    estimate
}

/// The estimate with the fused planar pose; height, quality and stamp stay
/// the median filter's (odometry is planar, and the stamp says how fresh the
/// fixes are).
fn fused(fusion: &PoseFusion, mut estimate: PositionSample) -> PositionSample {
    if let Some(p) = fusion.pose() {
        estimate.pose = mech_proto::Pose {
            z: estimate.pose.z,
            ..p
        };
        estimate.has_heading = true;
    }
    estimate
}

/// The platform's odometry as a matrix: column `i` is the body displacement
/// (forward, left, heading) of one metre of wheel `i`'s travel.
fn wheel_jacobian(platform: &dyn Platform) -> Option<DMatrix<f64>> {
    let n = platform.motors();
    let mut j = DMatrix::zeros(3, n);
    for i in 0..n {
        let mut unit = vec![0.0; n];
        unit[i] = 1.0;
        let Twist { vx, vy, wz, .. } = platform.wheel_odometry(&unit)?;
        j.set_column(i, &Vector3::new(vx, vy, wz));
    }
    Some(j)
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn an_encoder_reading_that_does_not_fit_the_robot_is_a_driver_fault() {
        let mut s = AgentSettings::new("r1");
        s.wheels = Some(WheelSettings {
            counting: crate::hal::Counting::Quadrature,
            counts_per_revolution: 1440.0,
            wheel_radius: 0.03,
            speed_loop: None,
            stall: crate::wheels::StallSettings::default(),
        });
        let mut a = Agent::new(s, PlatformSpec::diff_drive().build(), 0);
        let notice = a.observe_wheels(&[EdgeCount::default()], ms(0)).unwrap();
        assert!(
            matches!(&notice.body, Body::Notice(n) if n.code == NoticeCode::DriverFault && n.text.contains("1 encoder readings for 2 wheels"))
        );
        assert_eq!(a.counters().driver_faults, 1);
        // A robot without [encoders] ignores readings.
        let mut plain = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        assert!(
            plain
                .observe_wheels(&[EdgeCount::default()], ms(0))
                .is_none()
        );
        assert_eq!(
            plain.telemetry(ms(0)).velocity_source,
            VelocitySource::Commanded
        );
    }

    #[test]
    fn external_position_fixes_feed_the_filter_only_when_configured() {
        for external in [false, true] {
            let mut s = AgentSettings::new("r1");
            s.external_position = external;
            let mut a = Agent::new(s, PlatformSpec::diff_drive().build(), 0);
            let fix = mech_proto::PositionFix {
                robot: "r1".into(),
                pose: Pose {
                    x: 1.5,
                    ..Pose::default()
                },
                quality: 0.9,
            };
            a.handle(msg("", Body::PositionFix(fix)), ms(0));
            assert_eq!(a.estimate().map(|e| e.pose.x), external.then_some(1.5));
        }
    }
}
