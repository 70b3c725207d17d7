//! Fleet safety at the robot: whatever command the agent is about to obey
//! (any mode, any controller, an onboard mission), [`SafetyLayer::filter`]
//! limits it so the robot stays inside its arena, out of keep-outs, and
//! apart from its neighbours, and says when and why it did.
//!
//! - [`geometry`]: vectors, segments, polygons, a disc swept along a ray;
//! - [`constraints`]: braking paths and the constraints on them;
//! - [`geofence`]: the arena's constraints ([`Fence`]);
//! - [`separation`]: the neighbours' constraints ([`NeighbourSet`]);
//! - [`filter`]: the pure decision from constraints and a desired velocity;
//! - [`circulation`]: where a command heads, for the right-hand rule that
//!   steers robots round each other (in [`SafetyLayer::filter`]);
//! - [`mapping`]: actuator outputs to world velocity and back, per platform.
//!
//! # The seam
//!
//! The agent calls [`SafetyLayer::filter`] once per control period, on the
//! outputs its controller computed for the command it obeys (after
//! `Controller::update`, before the wheel speed loops and the actuators),
//! with its pose estimate, its world-frame velocity estimate (the one its
//! telemetry reports) and `now`; it writes the outputs returned. It hands
//! the layer every [`Arena`] addressed to it ([`SafetyLayer::apply_arena`],
//! answering with the [`ArenaAck`] returned) and every [`Neighbours`]
//! ([`SafetyLayer::apply_neighbours`]), and puts [`SafetyLayer::report`] in
//! its telemetry. Nothing here reads a clock or does I/O.
//!
//! The guarantees and their assumptions are in `docs/safety.md`.

pub mod circulation;
pub mod constraints;
pub mod filter;
pub mod geofence;
pub mod geometry;
mod manoeuvre;
pub mod mapping;
pub mod separation;

use std::time::Duration;

use mech_proto::{
    Arena, ArenaAck, Intervention, InterventionCounts, Neighbours, Pose, SafetyReport, SafetyState,
};
use serde::Deserialize;

pub use constraints::{Braking, Constraints};
pub use filter::{Decision, Mobility, decide};
pub use geofence::Fence;
pub use geometry::Vec2;
pub use separation::NeighbourSet;

use crate::platform::Platform;

/// The robot's safety settings, the `[safety]` table of its config.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyConfig {
    /// Radius of a disc around the robot's position that contains all of
    /// it, m.
    pub radius: f64,
    /// The deceleration the robot is sure to reach when its outputs go to
    /// zero, m/s² (measure it: drive at full speed, stop, halve
    /// speed²/distance for a margin).
    pub max_deceleration: f64,
    /// Time a commanded velocity lasts before braking starts: a control
    /// period plus the actuators' lag, s.
    pub reaction_time: f64,
    /// Neighbour information older than this slows the robot to a crawl,
    /// s.
    pub stale_after: f64,
    /// The crawl, m/s.
    pub crawl_speed: f64,
    /// Fastest turn of a diff-drive while the layer steers it (round a
    /// neighbour, or backing off), rad/s.
    pub yield_turn_rate: f64,
    /// How far ahead, s, a robot looks for neighbours its command would
    /// meet, to swerve right in time (0: never).
    pub horizon: f64,
    /// How long a robot may want to move without moving among its
    /// neighbours before it backs off from them, s (0: never).
    pub stuck_after: f64,
    /// How long it backs off, s (a diff-drive turns towards the way out at
    /// `yield_turn_rate` first, which may take longer than this).
    pub back_off_time: f64,
    /// How far the position estimate may be from the truth, m, for a
    /// position source that does not say (a UWB tag, an external
    /// tracker): the filtered fixes' error at rest. Odometry fused with
    /// fixes states its own (from its covariance) instead. The layer grows
    /// the robot's disc by it, and by what the estimate's age adds, so the
    /// distances it keeps hold on the true positions. 0: exact positions
    /// (motion capture, a simulator's truth).
    pub position_error: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            radius: 0.15,
            max_deceleration: 1.0,
            reaction_time: 0.1,
            stale_after: 0.3,
            crawl_speed: 0.05,
            yield_turn_rate: 1.0,
            horizon: 1.5,
            stuck_after: 1.0,
            back_off_time: 1.0,
            position_error: 0.05,
        }
    }
}

impl SafetyConfig {
    /// Checks every value; `Err` names the one that is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: f64, what: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "`safety.{what}` must be a positive number, got {v}"
                ))
            }
        };
        let nonnegative = |v: f64, what: &str| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!("`safety.{what}` must be zero or more, got {v}"))
            }
        };
        // Times are seconds a robot waits or looks ahead: an hour at most.
        let at_most_an_hour = |v: f64, what: &str| {
            if v <= 3600.0 {
                Ok(())
            } else {
                Err(format!("`safety.{what}` must be 3600 s or less, got {v}"))
            }
        };
        positive(self.radius, "radius")?;
        positive(self.max_deceleration, "max_deceleration")?;
        nonnegative(self.reaction_time, "reaction_time")?;
        positive(self.stale_after, "stale_after")?;
        nonnegative(self.crawl_speed, "crawl_speed")?;
        positive(self.yield_turn_rate, "yield_turn_rate")?;
        nonnegative(self.horizon, "horizon")?;
        nonnegative(self.stuck_after, "stuck_after")?;
        nonnegative(self.back_off_time, "back_off_time")?;
        nonnegative(self.position_error, "position_error")?;
        if self.position_error > MAX_POSITION_ERROR {
            return Err(format!(
                "`safety.position_error` must be {MAX_POSITION_ERROR} m or less, got {}",
                self.position_error
            ));
        }
        for (v, what) in [
            (self.reaction_time, "reaction_time"),
            (self.stale_after, "stale_after"),
            (self.horizon, "horizon"),
            (self.stuck_after, "stuck_after"),
            (self.back_off_time, "back_off_time"),
        ] {
            at_most_an_hour(v, what)?;
        }
        Ok(())
    }

    pub fn braking(&self) -> Braking {
        Braking {
            reaction_time: self.reaction_time,
            deceleration: self.max_deceleration,
        }
    }
}

/// Largest configured position error, m: beyond it a robot does not know
/// where it is well enough to move among others.
pub const MAX_POSITION_ERROR: f64 = 1.0;

/// Speed below which a robot that wants to move counts as stuck, m/s.
const STILL: f64 = 0.02;

/// Fastest back-off of a stuck robot, m/s.
const BACK_OFF_SPEED: f64 = 0.2;

/// Clearance kept between two robots' discs, m, until an [`Arena`] says
/// otherwise (its `margin`): the station's default.
pub const DEFAULT_MARGIN: f64 = 0.1;

/// The arena the robot obeys now.
#[derive(Debug, Clone, PartialEq)]
struct ArenaInForce {
    id: u32,
    enabled: bool,
    /// `None` for an empty arena (no fence; neighbours are still kept
    /// apart from, if the station sends them).
    fence: Option<Fence>,
    /// The arena's margin, also between robots.
    margin: f64,
}

/// A stuck robot backs off: it heads away from its neighbours for a
/// while.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BackOff {
    /// Where it heads, m/s, map frame.
    target: Vec2,
    until: Duration,
}

/// What [`SafetyLayer::filter`] returns: the outputs to write and why they
/// differ from the controller's.
#[derive(Debug, Clone, PartialEq)]
pub struct Filtered {
    pub outputs: Vec<f64>,
    pub intervention: Intervention,
}

/// The robot's safety layer: the arena and neighbours it was told of, and
/// what it did to the commands.
#[derive(Debug, Clone)]
pub struct SafetyLayer {
    config: SafetyConfig,
    arena: Option<ArenaInForce>,
    neighbours: Option<NeighbourSet>,
    backing_off: Option<BackOff>,
    /// The speed the robot was heading for when the right-hand rule took
    /// its way over, while it still does: a diff-drive whose mission turns
    /// it on the spot back towards its goal still circulates at that speed.
    circling: Option<f64>,
    /// The yaw rate per radian of heading error of the command in force,
    /// when it turns the robot towards a bearing (a mission,
    /// velocity-heading); `None` when its yaw rate is the operator's own
    /// ([`SafetyLayer::steered_by`]).
    bearing_gain: Option<f64>,
    /// Since when the robot wanted to move but did not, and whether it
    /// asked to go somewhere meanwhile (not only to turn on the spot).
    stuck_since: Option<(Duration, bool)>,
    /// Since when a diff-drive has been turning on the spot towards its
    /// swerve without moving in between (turns with breaks add up until it
    /// moves, backs off or stops wanting to).
    turning_since: Option<Duration>,
    /// This robot's id at the station (its Welcome's): it staggers when
    /// robots stuck together back off.
    id: Option<u16>,
    /// Registered with a router since the last arena: the next arena and
    /// neighbour list apply whatever their id and stamp.
    fresh_station: bool,
    /// How far the position estimate may be from the truth now, m
    /// ([`SafetyLayer::set_position_error`]): the robot's disc grows by it.
    position_error: f64,
    intervention: Intervention,
    counts: InterventionCounts,
}

impl SafetyLayer {
    pub fn new(config: SafetyConfig) -> SafetyLayer {
        SafetyLayer {
            config,
            arena: None,
            neighbours: None,
            backing_off: None,
            circling: None,
            bearing_gain: None,
            stuck_since: None,
            turning_since: None,
            id: None,
            fresh_station: false,
            position_error: 0.0,
            intervention: Intervention::None,
            counts: InterventionCounts::default(),
        }
    }

    pub fn config(&self) -> &SafetyConfig {
        &self.config
    }

    /// Takes an arena addressed to this robot. Returns the acknowledgement
    /// to send, or `None` when the arena is older than the one in force
    /// (ids compared as wrapping counters; a repeat of the current one is
    /// acknowledged again). An empty arena (the station has none, or
    /// cleared it) also forgets the neighbours held: the station sends
    /// none without an arena, so what is held would only grow stale and
    /// keep the robot crawling.
    pub fn apply_arena(&mut self, arena: &Arena) -> Option<ArenaAck> {
        if let Some(now) = &self.arena
            && !self.fresh_station
            && (arena.id.wrapping_sub(now.id) as i32) < 0
        {
            return None;
        }
        self.fresh_station = false;
        if arena.is_empty() {
            self.neighbours = None;
            self.backing_off = None;
            self.circling = None;
        }
        self.arena = Some(ArenaInForce {
            id: arena.id,
            enabled: arena.enabled,
            fence: (!arena.is_empty()).then(|| Fence::from_arena(arena)),
            margin: arena.margin,
        });
        Some(ArenaAck {
            robot: arena.robot.clone(),
            id: arena.id,
        })
    }

    /// Takes a neighbour list that arrived at `now`; `false` if it is older
    /// than the one held (by its station stamp) and so ignored.
    pub fn apply_neighbours(&mut self, n: &Neighbours, now: Duration) -> bool {
        if self
            .neighbours
            .as_ref()
            .is_some_and(|held| n.stamp_us < held.stamp_us)
            && !self.fresh_station
        {
            return false;
        }
        self.neighbours = Some(NeighbourSet::new(n, now));
        true
    }

    /// The robot registered (again) with a router, which may have
    /// restarted and numbers arenas afresh: the next arena applies whatever
    /// its id, and so does any neighbour list until then. Until it comes,
    /// the arena and neighbours held stay in force (the robot is no less
    /// safe for a station restart).
    pub fn registered(&mut self, id: u16) {
        self.fresh_station = true;
        self.id = Some(id);
    }

    /// How the command about to be filtered turns the robot: towards a
    /// bearing at `gain` rad/s per radian of heading error (a mission,
    /// velocity-heading: the controller's heading gain), or, `None`, as
    /// its sender says (twist, actuators, steering-throttle). The
    /// right-hand rule reads where a command heads from it
    /// ([`circulation::intent`]). Until told, `None`.
    pub fn steered_by(&mut self, gain: Option<f64>) {
        if gain != self.bearing_gain {
            self.circling = None;
        }
        self.bearing_gain = gain;
    }

    /// How far the position estimate the next [`SafetyLayer::filter`]
    /// judges may be from the true position, m (the agent's sensors say,
    /// each control period): every distance the layer keeps is kept from a
    /// disc grown by it. Until told, 0 (exact positions). A bound that is
    /// not a number holds the robot still, as no estimate does.
    pub fn set_position_error(&mut self, error: f64) {
        self.position_error = if error >= 0.0 { error } else { f64::NAN };
    }

    /// The disc the layer keeps inside the arena and apart from others:
    /// the robot's, grown by its position error, m.
    pub fn footprint(&self) -> f64 {
        self.config.radius + self.position_error
    }

    /// Whether the layer enforces anything.
    pub fn state(&self) -> SafetyState {
        match &self.arena {
            Some(a) if !a.enabled => SafetyState::Off,
            Some(ArenaInForce { fence: Some(_), .. }) => SafetyState::On,
            _ => SafetyState::NoArena,
        }
    }

    /// Whether the layer limits commands now: it is not switched off, and
    /// it has a fence or neighbours to keep apart from. Without an arena
    /// it has no fence, but separation works once neighbours come.
    pub fn enforcing(&self) -> bool {
        match &self.arena {
            Some(a) if !a.enabled => false,
            Some(ArenaInForce { fence: Some(_), .. }) => true,
            _ => self.neighbours.is_some(),
        }
    }

    /// Whether the neighbour information is older than `stale_after` at
    /// `now` (or there has been none).
    pub fn stale(&self, now: Duration) -> bool {
        self.neighbours
            .as_ref()
            .is_none_or(|n| n.age(now).as_secs_f64() > self.config.stale_after)
    }

    /// The outputs to write this control period instead of `outputs` (the
    /// controller's, for the command being obeyed), for a robot of
    /// `platform` at `pose` moving at `velocity` (m/s, map frame).
    pub fn filter(
        &mut self,
        platform: &dyn Platform,
        pose: &Pose,
        velocity: Vec2,
        outputs: &[f64],
        now: Duration,
    ) -> Filtered {
        if !self.enforcing() {
            self.forget_manoeuvre();
            return self.noted(outputs.to_vec(), Intervention::None);
        }
        let (fence, margin) = match &self.arena {
            Some(a) => (a.fence.as_ref(), a.margin),
            None => (None, DEFAULT_MARGIN),
        };
        let position = Vec2::new(pose.x, pose.y);
        let finite = position.is_finite() && pose.heading.is_finite() && velocity.is_finite();
        if !(finite && self.position_error.is_finite()) {
            return self.hold(outputs.len());
        }
        let (twist, desired) = mapping::commanded_motion(platform, pose.heading, outputs);
        let braking = self.config.braking();
        let fastest = platform
            .limits()
            .max_speed
            .max(desired.norm())
            .max(velocity.norm());
        let reach = braking.distance(fastest);
        let mut c = Constraints::new(position, braking);
        if let Some(fence) = fence {
            fence.constrain(&mut c, self.footprint(), reach);
        }
        if let Some(n) = &self.neighbours {
            n.constrain(&mut c, velocity, self.footprint(), margin, reach, now);
        }
        if self.stale(now) {
            c.caps
                .push((self.config.crawl_speed, Intervention::StaleNeighbours));
        }
        let mobility = Mobility {
            holonomic: platform.holonomic(),
            heading: pose.heading,
            yield_turn_rate: self.config.yield_turn_rate,
            yaw_rate: twist.wz,
            reaction_time: self.config.reaction_time,
            velocity,
        };
        let decision = self.decide(&c, desired, &twist, &mobility, margin, now);
        let out = if decision.intervention == Intervention::None {
            outputs.to_vec()
        } else {
            mapping::outputs_for(platform, pose.heading, &twist, &decision)
        };
        self.noted(out, decision.intervention)
    }

    /// Every output zero, for a robot the layer cannot judge (it has no
    /// position estimate, or a non-finite one) while it enforces
    /// something: without knowing where the robot is, standing still is
    /// the only command known to keep it inside and apart. Counted as a
    /// fence intervention when there is a fence, else as separation.
    pub fn hold(&mut self, motors: usize) -> Filtered {
        self.forget_manoeuvre();
        let fenced = matches!(self.arena, Some(ArenaInForce { fence: Some(_), .. }));
        let why = if fenced {
            Intervention::Fence
        } else {
            Intervention::Separation
        };
        self.noted(vec![0.0; motors], why)
    }

    /// Nothing was commanded this period (the robot's outputs are held at
    /// zero for another reason: failsafe, e-stop, idle): no intervention.
    pub fn idle(&mut self) {
        self.forget_manoeuvre();
        self.noted(Vec::new(), Intervention::None);
    }

    /// Records this period's intervention (counting each one that begins).
    fn noted(&mut self, outputs: Vec<f64>, intervention: Intervention) -> Filtered {
        if intervention != self.intervention {
            self.counts.count(intervention);
            self.intervention = intervention;
        }
        Filtered {
            outputs,
            intervention,
        }
    }

    /// The layer's state for telemetry.
    pub fn report(&self) -> SafetyReport {
        SafetyReport {
            state: self.state(),
            arena: self.arena.as_ref().map_or(0, |a| a.id),
            intervention: self.intervention,
            counts: self.counts,
            radius: self.config.radius,
            position_error: if self.position_error.is_finite() {
                self.position_error
            } else {
                MAX_POSITION_ERROR
            },
        }
    }
}

/// How far outwards of its cell's edge a robot pressed against it heads,
/// rad.
const EDGE_OUT: f64 = 0.15;

/// Zhou et al.'s rule for a robot at the edge of its buffered Voronoi
/// cell: a swerve `target` that the neighbour's constraint does not allow
/// at half its speed becomes the way along that edge to the right, a
/// little outwards (by [`EDGE_OUT`]), at the same speed. The swerve turns
/// right of the neighbour's disc; pressed at exactly the distance it must
/// keep, that tangent still leads into the cell's edge, and a diff-drive
/// aimed along it would not move at all.
fn along_cell_edge(c: &Constraints, target: Vec2) -> Vec2 {
    let Some(dir) = target.unit() else {
        return target;
    };
    let (speed, why) = c.limit(dir);
    if why != Intervention::Separation || speed >= 0.5 * target.norm() {
        return target;
    }
    c.binding_neighbour(dir).map_or(target, |normal| {
        normal.rotated(-(std::f64::consts::FRAC_PI_2 + EDGE_OUT)) * target.norm()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::{Neighbour, Point, Twist};

    fn arena(id: u32, enabled: bool) -> Arena {
        let p = |x, y| Point { x, y };
        Arena {
            robot: "robot_1".into(),
            id,
            enabled,
            boundary: vec![p(0.0, 0.0), p(4.0, 0.0), p(4.0, 3.0), p(0.0, 3.0)],
            keep_out: vec![],
            slow_zones: vec![],
            margin: 0.1,
        }
    }

    fn neighbours(stamp_us: u64, robots: Vec<Neighbour>) -> Neighbours {
        Neighbours {
            robot: "robot_1".into(),
            stamp_us,
            robots,
            obstacles: vec![],
        }
    }

    /// A layer registered as robot 1 with [`arena`] 1 in force.
    fn enforcing(config: SafetyConfig) -> SafetyLayer {
        let mut l = SafetyLayer::new(config);
        l.registered(1);
        l.apply_arena(&arena(1, true));
        l
    }

    /// The outputs that turn `platform` on the spot at `wz`.
    fn turning(platform: &dyn Platform, wz: f64) -> Vec<f64> {
        platform.mix(&Twist {
            wz,
            ..Twist::default()
        })
    }

    fn forward(platform: &dyn Platform, speed: f64) -> Vec<f64> {
        platform.mix(&Twist {
            vx: speed,
            ..Twist::default()
        })
    }

    #[test]
    fn arenas_apply_in_order_and_are_acknowledged() {
        let mut l = SafetyLayer::new(SafetyConfig::default());
        assert_eq!(l.state(), SafetyState::NoArena);
        assert_eq!(l.apply_arena(&arena(5, true)).unwrap().id, 5);
        assert_eq!(l.state(), SafetyState::On);
        assert_eq!(l.apply_arena(&arena(4, false)), None, "older: ignored");
        assert_eq!(l.state(), SafetyState::On);
        assert_eq!(l.apply_arena(&arena(5, true)).unwrap().id, 5, "a repeat");
        l.apply_arena(&arena(6, false)).unwrap();
        assert_eq!(l.state(), SafetyState::Off);
        assert!(l.report().alarm());
        let mut empty = arena(7, true);
        empty.boundary.clear();
        l.apply_arena(&empty).unwrap();
        assert_eq!(l.state(), SafetyState::NoArena);
        // Wrapping: 0 follows u32::MAX.
        let mut l = SafetyLayer::new(SafetyConfig::default());
        l.apply_arena(&arena(u32::MAX, true)).unwrap();
        assert!(l.apply_arena(&arena(0, true)).is_some());
    }

    #[test]
    fn after_registering_again_a_restarted_stations_arena_applies() {
        let mut l = SafetyLayer::new(SafetyConfig::default());
        l.apply_arena(&arena(40, true)).unwrap();
        l.apply_neighbours(&neighbours(5_000, vec![]), Duration::ZERO);
        assert_eq!(l.apply_arena(&arena(1, false)), None, "older, same station");
        l.registered(1);
        assert_eq!(l.state(), SafetyState::On, "the old arena holds meanwhile");
        assert!(l.apply_neighbours(&neighbours(10, vec![]), Duration::ZERO));
        assert_eq!(l.apply_arena(&arena(1, false)).unwrap().id, 1);
        assert_eq!(l.state(), SafetyState::Off);
        assert_eq!(l.apply_arena(&arena(0, true)), None, "ordered again");
    }

    #[test]
    fn older_neighbour_lists_are_ignored() {
        let mut l = SafetyLayer::new(SafetyConfig::default());
        assert!(l.stale(Duration::ZERO), "none yet");
        assert!(l.apply_neighbours(&neighbours(10, vec![]), Duration::ZERO));
        assert!(!l.apply_neighbours(&neighbours(9, vec![]), Duration::ZERO));
        assert!(!l.stale(Duration::from_millis(300)));
        assert!(l.stale(Duration::from_millis(301)));
    }

    #[test]
    fn off_or_without_an_arena_the_outputs_pass_untouched() {
        let dd = PlatformSpec::diff_drive().build();
        let out = forward(dd.as_ref(), 0.5);
        let at_wall = Pose {
            x: 3.8,
            y: 1.5,
            ..Pose::default()
        };
        let mut l = SafetyLayer::new(SafetyConfig::default());
        let f = l.filter(dd.as_ref(), &at_wall, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(
            (f.outputs, f.intervention),
            (out.clone(), Intervention::None)
        );
        l.apply_arena(&arena(1, false));
        let f = l.filter(dd.as_ref(), &at_wall, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(f.outputs, out);
        l.apply_arena(&arena(2, true));
        let f = l.filter(dd.as_ref(), &at_wall, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(f.intervention, Intervention::Returning);
        assert!(f.outputs.iter().all(|u| u.abs() < 1e-12), "{:?}", f.outputs);
    }

    #[test]
    fn stale_neighbours_slow_the_robot_to_a_crawl_and_count_once() {
        let kiwi = PlatformSpec::kiwi().build();
        let mut l = SafetyLayer::new(SafetyConfig::default());
        l.apply_arena(&arena(1, true));
        let mid = Pose {
            x: 2.0,
            y: 1.5,
            ..Pose::default()
        };
        let out = forward(kiwi.as_ref(), 0.3);
        l.apply_neighbours(&neighbours(1, vec![]), Duration::ZERO);
        let f = l.filter(
            kiwi.as_ref(),
            &mid,
            Vec2::ZERO,
            &out,
            Duration::from_millis(100),
        );
        assert_eq!(f.intervention, Intervention::None);
        for ms in [400, 420, 440] {
            let f = l.filter(
                kiwi.as_ref(),
                &mid,
                Vec2::ZERO,
                &out,
                Duration::from_millis(ms),
            );
            assert_eq!(f.intervention, Intervention::StaleNeighbours);
            let speed = kiwi.motion(&f.outputs).vx;
            assert!((speed - 0.05).abs() < 1e-9, "{speed}");
        }
        let r = l.report();
        assert_eq!(r.counts.stale_neighbours, 1);
        assert_eq!(r.intervention, Intervention::StaleNeighbours);
        assert_eq!(r.state, SafetyState::On);
    }

    fn neighbour_at(x: f64, y: f64) -> Neighbour {
        Neighbour {
            id: 2,
            x,
            y,
            z: 0.0,
            vx: 0.0,
            vy: 0.0,
            vz: 0.0,
            radius: 0.15,
            age_ms: 0,
            cooperative: true,
        }
    }

    #[test]
    fn without_an_arena_neighbours_are_still_kept_apart_from() {
        let kiwi = PlatformSpec::kiwi().build();
        let out = forward(kiwi.as_ref(), 0.5);
        let me = Pose::default();
        let mut l = SafetyLayer::new(SafetyConfig::default());
        assert!(!l.enforcing(), "nothing known: nothing enforced");
        let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(f.outputs, out);
        // A neighbour 0.45 m ahead, 0.4 m needed: 2.5 cm to advance.
        l.apply_neighbours(
            &neighbours(1, vec![neighbour_at(0.45, 0.0)]),
            Duration::ZERO,
        );
        assert!(l.enforcing());
        assert_eq!(l.state(), SafetyState::NoArena, "the layer says so");
        let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(f.intervention, Intervention::Separation);
        let towards = kiwi.motion(&f.outputs).vx;
        assert!(towards < 0.15, "{towards}: braking within 2.5 cm");
        // Stale: a crawl, as with an arena.
        let later = Duration::from_millis(400);
        let away = forward(kiwi.as_ref(), -0.5);
        let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &away, later);
        assert_eq!(f.intervention, Intervention::StaleNeighbours);
        // An empty arena (the station has none): the neighbours held are
        // forgotten, so they cannot keep the robot crawling.
        let mut empty = arena(3, true);
        empty.boundary.clear();
        l.apply_arena(&empty).unwrap();
        assert!(!l.enforcing());
        let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &away, later);
        assert_eq!((f.outputs, f.intervention), (away, Intervention::None));
    }

    #[test]
    fn a_robot_stuck_against_a_neighbour_backs_off_from_it() {
        // A kiwi told to drive into a neighbour pressed against it: the
        // look-ahead turns it aside, but it does not move (its velocity
        // stays zero here). After `stuck_after` (plus 0.3 s for id 1) it
        // backs off, away from the neighbour, and the command has its way
        // again after `back_off_time`.
        let kiwi = PlatformSpec::kiwi().build();
        let me = Pose {
            x: 2.0,
            y: 1.5,
            ..Pose::default()
        };
        let into = forward(kiwi.as_ref(), 0.3);
        let run = |config: SafetyConfig| {
            let mut l = enforcing(config);
            let mut motions = Vec::new();
            for k in 0..150u64 {
                let now = Duration::from_millis(20 * k);
                l.apply_neighbours(&neighbours(k + 1, vec![neighbour_at(2.4, 1.5)]), now);
                let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &into, now);
                let t = kiwi.motion(&f.outputs);
                motions.push((now.as_secs_f64(), Vec2::new(t.vx, t.vy)));
            }
            motions
        };
        let motions = run(SafetyConfig::default());
        let backing = |m: &&(f64, Vec2)| m.1.x < -0.1;
        let first = motions.iter().find(backing).expect("it backs off");
        assert!(
            (1.3..1.4).contains(&first.0),
            "after 1.3 s still: {first:?}"
        );
        assert!(first.1.y.abs() < 1e-6, "straight away: {first:?}");
        let after = motions.iter().filter(|m| m.0 > first.0 + 1.05);
        assert!(
            after.clone().count() > 0 && after.clone().all(|m| !backing(&m)),
            "then the command again"
        );
        let never = run(SafetyConfig {
            stuck_after: 0.0,
            ..SafetyConfig::default()
        });
        assert!(!never.iter().any(|m| backing(&m)), "0: never");
        // Told only to turn on the spot beside it: never moved.
        let mut l = enforcing(SafetyConfig::default());
        let turn = turning(kiwi.as_ref(), 1.0);
        for k in 0..150u64 {
            let now = Duration::from_millis(20 * k);
            l.apply_neighbours(&neighbours(k + 1, vec![neighbour_at(2.4, 1.5)]), now);
            let f = l.filter(kiwi.as_ref(), &me, Vec2::ZERO, &turn, now);
            let t = kiwi.motion(&f.outputs);
            assert!(
                t.vx.hypot(t.vy) < 1e-9,
                "a turn on the spot is not stuck: {t:?}"
            );
        }
    }

    #[test]
    fn a_turn_on_the_spot_never_moves_a_robot_the_layer_steered_before() {
        // A diff-drive driving at a neighbour standing ahead, swerving round
        // it; then told only to turn on the spot: after an e-stop (idle), or
        // at once when the turn is the operator's own (a twist).
        let dd = PlatformSpec::diff_drive().build();
        let me = Pose {
            x: 2.0,
            y: 1.5,
            ..Pose::default()
        };
        let ahead = forward(dd.as_ref(), 0.4);
        let spin = turning(dd.as_ref(), 0.5);
        let moved = |l: &mut SafetyLayer, outputs: &[f64], k: u64| {
            let now = Duration::from_millis(20 * k);
            l.apply_neighbours(&neighbours(k + 1, vec![neighbour_at(2.8, 1.5)]), now);
            let f = l.filter(dd.as_ref(), &me, Vec2::new(0.4, 0.0), outputs, now);
            let t = dd.motion(&f.outputs);
            (t.vx.hypot(t.vy), f.intervention)
        };
        for (gain, stop) in [(Some(3.0), true), (None, false)] {
            let mut l = enforcing(SafetyConfig::default());
            l.steered_by(gain);
            let swerved =
                (0..50u64).any(|k| moved(&mut l, &ahead, k).1 == Intervention::Separation);
            assert!(swerved, "{gain:?}: the rule took over");
            if stop {
                l.idle();
            }
            for k in 50..100u64 {
                let (speed, _) = moved(&mut l, &spin, k);
                assert!(
                    speed < 1e-9,
                    "{gain:?}: turned on the spot, moved at {speed}"
                );
            }
        }
    }

    /// A diff-drive's motion integrated ideally, 20 ms periods: from
    /// (2, 1.5) facing east and at rest, told `command` each period among
    /// neighbours standing at `around`; `each` sees the layer, the time and
    /// the pose and forward speed each period ends with.
    fn drive_ideally(
        l: &mut SafetyLayer,
        around: &[(f64, f64)],
        command: &[f64],
        steps: u64,
        mut each: impl FnMut(&SafetyLayer, Duration, &Pose, f64),
    ) {
        let dd = PlatformSpec::diff_drive().build();
        let mut me = Pose {
            x: 2.0,
            y: 1.5,
            ..Pose::default()
        };
        let mut speed = 0.0;
        for k in 0..steps {
            let now = Duration::from_millis(20 * k);
            let robots = around.iter().map(|&(x, y)| neighbour_at(x, y)).collect();
            l.apply_neighbours(&neighbours(k + 1, robots), now);
            let velocity = Vec2::from_angle(me.heading) * speed;
            let f = l.filter(dd.as_ref(), &me, velocity, command, now);
            let t = dd.motion(&f.outputs);
            me.heading += t.wz * 0.02;
            speed = t.vx;
            me.x += speed * me.heading.cos() * 0.02;
            me.y += speed * me.heading.sin() * 0.02;
            each(l, now, &me, speed);
        }
    }

    #[test]
    fn a_diff_drive_turning_on_the_spot_towards_its_swerve_is_not_stuck() {
        // On a mission (its command heads along its heading) at
        // neighbours standing ahead and to its right: the swerve is far to
        // the right, and at 1 rad/s the turn takes longer than
        // `stuck_after`; the robot turns, then drives, and never backs off
        // meanwhile.
        let dd = PlatformSpec::diff_drive().build();
        let mut l = enforcing(SafetyConfig::default());
        l.steered_by(Some(3.0));
        let ahead = forward(dd.as_ref(), 0.3);
        let around = [(2.5, 1.5), (2.35, 1.1), (1.95, 1.0)];
        let (mut drove, mut heading) = (None, 0.0);
        drive_ideally(&mut l, &around, &ahead, 150, |l, now, me, speed| {
            assert!(l.backing_off.is_none(), "backed off at {now:?}");
            if speed > 0.05 && drove.is_none() {
                drove = Some(now);
            }
            heading = me.heading;
        });
        let drove = drove.expect("it drives once turned");
        assert!(
            drove > Duration::from_millis(1300),
            "the turn took a while: {drove:?}"
        );
        assert!(heading < -0.6, "it turned right: {heading}");
    }

    /// When a diff-drive standing still at (2, 1.5), facing east, among
    /// `around`, told `command(k)` in period `k` (20 ms), starts backing
    /// off, over `steps` periods. Its pose never changes: its wheels slip.
    fn back_offs_while_slipping(
        around: &[(f64, f64)],
        command: impl Fn(u64) -> Vec<f64>,
        steps: u64,
    ) -> Vec<Duration> {
        let dd = PlatformSpec::diff_drive().build();
        let mut l = enforcing(SafetyConfig::default());
        l.steered_by(Some(3.0));
        let me = Pose {
            x: 2.0,
            y: 1.5,
            ..Pose::default()
        };
        let mut starts = Vec::new();
        let mut was_backing_off = false;
        for k in 0..steps {
            let now = Duration::from_millis(20 * k);
            let robots = around.iter().map(|&(x, y)| neighbour_at(x, y)).collect();
            l.apply_neighbours(&neighbours(k + 1, robots), now);
            l.filter(dd.as_ref(), &me, Vec2::ZERO, &command(k), now);
            let backing_off = l.backing_off.is_some_and(|b| now < b.until);
            if backing_off && !was_backing_off {
                starts.push(now);
            }
            was_backing_off = backing_off;
        }
        starts
    }

    #[test]
    fn a_diff_drive_that_turns_on_the_spot_without_getting_round_backs_off() {
        // As in the test above, but its wheels slip: it is told to turn
        // and never does. Turning is an excuse for not moving only as long
        // as half a turn takes (3.1 s at 1 rad/s); then it is stuck like
        // any robot, and backs off after `stuck_after` (plus its stagger,
        // 0.3 s for id 1). After backing off (1 s) it may turn as long
        // again before the next.
        let dd = PlatformSpec::diff_drive().build();
        let ahead = forward(dd.as_ref(), 0.3);
        let around = [(2.5, 1.5), (2.35, 1.1), (1.95, 1.0)];
        let starts = back_offs_while_slipping(&around, |_| ahead.clone(), 600);
        let (half_turn, stuck_after, back_off) = (std::f64::consts::PI, 1.0 + 0.3, 1.0);
        let first = starts.first().expect("it backs off").as_secs_f64();
        assert!(
            first > half_turn && first <= half_turn + stuck_after + 0.1,
            "backed off at {starts:?}"
        );
        let second = starts.get(1).expect("and again").as_secs_f64();
        assert!(
            second - first > back_off + half_turn,
            "a fresh half turn between back-offs: {starts:?}"
        );
    }

    #[test]
    fn turns_with_breaks_in_between_add_up_until_the_robot_moves() {
        // Reversing at neighbours behind it and to the right of its travel,
        // by a controller that stops driving to turn whenever the robot is
        // off its heading: driven backwards one period, turned on the spot
        // the next, and its wheels slip. Each reversing period turns it
        // towards the swerve; the turns add up, so it backs off.
        let dd = PlatformSpec::diff_drive().build();
        let back = forward(dd.as_ref(), -0.3);
        let turn = turning(dd.as_ref(), -0.5);
        let around = [(1.5, 1.5), (1.65, 1.9), (2.05, 2.0)];
        let command = |k: u64| {
            if k.is_multiple_of(2) {
                back.clone()
            } else {
                turn.clone()
            }
        };
        let starts = back_offs_while_slipping(&around, command, 400);
        let first = starts.first().expect("it backs off").as_secs_f64();
        assert!(first <= std::f64::consts::PI + 1.3 + 0.1, "{starts:?}");
    }

    #[test]
    fn a_diff_drive_reversing_towards_a_neighbour_swerves_to_the_right_of_its_travel() {
        // Driven backwards by a gamepad (a twist: the yaw rate is the
        // sender's) at a neighbour standing behind it, westwards: its rear
        // turns right (north) and it passes the neighbour backwards, never
        // within the distance to keep, never driven forwards.
        let dd = PlatformSpec::diff_drive().build();
        let mut l = enforcing(SafetyConfig::default());
        l.steered_by(None);
        let back = forward(dd.as_ref(), -0.3);
        let behind = (1.3, 1.5);
        let (mut nearest, mut fastest_forwards) = (f64::INFINITY, 0.0f64);
        let mut last = Pose::default();
        drive_ideally(&mut l, &[behind], &back, 250, |_, _, me, speed| {
            nearest = nearest.min((me.x - behind.0).hypot(me.y - behind.1));
            fastest_forwards = fastest_forwards.max(speed);
            last = *me;
        });
        // Two radii apart at least (0.15 m each).
        assert!(nearest >= 0.3, "came within {nearest:.3} m");
        assert!(
            fastest_forwards <= 0.0,
            "driven forwards at {fastest_forwards}"
        );
        assert!(last.heading < -0.3, "its rear turned right: {last:?}");
        assert!(
            last.x < behind.0 - 0.2 && last.y > behind.1 + 0.3,
            "passed the neighbour on its right: {last:?}"
        );
    }

    #[test]
    fn pressed_against_a_neighbour_a_swerve_follows_the_cell_edge_to_the_right() {
        use crate::safety::constraints::{Plane, Wall};
        use crate::safety::geometry::Segment;
        // The cell's edge 1 mm ahead (a neighbour straight ahead, at the
        // distance to keep); the swerve, right of its disc, leads a little
        // into the edge.
        let mut c = Constraints::new(Vec2::ZERO, SafetyConfig::default().braking());
        c.planes.push(Plane {
            normal: Vec2::new(1.0, 0.0),
            offset: 0.001,
            reason: Intervention::Separation,
        });
        let swerve = Vec2::new(0.3, 0.0).rotated(-1.45);
        assert!(c.limit(swerve.unit().unwrap()).0 < 0.15, "blocked");
        let edge = along_cell_edge(&c, swerve);
        assert!(
            edge.x < 0.0 && edge.y < -0.25,
            "right, a little out: {edge:?}"
        );
        assert!((edge.norm() - 0.3).abs() < 1e-9);
        assert!(
            c.limit(edge.unit().unwrap()).0.is_infinite(),
            "free along it"
        );
        // A swerve the neighbour allows is kept.
        let free = Vec2::new(0.0, -0.3);
        assert_eq!(along_cell_edge(&c, free), free);
        // So is one a wall, not a neighbour, blocks.
        let mut walled = Constraints::new(Vec2::ZERO, SafetyConfig::default().braking());
        walled.walls.push(Wall {
            segment: Segment::new(Vec2::new(0.05, -5.0), Vec2::new(0.05, 5.0)),
            radius: 0.0,
            reason: Intervention::Fence,
        });
        assert_eq!(along_cell_edge(&walled, swerve), swerve);
    }

    #[test]
    fn a_robot_without_a_position_is_held_while_the_layer_enforces() {
        let mut l = SafetyLayer::new(SafetyConfig::default());
        l.apply_arena(&arena(1, true));
        let f = l.hold(3);
        assert_eq!(f.outputs, vec![0.0; 3]);
        assert_eq!(f.intervention, Intervention::Fence);
        let nan = Pose {
            x: f64::NAN,
            ..Pose::default()
        };
        let kiwi = PlatformSpec::kiwi().build();
        let out = forward(kiwi.as_ref(), 0.3);
        let f = l.filter(kiwi.as_ref(), &nan, Vec2::ZERO, &out, Duration::ZERO);
        assert_eq!(f.outputs, vec![0.0; 3]);
        l.idle();
        assert_eq!(l.report().intervention, Intervention::None);
        assert_eq!(l.report().counts.fence, 1, "one run of holds, one count");
    }

    #[test]
    fn config_values_are_checked() {
        assert!(SafetyConfig::default().validate().is_ok());
        let bad = SafetyConfig {
            max_deceleration: 0.0,
            ..SafetyConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("max_deceleration"));
        let bad = SafetyConfig {
            radius: f64::NAN,
            ..SafetyConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("radius"));
        // A finite time no clock holds (it would end the agent when a
        // robot backs off) is refused with the rest.
        let bad = SafetyConfig {
            back_off_time: 1e20,
            ..SafetyConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("back_off_time"));
        let bad = SafetyConfig {
            stale_after: 3600.5,
            ..SafetyConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("stale_after"));
        // A layer that may not turn a diff-drive could never steer it round
        // anything, nor back it off.
        let bad = SafetyConfig {
            yield_turn_rate: 0.0,
            ..SafetyConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("yield_turn_rate"));
    }
}
