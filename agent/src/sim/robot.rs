//! A simulated vehicle: a platform's forward kinematics, actuator limits and
//! a first-order actuator response, integrated in the arena frame.
//!
//! A wheeled platform's wheels are simulated one by one (each motor lags its
//! output, scaled by the battery's charge; a jammed wheel does not turn), so
//! simulated encoders can measure them; other platforms lag as a whole
//! twist.
//!
//! [`SimRobot`] also carries the same onboard [`Controller`] the agent uses,
//! so a fleet controller can be simulated in lock-step without any agent:
//!
//! ```
//! use mech_agent::sim::SimRobot;
//! use mech_agent::PlatformSpec;
//! use mech_proto::{Command, Pose, Twist};
//!
//! let mut robots = vec![
//!     SimRobot::new(&PlatformSpec::diff_drive(), Pose::default()),
//!     SimRobot::new(&PlatformSpec::kiwi(), Pose { x: 1.0, ..Pose::default() }),
//! ];
//! for _ in 0..100 {
//!     for r in &mut robots {
//!         r.apply(&Command::Twist(Twist { vx: 0.2, ..Twist::default() })).unwrap();
//!         r.step(0.01);
//!     }
//! }
//! assert!(robots[0].pose().x > 0.15);
//! assert!(robots[1].telemetry().pose.x > 1.15);
//! ```

use std::time::Duration;

use mech_proto::{
    Command, Computation, ControlMode, FailsafeState, Health, Mission, Pose, Telemetry, Twist,
    Velocity,
};

use crate::control::{Controller, Gains, MissionRun, Refused};
use crate::platform::{Platform, PlatformSpec};
use mech_proto::wrap_angle;

/// Time constant of the simulated actuators (wheel or velocity-loop lag), s.
pub const DEFAULT_RESPONSE_TIME: f64 = 0.05;

/// One simulated vehicle.
#[derive(Debug)]
pub struct SimRobot {
    spec: PlatformSpec,
    /// Kinematics (forward direction: outputs -> motion).
    platform: Box<dyn Platform>,
    /// Onboard control for [`SimRobot::apply`] / [`SimRobot::step`].
    controller: Controller,
    mission: Option<MissionRun>,
    pose: Pose,
    /// Actual body-frame velocity, lagging the commanded one.
    twist: Twist,
    /// Actual rim speed of each wheel, m/s (wheeled platforms).
    wheels: Vec<f64>,
    /// Rim travel of each wheel during the last step, m.
    wheel_travel: Vec<f64>,
    /// Wheels that are jammed (do not turn whatever their output).
    jammed: Vec<bool>,
    /// Motor gain: the battery's charge as a fraction of the voltage at
    /// which the platform's top speeds hold (1 = full).
    battery: f64,
    outputs: Vec<f64>,
    response_time: f64,
    time: Duration,
}

impl SimRobot {
    /// A robot of `platform` at `pose`, at rest.
    pub fn new(platform: &PlatformSpec, pose: Pose) -> SimRobot {
        let kinematics = platform.build();
        let motors = kinematics.motors();
        SimRobot {
            spec: platform.clone(),
            controller: Controller::new(platform.build(), Gains::default(), true),
            platform: kinematics,
            mission: None,
            pose,
            twist: Twist::default(),
            wheels: vec![0.0; motors],
            wheel_travel: vec![0.0; motors],
            jammed: vec![false; motors],
            battery: 1.0,
            outputs: vec![0.0; motors],
            response_time: DEFAULT_RESPONSE_TIME,
            time: Duration::ZERO,
        }
    }

    /// Uses these controller gains for [`SimRobot::apply`].
    pub fn with_gains(mut self, gains: Gains) -> SimRobot {
        self.controller = Controller::new(self.spec.build(), gains, true);
        self
    }

    pub fn platform(&self) -> &dyn Platform {
        self.platform.as_ref()
    }

    /// True pose (no measurement noise).
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Actual body-frame velocity.
    pub fn twist(&self) -> Twist {
        self.twist
    }

    /// Outputs applied during the last step.
    pub fn outputs(&self) -> &[f64] {
        &self.outputs
    }

    /// Simulated time so far.
    pub fn time(&self) -> Duration {
        self.time
    }

    /// Sets the battery's charge: every motor turns at `charge` times the
    /// speed its output would give on a full battery (a DC motor's speed
    /// follows its voltage). Clamped to `[0, 1]`.
    pub fn set_battery(&mut self, charge: f64) {
        self.battery = if charge.is_nan() {
            1.0
        } else {
            charge.clamp(0.0, 1.0)
        };
    }

    /// Jams wheel `index` (it stops at once and turns no more) or frees it.
    pub fn set_jammed(&mut self, index: usize, jammed: bool) {
        if let Some(j) = self.jammed.get_mut(index) {
            *j = jammed;
        }
    }

    /// Actual rim speed of each wheel, m/s (empty for a platform without
    /// wheels).
    pub fn wheel_speeds(&self) -> &[f64] {
        if self.platform.max_wheel_speed().is_some() {
            &self.wheels
        } else {
            &[]
        }
    }

    /// Rim travel of each wheel during the last step, m (what an encoder on
    /// it measures, before slip).
    pub fn wheel_travel(&self) -> &[f64] {
        &self.wheel_travel
    }

    /// Gives the onboard controller a command (any mode; the mode changes
    /// with each command, as on the real agent).
    pub fn apply(&mut self, cmd: &Command) -> Result<(), Refused> {
        self.controller.command(cmd)
    }

    /// Starts following a waypoint mission with the onboard controller.
    pub fn set_mission(&mut self, mission: Mission) -> Result<(), Refused> {
        self.controller.follow_mission()?;
        self.mission = Some(MissionRun::new(mission));
        Ok(())
    }

    /// The mission being followed.
    pub fn mission(&self) -> Option<&MissionRun> {
        self.mission.as_ref()
    }

    /// Advances `dt` seconds: the onboard controller computes outputs from
    /// the true pose, then the vehicle moves.
    pub fn step(&mut self, dt: f64) {
        let now = self.time;
        let outputs = self
            .controller
            .update(&self.pose, now, self.mission.as_mut())
            .to_vec();
        self.step_outputs(&outputs, dt);
    }

    /// Advances `dt` seconds with these actuator outputs (bypassing the
    /// controller; the agent's own outputs in a simulated agent).
    pub fn step_outputs(&mut self, outputs: &[f64], dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        self.time += Duration::from_secs_f64(dt);
        self.outputs.clear();
        self.outputs
            .extend(outputs.iter().map(|u| crate::hal::clamp_output(*u)));
        let a = if self.response_time > 0.0 {
            1.0 - (-dt / self.response_time).exp()
        } else {
            1.0
        };
        match self.platform.max_wheel_speed() {
            Some(max) => self.step_wheels(max, a, dt),
            None => {
                let driven: Vec<f64> = self.outputs.iter().map(|u| u * self.battery).collect();
                let target = self.platform.motion(&driven);
                let t = &mut self.twist;
                t.vx += (target.vx - t.vx) * a;
                t.vy += (target.vy - t.vy) * a;
                t.vz += (target.vz - t.vz) * a;
                t.wz += (target.wz - t.wz) * a;
            }
        }
        let t = &self.twist;
        let mid = self.pose.heading + t.wz * dt / 2.0;
        let (s, c) = mid.sin_cos();
        self.pose.x += (t.vx * c - t.vy * s) * dt;
        self.pose.y += (t.vx * s + t.vy * c) * dt;
        if self.platform.flies() {
            self.pose.z = (self.pose.z + t.vz * dt).max(0.0);
        }
        self.pose.heading = wrap_angle(self.pose.heading + t.wz * dt);
    }

    /// Each wheel's motor lags toward its output's speed (`a` is the lag's
    /// step fraction); the body moves as the wheels turn.
    fn step_wheels(&mut self, max_wheel_speed: f64, a: f64, dt: f64) {
        for (i, w) in self.wheels.iter_mut().enumerate() {
            let target =
                self.outputs.get(i).copied().unwrap_or(0.0) * self.battery * max_wheel_speed;
            *w = if self.jammed.get(i).copied().unwrap_or(false) {
                0.0
            } else {
                *w + (target - *w) * a
            };
        }
        self.wheel_travel.clear();
        self.wheel_travel.extend(self.wheels.iter().map(|w| w * dt));
        if let Some(t) = self.platform.wheel_odometry(&self.wheels) {
            self.twist = t;
        }
    }

    /// Telemetry as an agent would report it (true pose, no failsafe).
    pub fn telemetry(&self) -> Telemetry {
        Telemetry {
            pose: self.pose,
            velocity: Velocity {
                vx: self.twist.vx,
                vy: self.twist.vy,
                vz: self.twist.vz,
                wz: self.twist.wz,
            },
            mode: self.controller.mode().control_mode(),
            channel: String::new(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: None,
            position_quality: 1.0,
            actuators: self.outputs.clone(),
            mission: self.mission.as_ref().map(MissionRun::progress),
            stale: 0,
            // The true motion: what ideal encoders would measure.
            velocity_source: mech_proto::VelocitySource::Measured,
            safety: None,
        }
    }

    /// The current control mode.
    pub fn mode(&self) -> ControlMode {
        self.controller.mode().control_mode()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn settle(spec: &PlatformSpec, twist: Twist) -> Twist {
        let mut r = SimRobot::new(spec, Pose::default());
        let out = r.platform().mix(&twist);
        for _ in 0..200 {
            r.step_outputs(&out, 0.01);
        }
        // Velocity measured from the motion itself over one more second.
        let (p0, h0) = (r.pose(), r.pose().heading);
        let steps = 100;
        for _ in 0..steps {
            r.step_outputs(&out, 0.01);
        }
        let p1 = r.pose();
        let dh = wrap_angle(p1.heading - h0);
        let wz = dh / 1.0;
        // Body velocity from the chord, rotated back by the mid heading.
        let (dx, dy) = (p1.x - p0.x, p1.y - p0.y);
        let mid = h0 + dh / 2.0;
        let (s, c) = mid.sin_cos();
        // For an arc the chord is shorter than the path by sinc(dh/2).
        let k = if dh.abs() > 1e-9 {
            (dh / 2.0) / (dh / 2.0).sin()
        } else {
            1.0
        };
        Twist {
            vx: (dx * c + dy * s) * k,
            vy: (-dx * s + dy * c) * k,
            vz: (p1.z - p0.z),
            wz,
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn diff_drive_reproduces_commanded_twist(vx in -0.3f64..0.3, wz in -2.0f64..2.0) {
            let spec = PlatformSpec::diff_drive();
            prop_assume!(vx.abs() + wz.abs() * 0.075 <= 0.5);
            let got = settle(&spec, Twist { vx, vy: 0.0, vz: 0.0, wz });
            prop_assert!((got.vx - vx).abs() < 0.01, "{got:?}");
            prop_assert!((got.wz - wz).abs() < 0.01, "{got:?}");
        }

        #[test]
        fn kiwi_reproduces_commanded_twist(vx in -0.2f64..0.2, vy in -0.2f64..0.2, wz in -1.0f64..1.0) {
            let spec = PlatformSpec::kiwi();
            let got = settle(&spec, Twist { vx, vy, vz: 0.0, wz });
            prop_assert!((got.vx - vx).abs() < 0.01 && (got.vy - vy).abs() < 0.01, "{got:?}");
            prop_assert!((got.wz - wz).abs() < 0.01, "{got:?}");
        }

        #[test]
        fn quadcopter_reproduces_commanded_twist(vx in -0.5f64..0.5, vy in -0.5f64..0.5, vz in 0.0f64..0.4, wz in -1.0f64..1.0) {
            let spec = PlatformSpec::quadcopter();
            let got = settle(&spec, Twist { vx, vy, vz, wz });
            prop_assert!((got.vx - vx).abs() < 0.01 && (got.vy - vy).abs() < 0.01, "{got:?}");
            prop_assert!((got.vz - vz).abs() < 0.01 && (got.wz - wz).abs() < 0.01, "{got:?}");
        }
    }

    #[test]
    fn mission_reaches_its_waypoint() {
        use mech_proto::Waypoint;
        for spec in [
            PlatformSpec::diff_drive(),
            PlatformSpec::kiwi(),
            PlatformSpec::quadcopter(),
        ] {
            let mut r = SimRobot::new(&spec, Pose::default());
            let wp = Waypoint {
                x: 1.0,
                y: -0.5,
                z: 0.5,
                time: None,
            };
            r.set_mission(Mission {
                id: 1,
                waypoints: vec![wp],
                looped: false,
                arrival_radius: 0.02,
                start_index: 0,
            })
            .unwrap();
            for _ in 0..3000 {
                r.step(0.01);
            }
            let p = r.pose();
            assert!(r.mission().unwrap().finished(), "{spec:?}");
            assert!((p.x - 1.0).hypot(p.y + 0.5) < 0.03, "{spec:?} {p:?}");
        }
    }

    #[test]
    fn with_gains_keeps_the_kinematics() {
        for spec in [
            PlatformSpec::diff_drive(),
            PlatformSpec::kiwi(),
            PlatformSpec::quadcopter(),
        ] {
            let r = SimRobot::new(&spec, Pose::default()).with_gains(Gains::default());
            assert_eq!(r.controller.platform().limits(), r.platform().limits());
        }
    }
}
