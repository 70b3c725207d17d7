//! Fleet safety on the wire: the arena a robot must stay inside
//! ([`Arena`], acknowledged by [`ArenaAck`]), the states of the robots and
//! obstacles near it ([`Neighbours`]), and what the robot's safety layer is
//! doing ([`SafetyReport`], carried at the end of [`crate::Telemetry`]).
//!
//! Everything is in metres and metres per second in the map (world) frame.
//! Sizes are bounded so that an arena with every polygon at its limit still
//! fits one datagram, and validation refuses what a robot could not use
//! safely: non-finite numbers, polygons with too few vertices, zero area or
//! crossing edges, negative margins.

use serde::{Deserialize, Serialize};
use serde_repr::{Deserialize_repr, Serialize_repr};

use crate::command::finite;
use crate::error::Error;
use crate::tagged::tagged_enum;

/// Most vertices of an arena's boundary.
pub const MAX_BOUNDARY_VERTICES: usize = 64;

/// Most vertices of one keep-out, slow zone or obstacle polygon.
pub const MAX_POLYGON_VERTICES: usize = 32;

/// Most keep-out polygons in one [`Arena`].
pub const MAX_KEEP_OUTS: usize = 32;

/// Most slow zones in one [`Arena`].
pub const MAX_SLOW_ZONES: usize = 16;

/// Most robots in one [`Neighbours`] message.
pub const MAX_NEIGHBOURS: usize = 128;

/// Most static obstacles in one [`Neighbours`] message.
pub const MAX_OBSTACLES: usize = 32;

/// Largest coordinate, radius or margin accepted, m: an arena is a lab or a
/// field, and a bound keeps the geometry's arithmetic far from overflow.
pub const MAX_EXTENT: f64 = 1.0e5;

/// A point of the map frame, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
}

/// A polygon of the map frame where robots must go no faster than
/// `max_speed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlowZone {
    /// Vertices in order (either winding), closed implicitly.
    pub polygon: Vec<Point>,
    /// m/s; 0 keeps robots out of the zone's interior altogether.
    pub max_speed: f64,
}

/// Router -> robot: the arena this robot must stay inside, and whether its
/// safety layer is on. Delivered reliably like a [`crate::Route`]: repeated
/// until an [`ArenaAck`] with the same `id` arrives; the robot ignores an
/// arena whose `id` is older than the one in force (wrapping compare).
///
/// An empty `boundary` with no keep-outs and no slow zones means "no arena":
/// the robot's safety layer has nothing to enforce.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Arena {
    pub robot: String,
    /// Increases with every change of this robot's arena or switch, so a
    /// late ack of an older one is not taken for the current one.
    pub id: u32,
    /// Whether the robot's safety layer enforces this arena and keeps its
    /// distance from neighbours. Only an operator switches it off, and a
    /// robot with its layer off reports it as an alarm.
    pub enabled: bool,
    /// The polygon robots stay inside (vertices in order, closed implicitly).
    pub boundary: Vec<Point>,
    /// Polygons robots stay out of.
    pub keep_out: Vec<Vec<Point>>,
    pub slow_zones: Vec<SlowZone>,
    /// Clearance, m, kept between a robot's disc and every edge of the
    /// boundary and keep-outs, and added to the sum of two robots' radii.
    pub margin: f64,
}

impl Arena {
    /// Whether this message carries no geometry (it clears the arena).
    pub fn is_empty(&self) -> bool {
        self.boundary.is_empty() && self.keep_out.is_empty() && self.slow_zones.is_empty()
    }
}

/// Robot -> router: the [`Arena`] with this `id` is in force.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ArenaAck {
    pub robot: String,
    pub id: u32,
}

/// Another robot as the station last saw it, for a robot to keep apart from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Neighbour {
    /// The robot's id (the router's [`crate::Welcome::robot_id`]).
    pub id: u16,
    /// Position, m, map frame (`z` matters only to flying robots).
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// Velocity, m/s, map frame.
    pub vx: f64,
    pub vy: f64,
    pub vz: f64,
    /// Radius of the disc the robot occupies, m, grown by how far its
    /// position estimate may be from the truth (its report's
    /// `position_error`).
    pub radius: f64,
    /// How old this state was when the station sent it, ms (time since the
    /// telemetry it comes from arrived, plus what that telemetry said about
    /// its own age).
    pub age_ms: u32,
    /// Whether that robot runs its safety layer (and so takes its half of
    /// every avoidance); a robot that does not is given a wide berth.
    pub cooperative: bool,
}

/// A static disc a robot must keep clear of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Disc {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

tagged_enum! {
    /// A static obstacle the station knows of besides the arena's keep-outs
    /// (a robot of another station, a box put down for an experiment).
    #[derive(Debug, Clone, PartialEq)]
    pub enum Obstacle {
        Disc(Disc) = 1,
        Polygon(Vec<Point>) = 2,
    }
}

/// Router -> robot, at 10 Hz or more: the robots near this one and the
/// static obstacles, so the robot can keep its distance. A robot whose
/// newest `Neighbours` is older than its stale limit slows to a crawl.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Neighbours {
    pub robot: String,
    /// Station time the states were gathered, µs since the Unix epoch; a
    /// robot ignores a message older than the newest it used.
    pub stamp_us: u64,
    pub robots: Vec<Neighbour>,
    pub obstacles: Vec<Obstacle>,
}

/// What a robot's safety layer is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
#[repr(u8)]
pub enum SafetyState {
    /// No arena is known yet: nothing is enforced.
    #[default]
    NoArena = 0,
    /// Every command is limited to the arena and kept apart from neighbours.
    On = 1,
    /// An operator switched the layer off: an alarm.
    Off = 2,
}

crate::named_enum! {
    /// Why the safety layer changed the command it was about to obey.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum Intervention: "intervention" {
        /// The command is obeyed as it is.
        #[default]
        None = 0 => "none",
        /// Slowed or stopped so the stopping point stays inside the boundary.
        Fence = 1 => "fence",
        /// Slowed or stopped so the stopping point stays out of a keep-out or
        /// static obstacle.
        KeepOut = 2 => "keep-out",
        /// Slowed, stopped or turned aside to keep apart from a neighbour.
        Separation = 3 => "separation",
        /// Neighbour information is stale: crawling.
        StaleNeighbours = 4 => "stale-neighbours",
        /// Inside or approaching a slow zone: speed capped.
        SlowZone = 5 => "slow-zone",
        /// Outside the arena, in a keep-out or within the margin: only motion
        /// back to safety is allowed.
        Returning = 6 => "returning",
    }
}

/// How many times each intervention began (a run of control periods
/// limited for the same reason counts once), since the robot started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct InterventionCounts {
    pub fence: u32,
    pub keep_out: u32,
    pub separation: u32,
    pub stale_neighbours: u32,
    pub slow_zone: u32,
    pub returning: u32,
}

impl InterventionCounts {
    /// The count of `i` (0 for [`Intervention::None`]).
    pub fn get(&self, i: Intervention) -> u32 {
        match i {
            Intervention::None => 0,
            Intervention::Fence => self.fence,
            Intervention::KeepOut => self.keep_out,
            Intervention::Separation => self.separation,
            Intervention::StaleNeighbours => self.stale_neighbours,
            Intervention::SlowZone => self.slow_zone,
            Intervention::Returning => self.returning,
        }
    }

    /// Counts one more `i` (nothing for [`Intervention::None`]); wraps.
    pub fn count(&mut self, i: Intervention) {
        let slot = match i {
            Intervention::None => return,
            Intervention::Fence => &mut self.fence,
            Intervention::KeepOut => &mut self.keep_out,
            Intervention::Separation => &mut self.separation,
            Intervention::StaleNeighbours => &mut self.stale_neighbours,
            Intervention::SlowZone => &mut self.slow_zone,
            Intervention::Returning => &mut self.returning,
        };
        *slot = slot.wrapping_add(1);
    }

    /// Sum over every reason.
    pub fn total(&self) -> u64 {
        Intervention::ALL
            .iter()
            .map(|&i| u64::from(self.get(i)))
            .sum()
    }
}

/// The safety layer's state, in telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SafetyReport {
    pub state: SafetyState,
    /// [`Arena::id`] in force (0 before any).
    pub arena: u32,
    /// What the layer did to the current command.
    pub intervention: Intervention,
    pub counts: InterventionCounts,
    /// Radius of the disc this robot occupies, m.
    pub radius: f64,
    /// How far the robot's position estimate may be from its true
    /// position now, m: its layer keeps its distances from a disc of
    /// `radius + position_error`, and the station tells its neighbours
    /// that disc. Added at the end: a report without it reads as 0 (exact
    /// positions), as such robots assumed.
    #[serde(default)]
    pub position_error: f64,
}

impl SafetyReport {
    /// Whether an operator switched the layer off (shown as an alarm).
    pub fn alarm(&self) -> bool {
        self.state == SafetyState::Off
    }
}

/// A length or coordinate: finite and within [`MAX_EXTENT`].
fn extent(v: f64, what: &str) -> Result<(), Error> {
    finite(v, what)?;
    if v.abs() > MAX_EXTENT {
        return Err(Error::invalid(format!(
            "{what} {v} is beyond {MAX_EXTENT} m"
        )));
    }
    Ok(())
}

fn nonnegative(v: f64, what: &str) -> Result<(), Error> {
    extent(v, what)?;
    if v < 0.0 {
        return Err(Error::invalid(format!("{what} {v} is negative")));
    }
    Ok(())
}

/// Checks a polygon: at least three finite vertices, at most `max`, no two
/// consecutive vertices equal, a non-zero area, and no two edges crossing
/// or touching except neighbours at their shared vertex (O(n²) for at most
/// [`MAX_BOUNDARY_VERTICES`] vertices: a few thousand segment tests).
pub fn check_polygon(points: &[Point], max: usize, what: &str) -> Result<(), Error> {
    let n = points.len();
    if n < 3 {
        return Err(Error::invalid(format!(
            "{what} has {n} vertices, at least 3 needed"
        )));
    }
    if n > max {
        return Err(Error::invalid(format!(
            "{what} has {n} vertices, at most {max} allowed"
        )));
    }
    for (i, p) in points.iter().enumerate() {
        extent(p.x, &format!("{what} vertex {i} x"))?;
        extent(p.y, &format!("{what} vertex {i} y"))?;
    }
    for i in 0..n {
        if points[i] == points[(i + 1) % n] {
            return Err(Error::invalid(format!(
                "{what} repeats vertex {} at {}",
                i,
                (i + 1) % n
            )));
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            // Edges i and j share a vertex when adjacent (including the
            // last and the first); those touch by construction.
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            let (a, b) = (points[i], points[(i + 1) % n]);
            let (c, d) = (points[j], points[(j + 1) % n]);
            if !adjacent && segments_touch(a, b, c, d) {
                return Err(Error::invalid(format!("{what}: edges {i} and {j} cross")));
            }
        }
    }
    let area2: f64 = (0..n)
        .map(|i| {
            let (a, b) = (points[i], points[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum();
    if area2.abs() < 1e-9 {
        return Err(Error::invalid(format!("{what} has no area")));
    }
    Ok(())
}

fn cross(o: Point, a: Point, b: Point) -> f64 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

fn on_segment(a: Point, b: Point, p: Point) -> bool {
    p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
}

/// Whether segments `ab` and `cd` share a point (crossing, touching or
/// overlapping).
fn segments_touch(a: Point, b: Point, c: Point, d: Point) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

impl Arena {
    pub(crate) fn validate(&self) -> Result<(), Error> {
        crate::names::nonempty_name(&self.robot, "robot name")?;
        nonnegative(self.margin, "arena margin")?;
        if !self.boundary.is_empty() {
            check_polygon(&self.boundary, MAX_BOUNDARY_VERTICES, "arena boundary")?;
        } else if !self.is_empty() {
            return Err(Error::invalid(
                "an arena with keep-outs or slow zones needs a boundary",
            ));
        }
        if self.keep_out.len() > MAX_KEEP_OUTS {
            return Err(Error::invalid(format!(
                "{} keep-outs, at most {MAX_KEEP_OUTS} allowed",
                self.keep_out.len()
            )));
        }
        for (i, k) in self.keep_out.iter().enumerate() {
            check_polygon(k, MAX_POLYGON_VERTICES, &format!("keep-out {i}"))?;
        }
        if self.slow_zones.len() > MAX_SLOW_ZONES {
            return Err(Error::invalid(format!(
                "{} slow zones, at most {MAX_SLOW_ZONES} allowed",
                self.slow_zones.len()
            )));
        }
        for (i, z) in self.slow_zones.iter().enumerate() {
            let what = format!("slow zone {i}");
            check_polygon(&z.polygon, MAX_POLYGON_VERTICES, &what)?;
            nonnegative(z.max_speed, &format!("{what} max speed"))?;
        }
        Ok(())
    }
}

impl Neighbours {
    pub(crate) fn validate(&self) -> Result<(), Error> {
        crate::names::nonempty_name(&self.robot, "robot name")?;
        if self.robots.len() > MAX_NEIGHBOURS {
            return Err(Error::invalid(format!(
                "{} neighbours, at most {MAX_NEIGHBOURS} allowed",
                self.robots.len()
            )));
        }
        for n in &self.robots {
            for (v, what) in [
                (n.x, "neighbour x"),
                (n.y, "neighbour y"),
                (n.z, "neighbour z"),
                (n.vx, "neighbour vx"),
                (n.vy, "neighbour vy"),
                (n.vz, "neighbour vz"),
            ] {
                extent(v, what)?;
            }
            nonnegative(n.radius, "neighbour radius")?;
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(Error::invalid(format!(
                "{} obstacles, at most {MAX_OBSTACLES} allowed",
                self.obstacles.len()
            )));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            match o {
                Obstacle::Disc(d) => {
                    extent(d.x, "obstacle x")?;
                    extent(d.y, "obstacle y")?;
                    nonnegative(d.radius, "obstacle radius")?;
                }
                Obstacle::Polygon(p) => {
                    check_polygon(p, MAX_POLYGON_VERTICES, &format!("obstacle {i}"))?
                }
            }
        }
        Ok(())
    }
}

impl SafetyReport {
    pub(crate) fn validate(&self) -> Result<(), Error> {
        nonnegative(self.radius, "safety radius")?;
        nonnegative(self.position_error, "safety position error")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[(f64, f64)]) -> Vec<Point> {
        v.iter().map(|&(x, y)| Point { x, y }).collect()
    }

    #[test]
    fn a_square_is_a_polygon_and_a_bow_tie_is_not() {
        let square = pts(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        assert!(check_polygon(&square, 64, "square").is_ok());
        let bow_tie = pts(&[(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)]);
        let err = check_polygon(&bow_tie, 64, "bow tie").unwrap_err();
        assert!(err.to_string().contains("edges 0 and 2 cross"), "{err}");
    }

    #[test]
    fn degenerate_polygons_are_refused() {
        let line = pts(&[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)]);
        assert!(check_polygon(&line, 64, "line").is_err(), "no area");
        let two = pts(&[(0.0, 0.0), (1.0, 0.0)]);
        assert!(check_polygon(&two, 64, "two").is_err());
        let repeat = pts(&[(0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (0.0, 1.0)]);
        assert!(check_polygon(&repeat, 64, "repeat").is_err());
        let nan = pts(&[(0.0, 0.0), (f64::NAN, 0.0), (0.0, 1.0)]);
        assert!(check_polygon(&nan, 64, "nan").is_err());
        let many: Vec<Point> = (0..40)
            .map(|i| {
                let a = i as f64 / 40.0 * std::f64::consts::TAU;
                Point {
                    x: a.cos(),
                    y: a.sin(),
                }
            })
            .collect();
        assert!(check_polygon(&many, 64, "circle").is_ok());
        assert!(check_polygon(&many, 32, "circle").is_err(), "too many");
        // A vertex touching a non-adjacent edge.
        let touching = pts(&[
            (0.0, 0.0),
            (2.0, 0.0),
            (1.0, 0.0001),
            (1.0, 0.0),
            (0.0, 1.0),
        ]);
        assert!(check_polygon(&touching, 64, "touching").is_err());
    }

    #[test]
    fn counts_follow_their_reason() {
        let mut c = InterventionCounts::default();
        for i in Intervention::ALL {
            c.count(i);
        }
        c.count(Intervention::Separation);
        assert_eq!(c.get(Intervention::None), 0);
        assert_eq!(c.get(Intervention::Separation), 2);
        assert_eq!(c.total(), 7);
    }
}
