//! The e-stop: engaged or released for every robot at once, repeated to
//! each robot until it acknowledges; an engaged e-stop is latched, so a
//! robot that registers later is stopped too.

use std::collections::HashSet;

use mech_proto::{Body, EStop, EStopAck};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{Delivery, EStopRun, Incoming, Outbox, Peer, Tables};
use crate::event::Event;

impl Tables {
    pub(super) fn on_estop(
        &mut self,
        m: Incoming<'_>,
        e: EStop,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        info!(from = %m.from, engage = e.engage, "e-stop requested by {}", m.header.sender);
        self.start_estop(e.engage, m.now, out, events);
        Delivery::Consumed
    }

    pub(super) fn on_estop_ack(
        &mut self,
        m: Incoming<'_>,
        ack: EStopAck,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(run) = self.estop.as_mut() else {
            return Delivery::Consumed;
        };
        if run.id != ack.id || run.engage != ack.engage || !run.pending.remove(sender) {
            return Delivery::Consumed;
        }
        events.push(Event::EStopAcked {
            robot: sender.to_string(),
            engage: ack.engage,
            id: ack.id,
        });
        if run.pending.is_empty() {
            info!(
                engage = run.engage,
                id = run.id,
                "every robot acknowledged the e-stop"
            );
            events.push(Event::EStopComplete {
                engage: run.engage,
                id: run.id,
            });
            self.estop = None;
        }
        Delivery::Consumed
    }

    /// Engages or releases the e-stop for every robot, repeated until each
    /// acknowledges. Returns its id.
    pub(crate) fn start_estop(
        &mut self,
        engage: bool,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> u32 {
        self.next_estop_id = self.next_estop_id.wrapping_add(1);
        let id = self.next_estop_id;
        self.estop_latched = engage.then_some(id);
        let pending: HashSet<String> = self.robots.keys().cloned().collect();
        if engage {
            warn!(id, robots = pending.len(), "E-STOP engaged");
        } else {
            warn!(id, robots = pending.len(), "e-stop released");
        }
        events.push(Event::EStop { engage, id });
        let names: Vec<String> = self.robots.keys().cloned().collect();
        for name in names {
            self.send_estop(&name, EStop { engage, id }, out);
        }
        if pending.is_empty() {
            events.push(Event::EStopComplete { engage, id });
            self.estop = None;
        } else {
            self.estop = Some(EStopRun {
                engage,
                id,
                pending,
                last: now,
            });
        }
        id
    }

    /// Sends an e-stop or release to `robot` on every link it has (each
    /// copy signed afresh): whichever arrives first stops it, and the
    /// robot obeys an id once.
    fn send_estop(&mut self, robot: &str, e: EStop, out: &mut Outbox) {
        let links: Vec<Peer> = match self.robots.get(robot) {
            Some(r) => r.links.all().collect(),
            None => return,
        };
        for peer in links {
            if let Some(b) = self.make(robot, Body::EStop(e)) {
                out.owned.push((peer, b));
            }
        }
    }

    /// A robot registering while the e-stop is latched is stopped too.
    pub(super) fn estop_newcomer(&mut self, robot: &str, now: Instant, out: &mut Outbox) {
        let Some(id) = self.estop_latched else {
            return;
        };
        let run = self.estop.get_or_insert_with(|| EStopRun {
            engage: true,
            id,
            pending: HashSet::new(),
            last: now,
        });
        if run.engage && run.id == id {
            run.pending.insert(robot.to_string());
            self.send_estop(robot, EStop { engage: true, id }, out);
        }
    }

    /// Resends the e-stop (or release) to every robot that has not
    /// acknowledged it, every `estop_retry`.
    pub(super) fn retry_estop(&mut self, now: Instant, out: &mut Outbox) {
        let retry = self.config.estop_retry;
        let Some(run) = self.estop.as_mut() else {
            return;
        };
        if now.saturating_duration_since(run.last) < retry {
            return;
        }
        run.last = now;
        let e = EStop {
            engage: run.engage,
            id: run.id,
        };
        let due: Vec<String> = run.pending.iter().cloned().collect();
        for name in due {
            self.send_estop(&name, e, out);
        }
    }
}
