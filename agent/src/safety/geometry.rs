//! Plane geometry for the safety filter: 2-D vectors, segments, polygons,
//! and the one question the filter asks of every edge: how far can a disc
//! travel along a ray before it touches this segment?
//!
//! Everything is in metres in the map frame; no allocation.

use std::ops::{Add, Mul, Neg, Sub};

/// A point or vector of the horizontal plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    pub x: f64,
    pub y: f64,
}

impl Vec2 {
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };

    pub const fn new(x: f64, y: f64) -> Vec2 {
        Vec2 { x, y }
    }

    /// The unit vector at `angle` rad counter-clockwise from +x.
    pub fn from_angle(angle: f64) -> Vec2 {
        let (s, c) = angle.sin_cos();
        Vec2::new(c, s)
    }

    pub fn dot(self, o: Vec2) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// z of the 3-D cross product: > 0 when `o` lies counter-clockwise.
    pub fn cross(self, o: Vec2) -> f64 {
        self.x * o.y - self.y * o.x
    }

    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// The unit vector along `self`, or `None` for a (near) zero vector.
    pub fn unit(self) -> Option<Vec2> {
        let n = self.norm();
        (n > 1e-12).then(|| Vec2::new(self.x / n, self.y / n))
    }

    /// Rotated counter-clockwise by `angle` rad.
    pub fn rotated(self, angle: f64) -> Vec2 {
        let (s, c) = angle.sin_cos();
        Vec2::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }

    /// Rotated a quarter turn clockwise: the right-hand side of `self`.
    pub fn right(self) -> Vec2 {
        Vec2::new(self.y, -self.x)
    }

    pub fn angle(self) -> f64 {
        self.y.atan2(self.x)
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

impl Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

impl From<mech_proto::Point> for Vec2 {
    fn from(p: mech_proto::Point) -> Vec2 {
        Vec2::new(p.x, p.y)
    }
}

/// A line segment; `a == b` is a point (a disc obstacle's centre).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a: Vec2,
    pub b: Vec2,
}

impl Segment {
    pub fn new(a: Vec2, b: Vec2) -> Segment {
        Segment { a, b }
    }

    /// The point of the segment closest to `p`.
    pub fn closest(&self, p: Vec2) -> Vec2 {
        let d = self.b - self.a;
        let len2 = d.dot(d);
        if len2 <= 1e-24 {
            return self.a;
        }
        let t = ((p - self.a).dot(d) / len2).clamp(0.0, 1.0);
        self.a + d * t
    }

    pub fn distance(&self, p: Vec2) -> f64 {
        (p - self.closest(p)).norm()
    }

    /// The closest pair of points of `self` and `o` (Ericson, *Real-Time
    /// Collision Detection*, 5.1.9), first on `self`.
    pub fn closest_pair(&self, o: &Segment) -> (Vec2, Vec2) {
        let (d1, d2) = (self.b - self.a, o.b - o.a);
        let r = self.a - o.a;
        let (a, e, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
        const EPS: f64 = 1e-18;
        if a <= EPS && e <= EPS {
            return (self.a, o.a);
        }
        let (s, t);
        if a <= EPS {
            s = 0.0;
            t = (f / e).clamp(0.0, 1.0);
        } else {
            let c = d1.dot(r);
            if e <= EPS {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else {
                let b = d1.dot(d2);
                let denom = a * e - b * b;
                let s0 = if denom > EPS {
                    ((b * f - c * e) / denom).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let t0 = (b * s0 + f) / e;
                if t0 < 0.0 {
                    t = 0.0;
                    s = (-c / a).clamp(0.0, 1.0);
                } else if t0 > 1.0 {
                    t = 1.0;
                    s = ((b - c) / a).clamp(0.0, 1.0);
                } else {
                    t = t0;
                    s = s0;
                }
            }
        }
        (self.a + d1 * s, o.a + d2 * t)
    }

    /// How far a disc of radius `radius` centred at `origin` travels along
    /// the unit vector `dir` before it touches the segment: the first
    /// `t >= 0` with `distance(origin + dir * t) <= radius`. `None` if it
    /// never does. `Some(0.0)` if it touches already.
    pub fn disc_hit(&self, origin: Vec2, dir: Vec2, radius: f64) -> Option<f64> {
        if self.distance(origin) <= radius {
            return Some(0.0);
        }
        let mut best: Option<f64> = None;
        let mut keep = |t: Option<f64>| {
            if let Some(t) = t.filter(|t| *t >= 0.0) {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        };
        keep(ray_circle(origin, dir, self.a, radius));
        keep(ray_circle(origin, dir, self.b, radius));
        if let Some(e) = (self.b - self.a).unit() {
            let side = e.right() * radius;
            for off in [side, -side] {
                keep(ray_segment(origin, dir, self.a + off, self.b + off));
            }
        }
        best
    }
}

/// First `t >= 0` at which `origin + dir * t` (unit `dir`) lies on the
/// circle around `centre`, for an origin outside it.
fn ray_circle(origin: Vec2, dir: Vec2, centre: Vec2, radius: f64) -> Option<f64> {
    let m = origin - centre;
    let b = m.dot(dir);
    let c = m.dot(m) - radius * radius;
    if c > 0.0 && b > 0.0 {
        return None;
    }
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    Some((-b - disc.sqrt()).max(0.0))
}

/// First `t >= 0` at which the ray crosses the segment `ab`.
fn ray_segment(origin: Vec2, dir: Vec2, a: Vec2, b: Vec2) -> Option<f64> {
    let e = b - a;
    let denom = dir.cross(e);
    if denom.abs() < 1e-15 {
        return None;
    }
    let w = a - origin;
    let t = w.cross(e) / denom;
    let u = w.cross(dir) / denom;
    (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
}

/// Whether `p` lies inside the polygon `points` (crossing number; a point
/// on an edge may fall either way, which the filter's margins absorb).
pub fn inside(points: &[Vec2], p: Vec2) -> bool {
    let n = points.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (points[i], points[(i + 1) % n]);
        if (a.y > p.y) != (b.y > p.y) {
            let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// The edges of a polygon, closing it.
pub fn edges(points: &[Vec2]) -> impl Iterator<Item = Segment> + '_ {
    let n = points.len();
    (0..n).map(move |i| Segment::new(points[i], points[(i + 1) % n]))
}

/// The point of the polygon's boundary closest to `p`.
pub fn closest_on_boundary(points: &[Vec2], p: Vec2) -> Option<Vec2> {
    edges(points)
        .map(|e| e.closest(p))
        .min_by(|x, y| (*x - p).norm().total_cmp(&(*y - p).norm()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_disc_moving_at_a_wall_touches_it_one_radius_early() {
        let wall = Segment::new(Vec2::new(2.0, -1.0), Vec2::new(2.0, 1.0));
        let t = wall.disc_hit(Vec2::ZERO, Vec2::new(1.0, 0.0), 0.5).unwrap();
        assert!((t - 1.5).abs() < 1e-12, "{t}");
        // Past the end of the wall: only the rounded end can be hit.
        let t = wall
            .disc_hit(Vec2::new(0.0, 1.3), Vec2::new(1.0, 0.0), 0.5)
            .unwrap();
        assert!((t - (2.0 - 0.4)).abs() < 1e-12, "{t}");
        assert_eq!(wall.disc_hit(Vec2::ZERO, Vec2::new(-1.0, 0.0), 0.5), None);
        assert_eq!(
            wall.disc_hit(Vec2::new(1.8, 0.0), Vec2::new(-1.0, 0.0), 0.5),
            Some(0.0)
        );
    }

    #[test]
    fn crossing_number_and_closest_points() {
        let square = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ];
        assert!(inside(&square, Vec2::new(0.5, 0.5)));
        assert!(!inside(&square, Vec2::new(1.5, 0.5)));
        let c = closest_on_boundary(&square, Vec2::new(0.5, 0.9)).unwrap();
        assert!((c - Vec2::new(0.5, 1.0)).norm() < 1e-12);
        let s = Segment::new(Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0));
        let o = Segment::new(Vec2::new(1.0, 1.0), Vec2::new(1.0, 3.0));
        let (p, q) = s.closest_pair(&o);
        assert!((p - Vec2::new(1.0, 0.0)).norm() < 1e-12);
        assert!((q - Vec2::new(1.0, 1.0)).norm() < 1e-12);
    }

    proptest! {
        /// Where `disc_hit` says the disc first touches, it touches (the
        /// distance is the radius), and halfway there it does not.
        #[test]
        fn the_first_touch_is_exact(
            ax in -3.0..3.0f64, ay in -3.0..3.0f64, bx in -3.0..3.0f64, by in -3.0..3.0f64,
            angle in -3.2..3.2f64, radius in 0.01..1.0f64,
        ) {
            let s = Segment::new(Vec2::new(ax, ay), Vec2::new(bx, by));
            let origin = Vec2::new(5.0, 0.0).rotated(angle * 0.7);
            prop_assume!(s.distance(origin) > radius + 1e-6);
            let dir = Vec2::from_angle(angle);
            if let Some(t) = s.disc_hit(origin, dir, radius) {
                let at = s.distance(origin + dir * t);
                prop_assert!((at - radius).abs() < 1e-6, "{at} vs {radius}");
                prop_assert!(s.distance(origin + dir * (t / 2.0)) > radius - 1e-9);
            } else {
                for k in 0..100 {
                    let d = s.distance(origin + dir * (k as f64 * 0.1));
                    prop_assert!(d > radius - 1e-9, "touches at {}", k as f64 * 0.1);
                }
            }
        }

        #[test]
        fn closest_pairs_are_no_farther_than_any_pair(
            p in proptest::collection::vec(-3.0..3.0f64, 8),
            s1 in 0.0..1.0f64, s2 in 0.0..1.0f64,
        ) {
            let a = Segment::new(Vec2::new(p[0], p[1]), Vec2::new(p[2], p[3]));
            let b = Segment::new(Vec2::new(p[4], p[5]), Vec2::new(p[6], p[7]));
            let (x, y) = a.closest_pair(&b);
            let any = (a.a + (a.b - a.a) * s1) - (b.a + (b.b - b.a) * s2);
            prop_assert!((x - y).norm() <= any.norm() + 1e-9);
        }
    }
}
