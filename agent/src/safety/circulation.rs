//! The right-hand rule's input: the way a command heads for, which the
//! look-ahead ([`super::NeighbourSet::anticipate`]) turns to the right of
//! every neighbour it would meet.
//!
//! For a holonomic robot that is its desired velocity. A diff-drive's
//! desired velocity lies along its heading, which the layer itself turns
//! while it steers the robot round a neighbour: judged from the heading,
//! the way looks clear as soon as the robot has turned aside, the
//! controller turns it back towards its goal, the way is blocked again,
//! and the robot turns back and forth on the spot. Judged from where the
//! command *turns* it (its heading plus its yaw rate times the mission
//! controller's heading time constant: the bearing of its goal, for a
//! mission), the way and so the swerve depend on where the robots are,
//! not on the robot's own heading: the layer steers it along a smooth
//! field round the congestion, every robot to the right, as at a
//! roundabout.

use mech_proto::Twist;

use super::filter::Mobility;
use super::geometry::Vec2;
use crate::control::Gains;

/// The time in which the mission controller's command turns a
/// non-holonomic robot onto its goal's bearing, s: the inverse of its
/// default heading gain (yaw rate per radian of heading error).
fn intent_time() -> f64 {
    1.0 / Gains::default().heading
}

/// The velocity the command heads for (map frame): `desired` for a
/// holonomic robot; for a diff-drive driving forwards, its heading turned
/// by the commanded yaw rate times [`intent_time`], at the desired speed,
/// or at `circling` (the speed it had when the right-hand rule took over)
/// if that is faster: a mission slows a robot that faces away from its
/// goal, down to turning on the spot, which must not end the swerve that
/// turned it away.
pub fn intent(desired: Vec2, twist: &Twist, mobility: &Mobility, circling: Option<f64>) -> Vec2 {
    if mobility.holonomic || twist.vx < 0.0 {
        return desired;
    }
    let speed = desired.norm().max(circling.unwrap_or(0.0));
    let turn = (twist.wz * intent_time()).clamp(-std::f64::consts::PI, std::f64::consts::PI);
    Vec2::from_angle(mobility.heading + turn) * speed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diff_drive(heading: f64) -> Mobility {
        Mobility {
            holonomic: false,
            heading,
            yield_turn_rate: 1.0,
            yaw_rate: 0.0,
            reaction_time: 0.1,
            velocity: Vec2::ZERO,
        }
    }

    #[test]
    fn a_diff_drive_heads_for_where_its_command_turns_it() {
        // Facing +x, turned left at 3 rad/s (1 rad of heading error at the
        // default gain): it heads for 1 rad.
        let twist = Twist {
            vx: 0.2,
            wz: 3.0,
            ..Twist::default()
        };
        let u = intent(Vec2::new(0.2, 0.0), &twist, &diff_drive(0.0), None);
        assert!((u.angle() - 1.0).abs() < 1e-9, "{u:?}");
        assert!((u.norm() - 0.2).abs() < 1e-9);
        // Turning on the spot while the rule has it circle at 0.3 m/s.
        let spin = Twist {
            wz: 3.0,
            ..Twist::default()
        };
        let u = intent(Vec2::ZERO, &spin, &diff_drive(0.0), Some(0.3));
        assert!((u.norm() - 0.3).abs() < 1e-9 && (u.angle() - 1.0).abs() < 1e-9);
        // Only turning, nothing taken over: nowhere.
        assert_eq!(
            intent(Vec2::ZERO, &spin, &diff_drive(0.0), None),
            Vec2::ZERO
        );
        // A holonomic robot heads where it moves.
        let kiwi = Mobility {
            holonomic: true,
            ..diff_drive(0.0)
        };
        let v = Vec2::new(0.1, -0.2);
        assert_eq!(intent(v, &twist, &kiwi, Some(0.5)), v);
    }
}
