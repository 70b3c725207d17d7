//! MAVLink's local NED frame and MECH's REP 103 ENU frame.
//!
//! MAVLink's `LOCAL_NED` frame (PX4 and ArduPilot: the EKF origin) has x
//! north, y east, z down; yaw is clockwise from north, and a positive yaw
//! rate turns clockwise seen from above. MECH's world frame (ROS REP 103)
//! has x east, y north, z up; heading is counter-clockwise from east (+x),
//! and a positive yaw rate turns counter-clockwise. Both are right-handed;
//! one is the other mirrored through the x = y plane and turned upside
//! down, so the conversion is its own inverse:
//!
//! | MECH (ENU) | MAVLink (NED) |
//! | --- | --- |
//! | x (east) | y |
//! | y (north) | x |
//! | z (up) | -z |
//! | heading | pi/2 - yaw |
//! | wz (yaw rate) | -yaw rate |
//!
//! MECH's body frame is FLU (x forward, y left, z up); MAVLink's is FRD
//! (x forward, y right, z down): a body twist is turned into the world by
//! the heading first (in ENU), then into NED.

use mech_proto::{Pose, Twist, Velocity, wrap_angle};

/// A position or velocity in MAVLink's local NED frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ned {
    pub north: f64,
    pub east: f64,
    pub down: f64,
}

/// An ENU point or vector `(x east, y north, z up)` in NED.
pub fn enu_to_ned(x: f64, y: f64, z: f64) -> Ned {
    Ned {
        north: y,
        east: x,
        down: -z,
    }
}

/// A NED point or vector as ENU `(x east, y north, z up)`.
pub fn ned_to_enu(v: Ned) -> (f64, f64, f64) {
    (v.east, v.north, -v.down)
}

/// MAVLink yaw (rad, clockwise from north) as a MECH heading (rad,
/// counter-clockwise from east), in `(-pi, pi]`.
pub fn yaw_to_heading(yaw: f64) -> f64 {
    wrap_angle(std::f64::consts::FRAC_PI_2 - yaw)
}

/// A MECH heading as MAVLink yaw, in `(-pi, pi]`.
pub fn heading_to_yaw(heading: f64) -> f64 {
    wrap_angle(std::f64::consts::FRAC_PI_2 - heading)
}

/// A yaw rate either way (clockwise-positive <-> counter-clockwise-positive).
pub fn flip_yaw_rate(rate: f64) -> f64 {
    -rate
}

/// The robot's pose from a NED position and a MAVLink yaw.
pub fn pose_from_ned(position: Ned, yaw: f64) -> Pose {
    let (x, y, z) = ned_to_enu(position);
    Pose {
        x,
        y,
        z,
        heading: yaw_to_heading(yaw),
    }
}

/// World-frame velocity (ENU) from a NED velocity and a MAVLink yaw rate.
pub fn velocity_from_ned(velocity: Ned, yaw_rate: f64) -> Velocity {
    let (vx, vy, vz) = ned_to_enu(velocity);
    Velocity {
        vx,
        vy,
        vz,
        wz: flip_yaw_rate(yaw_rate),
    }
}

/// A velocity setpoint in the local NED frame: what SET_POSITION_TARGET_LOCAL_NED
/// carries for a body twist.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NedSetpoint {
    pub velocity: Ned,
    /// Clockwise-positive, rad/s.
    pub yaw_rate: f64,
}

/// The NED velocity setpoint for a MECH body twist (FLU) of a vehicle
/// whose heading is `heading` (ENU).
pub fn twist_to_ned(twist: &Twist, heading: f64) -> NedSetpoint {
    let (sin, cos) = heading.sin_cos();
    let east = twist.vx * cos - twist.vy * sin;
    let north = twist.vx * sin + twist.vy * cos;
    NedSetpoint {
        velocity: enu_to_ned(east, north, twist.vz),
        yaw_rate: flip_yaw_rate(twist.wz),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn axes_map_as_documented() {
        // 1 m north, 2 m east, 3 m below the origin = (2 east, 1 north, -3 up).
        let p = pose_from_ned(
            Ned {
                north: 1.0,
                east: 2.0,
                down: 3.0,
            },
            0.0,
        );
        assert_eq!((p.x, p.y, p.z), (2.0, 1.0, -3.0));
        // Facing north (yaw 0) is heading +pi/2; facing east (yaw pi/2) is 0;
        // facing west (yaw -pi/2) is pi.
        assert!(close(p.heading, FRAC_PI_2));
        assert!(close(yaw_to_heading(FRAC_PI_2), 0.0));
        assert!(close(yaw_to_heading(-FRAC_PI_2), PI));
        assert!(close(heading_to_yaw(PI), -FRAC_PI_2));
        // Turning clockwise seen from above (NED yaw rate +) is wz < 0.
        let v = velocity_from_ned(
            Ned {
                north: 0.5,
                east: 0.0,
                down: -0.2,
            },
            0.3,
        );
        assert_eq!((v.vx, v.vy, v.vz, v.wz), (0.0, 0.5, 0.2, -0.3));
    }

    #[test]
    fn a_forward_twist_goes_where_the_vehicle_faces() {
        let forward = Twist {
            vx: 1.0,
            vy: 0.0,
            vz: 0.5,
            wz: 0.25,
        };
        // Facing east (ENU heading 0): forward is +east, climbing is -down,
        // a left (counter-clockwise) turn is a negative NED yaw rate.
        let s = twist_to_ned(&forward, 0.0);
        assert!(close(s.velocity.east, 1.0) && close(s.velocity.north, 0.0));
        assert!(close(s.velocity.down, -0.5) && close(s.yaw_rate, -0.25));
        // Facing north: forward is +north; sliding left (vy) is -east (west).
        let s = twist_to_ned(
            &Twist {
                vx: 1.0,
                vy: 0.5,
                ..Twist::default()
            },
            FRAC_PI_2,
        );
        assert!(close(s.velocity.north, 1.0) && close(s.velocity.east, -0.5));
    }

    proptest! {
        #[test]
        fn conversions_are_their_own_inverse(
            x in -100.0f64..100.0, y in -100.0f64..100.0, z in -100.0f64..100.0,
            heading in -PI..PI,
        ) {
            let (x2, y2, z2) = ned_to_enu(enu_to_ned(x, y, z));
            prop_assert!(close(x, x2) && close(y, y2) && close(z, z2));
            let back = yaw_to_heading(heading_to_yaw(heading));
            prop_assert!(wrap_angle(back - heading).abs() < 1e-9);
        }

        #[test]
        fn a_twist_keeps_its_speed_and_points_along_the_heading(
            vx in -2.0f64..2.0, vy in -2.0f64..2.0, heading in -PI..PI,
        ) {
            let s = twist_to_ned(&Twist { vx, vy, vz: 0.0, wz: 0.0 }, heading);
            let speed = s.velocity.north.hypot(s.velocity.east);
            prop_assert!((speed - vx.hypot(vy)).abs() < 1e-9);
            // The velocity's component along the vehicle's nose is vx: the
            // nose in NED is (cos yaw, sin yaw) with yaw = heading_to_yaw(heading).
            let yaw = heading_to_yaw(heading);
            let along = s.velocity.north * yaw.cos() + s.velocity.east * yaw.sin();
            prop_assert!((along - vx).abs() < 1e-9);
            // And its component to the right (FRD y) is -vy.
            let right = -s.velocity.north * yaw.sin() + s.velocity.east * yaw.cos();
            prop_assert!((right + vy).abs() < 1e-9);
        }
    }
}
