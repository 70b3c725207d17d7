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
//! When a neighbour blocks the way (less than half the desired speed is
//! allowed), both kinds yield to the right, as ships and Zhou et al.'s
//! buffered Voronoi cells do: the holonomic robot aims to the right of its
//! desired velocity, the diff-drive turns right. Two robots meeting
//! head-on both do, and pass.

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
}

/// How the robot can move, for [`decide`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mobility {
    /// Whether it can translate in any direction (kiwi, quadcopter).
    pub holonomic: bool,
    /// Its heading, rad: the only direction a non-holonomic robot moves.
    pub heading: f64,
    /// How fast a non-holonomic robot turns right to yield, rad/s.
    pub yield_turn_rate: f64,
}

/// The velocity a robot may have this period, given the one its command
/// would produce (`desired`, map frame).
pub fn decide(c: &Constraints, desired: Vec2, mobility: &Mobility) -> Decision {
    let pass = Decision {
        velocity: desired,
        yaw_rate: None,
        intervention: Intervention::None,
    };
    let speed = desired.norm();
    let Some(dir) = desired.unit() else {
        return pass;
    };
    let (allowed, why) = c.limit(dir);
    if speed <= allowed * (1.0 + 1e-9) {
        return pass;
    }
    let blocked = why == Intervention::Separation && allowed < 0.5 * speed;
    if !mobility.holonomic {
        return Decision {
            velocity: dir * allowed,
            yaw_rate: blocked.then_some(-mobility.yield_turn_rate.abs()),
            intervention: why,
        };
    }
    let target = if blocked {
        desired + dir.right() * (0.5 * speed)
    } else {
        desired
    };
    Decision {
        velocity: closest_allowed(c, target),
        yaw_rate: None,
        intervention: why,
    }
}

/// The allowed velocity closest to `target` among directions within 90°
/// of it (each at the speed nearest the target's projection on it).
fn closest_allowed(c: &Constraints, target: Vec2) -> Vec2 {
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
        let s = want.min(c.limit(d).0);
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
        assert!(d.velocity.y < -0.1, "to the right: {:?}", d.velocity);
        let mobility = Mobility {
            holonomic: false,
            ..holonomic()
        };
        let d = decide(&c, Vec2::new(0.5, 0.0), &mobility);
        assert_eq!(d.yaw_rate, Some(-1.0));
    }
}
