//! The e-stop: engaged or released for every robot at once, repeated to
//! each robot until it acknowledges; an engaged e-stop is latched, so a
//! robot that registers later is stopped too.
//!
//! [`EStops`] holds the run in progress (the robots that have not yet
//! acknowledged it; there is at most one, a newer e-stop or release
//! replaces it) and the latch (the id of an engaged, unreleased e-stop).

use std::collections::HashSet;
use std::time::Duration;

use mech_proto::{Body, EStop, EStopAck};
use tokio::time::Instant;
use tracing::{info, warn};

use super::{Ctx, Delivery, Incoming, Peer, Tables};
use crate::event::Event;

/// The e-stop in progress, the latch, and the ids handed out.
#[derive(Debug)]
pub(super) struct EStops {
    run: Option<EStopRun>,
    /// E-stop engaged and not released: robots that register get it too.
    latched: Option<u32>,
    next_id: u32,
}

#[derive(Debug)]
struct EStopRun {
    engage: bool,
    id: u32,
    pending: HashSet<String>,
    last: Instant,
}

/// What an acknowledgement did to the run in progress.
#[derive(Debug, PartialEq, Eq)]
enum Acked {
    /// Not for the run in progress, or already counted.
    Ignored,
    /// Counted; others still to acknowledge.
    Counted,
    /// Counted, and every robot has now acknowledged.
    Complete,
}

impl EStops {
    /// Ids start from `seed` (see `super::clock_seed`).
    pub(super) fn new(seed: u32) -> EStops {
        EStops {
            run: None,
            latched: None,
            next_id: seed,
        }
    }

    /// Starts a new e-stop (or release) for `robots`, in place of any in
    /// progress; returns its id, and whether it is complete already (no
    /// robots).
    fn start(&mut self, engage: bool, robots: HashSet<String>, now: Instant) -> (u32, bool) {
        self.next_id = self.next_id.wrapping_add(1);
        let id = self.next_id;
        self.latched = engage.then_some(id);
        let complete = robots.is_empty();
        self.run = (!complete).then_some(EStopRun {
            engage,
            id,
            pending: robots,
            last: now,
        });
        (id, complete)
    }

    /// `robot` acknowledged e-stop `id` (`engage`).
    fn ack(&mut self, robot: &str, id: u32, engage: bool) -> Acked {
        let Some(run) = self.run.as_mut() else {
            return Acked::Ignored;
        };
        if run.id != id || run.engage != engage || !run.pending.remove(robot) {
            return Acked::Ignored;
        }
        if run.pending.is_empty() {
            self.run = None;
            Acked::Complete
        } else {
            Acked::Counted
        }
    }

    /// The latched e-stop a newly registered `robot` must get (added to the
    /// run in progress, or to a new run), if any.
    fn newcomer(&mut self, robot: &str, now: Instant) -> Option<EStop> {
        let id = self.latched?;
        let run = self.run.get_or_insert_with(|| EStopRun {
            engage: true,
            id,
            pending: HashSet::new(),
            last: now,
        });
        if !(run.engage && run.id == id) {
            return None;
        }
        run.pending.insert(robot.to_string());
        Some(EStop { engage: true, id })
    }

    /// The e-stop to send again at `now` (every `retry`) and the robots
    /// that still owe an acknowledgement.
    fn due(&mut self, now: Instant, retry: Duration) -> Option<(EStop, Vec<String>)> {
        let run = self.run.as_mut()?;
        if now.saturating_duration_since(run.last) < retry {
            return None;
        }
        run.last = now;
        let e = EStop {
            engage: run.engage,
            id: run.id,
        };
        Some((e, run.pending.iter().cloned().collect()))
    }
}

impl Tables {
    pub(super) fn on_estop(&mut self, m: Incoming<'_>, e: EStop, cx: &mut Ctx<'_>) -> Delivery {
        info!(from = %cx.from, engage = e.engage, "e-stop requested by {}", m.header.sender);
        self.start_estop(e.engage, cx);
        Delivery::Consumed
    }

    pub(super) fn on_estop_ack(
        &mut self,
        m: Incoming<'_>,
        ack: EStopAck,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let acked = self.estop.ack(sender, ack.id, ack.engage);
        if acked == Acked::Ignored {
            return Delivery::Consumed;
        }
        cx.event(Event::EStopAcked {
            robot: sender.to_string(),
            engage: ack.engage,
            id: ack.id,
        });
        if acked == Acked::Complete {
            info!(
                engage = ack.engage,
                id = ack.id,
                "every robot acknowledged the e-stop"
            );
            cx.event(Event::EStopComplete {
                engage: ack.engage,
                id: ack.id,
            });
        }
        Delivery::Consumed
    }

    /// Engages or releases the e-stop for every robot, repeated until each
    /// acknowledges. Returns its id.
    pub(crate) fn start_estop(&mut self, engage: bool, cx: &mut Ctx<'_>) -> u32 {
        let robots: HashSet<String> = self.robots.names().cloned().collect();
        let count = robots.len();
        let (id, complete) = self.estop.start(engage, robots, cx.now);
        if engage {
            warn!(id, robots = count, "E-STOP engaged");
        } else {
            warn!(id, robots = count, "e-stop released");
        }
        cx.event(Event::EStop { engage, id });
        let names: Vec<String> = self.robots.names().cloned().collect();
        for name in names {
            self.send_estop(&name, EStop { engage, id }, cx);
        }
        if complete {
            cx.event(Event::EStopComplete { engage, id });
        }
        id
    }

    /// Sends an e-stop or release to `robot` on every link it has (each
    /// copy signed afresh): whichever arrives first stops it, and the
    /// robot obeys an id once.
    fn send_estop(&mut self, robot: &str, e: EStop, cx: &mut Ctx<'_>) {
        let links: Vec<Peer> = match self.robots.get(robot) {
            Some(r) => r.links.all().collect(),
            None => return,
        };
        for peer in links {
            if let Some(b) = self.make(robot, Body::EStop(e)) {
                cx.send(peer, b);
            }
        }
    }

    /// A robot registering while the e-stop is latched is stopped too.
    pub(super) fn estop_newcomer(&mut self, robot: &str, cx: &mut Ctx<'_>) {
        if let Some(e) = self.estop.newcomer(robot, cx.now) {
            self.send_estop(robot, e, cx);
        }
    }

    /// Resends the e-stop (or release) to every robot that has not
    /// acknowledged it, every `estop_retry`.
    pub(super) fn retry_estop(&mut self, cx: &mut Ctx<'_>) {
        let Some((e, due)) = self.estop.due(cx.now, self.config.estop_retry) else {
            return;
        };
        for name in due {
            self.send_estop(&name, e, cx);
        }
    }
}
