//! Mappings from shaped stick values to commands, one per teleop mode.
//!
//! Layout (sticks: Y positive pushed away, X positive right):
//! - steering-throttle: left stick Y = throttle, right stick X = steering;
//! - velocity-heading: left stick direction = world heading (up = +y,
//!   right = +x, as on the map), deflection = speed;
//! - tank: left stick Y = left motor, right stick Y = right motor;
//! - twist: left stick = vx (Y) and vy (X), right stick X = yaw rate,
//!   right minus left trigger = vz;
//! - cluster: left stick translates the cluster, right stick X rotates it,
//!   right stick Y grows (up) or shrinks (down) the formation.

use mech_proto::{
    Actuators, ClusterVelocity, Command, SteeringThrottle, Stop, Twist, VelocityHeading,
};

use mech_control::{ClusterStickRates, ClusterSticks, cluster_velocity_from_sticks};

mech_proto::named_enum! {
    /// What the sticks drive.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub enum TeleopMode: "teleop mode" {
        #[default]
        SteeringThrottle => "steering-throttle",
        VelocityHeading => "velocity-heading",
        Tank => "tank",
        Twist => "twist",
        Cluster => "cluster",
    }
}

impl TeleopMode {
    /// The next mode in the cycle the mode button walks through.
    pub fn next(self) -> TeleopMode {
        let i = Self::ALL.iter().position(|m| *m == self).unwrap_or(0);
        Self::ALL[(i + 1) % Self::ALL.len()]
    }

    /// How the routes panel and the log show the mode (shorter than its
    /// name).
    pub fn label(self) -> &'static str {
        match self {
            TeleopMode::SteeringThrottle => "steer-throttle",
            TeleopMode::VelocityHeading => "vel-heading",
            TeleopMode::Tank => "tank",
            TeleopMode::Twist => "twist",
            TeleopMode::Cluster => "cluster",
        }
    }
}

/// Shaped stick and trigger values.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sticks {
    pub left_x: f64,
    pub left_y: f64,
    pub right_x: f64,
    pub right_y: f64,
    /// `0..1`.
    pub left_trigger: f64,
    /// `0..1`.
    pub right_trigger: f64,
}

/// Full-deflection values for the velocity-level modes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// m/s at full stick.
    pub max_speed: f64,
    /// rad/s at full stick.
    pub max_yaw_rate: f64,
    /// Formation growth rate, 1/s, at full stick.
    pub max_scale_rate: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_speed: 0.5,
            max_yaw_rate: 1.5,
            max_scale_rate: 0.5,
        }
    }
}

/// A mapped output: a vehicle/actuator command, or a cluster velocity.
#[derive(Debug, Clone, PartialEq)]
pub enum Mapped {
    Command(Command),
    Cluster(ClusterVelocity),
}

impl Mapped {
    /// The "hold still" output for a mode: published once when the dead-man
    /// is released or the pad disappears.
    pub fn zero(mode: TeleopMode) -> Mapped {
        match mode {
            TeleopMode::Cluster => Mapped::Cluster(ClusterVelocity {
                vx: 0.0,
                vy: 0.0,
                wz: 0.0,
                scale_rate: 0.0,
            }),
            _ => Mapped::Command(Command::Stop(Stop {})),
        }
    }
}

/// Maps sticks to the mode's output. `last_heading` is held by
/// velocity-heading when the stick is centred (speed 0, keep facing).
pub fn map(mode: TeleopMode, s: &Sticks, limits: &Limits, last_heading: f64) -> Mapped {
    match mode {
        TeleopMode::SteeringThrottle => {
            Mapped::Command(Command::SteeringThrottle(SteeringThrottle {
                steering: (-s.right_x).clamp(-1.0, 1.0),
                throttle: s.left_y.clamp(-1.0, 1.0),
            }))
        }
        TeleopMode::VelocityHeading => {
            let mag = s.left_x.hypot(s.left_y).min(1.0);
            let heading = if mag > 0.0 {
                s.left_y.atan2(s.left_x)
            } else {
                last_heading
            };
            Mapped::Command(Command::VelocityHeading(VelocityHeading {
                speed: mag * limits.max_speed,
                heading,
            }))
        }
        TeleopMode::Tank => Mapped::Command(Command::Actuators(Actuators {
            outputs: vec![s.left_y.clamp(-1.0, 1.0), s.right_y.clamp(-1.0, 1.0)],
        })),
        TeleopMode::Twist => Mapped::Command(Command::Twist(Twist {
            vx: s.left_y * limits.max_speed,
            vy: -s.left_x * limits.max_speed,
            vz: (s.right_trigger - s.left_trigger) * limits.max_speed,
            wz: -s.right_x * limits.max_yaw_rate,
        })),
        // The one cluster stick mapping; the sticks are already shaped
        // (deadzone and expo), so no second dead zone here.
        TeleopMode::Cluster => Mapped::Cluster(cluster_velocity_from_sticks(
            &ClusterSticks {
                forward: s.left_y,
                left: -s.left_x,
                turn_left: -s.right_x,
                grow: s.right_y.max(0.0),
                shrink: (-s.right_y).max(0.0),
            },
            &ClusterStickRates {
                speed: limits.max_speed,
                yaw_rate: limits.max_yaw_rate,
                scale_rate: limits.max_scale_rate,
                dead_zone: 0.0,
            },
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sticks(lx: f64, ly: f64, rx: f64, ry: f64) -> Sticks {
        Sticks {
            left_x: lx,
            left_y: ly,
            right_x: rx,
            right_y: ry,
            ..Sticks::default()
        }
    }

    #[test]
    fn steering_throttle_left_is_positive_steering() {
        let m = map(
            TeleopMode::SteeringThrottle,
            &sticks(0.0, 0.8, -0.5, 0.0),
            &Limits::default(),
            0.0,
        );
        assert_eq!(
            m,
            Mapped::Command(Command::SteeringThrottle(SteeringThrottle {
                steering: 0.5,
                throttle: 0.8
            }))
        );
    }

    #[test]
    fn velocity_heading_points_where_the_stick_points() {
        let l = Limits::default();
        let Mapped::Command(Command::VelocityHeading(v)) = map(
            TeleopMode::VelocityHeading,
            &sticks(0.0, 1.0, 0.0, 0.0),
            &l,
            0.0,
        ) else {
            panic!("velocity-heading expected");
        };
        assert!((v.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((v.speed - l.max_speed).abs() < 1e-12);
        let Mapped::Command(Command::VelocityHeading(v)) =
            map(TeleopMode::VelocityHeading, &Sticks::default(), &l, 1.25)
        else {
            panic!("velocity-heading expected");
        };
        assert_eq!(
            (v.speed, v.heading),
            (0.0, 1.25),
            "centred stick keeps heading"
        );
    }

    #[test]
    fn tank_drives_two_motors_from_two_sticks() {
        let m = map(
            TeleopMode::Tank,
            &sticks(0.9, 0.5, -0.9, -0.25),
            &Limits::default(),
            0.0,
        );
        assert_eq!(
            m,
            Mapped::Command(Command::Actuators(Actuators {
                outputs: vec![0.5, -0.25]
            }))
        );
    }

    #[test]
    fn twist_uses_rep103_signs() {
        let l = Limits {
            max_speed: 2.0,
            max_yaw_rate: 1.0,
            max_scale_rate: 0.5,
        };
        let s = Sticks {
            left_x: 0.5,
            left_y: 1.0,
            right_x: -1.0,
            right_y: 0.0,
            left_trigger: 0.0,
            right_trigger: 0.5,
        };
        assert_eq!(
            map(TeleopMode::Twist, &s, &l, 0.0),
            Mapped::Command(Command::Twist(Twist {
                vx: 2.0,
                vy: -1.0,
                vz: 1.0,
                wz: 1.0
            }))
        );
    }

    #[test]
    fn cluster_translates_rotates_and_scales() {
        let l = Limits::default();
        let Mapped::Cluster(c) = map(TeleopMode::Cluster, &sticks(-1.0, 0.0, 0.0, 1.0), &l, 0.0)
        else {
            panic!("cluster expected");
        };
        assert_eq!(c.vy, l.max_speed);
        assert_eq!(c.scale_rate, l.max_scale_rate);
        assert_eq!(c.wz, 0.0);
    }

    #[test]
    fn mode_cycle_visits_every_mode() {
        let mut m = TeleopMode::default();
        let mut seen = vec![m];
        for _ in 0..TeleopMode::ALL.len() - 1 {
            m = m.next();
            seen.push(m);
        }
        assert_eq!(seen, TeleopMode::ALL.to_vec());
        assert_eq!(m.next(), TeleopMode::default());
    }
}
