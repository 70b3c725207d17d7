//! `/<robot>/cmd_vel`: a body-frame velocity (REP 105 `base_link`), which
//! is what a MECH Twist command is: linear x y z and the yaw rate.

use mech_proto::{Command, Twist as MechTwist};

use super::{Refusal, Refused, frame};
use crate::msgs::geometry::{Twist, TwistStamped};

/// The limits a cmd_vel must keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CmdVelLimits {
    /// m/s, on the length of the linear velocity.
    pub max_speed: f64,
    /// rad/s, on |angular.z|.
    pub max_yaw_rate: f64,
}

/// The MECH command for a plain Twist, or why it is refused.
pub fn from_twist(t: &Twist, limits: CmdVelLimits) -> Result<Command, Refused> {
    let (l, a) = (t.linear, t.angular);
    let all = [l.x, l.y, l.z, a.x, a.y, a.z];
    if let Some(v) = all.iter().find(|v| !v.is_finite()) {
        return Err(Refused::new(
            Refusal::NotFinite,
            format!("cmd_vel has a component {v}"),
        ));
    }
    if a.x != 0.0 || a.y != 0.0 {
        return Err(Refused::new(
            Refusal::OutOfRange,
            format!(
                "cmd_vel asks for roll/pitch rates ({}, {}) rad/s: MECH robots take yaw only",
                a.x, a.y
            ),
        ));
    }
    let speed = (l.x * l.x + l.y * l.y + l.z * l.z).sqrt();
    if speed > limits.max_speed {
        return Err(Refused::new(
            Refusal::OutOfRange,
            format!(
                "cmd_vel speed {speed:.3} m/s is above max_speed {} m/s",
                limits.max_speed
            ),
        ));
    }
    if a.z.abs() > limits.max_yaw_rate {
        return Err(Refused::new(
            Refusal::OutOfRange,
            format!(
                "cmd_vel yaw rate {:.3} rad/s is above max_yaw_rate {} rad/s",
                a.z, limits.max_yaw_rate
            ),
        ));
    }
    Ok(Command::Twist(MechTwist {
        vx: l.x,
        vy: l.y,
        vz: l.z,
        wz: a.z,
    }))
}

/// The MECH command for a TwistStamped of `robot`: its frame must be the
/// robot's body frame (`base_link`, `<robot>/base_link`, or empty, which
/// teleop nodes leave it as), since MECH twists are body-frame.
pub fn from_stamped(
    t: &TwistStamped,
    robot: &str,
    limits: CmdVelLimits,
) -> Result<Command, Refused> {
    let f = frame(&t.header.frame_id);
    let body = format!("{robot}/base_link");
    if !(f.is_empty() || f == "base_link" || f == body) {
        return Err(Refused::new(
            Refusal::WrongFrame,
            format!(
                "cmd_vel of {robot} in frame {:?}: only {body:?}, \"base_link\" or \"\" (body frame)",
                t.header.frame_id
            ),
        ));
    }
    from_twist(&t.twist, limits)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::geometry::Vector3;

    const LIMITS: CmdVelLimits = CmdVelLimits {
        max_speed: 2.0,
        max_yaw_rate: 3.0,
    };

    fn twist(vx: f64, wz: f64) -> Twist {
        Twist {
            linear: Vector3 {
                x: vx,
                y: 0.0,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: wz,
            },
        }
    }

    #[test]
    fn a_twist_becomes_a_body_frame_mech_twist() {
        let mut t = twist(0.5, -0.25);
        t.linear.y = 0.1;
        t.linear.z = 0.2;
        assert_eq!(
            from_twist(&t, LIMITS),
            Ok(Command::Twist(MechTwist {
                vx: 0.5,
                vy: 0.1,
                vz: 0.2,
                wz: -0.25
            }))
        );
    }

    #[test]
    fn nan_infinite_and_out_of_range_twists_are_refused() {
        let reason = |t: Twist| from_twist(&t, LIMITS).unwrap_err().reason;
        assert_eq!(reason(twist(f64::NAN, 0.0)), Refusal::NotFinite);
        assert_eq!(reason(twist(0.0, f64::INFINITY)), Refusal::NotFinite);
        assert_eq!(reason(twist(2.5, 0.0)), Refusal::OutOfRange);
        assert_eq!(reason(twist(0.0, -3.5)), Refusal::OutOfRange);
        let mut roll = twist(0.1, 0.0);
        roll.angular.x = 0.2;
        assert_eq!(reason(roll), Refusal::OutOfRange);
        let mut diagonal = twist(1.5, 0.0);
        diagonal.linear.y = 1.5;
        assert_eq!(
            reason(diagonal),
            Refusal::OutOfRange,
            "speed is the vector's length"
        );
        assert!(
            from_twist(&twist(2.0, 3.0), LIMITS).is_ok(),
            "the limits themselves"
        );
    }

    #[test]
    fn a_stamped_twist_must_be_in_the_robots_body_frame() {
        let mut t = TwistStamped {
            twist: twist(0.3, 0.0),
            ..TwistStamped::default()
        };
        for ok in ["", "base_link", "robot_1/base_link", "/robot_1/base_link"] {
            t.header.frame_id = ok.into();
            assert!(from_stamped(&t, "robot_1", LIMITS).is_ok(), "{ok}");
        }
        for bad in ["map", "odom", "robot_2/base_link"] {
            t.header.frame_id = bad.into();
            let e = from_stamped(&t, "robot_1", LIMITS).unwrap_err();
            assert_eq!(e.reason, Refusal::WrongFrame, "{bad}");
            assert!(e.detail.contains(bad), "{}", e.detail);
        }
    }
}
