//! Follow-the-leader: each follower keeps a fixed offset in the leader's body
//! frame (x forward, y left), whatever drives the leader (gamepad, waypoints,
//! an external program). The reference is the leader's pose composed with the
//! offset; its feed-forward velocity is the leader's reported velocity plus
//! `wz x offset`, so followers do not lag behind a moving leader.
//!
//! Without fresh leader telemetry there is no reference: followers are sent an
//! explicit stop (they are healthy, only their target is unknown). A follower
//! whose own telemetry is stale is not commanded at all.

use std::collections::BTreeSet;

use mech_proto::{Command, FleetCommand, Offset, RobotCommand, Stop};

use super::geometry::rotate;
use super::tracking::{Reference, TrackingGains, track};
use super::{ControlEvent, MemberState};

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
}

impl Default for FollowConfig {
    fn default() -> Self {
        FollowConfig {
            gains: TrackingGains::default(),
            telemetry_timeout: 0.5,
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
}

impl FollowTheLeader {
    pub fn new(leader: impl Into<String>, followers: Vec<Follower>, config: FollowConfig) -> Self {
        FollowTheLeader {
            leader: leader.into(),
            followers,
            config,
            lost: BTreeSet::new(),
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
        let timeout = self.config.telemetry_timeout;
        let mut events = Vec::new();
        let mut freshness = |robot: &str, lost: &mut BTreeSet<String>| -> Option<bool> {
            let s = states.iter().find(|s| s.robot == robot)?;
            let stale = s.is_stale(now, timeout);
            if stale && lost.insert(robot.to_string()) {
                events.push(ControlEvent::MemberLost {
                    robot: robot.to_string(),
                });
            } else if !stale && lost.remove(robot) {
                events.push(ControlEvent::MemberRecovered {
                    robot: robot.to_string(),
                });
            }
            Some(!stale)
        };
        let leader_fresh = freshness(&self.leader, &mut self.lost) == Some(true);
        let leader = states
            .iter()
            .find(|s| s.robot == self.leader)
            .filter(|_| leader_fresh);
        let mut commands = Vec::new();
        let mut targets = Vec::new();
        for f in &self.followers {
            if freshness(&f.robot, &mut self.lost) != Some(true) {
                continue;
            }
            let Some(s) = states.iter().find(|s| s.robot == f.robot) else {
                continue;
            };
            let Some(l) = leader else {
                commands.push(RobotCommand {
                    robot: f.robot.clone(),
                    command: Command::Stop(Stop {}),
                });
                continue;
            };
            let (ox, oy) = rotate(f.offset.x, f.offset.y, l.pose.heading);
            let reference = Reference {
                x: l.pose.x + ox,
                y: l.pose.y + oy,
                heading: l.pose.heading,
                vx: l.velocity.vx - l.velocity.wz * oy,
                vy: l.velocity.vy + l.velocity.wz * ox,
                wz: l.velocity.wz,
            };
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
        FollowOutput {
            commands,
            targets,
            lost: self.lost.iter().cloned().collect(),
            events,
        }
    }
}
