//! The constraints one control period's velocity must meet, and the
//! fastest speed they allow in a given direction.
//!
//! Every constraint is on the robot's *braking path* for a commanded
//! velocity `u`: the straight segment from its position `p` to
//! `p + û · L(|u|)`, where `L(s) = s·T + s²/(2a)` is the distance covered
//! while reacting (`T`: the control period plus the actuators' lag, during
//! which the robot keeps `u`) and then braking at the platform's maximum
//! deceleration `a`. Its end is the predicted stopping point: wherever
//! the robot is told to stop (a failsafe, an e-stop, a `Stop`), it stops
//! there or short of it. Four kinds of constraint:
//!
//! - [`Wall`]: a segment the braking path, swept by a disc, must not touch
//!   (arena edges, keep-out edges, obstacle discs);
//! - [`Plane`]: a half-plane the braking path must stay in (one per
//!   neighbour: the robot's share of the gap between the two);
//! - [`Away`]: a direction the robot may only move along or away from
//!   (when it is already outside, in a keep-out, within the margin or too
//!   close to a neighbour);
//! - a speed cap (slow zones, stale neighbour information).

use mech_proto::Intervention;

use super::geometry::{Segment, Vec2};

/// How far a robot travels before it stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Braking {
    /// Time the robot keeps a commanded velocity before braking: one
    /// control period plus the actuators' lag, s.
    pub reaction_time: f64,
    /// The platform's maximum deceleration, m/s².
    pub deceleration: f64,
}

impl Braking {
    /// Length of the braking path from speed `s`, m.
    pub fn distance(&self, s: f64) -> f64 {
        let s = s.max(0.0);
        s * self.reaction_time + s * s / (2.0 * self.deceleration)
    }

    /// The fastest speed whose braking path is at most `length` long.
    pub fn speed_for(&self, length: f64) -> f64 {
        if length <= 0.0 {
            return 0.0;
        }
        if !length.is_finite() {
            return f64::INFINITY;
        }
        let (t, a) = (self.reaction_time, self.deceleration);
        (a * (-t + (t * t + 2.0 * length / a).sqrt())).max(0.0)
    }
}

/// A segment the robot's braking path, swept by a disc of `radius`, must not
/// touch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    pub segment: Segment,
    pub radius: f64,
    pub reason: Intervention,
}

/// A half-plane: every point `x` of the braking path satisfies
/// `(x - p) · normal <= offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: Vec2,
    pub offset: f64,
    pub reason: Intervention,
}

/// Motion allowed only in directions `dir` with `dir · toward >= min_dot`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Away {
    pub toward: Vec2,
    pub min_dot: f64,
    pub reason: Intervention,
}

/// Every constraint on one robot in one control period.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints {
    /// The robot's position, m, map frame.
    pub position: Vec2,
    pub braking: Braking,
    pub walls: Vec<Wall>,
    pub planes: Vec<Plane>,
    pub away: Vec<Away>,
    pub caps: Vec<(f64, Intervention)>,
}

impl Constraints {
    pub fn new(position: Vec2, braking: Braking) -> Constraints {
        Constraints {
            position,
            braking,
            walls: Vec::new(),
            planes: Vec::new(),
            away: Vec::new(),
            caps: Vec::new(),
        }
    }

    /// The fastest speed allowed along the unit vector `dir`, and the
    /// constraint that sets it ([`Intervention::None`] if none does).
    pub fn limit(&self, dir: Vec2) -> (f64, Intervention) {
        let mut best = (f64::INFINITY, Intervention::None);
        let mut keep = |s: f64, why: Intervention| {
            if s < best.0 {
                best = (s, why);
            }
        };
        for a in &self.away {
            if dir.dot(a.toward) < a.min_dot - 1e-12 {
                keep(0.0, a.reason);
            }
        }
        for w in &self.walls {
            if let Some(t) = w.segment.disc_hit(self.position, dir, w.radius) {
                keep(self.braking.speed_for(t), w.reason);
            }
        }
        for p in &self.planes {
            let along = dir.dot(p.normal);
            if along > 1e-12 {
                keep(self.braking.speed_for(p.offset / along), p.reason);
            }
        }
        for &(cap, why) in &self.caps {
            keep(cap, why);
        }
        best
    }
}

impl Constraints {
    /// The direction towards the neighbour whose constraint (its share of
    /// the gap, or moving apart when too close) sets the speed along the
    /// unit vector `dir`, if one does: the normal of the robot's cell
    /// edge there.
    pub fn binding_neighbour(&self, dir: Vec2) -> Option<Vec2> {
        let mut best: Option<(f64, Vec2)> = None;
        let mut keep = |s: f64, normal: Vec2| {
            if best.is_none_or(|(b, _)| s < b) {
                best = Some((s, normal));
            }
        };
        for a in self
            .away
            .iter()
            .filter(|a| a.reason == Intervention::Separation)
        {
            if dir.dot(a.toward) < a.min_dot - 1e-12 {
                keep(0.0, -a.toward);
            }
        }
        for p in self
            .planes
            .iter()
            .filter(|p| p.reason == Intervention::Separation)
        {
            let along = dir.dot(p.normal);
            if along > 1e-12 {
                keep(self.braking.speed_for(p.offset / along), p.normal);
            }
        }
        best.map(|(_, normal)| normal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_for_inverts_distance() {
        let b = Braking {
            reaction_time: 0.1,
            deceleration: 1.5,
        };
        for s in [0.0, 0.05, 0.3, 1.0, 4.0] {
            assert!((b.speed_for(b.distance(s)) - s).abs() < 1e-9, "{s}");
        }
        assert_eq!(b.speed_for(-1.0), 0.0);
    }

    #[test]
    fn the_tightest_constraint_sets_the_speed_and_says_why() {
        let braking = Braking {
            reaction_time: 0.1,
            deceleration: 1.0,
        };
        let mut c = Constraints::new(Vec2::ZERO, braking);
        c.walls.push(Wall {
            segment: Segment::new(Vec2::new(1.0, -5.0), Vec2::new(1.0, 5.0)),
            radius: 0.2,
            reason: Intervention::Fence,
        });
        c.caps.push((1.5, Intervention::SlowZone));
        let (s, why) = c.limit(Vec2::new(1.0, 0.0));
        assert_eq!(why, Intervention::Fence);
        assert!((braking.distance(s) - 0.8).abs() < 1e-9);
        let (s, why) = c.limit(Vec2::new(0.0, 1.0));
        assert_eq!((s, why), (1.5, Intervention::SlowZone));
        c.away.push(Away {
            toward: Vec2::new(0.0, -1.0),
            min_dot: 0.0,
            reason: Intervention::Returning,
        });
        assert_eq!(c.limit(Vec2::new(0.0, 1.0)), (0.0, Intervention::Returning));
    }
}
