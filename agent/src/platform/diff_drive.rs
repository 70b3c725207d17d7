//! Differential drive: two wheels on one axle, steered by their speed
//! difference. The platform of the 2017 robots (MotorController.py).
//!
//! Motor order: `[left, right]`; output `1` = rim speed `max_wheel_speed`
//! forward.

use mech_proto::{CommandKind, SteeringThrottle, Twist};

use super::{Limits, Platform, saturation};

#[derive(Debug, Clone, PartialEq)]
pub struct DiffDrive {
    /// Distance between wheel contact points, m.
    pub track_width: f64,
    /// Rim speed at full output, m/s.
    pub max_wheel_speed: f64,
}

impl DiffDrive {
    pub fn new(track_width: f64, max_wheel_speed: f64) -> DiffDrive {
        DiffDrive {
            track_width,
            max_wheel_speed,
        }
    }
}

impl DiffDrive {
    /// Body twist from left and right rim speeds, m/s.
    fn wheels_to_twist(&self, left: f64, right: f64) -> Twist {
        Twist {
            vx: (left + right) / 2.0,
            vy: 0.0,
            vz: 0.0,
            wz: (right - left) / self.track_width,
        }
    }
}

impl Platform for DiffDrive {
    fn name(&self) -> &'static str {
        "diff-drive"
    }

    fn motors(&self) -> usize {
        2
    }

    fn limits(&self) -> Limits {
        Limits {
            max_speed: self.max_wheel_speed,
            max_yaw_rate: 2.0 * self.max_wheel_speed / self.track_width,
            max_climb: 0.0,
        }
    }

    fn holonomic(&self) -> bool {
        false
    }

    fn capabilities(&self) -> Vec<CommandKind> {
        CommandKind::ALL.to_vec()
    }

    fn mix(&self, twist: &Twist) -> Vec<f64> {
        let half = self.track_width / 2.0;
        let wheels = [twist.vx - twist.wz * half, twist.vx + twist.wz * half];
        let k = saturation(&wheels, self.max_wheel_speed) * self.max_wheel_speed;
        wheels.iter().map(|w| w / k).collect()
    }

    fn motion(&self, outputs: &[f64]) -> Twist {
        let get = |i: usize| outputs.get(i).copied().unwrap_or(0.0).clamp(-1.0, 1.0);
        self.wheels_to_twist(get(0) * self.max_wheel_speed, get(1) * self.max_wheel_speed)
    }

    fn max_wheel_speed(&self) -> Option<f64> {
        Some(self.max_wheel_speed)
    }

    fn wheel_odometry(&self, wheel_speeds: &[f64]) -> Option<Twist> {
        let get = |i: usize| wheel_speeds.get(i).copied().unwrap_or(0.0);
        Some(self.wheels_to_twist(get(0), get(1)))
    }

    fn motor_name(&self, index: usize) -> String {
        match index {
            0 => "left wheel".to_string(),
            1 => "right wheel".to_string(),
            _ => format!("motor {}", index + 1),
        }
    }

    /// Arcade mixing as the 2017 MotorController did: left = throttle -
    /// steering, right = throttle + steering, scaled down together when either
    /// exceeds full output.
    fn steering_throttle(&self, input: &SteeringThrottle) -> Vec<f64> {
        let wheels = [
            input.throttle - input.steering,
            input.throttle + input.steering,
        ];
        let k = saturation(&wheels, 1.0);
        wheels.iter().map(|w| w / k).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn robot() -> DiffDrive {
        DiffDrive::new(0.15, 0.5)
    }

    #[test]
    fn forward_spins_both_wheels_equally_and_turning_left_speeds_the_right_wheel() {
        let dd = robot();
        assert_eq!(
            dd.mix(&Twist {
                vx: 0.25,
                ..Twist::default()
            }),
            vec![0.5, 0.5]
        );
        let turn = dd.mix(&Twist {
            wz: 1.0,
            ..Twist::default()
        });
        assert!(turn[0] < 0.0 && turn[1] > 0.0);
        assert!((turn[0] + turn[1]).abs() < 1e-12);
    }

    #[test]
    fn arcade_mixing_scales_down_together() {
        let st = robot().steering_throttle(&SteeringThrottle {
            steering: 0.5,
            throttle: 1.0,
        });
        assert_eq!(st, vec![0.5 / 1.5, 1.0]);
    }

    proptest! {
        #[test]
        fn twist_within_limits_round_trips(vx in -0.5f64..0.5, wz in -6.0f64..6.0) {
            let dd = robot();
            let half = dd.track_width / 2.0;
            prop_assume!(vx.abs() + wz.abs() * half <= dd.max_wheel_speed);
            let out = dd.mix(&Twist { vx, vy: 0.0, vz: 0.0, wz });
            prop_assert!(out.iter().all(|u| u.abs() <= 1.0 + 1e-12));
            let back = dd.motion(&out);
            prop_assert!((back.vx - vx).abs() < 1e-9);
            prop_assert!((back.wz - wz).abs() < 1e-9);
        }

        #[test]
        fn odometry_of_wheel_speeds_is_the_motion_of_their_outputs(l in -1.0f64..1.0, r in -1.0f64..1.0) {
            let dd = robot();
            let max = dd.max_wheel_speed;
            prop_assert_eq!(dd.wheel_odometry(&[l * max, r * max]), Some(dd.motion(&[l, r])));
            // Beyond full output, measured speeds are not clamped.
            let fast = dd.wheel_odometry(&[2.0 * max, 2.0 * max]).unwrap();
            prop_assert!((fast.vx - 2.0 * max).abs() < 1e-12);
        }

        #[test]
        fn twist_beyond_limits_keeps_curvature(vx in 0.1f64..3.0, wz in -20.0f64..20.0) {
            let dd = robot();
            let out = dd.mix(&Twist { vx, vy: 0.0, vz: 0.0, wz });
            prop_assert!(out.iter().all(|u| u.abs() <= 1.0 + 1e-12));
            let back = dd.motion(&out);
            prop_assert!((back.wz / back.vx - wz / vx).abs() < 1e-6 * (1.0 + (wz / vx).abs()));
        }
    }
}
