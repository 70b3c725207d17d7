//! The traffic ledger: what the router counts of the messages it takes,
//! router-wide, per robot and per channel (`crate::counters`).
//!
//! [`Ledger`] holds the router-wide counts and is the only thing that
//! changes a count made of several: each robot's and each channel's
//! counts, a [`Tally`], live with the robot and the channel (so the hot
//! path finds them with the lookups it makes anyway), but are changed
//! here, together with the router-wide ones. What the counts keep:
//! - every message the router takes is `received` once router-wide; a
//!   robot's `received` counts what the robot sent (over UDP or a radio),
//!   a channel's what was published on it;
//! - a command forwarded to a robot routed to its channel is `forwarded`
//!   once by the robot and, when the robot has a link to send on, once
//!   router-wide and by the channel (with no link it is dropped, as for an
//!   unknown robot);
//! - a message that is not forwarded is `dropped` once, by reason: by its
//!   channel when the channel is known, else router-wide; a command for a
//!   robot routed elsewhere is also counted by that robot.

use std::collections::BTreeMap;

use super::{Delivery, Peer};
use crate::counters::{Counters, DropReason, Drops, Rejections, Traffic};

/// Router-wide counts (per robot and per channel are [`Tally`]s kept with
/// each robot and channel). Send failures are counted where sending is
/// done, in `super::super::net`.
#[derive(Debug, Default)]
pub(super) struct Ledger {
    received: u64,
    forwarded: u64,
    dropped: Drops,
}

/// One robot's or one channel's counts, changed by the [`Ledger`] (and,
/// for a message heard, by [`Tally::heard`]).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Tally(Traffic);

impl Tally {
    /// The counts of a robot or channel first heard with a message.
    pub(super) fn first() -> Tally {
        Tally(Traffic {
            received: 1,
            ..Traffic::default()
        })
    }

    /// A message from the robot, or published on the channel.
    pub(super) fn heard(&mut self) {
        self.0.received += 1;
    }

    pub(super) fn traffic(&self) -> Traffic {
        self.0
    }
}

impl Ledger {
    /// A message taken by the router; returns its number (from 1), as
    /// the recording numbers it.
    pub(super) fn received(&mut self) -> u64 {
        self.received += 1;
        self.received
    }

    /// Messages taken so far.
    pub(super) fn received_so_far(&self) -> u64 {
        self.received
    }

    /// A message dropped for `reason`, counted router-wide.
    pub(super) fn dropped(&mut self, reason: DropReason) -> Delivery {
        self.dropped.count(reason);
        Delivery::Dropped(reason)
    }

    /// A message for a robot, published on the channel counted by `on`
    /// (`None`: no channel, or one not known), dropped for `reason`.
    pub(super) fn dropped_on(&mut self, reason: DropReason, on: Option<&mut Tally>) -> DropReason {
        match on {
            Some(channel) => channel.0.dropped.count(reason),
            None => self.dropped.count(reason),
        }
        reason
    }

    /// A command for `robot`, which is routed to another channel than its
    /// own (`on`).
    pub(super) fn not_routed(&mut self, robot: &mut Tally, on: Option<&mut Tally>) -> DropReason {
        robot.0.dropped.count(DropReason::NotRouted);
        self.dropped_on(DropReason::NotRouted, on)
    }

    /// A message for `robot` that its route (or the sender's role) lets
    /// through, published on `on`, going out on link `to`: forwarded, or
    /// dropped when the robot has no link to send on.
    pub(super) fn forwarded(
        &mut self,
        robot: &mut Tally,
        on: Option<&mut Tally>,
        to: Option<Peer>,
    ) -> Result<Peer, DropReason> {
        robot.0.forwarded += 1;
        match to {
            Some(to) => {
                self.forwarded += 1;
                if let Some(channel) = on {
                    channel.0.forwarded += 1;
                }
                Ok(to)
            }
            None => Err(self.dropped_on(DropReason::UnknownRobot, on)),
        }
    }

    /// A message the router takes charge of delivering to `robot` (a
    /// mission, sent until acknowledged): forwarded, link or not.
    pub(super) fn handed_over(&mut self, robot: &mut Tally) {
        robot.0.forwarded += 1;
        self.forwarded += 1;
    }

    /// The counters, with each robot's and channel's and the gate's
    /// rejections (send failures are added by the caller).
    pub(super) fn counters(
        &self,
        robots: BTreeMap<String, Traffic>,
        channels: BTreeMap<String, Traffic>,
        rejected: Rejections,
    ) -> Counters {
        Counters {
            robots,
            channels,
            received: self.received,
            forwarded: self.forwarded,
            dropped: self.dropped,
            fanout_dropped: 0,
            rejected,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each command is counted once: forwarded by robot, channel and
    /// router, or dropped by its channel (and a robot routed elsewhere).
    #[test]
    fn a_command_is_counted_once_where_it_went() {
        let mut ledger = Ledger::default();
        let (mut robot, mut channel) = (Tally::first(), Tally::first());
        let to = Peer::Udp(([127, 0, 0, 1], 9000).into());
        assert_eq!(
            ledger.forwarded(&mut robot, Some(&mut channel), Some(to)),
            Ok(to)
        );
        ledger.not_routed(&mut robot, Some(&mut channel));
        ledger.dropped_on(DropReason::UnknownRobot, None);
        let c = ledger.counters(BTreeMap::new(), BTreeMap::new(), Rejections::default());
        assert_eq!(
            (c.forwarded, c.dropped.unknown_robot, c.dropped.not_routed),
            (1, 1, 0)
        );
        let (r, ch) = (robot.traffic(), channel.traffic());
        assert_eq!((r.forwarded, r.dropped.not_routed), (1, 1));
        assert_eq!((ch.forwarded, ch.dropped.not_routed), (1, 1));
    }
}
