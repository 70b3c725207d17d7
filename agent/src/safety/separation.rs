//! Separation: keeping this robot's braking path apart from every
//! neighbour's, with the robots' radii plus the arena's margin between
//! them.
//!
//! Buffered Voronoi cells (Zhou et al., 2017, as Crazyswarm flies them)
//! extended from positions to braking paths: for each neighbour the robot
//! takes the closest points `c_i`, `c_j` of its own braking path (from its
//! current velocity) and the neighbour's (extrapolated by the age of its
//! state), and the gap `F = |c_j - c_i| - (r_i + r_j + margin)` beyond the
//! required distance. Its new braking path must stay on its side of the
//! line through the middle of that gap: it may advance towards the
//! neighbour by `F / 2` past `c_i` (all of `F` if the neighbour does not run
//! its own safety layer). Two robots that both do so keep their braking
//! paths, and so themselves, at least `r_i + r_j + margin` apart, and
//! braking is always a way to stay within the share (a braking path only
//! shrinks along itself). See `docs/safety.md` for why this and not ORCA.
//!
//! Neighbour states are `age` old: each is extrapolated at its velocity to
//! now, and its disc grown by `a·age²/2` for what it may have changed
//! since (never dropped, however old). Static obstacle discs are walls the
//! braking path must not touch.

use std::time::Duration;

use mech_proto::{Intervention, Neighbour, Neighbours, Obstacle};

use super::constraints::{Away, Braking, Constraints, Plane, Wall};
use super::geofence::polygon_constraints;
use super::geometry::{Segment, Vec2};

/// The newest [`Neighbours`] the robot has, and when it arrived.
#[derive(Debug, Clone, PartialEq)]
pub struct NeighbourSet {
    /// Station time of the states (the message's `stamp_us`).
    pub stamp_us: u64,
    /// Agent time the message arrived.
    pub received: Duration,
    pub robots: Vec<Neighbour>,
    pub discs: Vec<(Vec2, f64)>,
    pub polygons: Vec<Vec<Vec2>>,
}

impl NeighbourSet {
    pub fn new(n: &Neighbours, received: Duration) -> NeighbourSet {
        let mut discs = Vec::new();
        let mut polygons = Vec::new();
        for o in &n.obstacles {
            match o {
                Obstacle::Disc(d) => discs.push((Vec2::new(d.x, d.y), d.radius)),
                Obstacle::Polygon(p) => polygons.push(p.iter().map(|q| Vec2::from(*q)).collect()),
            }
        }
        NeighbourSet {
            stamp_us: n.stamp_us,
            received,
            robots: n.robots.clone(),
            discs,
            polygons,
        }
    }

    /// How old this information is at `now`.
    pub fn age(&self, now: Duration) -> Duration {
        now.saturating_sub(self.received)
    }

    /// Where neighbour `n` is at `now` (extrapolated at its velocity), and
    /// how old its state is, s.
    pub fn predict(&self, n: &Neighbour, now: Duration) -> (Vec2, f64) {
        let age = f64::from(n.age_ms) / 1000.0 + self.age(now).as_secs_f64();
        let v = Vec2::new(n.vx, n.vy);
        (Vec2::new(n.x, n.y) + v * age, age)
    }

    /// Adds the separation constraints on a robot of `radius` at
    /// `c.position` moving at `velocity`.
    pub fn constrain(
        &self,
        c: &mut Constraints,
        velocity: Vec2,
        radius: f64,
        margin: f64,
        reach: f64,
        now: Duration,
    ) {
        let p = c.position;
        let braking = c.braking;
        let mine = braking_path(p, velocity, &braking);
        for n in &self.robots {
            let (q, age) = self.predict(n, now);
            let w = Vec2::new(n.vx, n.vy);
            let theirs = braking_path(q, w, &braking);
            let need = radius + n.radius + margin;
            let grown = need + 0.5 * braking.deceleration * age * age;
            let (ci, cj) = mine.closest_pair(&theirs);
            let gap = (cj - ci).norm() - grown;
            if gap > reach + theirs_length(&theirs) {
                continue;
            }
            let normal = (cj - ci)
                .unit()
                .or_else(|| (q - p).unit())
                .unwrap_or(Vec2::new(1.0, 0.0));
            if gap < 0.0 {
                // Already inside the buffer: never closer.
                let toward = (q - p).unit().map_or(-normal, |d| -d);
                c.away.push(Away {
                    toward,
                    min_dot: 0.0,
                    reason: Intervention::Separation,
                });
                continue;
            }
            let share = if n.cooperative { gap / 2.0 } else { gap };
            c.planes.push(Plane {
                normal,
                offset: (ci - p).dot(normal) + share,
                reason: Intervention::Separation,
            });
        }
        for &(centre, r) in &self.discs {
            let clearance = r + radius + margin;
            let d = (p - centre).norm();
            if d < clearance {
                if let Some(out) = (p - centre).unit() {
                    c.away.push(Away {
                        toward: out,
                        min_dot: 0.0,
                        reason: Intervention::Returning,
                    });
                }
            } else if d <= reach + clearance {
                c.walls.push(Wall {
                    segment: Segment::new(centre, centre),
                    radius: clearance,
                    reason: Intervention::KeepOut,
                });
            }
        }
        for poly in &self.polygons {
            polygon_constraints(
                c,
                poly,
                false,
                radius + margin,
                reach,
                Intervention::KeepOut,
            );
        }
    }
}

/// Steps of the turns tried by [`NeighbourSet::anticipate`] on each side,
/// over half a circle.
const ANTICIPATION_STEPS: usize = 36;

impl NeighbourSet {
    /// Anticipation, the cooperative half of separation: if moving at
    /// `desired` would bring this robot (at `p`, of `radius`) within
    /// `radius + r_j + margin` of a neighbour moving on at its own velocity
    /// within `horizon` seconds, the same velocity turned right by the
    /// smallest angle that avoids every such contact; if no turn to the
    /// right up to half a circle does, turned left by the smallest that
    /// does; if none does, the turn that puts the first contact off
    /// longest. `None` when `desired` is clear (or nothing better is
    /// found). Every robot turning right, two meeting head-on or crossing
    /// pass each other with a small swerve each, well before their braking
    /// paths meet; the constraints never rely on it.
    pub fn anticipate(
        &self,
        p: Vec2,
        desired: Vec2,
        radius: f64,
        margin: f64,
        horizon: f64,
        now: Duration,
    ) -> Option<Vec2> {
        let others: Vec<(Vec2, Vec2, f64)> = self
            .robots
            .iter()
            .map(|n| {
                let (q, _) = self.predict(n, now);
                (q, Vec2::new(n.vx, n.vy), radius + n.radius + margin)
            })
            .filter(|(q, _, need)| (*q - p).norm() < need + horizon * 4.0)
            .collect();
        // The soonest contact at velocity `u` (infinite if none within the
        // horizon).
        let soonest = |u: Vec2| {
            others
                .iter()
                .filter_map(|&(q, w, need)| contact_time(q - p, u - w, need))
                .filter(|t| *t <= horizon)
                .fold(f64::INFINITY, f64::min)
        };
        if desired.norm() < 1e-9 || soonest(desired).is_infinite() {
            return None;
        }
        // Turn right until clear; if no turn to the right up to half a
        // circle clears, to the left; if none clears at all, the turn that
        // puts contact off longest (robots jammed together back away from
        // each other).
        let step = std::f64::consts::PI / ANTICIPATION_STEPS as f64;
        let right = (1..=ANTICIPATION_STEPS).map(|k| -(k as f64) * step);
        let left = (1..ANTICIPATION_STEPS).map(|k| k as f64 * step);
        let mut best = (soonest(desired), desired);
        for a in right.chain(left) {
            let u = desired.rotated(a);
            let t = soonest(u);
            if t.is_infinite() {
                return Some(u);
            }
            if t > best.0 + 1e-9 {
                best = (t, u);
            }
        }
        (best.1 != desired).then_some(best.1)
    }
}

/// How far beyond the distance it must keep a neighbour counts as near
/// for [`NeighbourSet::away`], m.
const CROWD: f64 = 0.3;

impl NeighbourSet {
    /// The way out of a crowd: away from the neighbours near a robot at
    /// `p`, the nearest weighing most. Where they pull evenly from opposite
    /// sides (a robot pressed between two), the way out is across the line
    /// between them: to the robot's right as it faces the nearest. `None`
    /// with nobody near.
    pub fn away(&self, p: Vec2, radius: f64, margin: f64, now: Duration) -> Option<Vec2> {
        let mut sum = Vec2::ZERO;
        let mut nearest: Option<(f64, Vec2)> = None;
        for n in &self.robots {
            let (q, _) = self.predict(n, now);
            let d = p - q;
            let need = radius + n.radius + margin;
            let dist = d.norm();
            if dist < need + CROWD && dist > 1e-9 {
                let pull = d * (1.0 / (dist * dist));
                sum = sum + pull;
                if nearest.is_none_or(|(m, _)| pull.norm() > m) {
                    nearest = Some((pull.norm(), pull));
                }
            }
        }
        let (strongest, towards) = nearest?;
        if sum.norm() > 1e-3 * strongest {
            return sum.unit();
        }
        // Facing the nearest (`-towards`), its right is (-towards.y, towards.x).
        Vec2::new(-towards.y, towards.x).unit()
    }
}

/// When a point at `d` (relative position) moving at `-w` relative to us
/// first comes within `need`: the first `t >= 0` with `|d - w t| < need`.
/// `Some(0.0)` if it already is.
fn contact_time(d: Vec2, w: Vec2, need: f64) -> Option<f64> {
    let c = d.dot(d) - need * need;
    if c < 0.0 {
        // Already within: contact now unless moving apart.
        return (w.dot(d) > 0.0).then_some(0.0);
    }
    let a = w.dot(w);
    let b = w.dot(d);
    if a < 1e-18 || b <= 0.0 {
        return None;
    }
    let disc = b * b - a * c;
    (disc > 0.0).then(|| (b - disc.sqrt()) / a)
}

fn theirs_length(s: &Segment) -> f64 {
    (s.b - s.a).norm()
}

/// The braking path from `p` at velocity `v`.
pub fn braking_path(p: Vec2, v: Vec2, braking: &Braking) -> Segment {
    let end = v
        .unit()
        .map_or(p, |dir| p + dir * braking.distance(v.norm()));
    Segment::new(p, end)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn neighbour(x: f64, y: f64, vx: f64, cooperative: bool) -> Neighbour {
        Neighbour {
            id: 2,
            x,
            y,
            z: 0.0,
            vx,
            vy: 0.0,
            vz: 0.0,
            radius: 0.15,
            age_ms: 0,
            cooperative,
        }
    }

    fn set(robots: Vec<Neighbour>) -> NeighbourSet {
        NeighbourSet {
            stamp_us: 1,
            received: Duration::ZERO,
            robots,
            discs: vec![],
            polygons: vec![],
        }
    }

    const BRAKING: Braking = Braking {
        reaction_time: 0.1,
        deceleration: 1.0,
    };

    fn limit_toward(set: &NeighbourSet, now: Duration) -> f64 {
        let mut c = Constraints::new(Vec2::ZERO, BRAKING);
        set.constrain(&mut c, Vec2::ZERO, 0.15, 0.1, 10.0, now);
        c.limit(Vec2::new(1.0, 0.0)).0
    }

    #[test]
    fn a_cooperating_neighbour_gets_half_the_gap_and_another_none() {
        // 2 m apart, 0.4 m needed: 1.6 m of gap.
        let coop = limit_toward(&set(vec![neighbour(2.0, 0.0, 0.0, true)]), Duration::ZERO);
        assert!((BRAKING.distance(coop) - 0.8).abs() < 1e-9);
        let other = limit_toward(&set(vec![neighbour(2.0, 0.0, 0.0, false)]), Duration::ZERO);
        assert!((BRAKING.distance(other) - 1.6).abs() < 1e-9);
    }

    #[test]
    fn an_old_state_is_extrapolated_and_grown_never_dropped() {
        // Coming at 0.5 m/s, reported 1 s ago from 3 m: now at 2.5 m, its
        // braking path reaching back 0.3 m, and grown by 0.5 m.
        let s = set(vec![neighbour(3.0, 0.0, -0.5, true)]);
        let fresh = limit_toward(&s, Duration::ZERO);
        let old = limit_toward(&s, Duration::from_secs(1));
        let gap = 2.5 - BRAKING.distance(0.5) - 0.4 - 0.5;
        assert!((BRAKING.distance(old) - gap / 2.0).abs() < 1e-9, "{old}");
        assert!(old < fresh);
        // 3 s old: somewhere about 1.5 m away, give or take 4.5 m.
        let ancient = limit_toward(&s, Duration::from_secs(3));
        assert_eq!(ancient, 0.0, "information this old still blocks");
    }

    #[test]
    fn head_on_both_swerve_right_and_a_clear_way_is_left_alone() {
        let s = set(vec![neighbour(2.0, 0.0, -0.3, true)]);
        let u = s
            .anticipate(
                Vec2::ZERO,
                Vec2::new(0.3, 0.0),
                0.15,
                0.1,
                3.0,
                Duration::ZERO,
            )
            .unwrap();
        assert!(
            u.y < 0.0 && (u.norm() - 0.3).abs() < 1e-9,
            "to the right: {u:?}"
        );
        let w = Vec2::new(0.3, 0.0) - Vec2::new(-0.3, 0.0);
        let after = contact_time(Vec2::new(2.0, 0.0), u - Vec2::new(-0.3, 0.0), 0.4);
        assert!(after.is_none_or(|t| t > 3.0), "{after:?} {w:?}");
        let away = s.anticipate(
            Vec2::ZERO,
            Vec2::new(-0.3, 0.0),
            0.15,
            0.1,
            3.0,
            Duration::ZERO,
        );
        assert_eq!(away, None);
        // Far in time: not yet.
        let far = s.anticipate(
            Vec2::ZERO,
            Vec2::new(0.3, 0.0),
            0.15,
            0.1,
            1.0,
            Duration::ZERO,
        );
        assert_eq!(far, None);
    }

    #[test]
    fn the_way_out_of_a_crowd_leads_away_from_the_nearest() {
        let s = set(vec![
            neighbour(0.4, 0.0, 0.0, true),
            neighbour(0.0, 0.6, 0.0, true),
            neighbour(-3.0, 0.0, 0.0, true),
        ]);
        let out = s.away(Vec2::ZERO, 0.15, 0.1, Duration::ZERO).unwrap();
        assert!(out.x < -0.8 && out.y < 0.0, "{out:?}");
        assert!((out.norm() - 1.0).abs() < 1e-9);
        let alone = set(vec![neighbour(-3.0, 0.0, 0.0, true)]);
        assert_eq!(alone.away(Vec2::ZERO, 0.15, 0.1, Duration::ZERO), None);
    }

    /// Pressed evenly between two neighbours, a robot still has a way out:
    /// across the line between them, to its right as it faces the nearest.
    #[test]
    fn a_robot_pressed_between_two_backs_off_across_them() {
        let s = set(vec![
            neighbour(0.4, 0.0, 0.0, true),
            neighbour(-0.4, 0.0, 0.0, true),
        ]);
        let out = s.away(Vec2::ZERO, 0.15, 0.1, Duration::ZERO).unwrap();
        assert!(
            out.x.abs() < 1e-9 && (out.y.abs() - 1.0).abs() < 1e-9,
            "{out:?}"
        );
        // Four round it evenly: still one way out, at right angles to one.
        let ring = set(vec![
            neighbour(0.4, 0.0, 0.0, true),
            neighbour(-0.4, 0.0, 0.0, true),
            neighbour(0.0, 0.4, 0.0, true),
            neighbour(0.0, -0.4, 0.0, true),
        ]);
        let out = ring.away(Vec2::ZERO, 0.15, 0.1, Duration::ZERO).unwrap();
        assert!((out.norm() - 1.0).abs() < 1e-9, "{out:?}");
    }

    #[test]
    fn too_close_allows_only_moving_apart() {
        let s = set(vec![neighbour(0.3, 0.0, 0.0, true)]);
        let mut c = Constraints::new(Vec2::ZERO, BRAKING);
        s.constrain(&mut c, Vec2::ZERO, 0.15, 0.1, 10.0, Duration::ZERO);
        assert_eq!(
            c.limit(Vec2::new(1.0, 0.0)),
            (0.0, Intervention::Separation)
        );
        assert!(c.limit(Vec2::new(-1.0, 0.0)).0.is_infinite());
    }
}
