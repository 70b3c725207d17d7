//! The combined filter, pure and deterministic: from the velocity a
//! command would produce and the constraints of this period, the velocity
//! the robot may have, and why it differs.
//!
//! A desired velocity the constraints allow passes untouched. Otherwise:
//!
//! - a robot that can move sideways (kiwi, quadcopter) takes the allowed
//!   velocity closest to the desired one, searched over directions within
//!   90° of it (so it slides along a wall or around a neighbour instead of
//!   stopping dead);
//! - a robot that cannot (diff-drive) keeps its heading and is slowed
//!   along it; rotation on the spot never moves its disc, so its turn rate
//!   is kept.
//!
//! A robot whose present motion already goes beyond what the constraints
//! allow (its actuators lag the commands, a neighbour came closer than
//! predicted) is told to stop, and to stop turning (whatever the
//! platform): braking is always within what it promised.
//!
//! When a neighbour is in the way, the layer chooses another desired
//! velocity (the right-hand rule: [`crate::safety::circulation`] and
//! `SafetyLayer::filter`) and [`steer`]s the robot towards it, within the
//! same constraints: two robots meeting head-on both turn right and pass;
//! robots crowding a place all move the same way round it, as at a
//! roundabout.

use mech_proto::Intervention;

use super::constraints::Constraints;
use super::geometry::Vec2;

/// Directions tried on each side of the desired one, spread over 90°.
const SIDE_STEPS: usize = 12;

/// What the filter decided for one control period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The velocity the robot may have, m/s, map frame.
    pub velocity: Vec2,
    /// A yaw rate that replaces the commanded one (a diff-drive yielding
    /// to the right), rad/s.
    pub yaw_rate: Option<f64>,
    /// Why `velocity` differs from the desired one ([`Intervention::None`]:
    /// it does not).
    pub intervention: Intervention,
    /// A neighbour blocks the way (less than half the desired speed is
    /// allowed).
    pub blocked: bool,
}

/// How the robot can move, for [`decide`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mobility {
    /// Whether it can translate in any direction (kiwi, quadcopter).
    pub holonomic: bool,
    /// Its heading, rad: the only direction a non-holonomic robot moves.
    pub heading: f64,
    /// Fastest turn of a non-holonomic robot while yielding, rad/s.
    pub yield_turn_rate: f64,
    /// The commanded yaw rate, rad/s: a turning robot's velocity turns with
    /// it, so its braking path is checked at the direction it has now and
    /// the one it will have when braking starts.
    pub yaw_rate: f64,
    /// The reaction time of [`crate::safety::Braking`], s.
    pub reaction_time: f64,
    /// The velocity the robot has now, m/s, map frame: a robot whose own
    /// braking path no longer fits (its actuators lag the commands, a
    /// neighbour came closer) is told to stop, whatever was commanded.
    pub velocity: Vec2,
}

/// Speeds below this, m/s, are taken as standing still when judging the
/// current motion (an actuator's exponential tail never quite reaches
/// zero, and a robot at rest must be able to move away).
const AT_REST: f64 = 1e-4;

impl Mobility {
    /// The angle the velocity turns through before braking starts, at yaw
    /// rate `wz`.
    fn sweep(&self, wz: f64) -> f64 {
        wz * self.reaction_time
    }

    /// The same robot taken from its rear: a diff-drive whose command
    /// drives it backwards is [`steer`]ed rear first, its rear turned
    /// towards the swerve and driven backwards along it, so the right-hand
    /// rule holds in the direction it travels. (Turning round to face the
    /// swerve would swing its rear the other way first, for most of a
    /// second, and leave it driving forwards against its command.)
    pub fn rear_first(&self) -> Mobility {
        Mobility {
            heading: mech_proto::wrap_angle(self.heading + std::f64::consts::PI),
            ..*self
        }
    }
}

/// The fastest speed along `dir` that is allowed now and after turning
/// through `sweep` rad, and the constraint that sets it.
fn swept_limit(c: &Constraints, dir: Vec2, sweep: f64) -> (f64, Intervention) {
    let now = c.limit(dir);
    if sweep.abs() < 1e-9 {
        return now;
    }
    let later = c.limit(dir.rotated(sweep));
    if later.0 < now.0 { later } else { now }
}

/// The velocity a robot may have this period, given the one its command
/// would produce (`desired`, map frame).
pub fn decide(c: &Constraints, desired: Vec2, mobility: &Mobility) -> Decision {
    let pass = Decision {
        velocity: desired,
        yaw_rate: None,
        intervention: Intervention::None,
        blocked: false,
    };
    let speed = desired.norm();
    if let Some(stop) = overrun(c, mobility) {
        return stop;
    }
    let Some(dir) = desired.unit() else {
        return pass;
    };
    let (allowed, why) = swept_limit(c, dir, mobility.sweep(mobility.yaw_rate));
    if speed <= allowed * (1.0 + 1e-9) {
        return pass;
    }
    let blocked = why == Intervention::Separation && allowed < 0.5 * speed;
    let velocity = if mobility.holonomic {
        closest_allowed(c, desired, mobility.sweep(mobility.yaw_rate))
    } else {
        dir * allowed
    };
    Decision {
        velocity,
        yaw_rate: None,
        intervention: why,
        blocked,
    }
}

/// A stop when the robot's present motion already goes beyond what the
/// constraints allow. Without turning: the robot's actuators lag, so it
/// keeps moving for a while after the stop, and a turn meanwhile would
/// bend that motion off the straight braking path (towards the neighbour
/// or the wall it is pressed against).
fn overrun(c: &Constraints, mobility: &Mobility) -> Option<Decision> {
    let moving = mobility.velocity.unit()?;
    let (fits, why) = swept_limit(c, moving, mobility.sweep(mobility.yaw_rate));
    (mobility.velocity.norm() > fits + AT_REST).then_some(Decision {
        velocity: Vec2::ZERO,
        yaw_rate: Some(0.0),
        intervention: why,
        blocked: false,
    })
}

/// Steer: move towards `target` (map frame) as far as the constraints
/// allow, whatever the command. A holonomic robot takes the allowed
/// velocity closest to it; a diff-drive turns towards it and drives along
/// its heading once within [`TURN_FIRST`] of it.
pub fn steer(c: &Constraints, target: Vec2, mobility: &Mobility) -> Decision {
    if let Some(stop) = overrun(c, mobility) {
        return stop;
    }
    let yielding = |velocity, yaw_rate| Decision {
        velocity,
        yaw_rate,
        intervention: Intervention::Separation,
        blocked: false,
    };
    if mobility.holonomic {
        let v = closest_allowed(c, target, mobility.sweep(mobility.yaw_rate));
        return yielding(v, None);
    }
    let Some(dir) = target.unit() else {
        return yielding(Vec2::ZERO, None);
    };
    let err = mech_proto::wrap_angle(dir.angle() - mobility.heading);
    let turn = mobility.yield_turn_rate.abs();
    let wz = (3.0 * err).clamp(-turn, turn);
    let heading = Vec2::from_angle(mobility.heading);
    let forward = if !turns_first(target, mobility) {
        target.norm() * err.cos()
    } else {
        0.0
    };
    let allowed = swept_limit(c, heading, mobility.sweep(wz)).0;
    yielding(heading * forward.min(allowed), Some(wz))
}

/// Heading error, rad, beyond which a yielding diff-drive turns on the
/// spot before driving.
pub const TURN_FIRST: f64 = 0.6;

/// Whether a diff-drive [`steer`]ed towards `target` turns on the spot
/// first (its heading is more than [`TURN_FIRST`] off).
pub fn turns_first(target: Vec2, mobility: &Mobility) -> bool {
    target.unit().is_some_and(|dir| {
        mech_proto::wrap_angle(dir.angle() - mobility.heading).abs() >= TURN_FIRST
    })
}

/// The allowed velocity closest to `target` among directions within 90°
/// of it (each at the speed nearest the target's projection on it).
fn closest_allowed(c: &Constraints, target: Vec2, sweep: f64) -> Vec2 {
    let Some(dir) = target.unit() else {
        return Vec2::ZERO;
    };
    let speed = target.norm();
    let mut best = (speed * speed, Vec2::ZERO);
    let step = std::f64::consts::FRAC_PI_2 / SIDE_STEPS as f64;
    for k in 0..=2 * SIDE_STEPS {
        let phi = (k as f64 - SIDE_STEPS as f64) * step;
        let d = dir.rotated(phi);
        let want = speed * phi.cos();
        if want <= 0.0 {
            continue;
        }
        let s = want.min(swept_limit(c, d, sweep).0);
        let u = d * s;
        let cost = (u - target).dot(u - target);
        if cost < best.0 - 1e-15 {
            best = (cost, u);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::constraints::{Braking, Plane, Wall};
    use crate::safety::geometry::Segment;

    fn constraints() -> Constraints {
        Constraints::new(
            Vec2::ZERO,
            Braking {
                reaction_time: 0.1,
                deceleration: 1.0,
            },
        )
    }

    fn holonomic() -> Mobility {
        Mobility {
            holonomic: true,
            heading: 0.0,
            yield_turn_rate: 1.0,
            yaw_rate: 0.0,
            reaction_time: 0.1,
            velocity: Vec2::ZERO,
        }
    }

    #[test]
    fn an_allowed_command_passes_untouched() {
        let c = constraints();
        let d = decide(&c, Vec2::new(0.3, 0.1), &holonomic());
        assert_eq!(d.velocity, Vec2::new(0.3, 0.1));
        assert_eq!(d.intervention, Intervention::None);
    }

    #[test]
    fn a_holonomic_robot_slides_along_a_wall_it_approaches_at_an_angle() {
        let mut c = constraints();
        c.walls.push(Wall {
            segment: Segment::new(Vec2::new(-5.0, 0.3), Vec2::new(5.0, 0.3)),
            radius: 0.25,
            reason: Intervention::Fence,
        });
        let desired = Vec2::new(0.5, 0.5);
        let d = decide(&c, desired, &holonomic());
        assert_eq!(d.intervention, Intervention::Fence);
        // Faster along the wall than slowing down on the same heading.
        let (straight, _) = c.limit(desired.unit().unwrap());
        let slowed = desired.unit().unwrap() * straight;
        assert!(
            d.velocity.x > slowed.x + 0.1,
            "keeps going along: {:?} rather than {slowed:?}",
            d.velocity
        );
        let (s, _) = c.limit(d.velocity.unit().unwrap());
        assert!(d.velocity.norm() <= s + 1e-12);
    }

    #[test]
    fn a_diff_drive_is_only_slowed_along_its_heading() {
        let mut c = constraints();
        c.walls.push(Wall {
            segment: Segment::new(Vec2::new(0.35, -5.0), Vec2::new(0.35, 5.0)),
            radius: 0.25,
            reason: Intervention::Fence,
        });
        let mobility = Mobility {
            holonomic: false,
            ..holonomic()
        };
        let d = decide(&c, Vec2::new(0.5, 0.0), &mobility);
        assert_eq!(d.intervention, Intervention::Fence);
        assert_eq!(d.yaw_rate, None);
        assert!(d.velocity.y == 0.0 && d.velocity.x > 0.0 && d.velocity.x < 0.5);
    }

    #[test]
    fn blocked_by_a_neighbour_both_kinds_yield_to_the_right() {
        let mut c = constraints();
        c.planes.push(Plane {
            normal: Vec2::new(1.0, 0.0),
            offset: 0.01,
            reason: Intervention::Separation,
        });
        let d = decide(&c, Vec2::new(0.5, 0.0), &holonomic());
        assert_eq!(d.intervention, Intervention::Separation);
        assert!(d.blocked);
        let right = Vec2::new(0.5, 0.0).rotated(-1.0);
        let d = steer(&c, right, &holonomic());
        assert!(d.velocity.y < -0.1, "to the right: {:?}", d.velocity);
        let mobility = Mobility {
            holonomic: false,
            ..holonomic()
        };
        let d = steer(&c, right, &mobility);
        assert_eq!(d.yaw_rate, Some(-1.0), "turns right first");
        assert_eq!(d.velocity, Vec2::ZERO);
        let turned = Mobility {
            heading: -1.0,
            ..mobility
        };
        let d = steer(&c, right, &turned);
        assert!(d.velocity.norm() > 0.1, "then drives: {d:?}");
    }

    #[test]
    fn a_robot_already_moving_too_fast_for_its_room_is_told_to_stop() {
        let mut c = constraints();
        c.walls.push(Wall {
            segment: Segment::new(Vec2::new(0.3, -5.0), Vec2::new(0.3, 5.0)),
            radius: 0.25,
            reason: Intervention::Fence,
        });
        let moving = Mobility {
            velocity: Vec2::new(0.4, 0.0),
            ..holonomic()
        };
        let d = decide(&c, Vec2::new(0.01, 0.0), &moving);
        assert_eq!(
            (d.velocity, d.yaw_rate, d.intervention),
            (Vec2::ZERO, Some(0.0), Intervention::Fence)
        );
        // At rest (an actuator's tail), it may move away.
        let resting = Mobility {
            velocity: Vec2::new(0.00005, 0.0),
            ..holonomic()
        };
        let d = decide(&c, Vec2::new(-0.2, 0.0), &resting);
        assert_eq!(d.intervention, Intervention::None);
    }
}
