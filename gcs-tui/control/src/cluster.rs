//! Cluster-space control after Kitts & Mas, "Cluster space specification and
//! control of mobile multirobot systems" (IEEE/ASME T-Mech, 2009).
//!
//! A cluster is described by its pose (centroid `x, y`, orientation `heading`)
//! and its shape (a [`Formation`]: slot offsets in the cluster frame, times a
//! `scale`). The operator drives the *cluster* variables, either with a
//! cluster-frame velocity `(vx, vy, wz, scale_rate)` or with a list of cluster
//! waypoints the cluster pose visits in turn on a trapezoidal speed profile.
//! The controller integrates the desired cluster pose, maps it through the
//! inverse cluster kinematics to each member's slot position and slot velocity
//! (`v_slot = v_c + wz x r + scale_rate R o`, with `r = scale R(heading) o`),
//! and closes the loop per member with the platform's tracking law
//! ([`super::track`]). With equal gains on every cluster variable this
//! member-space feedback equals cluster-space feedback through the Jacobian
//! (`J^-1 K J = K` for `K = kI`), so it is the same controller, without the
//! Jacobian's singularities.
//!
//! Formation feedback (Lawton, Beard & Young, "A decentralized approach to
//! formation maneuvers", IEEE T-RA 2003): the desired cluster pose slows down,
//! and stops, while the worst member lags its slot by more than
//! [`ClusterConfig::lag_free`], so a member that has to turn in place (a
//! differential drive at a corner) is waited for instead of left behind.
//!
//! Slots are formed over the members present in the step input (routed to
//! the cluster's channel) and re-assigned with
//! [`super::assign_slots`] whenever that set or the formation changes, so
//! members take the nearest free slot and do not cross needlessly. A member
//! whose telemetry goes stale keeps its slot (uncommanded, its failsafe stops
//! it) so a brief radio drop-out does not reshuffle the formation. Feed-forward
//! slot speeds are limited to a margin of the slowest member's top speed,
//! leaving the rest for feedback.

use std::collections::{BTreeMap, BTreeSet};

use mech_proto::{
    ClusterPose, ClusterVelocity, FleetCommand, Formation, FormationKind, Offset, RobotCommand,
};

use super::assignment::assign_slots;
use super::formation::{FormationError, slot_offsets};
use super::geometry::{norm, rotate, wrap_angle};
use super::tracking::{Reference, TrackingGains, track};
use super::{ControlEvent, Kinematics, MemberState, StepClock, note_staleness};

/// One cluster waypoint: centroid position (m) and, optionally, the cluster
/// heading to reach there (rad); without one the heading is kept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterWaypoint {
    pub x: f64,
    pub y: f64,
    pub heading: Option<f64>,
}

/// What the cluster pose is doing.
#[derive(Debug, Clone, PartialEq)]
pub enum ClusterMotion {
    /// Hold the current desired pose.
    Hold,
    /// Move at a velocity given in the cluster frame, until told otherwise.
    Velocity(ClusterVelocity),
    /// Visit cluster waypoints in order; `next` is the one being approached
    /// (equals the list length when finished).
    Waypoints {
        list: Vec<ClusterWaypoint>,
        next: usize,
        looped: bool,
    },
}

/// Tuning of a cluster controller.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterConfig {
    pub gains: TrackingGains,
    /// Telemetry older than this (s) makes a member lost: it is not commanded.
    pub telemetry_timeout: f64,
    /// Cruise speed of the cluster centroid between waypoints, m/s.
    pub cruise_speed: f64,
    /// Acceleration of the centroid along a waypoint leg, m/s^2.
    pub max_accel: f64,
    /// Top cluster rotation rate, rad/s.
    pub max_yaw_rate: f64,
    /// Angular acceleration of the cluster heading, rad/s^2.
    pub max_yaw_accel: f64,
    /// Measured centroid within this distance (m) of a reached waypoint lets
    /// the cluster go on to the next one.
    pub arrival_radius: f64,
    /// Fraction of the slowest member's top speed that slot feed-forward may
    /// use; the rest is kept for feedback.
    pub speed_margin: f64,
    /// Slot error (m) up to which the cluster moves at full speed.
    pub lag_free: f64,
    /// Slot error (m) at which the cluster stops to wait for the member.
    pub lag_stop: f64,
    /// Bounds of the formation scale.
    pub min_scale: f64,
    pub max_scale: f64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        ClusterConfig {
            gains: TrackingGains::default(),
            telemetry_timeout: 0.5,
            cruise_speed: 0.25,
            max_accel: 0.25,
            max_yaw_rate: 0.6,
            max_yaw_accel: 0.8,
            arrival_radius: 0.1,
            speed_margin: 0.7,
            lag_free: 0.05,
            lag_stop: 0.15,
            min_scale: 0.2,
            max_scale: 5.0,
        }
    }
}

/// Where one member should be now, and how far it is from there.
#[derive(Debug, Clone, PartialEq)]
pub struct SlotTarget {
    pub robot: String,
    /// Index of the slot in the formation.
    pub slot: usize,
    /// Slot position in the world, m, and heading, rad.
    pub x: f64,
    pub y: f64,
    pub heading: f64,
    /// Distance from the member's reported position to the slot, m.
    pub error: f64,
}

/// Snapshot of a cluster for displays and logs.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterStatus {
    pub cluster: String,
    pub formation: Formation,
    /// The cluster pose being tracked (reference); `None` before the first
    /// member reports.
    pub desired: Option<ClusterPose>,
    /// Cluster pose measured from member positions: centroid, best-fit
    /// orientation and scale of the members relative to their slots.
    pub measured: Option<ClusterPose>,
    /// Desired cluster velocity, cluster frame.
    pub velocity: ClusterVelocity,
    pub slots: Vec<SlotTarget>,
    /// Members whose telemetry is stale: not commanded.
    pub lost: Vec<String>,
    /// Members not in the step input (routed elsewhere, or not registered).
    pub absent: Vec<String>,
    /// `(next, total)` while following cluster waypoints.
    pub waypoint: Option<(usize, usize)>,
}

impl ClusterStatus {
    /// Largest slot tracking error among commanded members, m.
    pub fn max_error(&self) -> f64 {
        self.slots.iter().map(|s| s.error).fold(0.0, f64::max)
    }
}

/// Result of one controller step.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterOutput {
    /// One command per commanded member; lost and absent members get none.
    pub commands: Vec<RobotCommand>,
    pub status: ClusterStatus,
    pub events: Vec<ControlEvent>,
}

impl ClusterOutput {
    /// The commands as one message for the cluster's channel.
    pub fn fleet_command(&self) -> FleetCommand {
        FleetCommand {
            parts: self.commands.clone(),
        }
    }
}

/// A cluster-space controller for one cluster; see the module docs.
#[derive(Debug, Clone)]
pub struct ClusterController {
    name: String,
    members: Vec<String>,
    formation: Formation,
    config: ClusterConfig,
    motion: ClusterMotion,
    desired: Option<ClusterPose>,
    /// Current centroid speed along a waypoint leg (for the acceleration ramp).
    path_speed: f64,
    /// Current heading rate toward a waypoint heading.
    turn_rate: f64,
    /// Desired velocity applied in the last step (cluster frame).
    velocity: ClusterVelocity,
    /// Members commanded in the last step, sorted.
    active: Vec<String>,
    slots: Vec<Offset>,
    assignment: BTreeMap<String, usize>,
    reassign: bool,
    lost: BTreeSet<String>,
    clock: StepClock,
    /// The desired pose has been set or moved by the operator; from then on
    /// membership changes no longer re-centre it.
    anchored: bool,
}

/// The members of one step, as its input has them.
struct Roster<'a> {
    /// Members in the input, sorted by name: slots are laid out for them.
    present: Vec<&'a MemberState>,
    /// Present members with fresh telemetry, sorted by name: the commanded ones.
    fresh: Vec<&'a MemberState>,
    /// Members not in the input, in member order.
    absent: Vec<String>,
}

const ZERO_VELOCITY: ClusterVelocity = ClusterVelocity {
    vx: 0.0,
    vy: 0.0,
    wz: 0.0,
    scale_rate: 0.0,
};

impl ClusterController {
    /// A cluster holding still until given a velocity or waypoints. Its pose
    /// starts at the members' centroid and mean heading when they first report.
    pub fn new(
        name: impl Into<String>,
        members: Vec<String>,
        formation: Formation,
        config: ClusterConfig,
    ) -> Result<ClusterController, FormationError> {
        slot_offsets(&formation, members.len())?;
        Ok(ClusterController {
            name: name.into(),
            members,
            formation,
            config,
            motion: ClusterMotion::Hold,
            desired: None,
            path_speed: 0.0,
            turn_rate: 0.0,
            velocity: ZERO_VELOCITY,
            active: Vec::new(),
            slots: Vec::new(),
            assignment: BTreeMap::new(),
            reassign: true,
            lost: BTreeSet::new(),
            clock: StepClock::default(),
            anchored: false,
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn members(&self) -> &[String] {
        &self.members
    }

    pub fn formation(&self) -> &Formation {
        &self.formation
    }

    pub fn motion(&self) -> &ClusterMotion {
        &self.motion
    }

    pub fn config(&self) -> &ClusterConfig {
        &self.config
    }

    /// Changes the shape, effective at the next step: slots are re-assigned to
    /// minimise the total distance members travel.
    pub fn set_formation(&mut self, formation: Formation) -> Result<(), FormationError> {
        slot_offsets(&formation, self.members.len())?;
        self.formation = formation;
        self.reassign = true;
        Ok(())
    }

    /// Replaces the member list; a member no longer listed gets no command
    /// from the next step on.
    pub fn set_members(&mut self, members: Vec<String>) -> Result<(), FormationError> {
        slot_offsets(&self.formation, members.len())?;
        self.lost.retain(|r| members.contains(r));
        self.members = members;
        self.reassign = true;
        Ok(())
    }

    /// Drops a member from the cluster.
    pub fn remove_member(&mut self, robot: &str) {
        self.members.retain(|m| m != robot);
        self.lost.remove(robot);
        self.reassign = true;
    }

    /// Drive the cluster at a cluster-frame velocity (gamepad, command line).
    pub fn set_velocity(&mut self, velocity: ClusterVelocity) {
        self.motion = ClusterMotion::Velocity(velocity);
        self.anchored = true;
    }

    /// Visit `list` in order, starting with the first.
    pub fn set_waypoints(&mut self, list: Vec<ClusterWaypoint>, looped: bool) {
        self.motion = ClusterMotion::Waypoints {
            list,
            next: 0,
            looped,
        };
        self.anchored = true;
        self.path_speed = 0.0;
        self.turn_rate = 0.0;
    }

    /// Stop the cluster where its desired pose is now.
    pub fn hold(&mut self) {
        self.motion = ClusterMotion::Hold;
        self.path_speed = 0.0;
        self.turn_rate = 0.0;
    }

    /// One control step at time `now` (s) on the members' latest states.
    /// States of robots that are not members are ignored; members without a
    /// state are absent and get no command.
    pub fn step(&mut self, now: f64, states: &[MemberState]) -> ClusterOutput {
        let dt = self.clock.interval(now);
        let mut events = Vec::new();
        let roster = self.classify(now, states, &mut events);
        self.watch_membership(&roster.present);
        self.place_until_anchored(&roster.fresh);
        let (commands, slots, measured) = match self.update_reference(dt, &roster) {
            Some(desired) => {
                let (commands, slots) = self.slot_commands(&desired, &roster.fresh);
                let measured = self.measure(&desired, &roster.fresh);
                self.check_arrival(measured.as_ref(), &mut events);
                (commands, slots, measured)
            }
            None => (Vec::new(), Vec::new(), None),
        };
        ClusterOutput {
            commands,
            status: self.status(measured, slots, roster.absent),
            events,
        }
    }

    /// Sorts the members into present, fresh and absent ones, and reports the
    /// members whose telemetry went stale or came back. An absent member is
    /// not lost: it is simply not this controller's to command.
    fn classify<'a>(
        &mut self,
        now: f64,
        states: &'a [MemberState],
        events: &mut Vec<ControlEvent>,
    ) -> Roster<'a> {
        let mut roster = Roster {
            present: Vec::new(),
            fresh: Vec::new(),
            absent: Vec::new(),
        };
        for robot in &self.members {
            let Some(s) = states.iter().find(|s| &s.robot == robot) else {
                roster.absent.push(robot.clone());
                self.lost.remove(robot);
                continue;
            };
            roster.present.push(s);
            let stale = s.is_stale(now, self.config.telemetry_timeout);
            note_staleness(&mut self.lost, robot, stale, events);
            if !stale {
                roster.fresh.push(s);
            }
        }
        roster.fresh.sort_by(|a, b| a.robot.cmp(&b.robot));
        roster.present.sort_by(|a, b| a.robot.cmp(&b.robot));
        roster
    }

    /// Asks for a new slot assignment when the set of present members changed.
    fn watch_membership(&mut self, present: &[&MemberState]) {
        let active: Vec<String> = present.iter().map(|s| s.robot.clone()).collect();
        if active != self.active {
            self.active = active;
            self.reassign = true;
        }
    }

    /// Until the cluster is first told to move (or placed), its pose is
    /// wherever its members are: members joining one by one (routed in turn)
    /// re-centre it instead of gathering round the first to report.
    fn place_until_anchored(&mut self, fresh: &[&MemberState]) {
        if (self.desired.is_none() || (!self.anchored && self.reassign)) && !fresh.is_empty() {
            self.desired = Some(initial_pose(fresh));
        }
    }

    /// Moves the desired cluster pose on by `dt`, re-assigning slots first if
    /// the members or the formation changed; `None` while the pose is not
    /// known yet (no member has reported).
    fn update_reference(&mut self, dt: f64, roster: &Roster) -> Option<ClusterPose> {
        let mut desired = self.desired?;
        if self.reassign && !roster.present.is_empty() {
            self.assign(&desired, &roster.present);
        }
        let max_offset = self
            .slots
            .iter()
            .map(|o| norm(o.x, o.y))
            .fold(0.0, f64::max);
        let speed_limit = self.slot_speed_limit(&desired, &roster.fresh);
        self.velocity = self.advance(&mut desired, dt, max_offset, speed_limit);
        self.desired = Some(desired);
        Some(desired)
    }

    /// How fast slots may move by feed-forward: a margin of the slowest fresh
    /// member's top speed (the cruise speed without one), throttled down to
    /// nothing as the worst member falls from `lag_free` to `lag_stop` behind
    /// its slot (formation feedback, see the module docs).
    fn slot_speed_limit(&self, desired: &ClusterPose, fresh: &[&MemberState]) -> f64 {
        let member_speed = fresh
            .iter()
            .map(|s| s.platform.max_speed)
            .fold(f64::INFINITY, f64::min);
        let speed_limit = if member_speed.is_finite() {
            member_speed * self.config.speed_margin
        } else {
            self.config.cruise_speed
        };
        let lag = self.worst_lag(desired, fresh);
        let span = (self.config.lag_stop - self.config.lag_free).max(1e-6);
        let throttle = ((self.config.lag_stop - lag) / span).clamp(0.0, 1.0);
        speed_limit * throttle
    }

    /// Each fresh member's command toward its slot at the desired pose and
    /// velocity, with the slot target it tracks.
    fn slot_commands(
        &self,
        desired: &ClusterPose,
        fresh: &[&MemberState],
    ) -> (Vec<RobotCommand>, Vec<SlotTarget>) {
        let mut commands = Vec::new();
        let mut slots = Vec::new();
        for s in fresh {
            let Some((slot, o)) = self.assigned_slot(&s.robot) else {
                continue;
            };
            let reference = slot_reference(desired, &self.velocity, o);
            commands.push(RobotCommand {
                robot: s.robot.clone(),
                command: track(s, &reference, &self.config.gains),
            });
            slots.push(SlotTarget {
                robot: s.robot.clone(),
                slot,
                x: reference.x,
                y: reference.y,
                heading: match s.platform.kinematics {
                    Kinematics::Holonomic => desired.heading,
                    Kinematics::NonHolonomic => s.pose.heading,
                },
                error: reference.position_error(s),
            });
        }
        (commands, slots)
    }

    fn status(
        &self,
        measured: Option<ClusterPose>,
        slots: Vec<SlotTarget>,
        absent: Vec<String>,
    ) -> ClusterStatus {
        let waypoint = match &self.motion {
            ClusterMotion::Waypoints { list, next, .. } => Some((*next, list.len())),
            _ => None,
        };
        ClusterStatus {
            cluster: self.name.clone(),
            formation: self.formation.clone(),
            desired: self.desired,
            measured,
            velocity: self.velocity,
            slots,
            lost: self.lost.iter().cloned().collect(),
            absent,
            waypoint,
        }
    }

    /// The slot assigned to `robot`: its index and offset.
    fn assigned_slot(&self, robot: &str) -> Option<(usize, &Offset)> {
        let &slot = self.assignment.get(robot)?;
        Some((slot, self.slots.get(slot)?))
    }

    /// Lays out slots for the commanded members and gives each the slot that
    /// minimises the total distance.
    fn assign(&mut self, desired: &ClusterPose, fresh: &[&MemberState]) {
        let offsets = match slot_offsets(&self.formation, fresh.len()) {
            Ok(o) => o,
            // Only a custom formation with too few offsets can fail here, and
            // set_formation/set_members refuse that; fall back to a circle.
            Err(_) => match slot_offsets(
                &Formation {
                    kind: FormationKind::Circle,
                    spacing: 1.0,
                    offsets: vec![],
                },
                fresh.len(),
            ) {
                Ok(o) => o,
                Err(_) => return,
            },
        };
        let world: Vec<(f64, f64)> = offsets.iter().map(|o| slot_position(desired, o)).collect();
        let positions: Vec<(f64, f64)> = fresh.iter().map(|s| (s.pose.x, s.pose.y)).collect();
        let assignment = assign_slots(&positions, &world);
        self.assignment = fresh
            .iter()
            .map(|s| s.robot.clone())
            .zip(assignment)
            .collect();
        self.slots = offsets;
        self.reassign = false;
    }

    /// Integrates the desired cluster pose over `dt` and returns the velocity
    /// used (cluster frame), limited so no slot's feed-forward speed exceeds
    /// `speed_limit`.
    fn advance(
        &mut self,
        desired: &mut ClusterPose,
        dt: f64,
        max_offset: f64,
        speed_limit: f64,
    ) -> ClusterVelocity {
        let v = self.motion_velocity(desired, dt);
        let v = self.limit_slot_speed(v, desired.scale, max_offset, speed_limit);
        let v = integrate(desired, v, dt, &self.config);
        self.snap_to_waypoint(desired);
        v
    }

    /// The cluster-frame velocity the current motion asks for, before any
    /// speed limit.
    fn motion_velocity(&mut self, desired: &ClusterPose, dt: f64) -> ClusterVelocity {
        let w = match &mut self.motion {
            ClusterMotion::Hold => return ZERO_VELOCITY,
            ClusterMotion::Velocity(v) => return *v,
            ClusterMotion::Waypoints { list, next, looped } => {
                if *next >= list.len() && *looped && !list.is_empty() {
                    *next = 0;
                }
                match list.get(*next) {
                    Some(w) => *w,
                    None => return ZERO_VELOCITY,
                }
            }
        };
        self.velocity_toward(&w, desired, dt)
    }

    /// Velocity along the leg to `w`: the centroid and the heading each on a
    /// trapezoidal profile that arrives without overshoot.
    fn velocity_toward(
        &mut self,
        w: &ClusterWaypoint,
        desired: &ClusterPose,
        dt: f64,
    ) -> ClusterVelocity {
        let cfg = &self.config;
        let (dx, dy) = (w.x - desired.x, w.y - desired.y);
        let dist = norm(dx, dy);
        let speed = ramp(
            &mut self.path_speed,
            cfg.max_accel,
            cfg.cruise_speed,
            dist,
            dt,
        );
        let (wx, wy) = if dist > 1e-12 {
            (speed * dx / dist, speed * dy / dist)
        } else {
            (0.0, 0.0)
        };
        let turn = w.heading.map_or(0.0, |h| wrap_angle(h - desired.heading));
        let rate = ramp(
            &mut self.turn_rate,
            cfg.max_yaw_accel,
            cfg.max_yaw_rate,
            turn.abs(),
            dt,
        );
        let (cx, cy) = rotate(wx, wy, -desired.heading);
        ClusterVelocity {
            vx: cx,
            vy: cy,
            wz: rate * turn.signum(),
            scale_rate: 0.0,
        }
    }

    /// Scales `v` down so the fastest slot (`max_offset` from the centroid at
    /// `scale`) moves no faster than `speed_limit`; the leg profiles slow
    /// down with it, so they resume from the speed really used.
    fn limit_slot_speed(
        &mut self,
        v: ClusterVelocity,
        scale: f64,
        max_offset: f64,
        speed_limit: f64,
    ) -> ClusterVelocity {
        let slot_speed = norm(v.vx, v.vy) + (v.wz.abs() * scale + v.scale_rate.abs()) * max_offset;
        if slot_speed > speed_limit && slot_speed > 0.0 {
            let k = (speed_limit / slot_speed).max(0.0);
            self.path_speed *= k;
            self.turn_rate *= k;
            return ClusterVelocity {
                vx: v.vx * k,
                vy: v.vy * k,
                wz: v.wz * k,
                scale_rate: v.scale_rate * k,
            };
        }
        v
    }

    /// Puts the desired pose exactly on the waypoint once it is there to
    /// rounding, so arrival can be checked with equality.
    fn snap_to_waypoint(&self, desired: &mut ClusterPose) {
        let ClusterMotion::Waypoints { list, next, .. } = &self.motion else {
            return;
        };
        let Some(w) = list.get(*next) else { return };
        let at_position = norm(w.x - desired.x, w.y - desired.y) < 1e-9;
        let at_heading = w
            .heading
            .is_none_or(|h| wrap_angle(h - desired.heading).abs() < 1e-6);
        if at_position && at_heading {
            desired.x = w.x;
            desired.y = w.y;
            if let Some(h) = w.heading {
                desired.heading = wrap_angle(h);
            }
        }
    }

    /// Largest distance between a commanded member and its slot at the
    /// current desired pose, m.
    fn worst_lag(&self, desired: &ClusterPose, fresh: &[&MemberState]) -> f64 {
        fresh
            .iter()
            .filter_map(|s| {
                let (_, o) = self.assigned_slot(&s.robot)?;
                let (x, y) = slot_position(desired, o);
                Some(norm(x - s.pose.x, y - s.pose.y))
            })
            .fold(0.0, f64::max)
    }

    /// Moves to the next waypoint once the desired pose sits on the current
    /// one and the measured centroid is within the arrival radius.
    fn check_arrival(&mut self, measured: Option<&ClusterPose>, events: &mut Vec<ControlEvent>) {
        let (Some(desired), Some(measured)) = (self.desired, measured) else {
            return;
        };
        let ClusterMotion::Waypoints { list, next, looped } = &mut self.motion else {
            return;
        };
        let Some(w) = list.get(*next) else { return };
        let settled = desired.x == w.x
            && desired.y == w.y
            && w.heading
                .is_none_or(|h| (wrap_angle(h) - desired.heading).abs() < 1e-9);
        if settled && norm(measured.x - w.x, measured.y - w.y) <= self.config.arrival_radius {
            events.push(ControlEvent::WaypointReached { index: *next });
            *next += 1;
            self.path_speed = 0.0;
            self.turn_rate = 0.0;
            if *next >= list.len() {
                if *looped {
                    *next = 0;
                } else {
                    events.push(ControlEvent::Finished);
                }
            }
        }
    }

    /// Cluster pose from member positions: centroid, plus the rotation and
    /// scale that best fit the assigned slot offsets to the members' positions
    /// about the centroid (least squares).
    fn measure(&self, desired: &ClusterPose, fresh: &[&MemberState]) -> Option<ClusterPose> {
        if fresh.is_empty() {
            return None;
        }
        // Pairs (slot offset rotated into the world, member position); with
        // every member present the offsets average to zero and the centre is
        // the plain centroid.
        let pairs: Vec<((f64, f64), (f64, f64))> = fresh
            .iter()
            .filter_map(|s| {
                let (_, o) = self.assigned_slot(&s.robot)?;
                Some((rotate(o.x, o.y, desired.heading), (s.pose.x, s.pose.y)))
            })
            .collect();
        if pairs.is_empty() {
            return None;
        }
        let n = pairs.len() as f64;
        let (ax0, ay0) = pairs
            .iter()
            .fold((0.0, 0.0), |(x, y), ((ax, ay), _)| (x + ax / n, y + ay / n));
        let (bx0, by0) = pairs
            .iter()
            .fold((0.0, 0.0), |(x, y), (_, (bx, by))| (x + bx / n, y + by / n));
        let (mut dot, mut cross, mut aa) = (0.0, 0.0, 0.0);
        for ((ax, ay), (bx, by)) in &pairs {
            let (ax, ay, bx, by) = (ax - ax0, ay - ay0, bx - bx0, by - by0);
            dot += ax * bx + ay * by;
            cross += ax * by - ay * bx;
            aa += ax * ax + ay * ay;
        }
        let (turn, scale) = if aa > 1e-9 {
            (cross.atan2(dot), norm(dot, cross) / aa)
        } else {
            (0.0, desired.scale)
        };
        let (rx, ry) = rotate(ax0, ay0, turn);
        Some(ClusterPose {
            x: bx0 - scale * rx,
            y: by0 - scale * ry,
            heading: wrap_angle(desired.heading + turn),
            scale,
        })
    }
}

/// Where the slot with offset `o` is in the world at the desired pose.
fn slot_position(desired: &ClusterPose, o: &Offset) -> (f64, f64) {
    let (x, y) = rotate(o.x, o.y, desired.heading);
    (desired.x + desired.scale * x, desired.y + desired.scale * y)
}

/// The slot with offset `o` as a tracking reference: its position, and its
/// velocity from the inverse cluster kinematics,
/// `v_slot = v_c + wz x r + scale_rate R o` with `r = scale R(heading) o`.
fn slot_reference(desired: &ClusterPose, v: &ClusterVelocity, o: &Offset) -> Reference {
    let (vwx, vwy) = rotate(v.vx, v.vy, desired.heading);
    let (ox, oy) = rotate(o.x, o.y, desired.heading);
    let (rx, ry) = (desired.scale * ox, desired.scale * oy);
    Reference {
        x: desired.x + rx,
        y: desired.y + ry,
        heading: desired.heading,
        vx: vwx - v.wz * ry + v.scale_rate * ox,
        vy: vwy + v.wz * rx + v.scale_rate * oy,
        wz: v.wz,
    }
}

/// One step of a trapezoidal profile toward a point `remaining` away:
/// `speed` (kept between steps) grows by `accel` up to `top`, but no faster
/// than still stops at the point, and the step never passes the point.
fn ramp(speed: &mut f64, accel: f64, top: f64, remaining: f64, dt: f64) -> f64 {
    let reachable = (2.0 * accel * remaining).sqrt();
    *speed = (*speed + accel * dt).min(top).min(reachable);
    if dt > 0.0 {
        speed.min(remaining / dt)
    } else {
        0.0
    }
}

/// Moves `desired` on by `v` (cluster frame) for `dt`, keeping the scale
/// within its bounds; a scale rate that hits a bound is not applied and comes
/// back as zero.
fn integrate(
    desired: &mut ClusterPose,
    mut v: ClusterVelocity,
    dt: f64,
    cfg: &ClusterConfig,
) -> ClusterVelocity {
    let (wx, wy) = rotate(v.vx, v.vy, desired.heading);
    desired.x += wx * dt;
    desired.y += wy * dt;
    desired.heading = wrap_angle(desired.heading + v.wz * dt);
    let scale = (desired.scale + v.scale_rate * dt).clamp(cfg.min_scale, cfg.max_scale);
    if scale != desired.scale + v.scale_rate * dt {
        v.scale_rate = 0.0;
    }
    desired.scale = scale;
    v
}

/// Starting cluster pose: centroid and circular-mean heading of the members.
fn initial_pose(fresh: &[&MemberState]) -> ClusterPose {
    let n = fresh.len() as f64;
    let x = fresh.iter().map(|s| s.pose.x).sum::<f64>() / n;
    let y = fresh.iter().map(|s| s.pose.y).sum::<f64>() / n;
    let s: f64 = fresh.iter().map(|m| m.pose.heading.sin()).sum();
    let c: f64 = fresh.iter().map(|m| m.pose.heading.cos()).sum();
    let heading = if norm(s, c) > 1e-9 { s.atan2(c) } else { 0.0 };
    ClusterPose {
        x,
        y,
        heading,
        scale: 1.0,
    }
}
