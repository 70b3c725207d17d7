//! The geofence: an [`Arena`] made ready for the filter ([`Fence`]) and the
//! constraints it puts on a robot at a given position.
//!
//! The free space is the inside of the boundary, outside every keep-out,
//! at least the robot's radius plus the arena's margin from every edge. A
//! robot in the free space may move only so that its braking path stays
//! clear of every edge by that clearance (a [`Wall`] per edge within
//! reach). A robot found outside the free space (its pose jumped, it was
//! pushed, the arena changed under it) may only move back: out of the
//! margin band, back across the boundary, out of the keep-out (an
//! [`Away`] constraint). Slow zones cap the speed, and the cap is reached
//! before the zone is (the robot slows at its deceleration on the way in).

use mech_proto::{Arena, Intervention};

use super::constraints::{Away, Constraints, Wall};
use super::geometry::{self, Vec2};

/// How strictly a robot outside a polygon it must be in (or inside one it
/// must not be in) has to head back: the cosine of the widest angle
/// allowed between its motion and the way back (about 84°).
const RETURN_MIN_DOT: f64 = 0.1;

/// An arena ready for the filter: polygons as vertex lists in the map
/// frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Fence {
    /// Empty when there is no boundary (keep-outs only is not an arena the
    /// protocol sends, but an empty arena is).
    pub boundary: Vec<Vec2>,
    pub keep_out: Vec<Vec<Vec2>>,
    /// Polygon and speed cap, m/s.
    pub slow_zones: Vec<(Vec<Vec2>, f64)>,
    /// Clearance kept from every edge on top of the robot's radius, m.
    pub margin: f64,
}

fn polygon(points: &[mech_proto::Point]) -> Vec<Vec2> {
    points.iter().map(|p| Vec2::from(*p)).collect()
}

impl Fence {
    /// The fence of a (validated) arena message.
    pub fn from_arena(arena: &Arena) -> Fence {
        Fence {
            boundary: polygon(&arena.boundary),
            keep_out: arena.keep_out.iter().map(|k| polygon(k)).collect(),
            slow_zones: arena
                .slow_zones
                .iter()
                .map(|z| (polygon(&z.polygon), z.max_speed))
                .collect(),
            margin: arena.margin,
        }
    }

    /// Whether `p` is in the free space of a robot of `radius`: inside the
    /// boundary and outside every keep-out, with `radius + margin` to
    /// spare from every edge.
    pub fn clear(&self, p: Vec2, radius: f64) -> bool {
        let rho = radius + self.margin;
        let edges_clear =
            |poly: &[Vec2]| geometry::edges(poly).all(|e| e.distance(p) >= rho - 1e-9);
        (self.boundary.is_empty()
            || (geometry::inside(&self.boundary, p) && edges_clear(&self.boundary)))
            && self
                .keep_out
                .iter()
                .all(|k| !geometry::inside(k, p) && edges_clear(k))
    }

    /// Signed distance from `p` to the nearest edge of the boundary or a
    /// keep-out: positive on the free side (inside the boundary, outside
    /// keep-outs), negative beyond; infinite with no edges.
    pub fn clearance(&self, p: Vec2) -> f64 {
        let mut best = f64::INFINITY;
        let mut polygon = |poly: &[Vec2], keep_inside: bool| {
            let d = geometry::edges(poly)
                .map(|e| e.distance(p))
                .fold(f64::INFINITY, f64::min);
            let right_side = geometry::inside(poly, p) == keep_inside;
            best = best.min(if right_side { d } else { -d });
        };
        if !self.boundary.is_empty() {
            polygon(&self.boundary, true);
        }
        for k in &self.keep_out {
            polygon(k, false);
        }
        best
    }

    /// Adds this fence's constraints on a robot of `radius` at
    /// `c.position` whose braking paths reach at most `reach` m.
    pub fn constrain(&self, c: &mut Constraints, radius: f64, reach: f64) {
        let rho = radius + self.margin;
        if !self.boundary.is_empty() {
            polygon_constraints(c, &self.boundary, true, rho, reach, Intervention::Fence);
        }
        for k in &self.keep_out {
            polygon_constraints(c, k, false, rho, reach, Intervention::KeepOut);
        }
        let p = c.position;
        let a = c.braking.deceleration;
        for (zone, cap) in &self.slow_zones {
            let dist = if geometry::inside(zone, p) {
                0.0
            } else {
                geometry::edges(zone)
                    .map(|e| e.distance(p))
                    .fold(f64::INFINITY, f64::min)
            };
            // Reach the cap by the time the robot's disc reaches the zone.
            let gap = (dist - radius).max(0.0);
            c.caps
                .push(((cap * cap + 2.0 * a * gap).sqrt(), Intervention::SlowZone));
        }
    }
}

/// Constraints of one polygon the robot must stay inside (`keep_inside`)
/// or outside of, keeping `rho` from its edges; edges farther than
/// `reach + rho` cannot be touched this period and are left out.
pub(crate) fn polygon_constraints(
    c: &mut Constraints,
    poly: &[Vec2],
    keep_inside: bool,
    rho: f64,
    reach: f64,
    reason: Intervention,
) {
    let p = c.position;
    if geometry::inside(poly, p) != keep_inside {
        // On the wrong side altogether: head for the nearest edge point.
        if let Some(back) = geometry::closest_on_boundary(poly, p).and_then(|q| (q - p).unit()) {
            c.away.push(Away {
                toward: back,
                min_dot: RETURN_MIN_DOT,
                reason: Intervention::Returning,
            });
        }
        return;
    }
    for e in geometry::edges(poly) {
        let d = e.distance(p);
        if d < rho {
            // Within the margin band: never closer to this edge.
            if let Some(out) = (p - e.closest(p)).unit() {
                c.away.push(Away {
                    toward: out,
                    min_dot: 0.0,
                    reason: Intervention::Returning,
                });
            }
        } else if d <= reach + rho {
            c.walls.push(Wall {
                segment: e,
                radius: rho,
                reason,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::constraints::Braking;

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Vec2> {
        vec![
            Vec2::new(x0, y0),
            Vec2::new(x1, y0),
            Vec2::new(x1, y1),
            Vec2::new(x0, y1),
        ]
    }

    fn fence() -> Fence {
        Fence {
            boundary: square(0.0, 0.0, 4.0, 3.0),
            keep_out: vec![square(2.0, 1.0, 2.5, 2.0)],
            slow_zones: vec![(square(0.0, 2.5, 1.0, 3.0), 0.1)],
            margin: 0.1,
        }
    }

    fn at(p: Vec2) -> Constraints {
        let mut c = Constraints::new(
            p,
            Braking {
                reaction_time: 0.1,
                deceleration: 1.0,
            },
        );
        fence().constrain(&mut c, 0.15, 10.0);
        c
    }

    #[test]
    fn the_braking_path_ends_one_clearance_short_of_a_wall() {
        let c = at(Vec2::new(1.0, 1.5));
        let (s, why) = c.limit(Vec2::new(-1.0, 0.0));
        assert_eq!(why, Intervention::Fence);
        assert!((c.braking.distance(s) - (1.0 - 0.25)).abs() < 1e-9);
        let (s, why) = c.limit(Vec2::new(1.0, 0.0));
        assert_eq!(why, Intervention::KeepOut);
        assert!((c.braking.distance(s) - (1.0 - 0.25)).abs() < 1e-9);
    }

    #[test]
    fn outside_or_within_the_margin_only_the_way_back_is_open() {
        let outside = at(Vec2::new(-0.5, 1.5));
        assert_eq!(outside.limit(Vec2::new(-1.0, 0.0)).0, 0.0);
        assert_eq!(outside.limit(Vec2::new(0.0, 1.0)).0, 0.0, "not along");
        assert!(outside.limit(Vec2::new(1.0, 0.0)).0 > 1.0);
        let in_band = at(Vec2::new(0.1, 1.5));
        assert_eq!(
            in_band.limit(Vec2::new(-1.0, 0.0)),
            (0.0, Intervention::Returning)
        );
        assert!(in_band.limit(Vec2::new(0.0, 1.0)).0 > 0.5, "along is fine");
        let in_keep_out = at(Vec2::new(2.1, 1.5));
        assert_eq!(in_keep_out.limit(Vec2::new(1.0, 0.0)).0, 0.0);
        assert!(in_keep_out.limit(Vec2::new(-1.0, 0.0)).0 > 0.0);
    }

    #[test]
    fn slow_zones_cap_the_speed_before_the_robot_reaches_them() {
        let inside = at(Vec2::new(0.5, 2.7));
        assert_eq!(
            inside.limit(Vec2::new(1.0, 0.0)),
            (0.1, Intervention::SlowZone)
        );
        let near = at(Vec2::new(0.5, 2.0));
        let (s, why) = near.limit(Vec2::new(1.0, 0.0));
        assert_eq!(why, Intervention::SlowZone);
        assert!((s - (0.01f64 + 2.0 * 0.35).sqrt()).abs() < 1e-9, "{s}");
    }

    #[test]
    fn free_space_is_inside_the_boundary_and_outside_keep_outs_with_clearance() {
        let f = fence();
        assert!(f.clear(Vec2::new(1.0, 1.5), 0.15));
        assert!(!f.clear(Vec2::new(0.2, 1.5), 0.15), "within the margin");
        assert!(!f.clear(Vec2::new(2.2, 1.5), 0.15), "in the keep-out");
        assert!(!f.clear(Vec2::new(5.0, 1.5), 0.15), "outside");
    }
}
