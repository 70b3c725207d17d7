//! Telemetry and the other traffic for the station itself: telemetry fans
//! out to external subscribers and becomes an event (and, when the robot's
//! safety layer changed, a safety event, `super::safety`); subscriptions lapse
//! unless renewed; position fixes go to their robot; notices, which also
//! go to the station's log (its file), at their own level.
//!
//! A peer's notices reach the log and the operators at most
//! [`NOTICES_PER_SECOND`] a second ([`Notices`]); the rest are counted and
//! said in one line once the second is over.
//!
//! [`Subscribers`] holds the external telemetry subscribers (a tool over
//! UDP or TCP), each until its subscription lapses: at most
//! [`SUBSCRIBERS`], and [`SUBSCRIBERS_PER_NAME`] for one sender name, since
//! every telemetry message is sent to each (a name's key is not tied to an
//! address, so one sender could otherwise subscribe from many).

use std::collections::HashMap;

use mech_proto::{Level, Notice, PositionFix, Subscribe, Telemetry};
use tokio::time::Instant;

use super::{Ctx, Delivery, Incoming, Peer, Tables};
use crate::counters::DropReason;
use crate::event::Event;

/// Most notices of one sender shown (logged, and sent to the operators)
/// in a second.
pub(super) const NOTICES_PER_SECOND: u32 = 20;

/// Most senders whose notices are counted at once (a new one past that
/// starts the count afresh for all).
const NOTICE_SENDERS: usize = 4096;

/// How many notices each sender had shown and held back in its current
/// second.
#[derive(Debug, Default)]
pub(super) struct Notices {
    by_sender: HashMap<String, NoticeCount>,
}

#[derive(Debug, Clone, Copy)]
struct NoticeCount {
    since: Instant,
    shown: u32,
    held: u32,
}

impl Notices {
    /// Whether a notice from `sender` at `now` is shown (else it is
    /// counted, for [`Notices::due`]).
    fn admit(&mut self, sender: &str, now: Instant) -> bool {
        if !self.by_sender.contains_key(sender) && self.by_sender.len() >= NOTICE_SENDERS {
            self.by_sender.clear();
        }
        if !self.by_sender.contains_key(sender) {
            let fresh = NoticeCount {
                since: now,
                shown: 0,
                held: 0,
            };
            self.by_sender.insert(sender.to_string(), fresh);
        }
        let Some(c) = self.by_sender.get_mut(sender) else {
            return false;
        };
        if c.shown < NOTICES_PER_SECOND {
            c.shown += 1;
            true
        } else {
            c.held += 1;
            false
        }
    }

    /// The senders whose second ended by `now` with notices held back, and
    /// how many; every sender whose second ended starts afresh.
    fn due(&mut self, now: Instant) -> Vec<(String, u32)> {
        let mut held = Vec::new();
        self.by_sender.retain(|sender, c| {
            if now.saturating_duration_since(c.since) < std::time::Duration::from_secs(1) {
                return true;
            }
            if c.held > 0 {
                held.push((sender.clone(), c.held));
            }
            false
        });
        held
    }
}

/// Most telemetry subscribers at once.
pub(super) const SUBSCRIBERS: usize = 64;

/// Most subscriptions of one sender name (from as many addresses).
pub(super) const SUBSCRIBERS_PER_NAME: usize = 4;

/// External telemetry subscribers, by where they are.
#[derive(Debug, Default)]
pub(super) struct Subscribers {
    by_peer: HashMap<Peer, Subscriber>,
}

#[derive(Debug)]
struct Subscriber {
    /// When the subscription lapses unless renewed.
    until: Instant,
    /// The subscriber's name, to sign what it is sent.
    name: String,
}

impl Subscribers {
    /// Subscribes (or renews) `peer` as `name` until `until`; a new one
    /// past the limits is refused: `Err` says which.
    fn subscribe(&mut self, peer: Peer, name: &str, until: Instant) -> Result<(), String> {
        if !self.by_peer.contains_key(&peer) {
            if self.by_peer.len() >= SUBSCRIBERS {
                return Err(format!("{SUBSCRIBERS} telemetry subscribers already"));
            }
            let theirs = self.by_peer.values().filter(|s| s.name == name).count();
            if theirs >= SUBSCRIBERS_PER_NAME {
                return Err(format!(
                    "{name:?} has {SUBSCRIBERS_PER_NAME} telemetry subscriptions already"
                ));
            }
        }
        self.by_peer.insert(
            peer,
            Subscriber {
                until,
                name: name.to_string(),
            },
        );
        Ok(())
    }

    pub(super) fn remove(&mut self, peer: Peer) {
        self.by_peer.remove(&peer);
    }

    /// Drops the subscriptions that lapsed by `now`.
    pub(super) fn lapse(&mut self, now: Instant) {
        self.by_peer.retain(|_, s| s.until > now);
    }

    /// Every subscriber: where, and its name.
    fn list(&self) -> Vec<(Peer, String)> {
        self.by_peer
            .iter()
            .map(|(peer, s)| (*peer, s.name.clone()))
            .collect()
    }

    #[cfg(test)]
    pub(super) fn contains(&self, peer: Peer) -> bool {
        self.by_peer.contains_key(&peer)
    }
}

impl Tables {
    pub(super) fn on_telemetry(
        &mut self,
        m: Incoming<'_>,
        t: Telemetry,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let sender = m.header.sender.as_str();
        let Some(robot) = self.robots.get_mut(sender) else {
            self.unknown_robot(m, cx);
            return self.ledger.dropped(DropReason::UnknownRobot);
        };
        if let Peer::Serial(_) = cx.from {
            robot.links.radio_telemetry(m.bytes.len());
        }
        for (peer, name) in self.subscribers.list() {
            self.pass_on(m.bytes, peer, &name, cx);
        }
        if let Some(e) = self.safety.reported(sender, t.safety) {
            cx.event(e);
        }
        cx.event(Event::Telemetry {
            robot: sender.to_string(),
            telemetry: t,
        });
        Delivery::Consumed
    }

    pub(super) fn on_subscribe(
        &mut self,
        m: Incoming<'_>,
        s: Subscribe,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        if s.telemetry {
            let until = cx.now + self.config.subscriber_timeout;
            if let Err(detail) = self.subscribers.subscribe(cx.from, &m.header.sender, until) {
                let r = crate::auth::Rejection {
                    reason: crate::counters::RejectReason::NotPermitted,
                    detail,
                };
                return self.reject(r, cx);
            }
        } else {
            self.subscribers.remove(cx.from);
        }
        Delivery::Consumed
    }

    pub(super) fn on_position_fix(
        &mut self,
        m: Incoming<'_>,
        fix: PositionFix,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        match self.target(&fix.robot, cx.now) {
            Some(to) => {
                self.pass_on(m.bytes, to, &fix.robot, cx);
                self.count_sent(&fix.robot);
                Delivery::Consumed
            }
            None => self.ledger.dropped(DropReason::UnknownRobot),
        }
    }

    /// A notice (a robot's "autopilot found", a refusal, a fault): an event
    /// for the operator's log, and a line in the station's log file, where
    /// whoever reads the file afterwards finds what the robots said.
    pub(super) fn on_notice(
        &mut self,
        m: Incoming<'_>,
        notice: Notice,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let (from, text, code) = (&m.header.sender, &notice.text, notice.code);
        if !self.notices.admit(from, cx.now) {
            return Delivery::Consumed;
        }
        match notice.level {
            Level::Debug => tracing::debug!(%from, ?code, "notice: {text}"),
            Level::Info => tracing::info!(%from, ?code, "notice: {text}"),
            Level::Warn => tracing::warn!(%from, ?code, "notice: {text}"),
            Level::Error => tracing::error!(%from, ?code, "notice: {text}"),
        }
        cx.event(Event::Notice {
            from: m.header.sender.clone(),
            notice,
        });
        Delivery::Consumed
    }
}

impl Tables {
    /// Says, for each peer whose second of notices is over, how many were
    /// not shown.
    pub(super) fn report_held_notices(&mut self, cx: &mut Ctx<'_>) {
        for (from, held) in self.notices.due(cx.now) {
            let text = format!("{held} more notices from {from} in a second were not shown");
            tracing::warn!(%from, held, "{text}");
            let notice = Notice {
                level: Level::Warn,
                code: mech_proto::NoticeCode::Text,
                text,
            };
            cx.event(Event::Notice { from, notice });
        }
    }
}
