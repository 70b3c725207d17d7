//! The authenticated control plane at the router: every message from a
//! peer is checked (tag, freshness, role) before the tables act on it, and
//! everything the router sends a peer is signed for that peer. Off when the
//! station runs unauthenticated; in-process publishers are the station's
//! own operator and are never checked.
//!
//! [`Gate`] owns the keys, the stamps of what the router signs, the count
//! of rejections and the memory that rate-limits their logging and the
//! answers to time requests.

use std::collections::HashMap;
use std::time::Duration;

use mech_proto::auth::{FROM_ROUTER, Stamper, Tag, split};
use mech_proto::{Body, Time, TimeRequest};
use tokio::time::Instant;
use tracing::warn;

use super::{Ctx, Delivery, Peer, Tables};
use crate::auth::{Identity, Keyring, Rejection, Role};
use crate::counters::{DropReason, RejectReason, Rejections};
use crate::event::Event;

/// The shortest time between two answers to one key's time requests: a
/// replayed request cannot make the router a reflector.
const TIME_ANSWER_GAP: Duration = Duration::from_millis(100);

/// Distinct sources whose last rejection log line is remembered; beyond
/// that the memory is cleared (a flood from many sources logs more, never
/// grows the table without bound).
const REJECT_LOG_SOURCES: usize = 4096;

/// A message that passed the gate: the key id it was signed with (`None`
/// from an in-process publisher or when authentication is off).
pub(super) type Admitted = Option<u32>;

/// Keys, stamps and rejections.
#[derive(Debug)]
pub(super) struct Gate {
    /// Keys and stream freshness; `None` when the station runs
    /// unauthenticated.
    keys: Option<Keyring>,
    /// Stamps of what the router signs.
    stamper: Stamper,
    rejected: Rejections,
    /// When each source's last rejection was logged.
    reject_logged: HashMap<String, Instant>,
    /// When each key's last time request was answered.
    time_answers: HashMap<u32, Instant>,
}

impl Gate {
    pub(super) fn new(keys: Option<Keyring>) -> Gate {
        Gate {
            keys,
            stamper: Stamper::default(),
            rejected: Rejections::default(),
            reject_logged: HashMap::new(),
            time_answers: HashMap::new(),
        }
    }

    /// Whether messages are checked and signed.
    pub(super) fn on(&self) -> bool {
        self.keys.is_some()
    }

    pub(super) fn add_key(&mut self, identity: Identity) {
        if let Some(keys) = self.keys.as_mut() {
            keys.add(identity);
        }
    }

    pub(super) fn identity(&self, key_id: u32) -> Option<Identity> {
        self.keys.as_ref()?.identity(key_id).cloned()
    }

    pub(super) fn rejections(&self) -> Rejections {
        self.rejected
    }

    /// Counts a rejection from `source`; `true` when it is due to be logged
    /// and reported (at most once per source per second).
    fn count_rejection(&mut self, source: &str, reason: RejectReason, now: Instant) -> bool {
        self.rejected.count(reason);
        let due = self
            .reject_logged
            .get(source)
            .is_none_or(|t| now.saturating_duration_since(*t) >= Duration::from_secs(1));
        if due {
            if self.reject_logged.len() >= REJECT_LOG_SOURCES {
                self.reject_logged.clear();
            }
            self.reject_logged.insert(source.to_string(), now);
        }
        due
    }

    /// Whether a time request signed with `key_id` may be answered at
    /// `now` (noted as answered when it may).
    fn time_answer_due(&mut self, key_id: u32, now: Instant) -> bool {
        let recent = self
            .time_answers
            .get(&key_id)
            .is_some_and(|t| now.saturating_duration_since(*t) < TIME_ANSWER_GAP);
        if !recent {
            self.time_answers.insert(key_id, now);
        }
        !recent
    }

    /// `region` (a message without its `auth` element) with a tag for
    /// `name`, or with a nil tag when authentication is off. `None` if the
    /// router holds no key for `name`.
    pub(super) fn seal(&mut self, region: &[u8], name: &str) -> Option<Vec<u8>> {
        let mut bytes = Vec::with_capacity(region.len() + mech_proto::auth::TAG_LEN + 2);
        bytes.extend_from_slice(region);
        bytes.push(0xc0);
        let Some(keys) = self.keys.as_ref() else {
            return Some(bytes);
        };
        let Some(key) = keys.key_for(name) else {
            warn!(to = name, "no key to sign for this receiver; not sent");
            return None;
        };
        let stamp = self.stamper.next(mech_proto::unix_micros());
        if let Err(e) = key.seal(&mut bytes, FROM_ROUTER, stamp) {
            warn!(error = %e, "cannot sign");
            return None;
        }
        Some(bytes)
    }
}

impl Tables {
    /// Checks the tag and freshness of a message from `cx.from`. On failure
    /// the rejection is counted (and logged, rate-limited) and the delivery
    /// to return is given.
    pub(super) fn admit(
        &mut self,
        bytes: &[u8],
        sender: &str,
        fresh: bool,
        cx: &mut Ctx<'_>,
    ) -> Result<(Admitted, Option<Tag>), Delivery> {
        let Some(keys) = self.gate.keys.as_mut().filter(|_| cx.from != Peer::Local) else {
            return Ok((None, None));
        };
        let checked = match split(bytes) {
            Err(e) => Err(Rejection {
                reason: RejectReason::BadTag,
                detail: format!("from {sender:?}: {e}"),
            }),
            Ok((region, tag)) => keys
                .verify(region, tag, sender, mech_proto::unix_micros(), fresh)
                .map(|v| (Some(v.tag.key_id), Some(v.tag))),
        };
        checked.map_err(|r| self.reject(r, cx))
    }

    /// Checks that the key `admitted` may send `body` on `channel`.
    pub(super) fn permit(
        &mut self,
        admitted: Admitted,
        body: &Body,
        channel: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<(), Delivery> {
        let (Some(id), Some(keys)) = (admitted, self.gate.keys.as_ref()) else {
            return Ok(());
        };
        let why = match keys.identity(id) {
            Some(identity) => identity.permits(body, channel),
            None => Some(format!("key {id:08x} was removed")),
        };
        match why {
            None => Ok(()),
            Some(detail) => {
                let r = Rejection {
                    reason: RejectReason::NotPermitted,
                    detail,
                };
                Err(self.reject(r, cx))
            }
        }
    }

    /// Counts a rejection of the message from `cx.from`; logs it and
    /// reports it as an event at most once per source per second.
    fn reject(&mut self, r: Rejection, cx: &mut Ctx<'_>) -> Delivery {
        self.reject_from(cx.from.to_string(), r, cx);
        Delivery::Dropped(DropReason::Rejected)
    }

    /// [`Tables::reject`] for a source named by text.
    fn reject_from(&mut self, source: String, r: Rejection, cx: &mut Ctx<'_>) {
        self.tap
            .note_refusal(|| format!("{}: {}", r.reason.as_str(), r.detail));
        if !self.gate.count_rejection(&source, r.reason, cx.now) {
            return;
        }
        let total = self.gate.rejected.total();
        warn!(from = %source, reason = r.reason.as_str(), total, "rejected: {}", r.detail);
        cx.event(Event::Rejected {
            from: source,
            reason: r.reason,
            detail: r.detail,
        });
    }

    /// The gate for a publisher inside the station that carries messages
    /// from beyond it under its own name (a bridge to other stations): the
    /// key listed as `sender` must permit `body` on `channel`, as if
    /// `sender` had signed it. Everything passes when the station runs
    /// unauthenticated. A refusal is counted and reported.
    pub(crate) fn permit_named(
        &mut self,
        sender: &str,
        body: &Body,
        channel: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<(), Rejection> {
        let Some(keys) = self.gate.keys.as_ref() else {
            return Ok(());
        };
        let identity = keys.key_for(sender).and_then(|k| keys.identity(k.id()));
        let why = match identity {
            Some(identity) => identity.permits(body, channel),
            None => Some(format!("{sender:?} has no key in [auth]")),
        };
        let Some(detail) = why else {
            return Ok(());
        };
        let r = Rejection {
            reason: RejectReason::NotPermitted,
            detail,
        };
        self.reject_from(sender.to_string(), r.clone(), cx);
        Err(r)
    }

    /// Checks a request signed outside the message protocol (a route
    /// request from another station, received from `source`): `tag` must be
    /// a fresh tag over `region` by the key listed as `sender`, a key with
    /// `role`. A refusal is counted and reported.
    pub(crate) fn verify_signed(
        &mut self,
        source: &str,
        sender: &str,
        signed: (&[u8], Tag),
        role: Role,
        cx: &mut Ctx<'_>,
    ) -> Result<(), Rejection> {
        let (region, tag) = signed;
        let checked = match self.gate.keys.as_mut() {
            None => Err(Rejection {
                reason: RejectReason::UnknownKey,
                detail: "this station runs unauthenticated: it holds no key to check a \
                         signature with"
                    .into(),
            }),
            Some(keys) => keys
                .verify(region, Some(tag), sender, mech_proto::unix_micros(), true)
                .and_then(|v| match v.identity.role {
                    r if r == role => Ok(()),
                    other => Err(Rejection {
                        reason: RejectReason::NotPermitted,
                        detail: format!(
                            "{sender:?} is a {}, not an {}",
                            other.as_str(),
                            role.as_str()
                        ),
                    }),
                }),
        };
        checked.inspect_err(|r| self.reject_from(source.to_string(), r.clone(), cx))
    }

    /// Answers a time request signed with a listed key (its stamp may be
    /// anything: the requester does not know the time yet), at most every
    /// [`TIME_ANSWER_GAP`] per key.
    pub(super) fn answer_time(
        &mut self,
        request: TimeRequest,
        tag: Option<Tag>,
        sender: &str,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let key_id = tag.map_or(0, |t| t.key_id);
        if !self.gate.time_answer_due(key_id, cx.now) {
            return Delivery::Consumed;
        }
        let body = Body::Time(Time {
            nonce: request.nonce,
            station_us: mech_proto::unix_micros(),
        });
        if let Some(b) = self.make(sender, body) {
            cx.send(cx.from, b);
        }
        Delivery::Consumed
    }

    /// Sends received `bytes` on to `to`, the peer named `name`: unchanged
    /// when authentication is off, signed for the receiver when it is on.
    pub(super) fn pass_on(&mut self, bytes: &[u8], to: Peer, name: &str, cx: &mut Ctx<'_>) {
        if !self.gate.on() || to == Peer::Local {
            cx.forward(to);
            return;
        }
        match split(bytes) {
            Ok((region, _)) => {
                if let Some(b) = self.gate.seal(region, name) {
                    cx.send(to, b);
                }
            }
            Err(e) => warn!(error = %e, "cannot re-sign a message to pass on"),
        }
    }
}
