//! Quadcopter modelled at velocity level: its flight controller holds
//! attitude and thrust; the agent commands body-frame velocity and yaw rate,
//! as PX4 offboard or a Crazyflie's velocity setpoints do.
//!
//! Actuator order: `[vx, vy, vz, wz]`, each normalised to its limit.

use mech_proto::{CommandKind, Twist};

use super::{Limits, Platform};

#[derive(Debug, Clone, PartialEq)]
pub struct Quadcopter {
    pub max_speed: f64,
    pub max_climb: f64,
    pub max_yaw_rate: f64,
}

impl Quadcopter {
    pub fn new(max_speed: f64, max_climb: f64, max_yaw_rate: f64) -> Quadcopter {
        Quadcopter {
            max_speed,
            max_climb,
            max_yaw_rate,
        }
    }
}

impl Platform for Quadcopter {
    fn name(&self) -> &'static str {
        "quadcopter"
    }

    fn motors(&self) -> usize {
        4
    }

    fn limits(&self) -> Limits {
        Limits {
            max_speed: self.max_speed,
            max_yaw_rate: self.max_yaw_rate,
            max_climb: self.max_climb,
        }
    }

    fn holonomic(&self) -> bool {
        true
    }

    fn flies(&self) -> bool {
        true
    }

    /// Car-style steering has no meaning for a hovering vehicle.
    fn capabilities(&self) -> Vec<CommandKind> {
        CommandKind::ALL
            .into_iter()
            .filter(|k| *k != CommandKind::SteeringThrottle)
            .collect()
    }

    /// Horizontal speed is limited as a vector (the direction is kept);
    /// climb and yaw rate are clipped on their own.
    fn mix(&self, twist: &Twist) -> Vec<f64> {
        let horizontal = twist.vx.hypot(twist.vy);
        let k = if horizontal > self.max_speed {
            self.max_speed / horizontal
        } else {
            1.0
        };
        vec![
            twist.vx * k / self.max_speed,
            twist.vy * k / self.max_speed,
            (twist.vz / self.max_climb).clamp(-1.0, 1.0),
            (twist.wz / self.max_yaw_rate).clamp(-1.0, 1.0),
        ]
    }

    fn motion(&self, outputs: &[f64]) -> Twist {
        let get = |i: usize| outputs.get(i).copied().unwrap_or(0.0).clamp(-1.0, 1.0);
        Twist {
            vx: get(0) * self.max_speed,
            vy: get(1) * self.max_speed,
            vz: get(2) * self.max_climb,
            wz: get(3) * self.max_yaw_rate,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn twist_round_trips(vx in -0.7f64..0.7, vy in -0.7f64..0.7, vz in -0.5f64..0.5, wz in -1.5f64..1.5) {
            prop_assume!(vx.hypot(vy) <= 1.0);
            let q = Quadcopter::new(1.0, 0.5, 1.5);
            let back = q.motion(&q.mix(&Twist { vx, vy, vz, wz }));
            prop_assert!((back.vx - vx).abs() < 1e-9 && (back.vy - vy).abs() < 1e-9);
            prop_assert!((back.vz - vz).abs() < 1e-9 && (back.wz - wz).abs() < 1e-9);
        }
    }

    #[test]
    fn no_steering_throttle() {
        assert!(
            !Quadcopter::new(1.0, 0.5, 1.5)
                .capabilities()
                .contains(&CommandKind::SteeringThrottle)
        );
    }
}
