//! Three-wheel holonomic ("kiwi") drive: three omni-wheels at 120 degrees,
//! each rolling freely sideways, so any body twist `(vx, vy, wz)` is
//! reachable.
//!
//! Wheel `i` sits at angle `θi` = 90°, 210°, 330° from the body +x axis, at
//! `radius` from the centre, and drives tangentially (counter-clockwise
//! positive): `v_i = -sin θi · vx + cos θi · vy + radius · wz`.
//! Motor order: wheel at 90° (left), 210° (rear right), 330° (front right).

use mech_proto::Twist;
use nalgebra::{Matrix3, Vector3};

use super::{Limits, Platform, saturation};

#[derive(Debug, Clone, PartialEq)]
pub struct Kiwi {
    /// Centre-to-wheel distance, m.
    pub radius: f64,
    /// Rim speed at full output, m/s.
    pub max_wheel_speed: f64,
    /// Wheel speeds from body twist.
    inverse: Matrix3<f64>,
    /// Body twist from wheel speeds.
    forward: Matrix3<f64>,
}

/// Wheel positions around the body, rad from +x.
const WHEEL_ANGLES: [f64; 3] = [
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_2 + 2.0 * std::f64::consts::FRAC_PI_3,
    std::f64::consts::FRAC_PI_2 + 4.0 * std::f64::consts::FRAC_PI_3,
];

impl Kiwi {
    pub fn new(radius: f64, max_wheel_speed: f64) -> Kiwi {
        let row = |t: f64| [-t.sin(), t.cos(), radius];
        let [a, b, c] = WHEEL_ANGLES.map(row);
        let inverse = Matrix3::new(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]);
        // Wheels 120 degrees apart with a positive radius always give an
        // invertible matrix (determinant 3·sqrt(3)/2 · radius).
        let forward = inverse.try_inverse().unwrap_or_else(Matrix3::zeros);
        Kiwi {
            radius,
            max_wheel_speed,
            inverse,
            forward,
        }
    }
}

impl Kiwi {
    /// Body twist from the three rim speeds, m/s.
    fn wheels_to_twist(&self, wheels: Vector3<f64>) -> Twist {
        let t = self.forward * wheels;
        Twist {
            vx: t[0],
            vy: t[1],
            vz: 0.0,
            wz: t[2],
        }
    }
}

impl Platform for Kiwi {
    fn name(&self) -> &'static str {
        "kiwi"
    }

    fn motors(&self) -> usize {
        3
    }

    fn limits(&self) -> Limits {
        Limits {
            // A pure translation at speed v needs |v·sin(φ - θi)| <= v on
            // each wheel, so the rim speed is reachable in every direction.
            max_speed: self.max_wheel_speed,
            max_yaw_rate: self.max_wheel_speed / self.radius,
            max_climb: 0.0,
        }
    }

    fn holonomic(&self) -> bool {
        true
    }

    fn mix(&self, twist: &Twist) -> Vec<f64> {
        let w = self.inverse * Vector3::new(twist.vx, twist.vy, twist.wz);
        let k = saturation(w.as_slice(), self.max_wheel_speed) * self.max_wheel_speed;
        w.iter().map(|v| v / k).collect()
    }

    fn motion(&self, outputs: &[f64]) -> Twist {
        let get = |i: usize| outputs.get(i).copied().unwrap_or(0.0).clamp(-1.0, 1.0);
        self.wheels_to_twist(Vector3::new(get(0), get(1), get(2)) * self.max_wheel_speed)
    }

    fn max_wheel_speed(&self) -> Option<f64> {
        Some(self.max_wheel_speed)
    }

    fn wheel_odometry(&self, wheel_speeds: &[f64]) -> Option<Twist> {
        let get = |i: usize| wheel_speeds.get(i).copied().unwrap_or(0.0);
        Some(self.wheels_to_twist(Vector3::new(get(0), get(1), get(2))))
    }

    fn motor_name(&self, index: usize) -> String {
        match index {
            0 => "left wheel".to_string(),
            1 => "rear right wheel".to_string(),
            2 => "front right wheel".to_string(),
            _ => format!("motor {}", index + 1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn sideways_motion_is_possible() {
        let k = Kiwi::new(0.1, 0.5);
        let out = k.mix(&Twist {
            vy: 0.2,
            ..Twist::default()
        });
        let back = k.motion(&out);
        assert!((back.vy - 0.2).abs() < 1e-9 && back.vx.abs() < 1e-9 && back.wz.abs() < 1e-9);
        // Left wheel (tangent pointing -x) does not turn for pure +y motion.
        assert!(
            k.mix(&Twist {
                vx: 0.2,
                ..Twist::default()
            })[0]
                < 0.0
        );
    }

    proptest! {
        #[test]
        fn odometry_of_wheel_speeds_is_the_motion_of_their_outputs(a in -1.0f64..1.0, b in -1.0f64..1.0, c in -1.0f64..1.0) {
            let k = Kiwi::new(0.1, 0.5);
            let odometry = k.wheel_odometry(&[a * 0.5, b * 0.5, c * 0.5]).unwrap();
            let motion = k.motion(&[a, b, c]);
            prop_assert!((odometry.vx - motion.vx).abs() < 1e-12);
            prop_assert!((odometry.vy - motion.vy).abs() < 1e-12);
            prop_assert!((odometry.wz - motion.wz).abs() < 1e-12);
        }

        #[test]
        fn twist_round_trips_within_limits(vx in -0.4f64..0.4, vy in -0.4f64..0.4, wz in -3.0f64..3.0) {
            let k = Kiwi::new(0.1, 0.5);
            let out = k.mix(&Twist { vx, vy, vz: 0.0, wz });
            prop_assert!(out.iter().all(|u| u.abs() <= 1.0 + 1e-12));
            let back = k.motion(&out);
            let raw = k.inverse * Vector3::new(vx, vy, wz);
            let scale = saturation(raw.as_slice(), k.max_wheel_speed);
            prop_assert!((back.vx * scale - vx).abs() < 1e-9);
            prop_assert!((back.vy * scale - vy).abs() < 1e-9);
            prop_assert!((back.wz * scale - wz).abs() < 1e-9);
        }
    }
}
