//! Missions: forwarded to their robot, repeated until it acknowledges the
//! id or reported failed after `mission_give_up`; the acknowledgement goes
//! back to whoever sent the mission.

use mech_proto::{Mission, MissionAck};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{Delivery, Incoming, Outbox, Peer, PendingMission, Tables};
use crate::counters::DropReason;
use crate::event::Event;

impl Tables {
    pub(super) fn on_mission(
        &mut self,
        m: Incoming<'_>,
        mission: Mission,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let h = m.header;
        let robot = h.destination.clone();
        self.note_publisher(&h.sender, &h.channel, m.from, m.now, events);
        let Some(entry) = self.robots.get_mut(&robot) else {
            self.dropped.count(DropReason::UnknownRobot);
            return Delivery::Dropped(DropReason::UnknownRobot);
        };
        entry.traffic.forwarded += 1;
        let to = self.target(&robot, m.now);
        self.forwarded += 1;
        let region = match mech_proto::auth::split(m.bytes) {
            Ok((region, _)) => region.to_vec(),
            Err(e) => return self.bad(m.from, e.to_string(), events),
        };
        if let (Some(b), Some(to)) = (self.seal(&region, &robot), to) {
            out.owned.push((to, b));
        }
        self.missions
            .retain(|p| !(p.robot == robot && p.id == mission.id));
        self.missions.push(PendingMission {
            robot: robot.clone(),
            id: mission.id,
            region,
            reply_to: m.from,
            sender: h.sender.clone(),
            first: m.now,
            last: m.now,
        });
        info!(%robot, id = mission.id, waypoints = mission.waypoints.len(), channel = %h.channel, "mission sent");
        events.push(Event::MissionSent {
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
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(i) = self
            .missions
            .iter()
            .position(|p| p.robot == sender && p.id == ack.id)
        else {
            return Delivery::Consumed;
        };
        let pending = self.missions.remove(i);
        if pending.reply_to != Peer::Local {
            self.pass_on(m.bytes, pending.reply_to, &pending.sender, out);
        }
        info!(
            robot = sender,
            id = ack.id,
            accepted = ack.accepted,
            "mission acknowledged"
        );
        events.push(Event::MissionAcked {
            robot: sender.to_string(),
            id: ack.id,
            accepted: ack.accepted,
            reason: ack.reason,
        });
        Delivery::Consumed
    }

    /// A fresh mission id (see [`clock_seed`]).
    pub(crate) fn mission_id(&mut self) -> u32 {
        self.next_mission_id = self.next_mission_id.wrapping_add(1);
        self.next_mission_id
    }

    /// Resends unacknowledged missions every `mission_retry`; gives up on
    /// one after `mission_give_up`.
    pub(super) fn retry_missions(
        &mut self,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) {
        let (retry, give_up) = (self.config.mission_retry, self.config.mission_give_up);
        let timeout = self.config.link_timeout;
        let robots = &self.robots;
        let mut due = Vec::new();
        self.missions.retain_mut(|m| {
            if now.saturating_duration_since(m.first) >= give_up {
                warn!(robot = %m.robot, id = m.id, "mission not acknowledged, giving up");
                events.push(Event::MissionFailed {
                    robot: m.robot.clone(),
                    id: m.id,
                    reason: format!("not acknowledged within {:.1} s", give_up.as_secs_f64()),
                });
                return false;
            }
            if now.saturating_duration_since(m.last) >= retry {
                m.last = now;
                if let Some(to) = robots
                    .get(&m.robot)
                    .and_then(|r| r.links.target(now, timeout))
                {
                    due.push((to, m.robot.clone(), m.region.clone()));
                }
            }
            true
        });
        for (to, robot, region) in due {
            if let Some(b) = self.seal(&region, &robot) {
                out.owned.push((to, b));
            }
        }
    }
}
