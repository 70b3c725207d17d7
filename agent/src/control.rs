//! Onboard control: turns the current command (or mission) and the position
//! estimate into actuator outputs through the robot's [`Platform`].
//!
//! The control mode changes with each command received, as the 2017 control
//! field did: raw actuators, steering-throttle, velocity-heading (heading
//! held by a proportional controller, turning on the spot first when the
//! error is large), body twist, waypoint missions (arrival radius, optional
//! arrival times, looping), stop.

pub mod mission;

use std::time::Duration;

use mech_proto::{
    Command, CommandKind, ControlMode, Pose, SteeringThrottle, Twist, VelocityHeading,
};
use serde::Deserialize;

use crate::platform::Platform;
use mech_proto::wrap_angle;

pub use mission::MissionRun;

/// Controller gains and limits, from the config's `[control]` table.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Gains {
    /// Yaw rate per radian of heading error, 1/s.
    pub heading: f64,
    /// Approach speed per metre of distance to the waypoint, 1/s.
    pub position: f64,
    /// Fraction of the platform's top speed used for waypoints without a time.
    pub cruise_fraction: f64,
    /// Heading error (rad) above which a non-holonomic robot turns on the
    /// spot before driving.
    pub turn_in_place: f64,
}

impl Default for Gains {
    fn default() -> Self {
        Gains {
            heading: 3.0,
            position: 1.2,
            cruise_fraction: 0.6,
            turn_in_place: 0.6,
        }
    }
}

/// What the controller is doing now.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// Nothing commanded yet (or after a route change): outputs zero.
    Idle,
    Actuators(Vec<f64>),
    SteeringThrottle(SteeringThrottle),
    VelocityHeading(VelocityHeading),
    Twist(Twist),
    /// Following the mission passed to [`Controller::update`].
    Waypoints,
    /// A `Stop` command: outputs zero until the next command.
    Stopped,
}

impl Mode {
    pub fn control_mode(&self) -> ControlMode {
        match self {
            Mode::Idle => ControlMode::Idle,
            Mode::Actuators(_) => ControlMode::Actuators,
            Mode::SteeringThrottle(_) => ControlMode::SteeringThrottle,
            Mode::VelocityHeading(_) => ControlMode::VelocityHeading,
            Mode::Twist(_) => ControlMode::Twist,
            Mode::Waypoints => ControlMode::Waypoints,
            Mode::Stopped => ControlMode::Stopped,
        }
    }
}

/// Why a command was not taken.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    #[error("this robot does not accept {0} commands")]
    Unsupported(CommandKind),
    #[error("{given} actuator outputs for a robot with {motors} motors")]
    MotorCount { given: usize, motors: usize },
}

/// What the controller asks of the vehicle for one period, at the level its
/// mode works at, before the platform turns it into actuator outputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Demand {
    /// Every output zero (idle, stopped, or waypoints without a mission);
    /// wheel speed loops hold the wheels at rest.
    Zero,
    /// Per-motor outputs, as commanded (actuator level).
    Actuators(Vec<f64>),
    /// Car-style input, mixed by the platform's own rule.
    SteeringThrottle(SteeringThrottle),
    /// A body-frame twist: twist commands, and what the velocity-heading and
    /// waypoint controllers compute.
    Twist(Twist),
}

impl Demand {
    /// The platform's actuator outputs for this demand, one per motor, each
    /// in `[-1, 1]`.
    pub fn outputs(&self, platform: &dyn Platform) -> Vec<f64> {
        let outputs = match self {
            Demand::Zero => vec![0.0; platform.motors()],
            Demand::Actuators(a) => a.clone(),
            Demand::SteeringThrottle(s) => platform.steering_throttle(s),
            Demand::Twist(t) => platform.mix(t),
        };
        outputs.into_iter().map(crate::hal::clamp_output).collect()
    }
}

/// The onboard controller of one robot.
#[derive(Debug)]
pub struct Controller {
    platform: Box<dyn Platform>,
    gains: Gains,
    capabilities: Vec<CommandKind>,
    mode: Mode,
    outputs: Vec<f64>,
}

impl Controller {
    /// A controller for `platform`. `has_position` says whether a position
    /// estimate exists; without one, modes that need it (velocity-heading,
    /// waypoints) are not offered.
    pub fn new(platform: Box<dyn Platform>, gains: Gains, has_position: bool) -> Controller {
        let capabilities = platform
            .capabilities()
            .into_iter()
            .filter(|k| {
                has_position || !matches!(k, CommandKind::VelocityHeading | CommandKind::Waypoints)
            })
            .collect();
        let outputs = vec![0.0; platform.motors()];
        Controller {
            platform,
            gains,
            capabilities,
            mode: Mode::Idle,
            outputs,
        }
    }

    pub fn platform(&self) -> &dyn Platform {
        self.platform.as_ref()
    }

    pub fn capabilities(&self) -> &[CommandKind] {
        &self.capabilities
    }

    /// The yaw rate per radian of heading error with which the command in
    /// force turns the robot towards a bearing (a mission,
    /// velocity-heading: the heading gain), or `None` when the yaw rate is
    /// the sender's own (twist, actuators, steering-throttle). Fleet safety
    /// reads where a command heads from it.
    pub fn bearing_gain(&self) -> Option<f64> {
        matches!(self.mode, Mode::Waypoints | Mode::VelocityHeading(_))
            .then_some(self.gains.heading)
    }

    pub fn mode(&self) -> &Mode {
        &self.mode
    }

    /// Last outputs computed by [`Controller::update`].
    pub fn outputs(&self) -> &[f64] {
        &self.outputs
    }

    /// Takes a command: the mode changes to the command's.
    pub fn command(&mut self, cmd: &Command) -> Result<(), Refused> {
        let kind = cmd.command_kind();
        if !self.capabilities.contains(&kind) {
            return Err(Refused::Unsupported(kind));
        }
        self.mode = match cmd {
            Command::Actuators(a) => {
                if a.outputs.len() != self.platform.motors() {
                    return Err(Refused::MotorCount {
                        given: a.outputs.len(),
                        motors: self.platform.motors(),
                    });
                }
                Mode::Actuators(a.outputs.clone())
            }
            Command::SteeringThrottle(s) => Mode::SteeringThrottle(*s),
            Command::VelocityHeading(v) => Mode::VelocityHeading(*v),
            Command::Twist(t) => Mode::Twist(*t),
            Command::Stop(_) => Mode::Stopped,
        };
        Ok(())
    }

    /// Switches to following a mission (the run itself is passed to
    /// [`Controller::update`] each period).
    pub fn follow_mission(&mut self) -> Result<(), Refused> {
        if !self.capabilities.contains(&CommandKind::Waypoints) {
            return Err(Refused::Unsupported(CommandKind::Waypoints));
        }
        self.mode = Mode::Waypoints;
        Ok(())
    }

    /// Back to idle (route change, e-stop): outputs zero.
    pub fn idle(&mut self) {
        self.mode = Mode::Idle;
        self.outputs.iter_mut().for_each(|u| *u = 0.0);
    }

    /// Whether the current mode steers by the position estimate
    /// (velocity-heading, waypoints): without an estimate it cannot run.
    pub fn needs_position(&self) -> bool {
        matches!(self.mode, Mode::VelocityHeading(_) | Mode::Waypoints)
    }

    /// One control period: what the current mode asks of the vehicle, from
    /// the pose estimate. `mission` is the run followed in
    /// [`Mode::Waypoints`] (none = hold still); following it advances it.
    pub fn demand(&self, pose: &Pose, now: Duration, mission: Option<&mut MissionRun>) -> Demand {
        match &self.mode {
            Mode::Idle | Mode::Stopped => Demand::Zero,
            Mode::Actuators(a) => Demand::Actuators(a.clone()),
            Mode::SteeringThrottle(s) => Demand::SteeringThrottle(*s),
            Mode::VelocityHeading(v) => Demand::Twist(self.velocity_heading(pose, v)),
            Mode::Twist(t) => Demand::Twist(*t),
            Mode::Waypoints => match mission {
                Some(run) => {
                    Demand::Twist(run.step(pose, now, self.platform.as_ref(), &self.gains))
                }
                None => Demand::Zero,
            },
        }
    }

    /// One control period: computes the outputs for the current mode from
    /// the pose estimate ([`Controller::demand`] through the platform).
    /// `mission` is the run followed in [`Mode::Waypoints`] (none = hold
    /// still).
    pub fn update(
        &mut self,
        pose: &Pose,
        now: Duration,
        mission: Option<&mut MissionRun>,
    ) -> &[f64] {
        let outputs = self.demand(pose, now, mission).outputs(self.platform());
        self.outputs = outputs;
        &self.outputs
    }

    fn velocity_heading(&self, pose: &Pose, v: &VelocityHeading) -> Twist {
        let err = wrap_angle(v.heading - pose.heading);
        let limits = self.platform.limits();
        let wz = (self.gains.heading * err).clamp(-limits.max_yaw_rate, limits.max_yaw_rate);
        let speed = v.speed.clamp(-limits.max_speed, limits.max_speed);
        if self.platform.holonomic() {
            // Move along the commanded world heading at once while turning
            // to face it.
            let (s, c) = (v.heading - pose.heading).sin_cos();
            Twist {
                vx: speed * c,
                vy: speed * s,
                vz: 0.0,
                wz,
            }
        } else {
            Twist {
                vx: speed * drive_factor(err, self.gains.turn_in_place),
                vy: 0.0,
                vz: 0.0,
                wz,
            }
        }
    }
}

/// Fraction of the commanded speed a non-holonomic robot uses with heading
/// error `err`: full when aligned, falling with cos(err), zero (turn on the
/// spot) beyond `turn_in_place`.
pub(crate) fn drive_factor(err: f64, turn_in_place: f64) -> f64 {
    if err.abs() > turn_in_place {
        0.0
    } else {
        err.cos().max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::{Actuators, Stop};

    #[test]
    fn each_mode_demands_at_its_own_level_and_outputs_are_clamped() {
        let mut c = dd();
        let p = Pose::default();
        assert_eq!(c.demand(&p, Duration::ZERO, None), Demand::Zero);
        c.command(&Command::Actuators(Actuators {
            outputs: vec![2.0, -0.5],
        }))
        .unwrap();
        let d = c.demand(&p, Duration::ZERO, None);
        assert_eq!(d, Demand::Actuators(vec![2.0, -0.5]));
        assert_eq!(d.outputs(c.platform()), [1.0, -0.5]);
        let st = SteeringThrottle {
            steering: 0.5,
            throttle: 1.0,
        };
        c.command(&Command::SteeringThrottle(st)).unwrap();
        let d = c.demand(&p, Duration::ZERO, None);
        assert_eq!(d, Demand::SteeringThrottle(st));
        assert_eq!(d.outputs(c.platform()), c.platform().steering_throttle(&st));
        assert!(!c.needs_position());
        c.command(&Command::VelocityHeading(VelocityHeading {
            speed: 0.3,
            heading: 0.0,
        }))
        .unwrap();
        assert!(c.needs_position());
        assert!(
            matches!(c.demand(&p, Duration::ZERO, None), Demand::Twist(t) if (t.vx - 0.3).abs() < 1e-9)
        );
        c.follow_mission().unwrap();
        assert!(c.needs_position());
        assert_eq!(
            c.demand(&p, Duration::ZERO, None),
            Demand::Zero,
            "no mission"
        );
    }

    fn dd() -> Controller {
        Controller::new(PlatformSpec::diff_drive().build(), Gains::default(), true)
    }

    #[test]
    fn mode_follows_each_command() {
        let mut c = dd();
        let p = Pose::default();
        c.command(&Command::Twist(Twist {
            vx: 0.2,
            ..Twist::default()
        }))
        .unwrap();
        assert_eq!(c.mode().control_mode(), ControlMode::Twist);
        assert!(c.update(&p, Duration::ZERO, None).iter().all(|u| *u > 0.0));
        c.command(&Command::Actuators(Actuators {
            outputs: vec![0.3, -0.3],
        }))
        .unwrap();
        assert_eq!(c.update(&p, Duration::ZERO, None), &[0.3, -0.3]);
        c.command(&Command::Stop(Stop {})).unwrap();
        assert_eq!(c.update(&p, Duration::ZERO, None), &[0.0, 0.0]);
        assert_eq!(c.mode().control_mode(), ControlMode::Stopped);
    }

    #[test]
    fn wrong_motor_count_and_missing_capability_are_refused() {
        let mut c = dd();
        assert_eq!(
            c.command(&Command::Actuators(Actuators { outputs: vec![0.1] })),
            Err(Refused::MotorCount {
                given: 1,
                motors: 2
            })
        );
        let mut blind =
            Controller::new(PlatformSpec::diff_drive().build(), Gains::default(), false);
        let vh = Command::VelocityHeading(VelocityHeading {
            speed: 0.1,
            heading: 0.0,
        });
        assert_eq!(
            blind.command(&vh),
            Err(Refused::Unsupported(CommandKind::VelocityHeading))
        );
        assert!(blind.follow_mission().is_err());
    }

    #[test]
    fn velocity_heading_turns_on_the_spot_when_far_off() {
        let mut c = dd();
        c.command(&Command::VelocityHeading(VelocityHeading {
            speed: 0.3,
            heading: 2.0,
        }))
        .unwrap();
        let out = c.update(&Pose::default(), Duration::ZERO, None).to_vec();
        let twist = c.platform().motion(&out);
        assert!(twist.vx.abs() < 1e-9 && twist.wz > 0.0);
        let aligned = Pose {
            heading: 2.0,
            ..Pose::default()
        };
        let out = c.update(&aligned, Duration::ZERO, None).to_vec();
        let twist = c.platform().motion(&out);
        assert!((twist.vx - 0.3).abs() < 1e-9 && twist.wz.abs() < 1e-9);
    }
}
