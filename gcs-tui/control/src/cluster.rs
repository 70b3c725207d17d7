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

use std::collections::BTreeSet;

use mech_proto::{ClusterPose, ClusterVelocity, FleetCommand, Formation, RobotCommand};

use super::formation::{FormationError, slot_offsets};
use super::geometry::{norm, rotate, wrap_angle};
use super::tracking::{TrackingGains, track};
use super::{ControlEvent, Kinematics, MemberState, StepClock, note_staleness};

mod desired;
mod slots;

use desired::DesiredPose;
use slots::{SlotAssignment, slot_reference};

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

/// A cluster-space controller for one cluster; see the module docs. Beside
/// its definition it keeps the desired cluster pose and its motion
/// (`desired`), which member holds which slot (`slots`), and which members
/// are lost.
#[derive(Debug, Clone)]
pub struct ClusterController {
    name: String,
    members: Vec<String>,
    formation: Formation,
    config: ClusterConfig,
    desired: DesiredPose,
    slots: SlotAssignment,
    lost: BTreeSet<String>,
    clock: StepClock,
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
            desired: DesiredPose::new(),
            slots: SlotAssignment::new(),
            lost: BTreeSet::new(),
            clock: StepClock::default(),
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
        self.desired.motion()
    }

    pub fn config(&self) -> &ClusterConfig {
        &self.config
    }

    /// Changes the shape, effective at the next step: slots are re-assigned to
    /// minimise the total distance members travel.
    pub fn set_formation(&mut self, formation: Formation) -> Result<(), FormationError> {
        slot_offsets(&formation, self.members.len())?;
        self.formation = formation;
        self.slots.invalidate();
        Ok(())
    }

    /// Replaces the member list; a member no longer listed gets no command
    /// from the next step on.
    pub fn set_members(&mut self, members: Vec<String>) -> Result<(), FormationError> {
        slot_offsets(&self.formation, members.len())?;
        self.lost.retain(|r| members.contains(r));
        self.members = members;
        self.slots.invalidate();
        Ok(())
    }

    /// Drops a member from the cluster.
    pub fn remove_member(&mut self, robot: &str) {
        self.members.retain(|m| m != robot);
        self.lost.remove(robot);
        self.slots.invalidate();
    }

    /// Drive the cluster at a cluster-frame velocity (gamepad, command line).
    pub fn set_velocity(&mut self, velocity: ClusterVelocity) {
        self.desired.set_velocity(velocity);
    }

    /// Visit `list` in order, starting with the first.
    pub fn set_waypoints(&mut self, list: Vec<ClusterWaypoint>, looped: bool) {
        self.desired.set_waypoints(list, looped);
    }

    /// Stop the cluster where its desired pose is now.
    pub fn hold(&mut self) {
        self.desired.hold();
    }

    /// One control step at time `now` (s) on the members' latest states.
    /// States of robots that are not members are ignored; members without a
    /// state are absent and get no command.
    pub fn step(&mut self, now: f64, states: &[MemberState]) -> ClusterOutput {
        let dt = self.clock.interval(now);
        let mut events = Vec::new();
        let roster = self.classify(now, states, &mut events);
        self.slots.watch(&roster.present);
        self.desired
            .place_until_anchored(self.slots.is_stale(), &roster.fresh);
        let (commands, slots, measured) = match self.update_reference(dt, &roster) {
            Some(desired) => {
                let (commands, slots) = self.slot_commands(&desired, &roster.fresh);
                let measured = self.measure(&desired, &roster.fresh);
                self.desired.check_arrival(
                    measured.as_ref(),
                    self.config.arrival_radius,
                    &mut events,
                );
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

    /// Moves the desired cluster pose on by `dt`, re-assigning slots first if
    /// the members or the formation changed; `None` while the pose is not
    /// known yet (no member has reported).
    fn update_reference(&mut self, dt: f64, roster: &Roster) -> Option<ClusterPose> {
        let desired = self.desired.pose()?;
        if self.slots.is_stale() && !roster.present.is_empty() {
            self.slots
                .assign(&self.formation, &desired, &roster.present);
        }
        let speed_limit = self.slot_speed_limit(&desired, &roster.fresh);
        self.desired
            .advance(dt, self.slots.max_offset(), speed_limit, &self.config)
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
        let lag = self.slots.worst_lag(desired, fresh);
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
        let velocity = self.desired.velocity();
        for s in fresh {
            let Some((slot, o)) = self.slots.slot_of(&s.robot) else {
                continue;
            };
            let reference = slot_reference(desired, &velocity, o);
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
        ClusterStatus {
            cluster: self.name.clone(),
            formation: self.formation.clone(),
            desired: self.desired.pose(),
            measured,
            velocity: self.desired.velocity(),
            slots,
            lost: self.lost.iter().cloned().collect(),
            absent,
            waypoint: self.desired.waypoint(),
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
                let (_, o) = self.slots.slot_of(&s.robot)?;
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
