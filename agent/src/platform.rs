//! Platforms: the "math packages" that map vehicle-level commands to
//! actuator outputs and, for simulation, actuator outputs back to motion.
//!
//! Adding a platform is one file implementing [`Platform`] plus one variant
//! in [`PlatformSpec`] (its configuration).

pub mod diff_drive;
pub mod kiwi;
pub mod quadcopter;

use std::fmt::Debug;

use mech_proto::{CommandKind, SteeringThrottle, Twist};
use serde::Deserialize;

pub use diff_drive::DiffDrive;
pub use kiwi::Kiwi;
pub use quadcopter::Quadcopter;

/// Speed limits a platform reports in `Hello` and the controllers respect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Fastest translation, m/s.
    pub max_speed: f64,
    /// Fastest yaw rate, rad/s.
    pub max_yaw_rate: f64,
    /// Fastest climb or descent, m/s (0 for ground robots).
    pub max_climb: f64,
}

/// The kinematics of one kind of vehicle.
pub trait Platform: Debug + Send {
    /// Name used in `Hello` and configs (`diff-drive`, `kiwi`, `quadcopter`).
    fn name(&self) -> &'static str;

    /// Number of actuator outputs.
    fn motors(&self) -> usize;

    fn limits(&self) -> Limits;

    /// Whether the vehicle can translate sideways (`vy`) in its body frame;
    /// controllers then steer the velocity vector instead of turning first.
    fn holonomic(&self) -> bool;

    /// Whether the vehicle controls its height (`vz`).
    fn flies(&self) -> bool {
        false
    }

    /// Actuator outputs (each in `[-1, 1]`) that produce `twist` (body frame).
    /// A twist beyond the limits is scaled down as a whole, keeping the path's
    /// curvature, rather than clipped per motor.
    fn mix(&self, twist: &Twist) -> Vec<f64>;

    /// The body twist the vehicle settles to with these outputs (forward
    /// kinematics, used by the simulator and for velocity telemetry).
    fn motion(&self, outputs: &[f64]) -> Twist;

    /// Rim speed of a wheel at full output, m/s, for a platform whose
    /// outputs drive wheels (`None` otherwise: a quadcopter's outputs are
    /// velocity setpoints). Wheel encoders measure this speed, so it is what
    /// turns an output into a wheel speed setpoint for closed-loop control
    /// and what makes odometry possible.
    fn max_wheel_speed(&self) -> Option<f64> {
        None
    }

    /// The body twist that measured wheel rim speeds (m/s, motor order)
    /// produce: odometry. Unlike [`Platform::motion`], nothing is clamped to
    /// the outputs' range (a wheel may turn faster than its nominal top
    /// speed). `None` for a platform without wheels.
    fn wheel_odometry(&self, _wheel_speeds: &[f64]) -> Option<Twist> {
        None
    }

    /// What to call motor `index` in a fault text ("left wheel").
    fn motor_name(&self, index: usize) -> String {
        format!("motor {}", index + 1)
    }

    /// Command kinds this platform obeys.
    fn capabilities(&self) -> Vec<CommandKind> {
        CommandKind::ALL.to_vec()
    }

    /// Car-style input: throttle scales forward speed, steering scales yaw
    /// rate, both to the platform's limits.
    fn steering_throttle(&self, input: &SteeringThrottle) -> Vec<f64> {
        let l = self.limits();
        self.mix(&Twist {
            vx: input.throttle.clamp(-1.0, 1.0) * l.max_speed,
            vy: 0.0,
            vz: 0.0,
            wz: input.steering.clamp(-1.0, 1.0) * l.max_yaw_rate,
        })
    }
}

/// A platform and its geometry, as written in a robot's config
/// (`[platform] kind = "diff-drive"`, read through [`crate::config::Kind`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum PlatformSpec {
    DiffDrive {
        /// Distance between the wheel contact points, m.
        track_width: f64,
        /// Wheel rim speed at full output, m/s.
        max_wheel_speed: f64,
    },
    Kiwi {
        /// Distance from the centre to each wheel, m.
        radius: f64,
        /// Wheel rim speed at full output, m/s.
        max_wheel_speed: f64,
    },
    Quadcopter {
        max_speed: f64,
        max_climb: f64,
        max_yaw_rate: f64,
    },
}

impl PlatformSpec {
    /// A small lab diff-drive robot (15 cm track, 0.5 m/s).
    pub fn diff_drive() -> PlatformSpec {
        PlatformSpec::DiffDrive {
            track_width: 0.15,
            max_wheel_speed: 0.5,
        }
    }

    /// A small kiwi robot (10 cm wheel radius, 0.5 m/s wheels).
    pub fn kiwi() -> PlatformSpec {
        PlatformSpec::Kiwi {
            radius: 0.1,
            max_wheel_speed: 0.5,
        }
    }

    /// A small indoor quadcopter.
    pub fn quadcopter() -> PlatformSpec {
        PlatformSpec::Quadcopter {
            max_speed: 1.0,
            max_climb: 0.5,
            max_yaw_rate: 1.5,
        }
    }

    /// Checks the geometry; `Err` says which value is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: f64, what: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("`{what}` must be a positive number, got {v}"))
            }
        };
        match *self {
            PlatformSpec::DiffDrive {
                track_width,
                max_wheel_speed,
            } => {
                positive(track_width, "track_width")?;
                positive(max_wheel_speed, "max_wheel_speed")
            }
            PlatformSpec::Kiwi {
                radius,
                max_wheel_speed,
            } => {
                positive(radius, "radius")?;
                positive(max_wheel_speed, "max_wheel_speed")
            }
            PlatformSpec::Quadcopter {
                max_speed,
                max_climb,
                max_yaw_rate,
            } => {
                positive(max_speed, "max_speed")?;
                positive(max_climb, "max_climb")?;
                positive(max_yaw_rate, "max_yaw_rate")
            }
        }
    }

    /// Builds the platform.
    pub fn build(&self) -> Box<dyn Platform> {
        match *self {
            PlatformSpec::DiffDrive {
                track_width,
                max_wheel_speed,
            } => Box::new(DiffDrive::new(track_width, max_wheel_speed)),
            PlatformSpec::Kiwi {
                radius,
                max_wheel_speed,
            } => Box::new(Kiwi::new(radius, max_wheel_speed)),
            PlatformSpec::Quadcopter {
                max_speed,
                max_climb,
                max_yaw_rate,
            } => Box::new(Quadcopter::new(max_speed, max_climb, max_yaw_rate)),
        }
    }
}

/// Largest ratio `|value| / limit` over a set of outputs, at least 1: the
/// factor every output is divided by to keep all of them within limits.
pub(crate) fn saturation(values: &[f64], limit: f64) -> f64 {
    values.iter().fold(1.0_f64, |m, v| m.max(v.abs() / limit))
}
