//! Follow-the-leader as the hub runs it, one controller per leader on
//! `follow/<leader>`: which robots follow whom (a robot follows one leader
//! at a time; a leader without followers is dropped), one period of each,
//! and the hub's requests that change them.

use std::collections::BTreeMap;

use mech_proto::Offset;

use super::period::{Outgoing, PeriodInputs, PeriodOutput};
use super::{ControlError, ControlHub, follow_channel};
use crate::follow::{FollowConfig, FollowTarget, FollowTheLeader, Follower};
use mech_core::sync::lock;

/// Followers of one leader as displays show them.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowView {
    pub leader: String,
    pub channel: String,
    pub followers: Vec<Follower>,
    pub targets: Vec<FollowTarget>,
    pub lost: Vec<String>,
}

/// Every follow controller, by leader.
#[derive(Debug, Default)]
pub(super) struct Follows {
    entries: BTreeMap<String, FollowEntry>,
}

/// One leader's controller and its last step's targets and lost
/// followers.
#[derive(Debug)]
struct FollowEntry {
    controller: FollowTheLeader,
    targets: Vec<FollowTarget>,
    lost: Vec<String>,
}

impl Follows {
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Makes `follower` keep `offset` from `leader`, and no other leader.
    pub fn set(&mut self, follower: &str, leader: &str, offset: Offset, config: &FollowConfig) {
        for (l, e) in self.entries.iter_mut() {
            if l != leader {
                e.controller.remove_follower(follower);
            }
        }
        self.prune();
        self.entries
            .entry(leader.to_string())
            .or_insert_with(|| FollowEntry {
                controller: FollowTheLeader::new(leader, Vec::new(), config.clone()),
                targets: Vec::new(),
                lost: Vec::new(),
            })
            .controller
            .set_follower(follower, offset);
    }

    /// Stops `follower` following anyone.
    pub fn remove(&mut self, follower: &str) {
        for e in self.entries.values_mut() {
            e.controller.remove_follower(follower);
        }
        self.prune();
    }

    /// Drops the leaders nobody follows any more.
    fn prune(&mut self) {
        self.entries
            .retain(|_, e| !e.controller.followers().is_empty());
    }

    /// One period of every leader's followers: the leader wherever it is
    /// routed, the followers routed to `follow/<leader>`.
    pub fn step(&mut self, inputs: &PeriodInputs, output: &mut PeriodOutput) {
        for (leader, e) in self.entries.iter_mut() {
            let channel = follow_channel(leader);
            let routed = inputs.routed_states(&channel, Some(leader));
            let result = e.controller.step(inputs.now, &routed);
            output.events(&channel, &result.events);
            e.targets = result.targets;
            e.lost = result.lost;
            if !result.commands.is_empty() {
                output.outgoing.push(Outgoing::Fleet {
                    channel,
                    parts: result.commands,
                });
            }
        }
    }

    pub fn views(&self) -> Vec<FollowView> {
        self.entries
            .iter()
            .map(|(leader, e)| FollowView {
                leader: leader.clone(),
                channel: follow_channel(leader),
                followers: e.controller.followers().to_vec(),
                targets: e.targets.clone(),
                lost: e.lost.clone(),
            })
            .collect()
    }
}

impl ControlHub {
    /// Makes `follower` keep `offset` (leader frame) from `leader`; it obeys
    /// once routed to `follow/<leader>`. A robot follows one leader at a time.
    pub fn follow(&self, follower: &str, leader: &str, offset: Offset) -> Result<(), ControlError> {
        if follower == leader {
            return Err(ControlError::SelfFollow(follower.to_string()));
        }
        for r in [follower, leader] {
            if !self.shared.gcs.with_fleet(|f| f.robot(r).is_some()) {
                return Err(ControlError::UnknownRobot(r.to_string()));
            }
        }
        lock(&self.shared.follows).set(follower, leader, offset, &self.shared.config.follow);
        self.kick();
        Ok(())
    }

    /// Stops `follower` following anyone.
    pub fn unfollow(&self, follower: &str) {
        lock(&self.shared.follows).remove(follower);
    }
}

#[cfg(test)]
mod tests {
    use super::super::period::tests::{inputs, state};
    use super::*;

    fn offset(dx: f64) -> Offset {
        Offset { x: dx, y: 0.0 }
    }

    fn leaders(f: &Follows) -> Vec<(String, Vec<String>)> {
        f.views()
            .into_iter()
            .map(|v| (v.leader, v.followers.into_iter().map(|f| f.robot).collect()))
            .collect()
    }

    #[test]
    fn a_robot_follows_one_leader_and_a_leader_nobody_follows_is_dropped() {
        let config = FollowConfig::default();
        let mut f = Follows::default();
        f.set("b", "a", offset(-0.5), &config);
        f.set("c", "a", offset(-1.0), &config);
        f.set("b", "d", offset(-0.5), &config);
        assert_eq!(
            leaders(&f),
            [
                ("a".to_string(), vec!["c".to_string()]),
                ("d".to_string(), vec!["b".to_string()])
            ]
        );
        f.remove("c");
        assert_eq!(leaders(&f), [("d".to_string(), vec!["b".to_string()])]);
        f.remove("b");
        assert!(f.is_empty());
    }

    #[test]
    fn the_leader_is_read_wherever_it_is_routed_and_followers_only_on_the_channel() {
        let mut f = Follows::default();
        f.set("b", "a", offset(-0.5), &FollowConfig::default());
        f.set("c", "a", offset(-1.0), &FollowConfig::default());
        let i = inputs(
            1.0,
            vec![
                state("a", 0.0, 0.0, 1.0),
                state("b", -0.5, 0.0, 1.0),
                state("c", -1.0, 0.0, 1.0),
            ],
            &[("a", "joy/0"), ("b", "follow/a"), ("c", "joy/1")],
        );
        let mut out = PeriodOutput::default();
        f.step(&i, &mut out);
        let Some(Outgoing::Fleet { channel, parts }) = out.outgoing.first() else {
            panic!("a fleet command: {:?}", out.outgoing);
        };
        assert_eq!(channel, "follow/a");
        let robots: Vec<&str> = parts.iter().map(|p| p.robot.as_str()).collect();
        assert_eq!(robots, ["b"]);
    }
}
