//! Missions: forwarded to their robot, repeated until it acknowledges the
//! id or reported failed after `mission_give_up`; the acknowledgement goes
//! back to whoever sent the mission.
//!
//! [`Missions`] holds the pending ones: at most one per robot and id (a
//! mission sent again replaces the pending one), at most
//! [`PENDING_PER_ROBOT`] per robot (a new one past that gives up the
//! robot's oldest at once), each removed by its acknowledgement or when
//! given up.

use std::time::Duration;

use mech_proto::{Mission, MissionAck};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{Ctx, Delivery, Incoming, Peer, Tables};
use crate::counters::DropReason;
use crate::event::Event;

/// Most missions waiting for one robot's acknowledgement. A robot keeps
/// one mission per channel, and a controller waits for each answer, so
/// more pending than this is a sender outrunning a robot that does not
/// answer (off, or out of reach): each would hold its bytes and be resent
/// every `mission_retry` until given up.
pub(super) const PENDING_PER_ROBOT: usize = 16;

/// Missions waiting for their acknowledgement, and the ids handed out.
#[derive(Debug)]
pub(super) struct Missions {
    pending: Vec<PendingMission>,
    next_id: u32,
}

#[derive(Debug)]
struct PendingMission {
    robot: String,
    id: u32,
    /// The mission message without its `auth` element: each (re)send is
    /// signed afresh, since a receiver refuses a repeated stamp.
    region: Vec<u8>,
    reply_to: Peer,
    /// Who sent it, for relaying the acknowledgement.
    sender: String,
    first: Instant,
    last: Instant,
}

/// What the mission timers found due: resends and missions given up.
#[derive(Debug, Default)]
struct Due {
    /// (robot, signed region) to send again.
    resend: Vec<(String, Vec<u8>)>,
    /// (robot, id) not acknowledged in time.
    given_up: Vec<(String, u32)>,
}

impl Missions {
    /// Ids start from `seed` (see `super::clock_seed`).
    pub(super) fn new(seed: u32) -> Missions {
        Missions {
            pending: Vec::new(),
            next_id: seed,
        }
    }

    /// A fresh mission id.
    fn next_id(&mut self) -> u32 {
        self.next_id = self.next_id.wrapping_add(1);
        self.next_id
    }

    /// Adds a mission to wait for, in place of one with the same robot and
    /// id. When the robot already has [`PENDING_PER_ROBOT`] pending, its
    /// oldest is no longer waited for: returned, to be reported given up.
    fn add(&mut self, mission: PendingMission) -> Option<(String, u32)> {
        self.pending
            .retain(|p| !(p.robot == mission.robot && p.id == mission.id));
        let mut theirs = self
            .pending
            .iter()
            .enumerate()
            .filter(|(_, p)| p.robot == mission.robot);
        let oldest = theirs.next().map(|(i, _)| i);
        let dropped = (theirs.count() + 1 >= PENDING_PER_ROBOT)
            .then(|| oldest.map(|i| self.pending.remove(i)))
            .flatten()
            .map(|p| (p.robot, p.id));
        self.pending.push(mission);
        dropped
    }

    /// The pending mission `id` of `robot`, acknowledged: no longer pending.
    fn acknowledged(&mut self, robot: &str, id: u32) -> Option<PendingMission> {
        let i = self
            .pending
            .iter()
            .position(|p| p.robot == robot && p.id == id)?;
        Some(self.pending.remove(i))
    }

    /// Missions due again at `now` (every `retry`) and those given up
    /// (after `give_up`, no longer pending).
    fn due(&mut self, now: Instant, retry: Duration, give_up: Duration) -> Due {
        let mut due = Due::default();
        self.pending.retain_mut(|m| {
            if now.saturating_duration_since(m.first) >= give_up {
                due.given_up.push((m.robot.clone(), m.id));
                return false;
            }
            if now.saturating_duration_since(m.last) >= retry {
                m.last = now;
                due.resend.push((m.robot.clone(), m.region.clone()));
            }
            true
        });
        due
    }
}

impl Tables {
    pub(super) fn on_mission(
        &mut self,
        m: Incoming<'_>,
        mission: Mission,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let h = m.header;
        let robot = h.destination.clone();
        self.note_publisher(&h.sender, &h.channel, cx);
        let Some(entry) = self.robots.get_mut(&robot) else {
            return self.ledger.dropped(DropReason::UnknownRobot);
        };
        self.ledger.handed_over(&mut entry.traffic);
        let to = self.target(&robot, cx.now);
        let region = match mech_proto::auth::split(m.bytes) {
            Ok((region, _)) => region.to_vec(),
            Err(e) => return self.bad(e.to_string(), cx),
        };
        if let (Some(b), Some(to)) = (self.gate.seal(&region, &robot, cx.station_us), to) {
            cx.send(to, b);
            self.count_sent(&robot);
        }
        let dropped = self.missions.add(PendingMission {
            robot: robot.clone(),
            id: mission.id,
            region,
            reply_to: cx.from,
            sender: h.sender.clone(),
            first: cx.now,
            last: cx.now,
        });
        if let Some((robot, id)) = dropped {
            warn!(%robot, id, "mission given up: {PENDING_PER_ROBOT} newer ones pending");
            cx.event(Event::MissionFailed {
                robot,
                id,
                reason: format!("{PENDING_PER_ROBOT} newer missions pending for the robot"),
            });
        }
        info!(%robot, id = mission.id, waypoints = mission.waypoints.len(), channel = %h.channel, "mission sent");
        cx.event(Event::MissionSent {
            robot,
            channel: h.channel.clone(),
            id: mission.id,
            waypoints: mission.waypoints,
            looped: mission.looped,
        });
        Delivery::Forwarded(1)
    }

    pub(super) fn on_mission_ack(
        &mut self,
        m: Incoming<'_>,
        ack: MissionAck,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(pending) = self.missions.acknowledged(sender, ack.id) else {
            return Delivery::Consumed;
        };
        if pending.reply_to != Peer::Local {
            self.pass_on(m.bytes, pending.reply_to, &pending.sender, cx);
        }
        info!(
            robot = sender,
            id = ack.id,
            accepted = ack.accepted,
            "mission acknowledged"
        );
        cx.event(Event::MissionAcked {
            robot: sender.to_string(),
            id: ack.id,
            accepted: ack.accepted,
            reason: ack.reason,
        });
        Delivery::Consumed
    }

    /// A fresh mission id (see `super::clock_seed`).
    pub(crate) fn mission_id(&mut self) -> u32 {
        self.missions.next_id()
    }

    /// Resends unacknowledged missions every `mission_retry`; gives up on
    /// one after `mission_give_up`.
    pub(super) fn retry_missions(&mut self, cx: &mut Ctx<'_>) {
        let (retry, give_up) = (self.config.mission_retry, self.config.mission_give_up);
        let due = self.missions.due(cx.now, retry, give_up);
        for (robot, id) in due.given_up {
            warn!(%robot, id, "mission not acknowledged, giving up");
            cx.event(Event::MissionFailed {
                robot,
                id,
                reason: format!("not acknowledged within {:.1} s", give_up.as_secs_f64()),
            });
        }
        for (robot, region) in due.resend {
            let Some(to) = self.target(&robot, cx.now) else {
                continue;
            };
            if let Some(b) = self.gate.seal(&region, &robot, cx.station_us) {
                cx.send(to, b);
                self.count_sent(&robot);
            }
        }
    }
}
