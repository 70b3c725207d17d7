//! Between commands and world-frame velocities, for every platform.
//!
//! Whatever the command mode (raw actuator outputs, steering-throttle,
//! velocity-heading, twist, an onboard mission), the controller ends in
//! actuator outputs; the platform's forward model ([`Platform::motion`],
//! the one the simulator moves vehicles with) says what motion they
//! produce, and the pose's heading turns it into the map frame. That is
//! the velocity the filter judges.
//!
//! Back from the filter's velocity to outputs:
//! - holonomic platforms (kiwi, quadcopter) take the safe velocity as it is,
//!   turned into the body frame, with the commanded yaw rate (unless the
//!   filter sets one: a stop for an overrun stops the turn) and climb rate
//!   (the filter works in the horizontal plane);
//! - a diff-drive cannot move sideways: it drives the safe velocity's
//!   component along its heading (the filter keeps that along the heading
//!   for it) and keeps the commanded yaw rate, unless the filter sets one
//!   (steering it round a neighbour, or a stop that stops the turn too). Its mixing then scales both wheels down together if needed,
//!   which only slows it further along the same arc.

use mech_proto::Twist;

use super::filter::Decision;
use super::geometry::Vec2;
use crate::platform::Platform;

/// The body twist `outputs` produce, and its horizontal velocity in the map
/// frame for a robot at `heading`.
pub fn commanded_motion(platform: &dyn Platform, heading: f64, outputs: &[f64]) -> (Twist, Vec2) {
    let twist = platform.motion(outputs);
    let world = Vec2::new(twist.vx, twist.vy).rotated(heading);
    (twist, world)
}

/// Actuator outputs that give the decision's velocity, keeping what the
/// filter does not judge (yaw rate, climb) from the commanded `twist`.
pub fn outputs_for(
    platform: &dyn Platform,
    heading: f64,
    twist: &Twist,
    decision: &Decision,
) -> Vec<f64> {
    let body = decision.velocity.rotated(-heading);
    let safe = if platform.holonomic() {
        Twist {
            vx: body.x,
            vy: body.y,
            vz: twist.vz,
            wz: decision.yaw_rate.unwrap_or(twist.wz),
        }
    } else {
        Twist {
            vx: body.x,
            vy: 0.0,
            vz: twist.vz,
            wz: decision.yaw_rate.unwrap_or(twist.wz),
        }
    };
    platform
        .mix(&safe)
        .into_iter()
        .map(crate::hal::clamp_output)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::Intervention;

    fn decision(velocity: Vec2) -> Decision {
        Decision {
            velocity,
            yaw_rate: None,
            intervention: Intervention::Fence,
            blocked: false,
        }
    }

    #[test]
    fn a_holonomic_robot_gets_the_safe_velocity_in_its_body_frame() {
        let kiwi = PlatformSpec::kiwi().build();
        let heading = 1.0;
        let twist = Twist {
            vx: 0.3,
            vy: 0.0,
            vz: 0.0,
            wz: 0.4,
        };
        let safe = Vec2::new(0.1, -0.2);
        let out = outputs_for(kiwi.as_ref(), heading, &twist, &decision(safe));
        let (got, world) = commanded_motion(kiwi.as_ref(), heading, &out);
        assert!((world - safe).norm() < 1e-9, "{world:?}");
        assert!((got.wz - 0.4).abs() < 1e-9, "turn rate kept");
    }

    #[test]
    fn a_diff_drive_drives_the_part_along_its_heading_and_keeps_its_turn() {
        let dd = PlatformSpec::diff_drive().build();
        let twist = Twist {
            vx: 0.4,
            vy: 0.0,
            vz: 0.0,
            wz: 0.5,
        };
        let out = outputs_for(dd.as_ref(), 0.0, &twist, &decision(Vec2::new(0.1, 0.0)));
        let (got, _) = commanded_motion(dd.as_ref(), 0.0, &out);
        assert!((got.vx - 0.1).abs() < 1e-9 && (got.wz - 0.5).abs() < 1e-9);
        let yielding = Decision {
            yaw_rate: Some(-1.0),
            ..decision(Vec2::ZERO)
        };
        let out = outputs_for(dd.as_ref(), 0.0, &twist, &yielding);
        let (got, _) = commanded_motion(dd.as_ref(), 0.0, &out);
        assert!(got.vx.abs() < 1e-9 && (got.wz + 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_quadcopter_keeps_its_climb() {
        let quad = PlatformSpec::quadcopter().build();
        let twist = Twist {
            vx: 0.8,
            vy: 0.0,
            vz: 0.3,
            wz: 0.0,
        };
        let out = outputs_for(quad.as_ref(), 0.0, &twist, &decision(Vec2::ZERO));
        let (got, _) = commanded_motion(quad.as_ref(), 0.0, &out);
        assert!(got.vx.abs() < 1e-9 && (got.vz - 0.3).abs() < 1e-9);
    }
}
