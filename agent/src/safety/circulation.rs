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
//! command *turns* it (its heading plus its yaw rate over the
//! controller's heading gain: the bearing of its goal, for a mission),
//! the way and so the swerve depend on where the robots are,
//! not on the robot's own heading: the layer steers it along a smooth
//! field round the congestion, every robot to the right, as at a
//! roundabout.
//!
//! Only a command that steers towards a bearing is read so: a gamepad's
//! or a program's yaw rate is its own, and such a command heads where it
//! moves.

use mech_proto::Twist;

use super::filter::Mobility;
use super::geometry::Vec2;

/// The velocity the command heads for (map frame): `desired` for a
/// holonomic robot, for one reversing, and for a command whose yaw rate is
/// the operator's own (`gain` `None`: twist, actuators, steering-throttle:
/// a gamepad's turn says nothing of where the robot is going). For a
/// diff-drive driving forwards on a command that turns it towards a
/// bearing at `gain` rad/s per radian of heading error (a mission,
/// velocity-heading): its heading turned by the commanded yaw rate over
/// the gain, which is that bearing while the yaw rate is not at its
/// limit, at the desired speed, or at `circling` (the speed it had when
/// the right-hand rule took over) if that is faster: such a controller
/// slows a robot that faces away from its goal, down to turning on the
/// spot, which must not end the swerve that turned it away.
pub fn intent(
    desired: Vec2,
    twist: &Twist,
    mobility: &Mobility,
    gain: Option<f64>,
    circling: Option<f64>,
) -> Vec2 {
    let Some(gain) = gain.filter(|g| g.is_finite() && *g > 0.0) else {
        return desired;
    };
    if mobility.holonomic || twist.vx < 0.0 {
        return desired;
    }
    let speed = desired.norm().max(circling.unwrap_or(0.0));
    let turn = (twist.wz / gain).clamp(-std::f64::consts::PI, std::f64::consts::PI);
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
        let u = intent(
            Vec2::new(0.2, 0.0),
            &twist,
            &diff_drive(0.0),
            Some(3.0),
            None,
        );
        assert!((u.angle() - 1.0).abs() < 1e-9, "{u:?}");
        assert!((u.norm() - 0.2).abs() < 1e-9);
        // Turning on the spot while the rule has it circle at 0.3 m/s.
        let spin = Twist {
            wz: 3.0,
            ..Twist::default()
        };
        let u = intent(Vec2::ZERO, &spin, &diff_drive(0.0), Some(3.0), Some(0.3));
        assert!((u.norm() - 0.3).abs() < 1e-9 && (u.angle() - 1.0).abs() < 1e-9);
        // Only turning, nothing taken over: nowhere.
        assert_eq!(
            intent(Vec2::ZERO, &spin, &diff_drive(0.0), Some(3.0), None),
            Vec2::ZERO
        );
        // A holonomic robot heads where it moves.
        let kiwi = Mobility {
            holonomic: true,
            ..diff_drive(0.0)
        };
        let v = Vec2::new(0.1, -0.2);
        assert_eq!(intent(v, &twist, &kiwi, Some(3.0), Some(0.5)), v);
        // A command whose turn is the operator's own heads where it moves,
        // whatever the layer did before.
        assert_eq!(
            intent(Vec2::ZERO, &spin, &diff_drive(0.0), None, Some(0.3)),
            Vec2::ZERO
        );
        let ahead = Vec2::new(0.2, 0.0);
        assert_eq!(intent(ahead, &twist, &diff_drive(0.0), None, None), ahead);
    }
}
