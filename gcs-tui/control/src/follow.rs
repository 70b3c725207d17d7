//! Follow-the-leader: each follower keeps a fixed offset in the leader's body
//! frame (x forward, y left), whatever drives the leader (gamepad, waypoints,
//! an external program). The reference is the leader's pose composed with the
//! offset; its feed-forward velocity is the leader's velocity plus
//! `wz x offset`, so followers do not lag behind a moving leader.
//!
//! The leader's velocity is estimated from successive telemetry poses (a
//! finite difference, low-pass filtered) rather than read from the reported
//! velocity: every agent reports a pose, while what a reported velocity means
//! (frame, filtering, commanded or measured) varies between platforms.
//!
//! The offsets are laid out in a *formation frame* that follows the leader's
//! heading at a limited rate: when a differential-drive leader spins in place,
//! a rigid offset would swing round faster than any follower can drive, so
//! the frame turns no faster than lets the farthest follower keep up at
//! [`FollowConfig::speed_margin`] of the slowest follower's top speed, and
//! catches up with the leader's heading afterwards.
//!
//! Without fresh leader telemetry there is no reference: followers are sent an
//! explicit stop (they are healthy, only their target is unknown). A follower
//! whose own telemetry is stale is not commanded at all.

use std::collections::BTreeSet;

use mech_proto::{Command, FleetCommand, Offset, RobotCommand, Stop};

use super::geometry::{rotate, wrap_angle};
use super::tracking::{Reference, TrackingGains, track};
use super::{ControlEvent, MemberState, StepClock, note_staleness};

/// A follower and its offset in the leader's frame, m.
#[derive(Debug, Clone, PartialEq)]
pub struct Follower {
    pub robot: String,
    pub offset: Offset,
}

/// Tuning of a follow-the-leader controller.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowConfig {
    pub gains: TrackingGains,
    /// Telemetry older than this (s) makes a robot lost.
    pub telemetry_timeout: f64,
    /// Fraction of the slowest follower's top speed the formation frame's
    /// rotation may ask of the farthest follower.
    pub speed_margin: f64,
    /// Weight of each new finite-difference sample in the leader velocity
    /// estimate, in `(0, 1]` (1 = no filtering).
    pub velocity_smoothing: f64,
}

impl Default for FollowConfig {
    fn default() -> Self {
        FollowConfig {
            gains: TrackingGains::default(),
            telemetry_timeout: 0.5,
            velocity_smoothing: 0.5,
            speed_margin: 0.6,
        }
    }
}

/// Where a follower should be now, and how far it is from there.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowTarget {
    pub robot: String,
    pub x: f64,
    pub y: f64,
    pub heading: f64,
    /// Distance from the follower's reported position to the target, m.
    pub error: f64,
}

/// Result of one follow-the-leader step.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowOutput {
    pub commands: Vec<RobotCommand>,
    pub targets: Vec<FollowTarget>,
    /// Robots (leader or followers) whose telemetry is stale.
    pub lost: Vec<String>,
    pub events: Vec<ControlEvent>,
}

impl FollowOutput {
    /// The commands as one message for the controller's channel.
    pub fn fleet_command(&self) -> FleetCommand {
        FleetCommand {
            parts: self.commands.clone(),
        }
    }
}

/// Followers holding offsets from one leader.
#[derive(Debug, Clone)]
pub struct FollowTheLeader {
    leader: String,
    followers: Vec<Follower>,
    config: FollowConfig,
    lost: BTreeSet<String>,
    leader_motion: Option<LeaderMotion>,
    /// Heading of the formation frame, rad; `None` until the leader reports.
    frame: Option<f64>,
    clock: StepClock,
}

/// The leader's last pose and its estimated world-frame velocity.
#[derive(Debug, Clone, Copy)]
struct LeaderMotion {
    stamp: f64,
    x: f64,
    y: f64,
    heading: f64,
    vx: f64,
    vy: f64,
    wz: f64,
}

impl LeaderMotion {
    /// Folds in a new report; reports with the same stamp change nothing.
    fn update(previous: Option<LeaderMotion>, s: &MemberState, smoothing: f64) -> LeaderMotion {
        let fresh = LeaderMotion {
            stamp: s.stamp,
            x: s.pose.x,
            y: s.pose.y,
            heading: s.pose.heading,
            vx: 0.0,
            vy: 0.0,
            wz: 0.0,
        };
        let Some(p) = previous else { return fresh };
        let dt = s.stamp - p.stamp;
        if dt <= 1e-6 {
            return p;
        }
        if dt > 1.0 {
            return fresh;
        }
        let a = smoothing.clamp(0.0, 1.0);
        LeaderMotion {
            vx: p.vx + a * ((s.pose.x - p.x) / dt - p.vx),
            vy: p.vy + a * ((s.pose.y - p.y) / dt - p.vy),
            wz: p.wz + a * (wrap_angle(s.pose.heading - p.heading) / dt - p.wz),
            ..fresh
        }
    }
}

impl FollowTheLeader {
    pub fn new(leader: impl Into<String>, followers: Vec<Follower>, config: FollowConfig) -> Self {
        FollowTheLeader {
            leader: leader.into(),
            followers,
            config,
            lost: BTreeSet::new(),
            leader_motion: None,
            frame: None,
            clock: StepClock::default(),
        }
    }

    pub fn leader(&self) -> &str {
        &self.leader
    }

    pub fn followers(&self) -> &[Follower] {
        &self.followers
    }

    /// Adds a follower, or changes its offset if it already follows.
    pub fn set_follower(&mut self, robot: &str, offset: Offset) {
        match self.followers.iter_mut().find(|f| f.robot == robot) {
            Some(f) => f.offset = offset,
            None => self.followers.push(Follower {
                robot: robot.to_string(),
                offset,
            }),
        }
    }

    /// Stops following; the robot gets no command from the next step on.
    pub fn remove_follower(&mut self, robot: &str) {
        self.followers.retain(|f| f.robot != robot);
        self.lost.remove(robot);
    }

    /// One step at `now` (s). Followers missing from `states` get no command.
    pub fn step(&mut self, now: f64, states: &[MemberState]) -> FollowOutput {
        let reports = Reports {
            states,
            now,
            timeout: self.config.telemetry_timeout,
        };
        let mut events = Vec::new();
        let leader = reports.fresh(&self.leader, &mut self.lost, &mut events);
        self.leader_motion = leader
            .map(|l| LeaderMotion::update(self.leader_motion, l, self.config.velocity_smoothing));
        let motion = self.leader_motion;
        let dt = self.clock.interval(now);
        let frame_rate = match motion {
            Some(l) => self.turn_frame(&l, states, dt),
            None => 0.0,
        };
        let (commands, targets) = self.follower_commands(&reports, motion, frame_rate, &mut events);
        FollowOutput {
            commands,
            targets,
            lost: self.lost.iter().cloned().collect(),
            events,
        }
    }

    /// Turns the formation frame toward the leader's heading, no faster than
    /// [`FollowTheLeader::frame_rate_limit`], and returns the frame's rate for
    /// feed-forward: the leader's own once caught up, else the frame's.
    fn turn_frame(&mut self, leader: &LeaderMotion, states: &[MemberState], dt: f64) -> f64 {
        let limit = self.frame_rate_limit(states);
        let frame = self.frame.unwrap_or(leader.heading);
        let turn = wrap_angle(leader.heading - frame);
        let step = if limit.is_finite() {
            turn.clamp(-limit * dt, limit * dt)
        } else {
            turn
        };
        self.frame = Some(wrap_angle(frame + step));
        if (turn - step).abs() < 1e-9 {
            leader.wz.clamp(-limit, limit)
        } else if dt > 0.0 {
            step / dt
        } else {
            0.0
        }
    }

    /// The fastest the formation frame may turn, rad/s: the rate at which the
    /// farthest offset moves at the speed margin of the slowest follower
    /// (unlimited without offsets or reporting followers).
    fn frame_rate_limit(&self, states: &[MemberState]) -> f64 {
        let reach = self
            .followers
            .iter()
            .map(|f| f.offset.x.hypot(f.offset.y))
            .fold(0.0, f64::max);
        let slowest = self
            .followers
            .iter()
            .filter_map(|f| states.iter().find(|s| s.robot == f.robot))
            .map(|s| s.platform.max_speed)
            .fold(f64::INFINITY, f64::min);
        if reach > 1e-9 && slowest.is_finite() {
            self.config.speed_margin * slowest / reach
        } else {
            f64::INFINITY
        }
    }

    /// Each fresh follower's command toward its offset in the formation
    /// frame, with the target it tracks; an explicit stop without a leader.
    fn follower_commands(
        &mut self,
        reports: &Reports,
        motion: Option<LeaderMotion>,
        frame_rate: f64,
        events: &mut Vec<ControlEvent>,
    ) -> (Vec<RobotCommand>, Vec<FollowTarget>) {
        let frame = self.frame.unwrap_or_default();
        let mut commands = Vec::new();
        let mut targets = Vec::new();
        for f in &self.followers {
            let Some(s) = reports.fresh(&f.robot, &mut self.lost, events) else {
                continue;
            };
            let Some(l) = motion else {
                commands.push(RobotCommand {
                    robot: f.robot.clone(),
                    command: Command::Stop(Stop {}),
                });
                continue;
            };
            let reference = offset_reference(&l, &f.offset, frame, frame_rate);
            commands.push(RobotCommand {
                robot: f.robot.clone(),
                command: track(s, &reference, &self.config.gains),
            });
            targets.push(FollowTarget {
                robot: f.robot.clone(),
                x: reference.x,
                y: reference.y,
                heading: reference.heading,
                error: reference.position_error(s),
            });
        }
        (commands, targets)
    }
}

/// The step's input, and the age past which it is stale.
struct Reports<'a> {
    states: &'a [MemberState],
    now: f64,
    timeout: f64,
}

impl<'a> Reports<'a> {
    /// `robot`'s state when its telemetry is fresh. Notes it lost or
    /// recovered in `lost`; a robot missing from the input stays as it was.
    fn fresh(
        &self,
        robot: &str,
        lost: &mut BTreeSet<String>,
        events: &mut Vec<ControlEvent>,
    ) -> Option<&'a MemberState> {
        let s = self.states.iter().find(|s| s.robot == robot)?;
        let stale = s.is_stale(self.now, self.timeout);
        note_staleness(lost, robot, stale, events);
        (!stale).then_some(s)
    }
}

/// The point at `offset` in the formation frame (heading `frame`, turning at
/// `frame_rate`) about the leader, moving with the leader plus `wz x offset`.
fn offset_reference(
    leader: &LeaderMotion,
    offset: &Offset,
    frame: f64,
    frame_rate: f64,
) -> Reference {
    let (ox, oy) = rotate(offset.x, offset.y, frame);
    Reference {
        x: leader.x + ox,
        y: leader.y + oy,
        heading: frame,
        vx: leader.vx - frame_rate * oy,
        vy: leader.vy + frame_rate * ox,
        wz: frame_rate,
    }
}
