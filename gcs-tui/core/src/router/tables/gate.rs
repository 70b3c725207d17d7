//! The authenticated control plane at the router: every message from a
//! peer is checked (tag, freshness, role) before the tables act on it, and
//! everything the router sends a peer is signed for that peer. Off when the
//! station runs unauthenticated; in-process publishers are the station's
//! own operator and are never checked.
//!
//! [`Gate`] owns the keys, the stamps of what the router signs, the count
//! of rejections and which time requests are answered ([`time`]). How
//! rejections are reported is `super::refusals`'s.

mod time;

use std::collections::HashMap;
use std::time::Duration;

use mech_proto::auth::{FROM_ROUTER, Stamper, Tag, split};
use mech_proto::{Body, Level, MissionAck, Notice, NoticeCode, Time, TimeRequest};
use tokio::time::Instant;
use tracing::warn;

use super::refusals::{Source, Why};
use super::{Ctx, Delivery, Peer, Tables};
use crate::auth::{Identity, Keyring, Rejection, Role};
use crate::counters::{DropReason, RejectReason, Rejections};
use time::{TimeAnswers, Verdict};

/// A message that passed the gate: the key id it was signed with (`None`
/// from an in-process publisher or when authentication is off).
pub(super) type Admitted = Option<u32>;

/// When a message's stamp must be fresh on its stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Fresh {
    /// Always (every message but a time request).
    Always,
    /// When its stamp is within the freshness window of the station's
    /// clock: a time request from a robot whose clock is right (it has
    /// one, or kept station time from before) can be judged like any
    /// message; one from a robot without a clock cannot.
    NearClock,
}

/// Keys, stamps and rejections.
#[derive(Debug)]
pub(super) struct Gate {
    /// Keys and stream freshness; `None` when the station runs
    /// unauthenticated.
    keys: Option<Keyring>,
    /// Stamps of what the router signs.
    stamper: Stamper,
    rejected: Rejections,
    /// Which time requests were answered.
    time_answers: TimeAnswers,
    /// When each key was last told why the station's permissions refused
    /// it (see [`Tables::permit`]).
    told: Told,
}

/// The replies to senders refused by the station's permissions: at most
/// [`Told::BURST`] per key in any [`Told::WINDOW`]. Only keys that signed
/// a fresh message are told, so the map holds at most one entry per key
/// the station lists.
#[derive(Debug, Default)]
struct Told {
    /// Per key id: the window's start and the replies sent in it.
    by_key: HashMap<u32, (Instant, u32)>,
}

impl Told {
    const WINDOW: Duration = Duration::from_secs(1);
    const BURST: u32 = 4;

    /// Whether key `id` may be told once more at `now` (counted if so).
    fn take(&mut self, id: u32, now: Instant) -> bool {
        let (start, n) = self.by_key.entry(id).or_insert((now, 0));
        if now.saturating_duration_since(*start) >= Self::WINDOW {
            (*start, *n) = (now, 0);
        }
        *n += 1;
        *n <= Self::BURST
    }
}

impl Gate {
    pub(super) fn new(keys: Option<Keyring>) -> Gate {
        Gate {
            keys,
            stamper: Stamper::default(),
            rejected: Rejections::default(),
            time_answers: TimeAnswers::default(),
            told: Told::default(),
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

    /// `region` (a message without its `auth` element) with a tag for
    /// `name`, stamped at station time `station_us` or later, or with a nil
    /// tag when authentication is off. `None` if the router holds no key
    /// for `name`.
    pub(super) fn seal(&mut self, region: &[u8], name: &str, station_us: u64) -> Option<Vec<u8>> {
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
        let stamp = self.stamper.next(station_us);
        if let Err(e) = key.seal(&mut bytes, FROM_ROUTER, stamp) {
            warn!(error = %e, "cannot sign");
            return None;
        }
        Some(bytes)
    }
}

impl Tables {
    /// The gate's checks that cost no MAC ([`Keyring::screen`]), made
    /// before a message's body is read: a forgery without a tag, with a key
    /// the station does not list or with another's key costs no decoding
    /// and no MAC. On failure the rejection is counted and reported.
    pub(super) fn screen(
        &mut self,
        bytes: &[u8],
        sender: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<(), Delivery> {
        let Some(keys) = self.gate.keys.as_ref().filter(|_| cx.from != Peer::Local) else {
            return Ok(());
        };
        let checked = match split(bytes) {
            Err(e) => Err(Rejection {
                reason: RejectReason::BadTag,
                detail: format!("from {sender:?}: {e}"),
            }),
            Ok((_, tag)) => keys.screen(tag, sender),
        };
        checked.map_err(|r| self.reject(r, cx))
    }

    /// Checks the tag and freshness of a message from `cx.from`. On failure
    /// the rejection is counted (and reported, summarized) and the delivery
    /// to return is given.
    pub(super) fn admit(
        &mut self,
        bytes: &[u8],
        sender: &str,
        fresh: Fresh,
        cx: &mut Ctx<'_>,
    ) -> Result<(Admitted, Option<Tag>), Delivery> {
        let Some(keys) = self.gate.keys.as_mut().filter(|_| cx.from != Peer::Local) else {
            return Ok((None, None));
        };
        let now_us = cx.station_us;
        let checked = match split(bytes) {
            Err(e) => Err(Rejection {
                reason: RejectReason::BadTag,
                detail: format!("from {sender:?}: {e}"),
            }),
            Ok((region, tag)) => {
                let fresh = match (fresh, tag) {
                    (Fresh::Always, _) => true,
                    (Fresh::NearClock, Some(t)) => keys.near_clock(t.stamp_us, now_us),
                    (Fresh::NearClock, None) => false,
                };
                cx.fx.unproven = !fresh;
                keys.verify(region, tag, sender, now_us, fresh)
                    .map(|v| (Some(v.tag.key_id), Some(v.tag)))
            }
        };
        checked.map_err(|r| self.reject(r, cx))
    }

    /// Checks that the key `admitted` may send `body` on `channel` (to
    /// `destination`). A refused sender is told why, as its message proved
    /// it holds its key and is fresh (a stranger's or a copy never gets
    /// this far), and at most [`Told::BURST`] times a second per key: a
    /// refused mission gets the robot's answer, a [`MissionAck`] that
    /// refuses it, so that a client waiting for one learns why at once;
    /// anything else a [`NoticeCode::NotPermitted`] notice.
    pub(super) fn permit(
        &mut self,
        admitted: Admitted,
        body: &Body,
        to: (&str, &str),
        sender: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<(), Delivery> {
        let (destination, channel) = to;
        let (Some(id), Some(keys)) = (admitted, self.gate.keys.as_ref()) else {
            return Ok(());
        };
        let why = match keys.identity(id) {
            Some(identity) => identity.permits(body, channel),
            None => Some(format!("key {id:08x} was removed")),
        };
        let Some(detail) = why else {
            return Ok(());
        };
        if self.gate.told.take(id, cx.now) {
            let reason = format!("refused by the station: {detail}");
            let (from, reply) = match body {
                Body::Mission(m) => (
                    destination.to_string(),
                    Body::MissionAck(MissionAck {
                        id: m.id,
                        accepted: false,
                        reason,
                    }),
                ),
                _ => (
                    self.config.name.clone(),
                    Body::Notice(Notice {
                        level: Level::Warn,
                        code: NoticeCode::NotPermitted,
                        text: format!("{} to {destination} {reason}", body.kind()),
                    }),
                ),
            };
            if let Some(b) = self.make_as(&from, sender, reply) {
                cx.send(cx.from, b);
            }
        }
        let r = Rejection {
            reason: RejectReason::NotPermitted,
            detail,
        };
        Err(self.reject(r, cx))
    }

    /// Counts a rejection of the message from `cx.from` and reports it
    /// (summarized: see `super::refusals`).
    pub(super) fn reject(&mut self, r: Rejection, cx: &mut Ctx<'_>) -> Delivery {
        self.reject_from(Source::Peer(cx.from), r, cx);
        Delivery::Dropped(DropReason::Rejected)
    }

    /// [`Tables::reject`] for any source.
    fn reject_from(&mut self, source: Source, r: Rejection, cx: &mut Ctx<'_>) {
        self.tap
            .note_refusal(cx.now, || format!("{}: {}", r.reason.as_str(), r.detail));
        self.gate.rejected.count(r.reason);
        self.refused(Why::Rejected(r.reason), source, || r.detail, cx);
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
        self.reject_from(Source::Named(sender.to_string()), r.clone(), cx);
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
        checked.inspect_err(|r| self.reject_from(Source::Named(source.to_string()), r.clone(), cx))
    }

    /// Answers a time request signed with a listed key, unless it is a
    /// copy of one answered before or may be one and its source had an
    /// answer a moment ago (see [`time`]). Unsigned ones (authentication
    /// off) are answered each time.
    pub(super) fn answer_time(
        &mut self,
        request: TimeRequest,
        tag: Option<Tag>,
        sender: &str,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        if let Some(tag) = tag {
            let r = time::Request {
                key_id: tag.key_id,
                link: tag.link,
                stamp_us: tag.stamp_us,
                nonce: request.nonce,
                from: cx.from,
            };
            let why = match self.gate.time_answers.judge(r, cx.now) {
                Verdict::Answer => None,
                Verdict::Repeated => Some(format!(
                    "{sender:?} time request {:016x} was answered before (a copy)",
                    request.nonce
                )),
                Verdict::TooSoon => Some(format!(
                    "{sender:?} time request {:016x} is not newer than one answered, and its \
                     source had an answer less than {} ms ago (a copy?)",
                    request.nonce,
                    time::ANSWER_GAP.as_millis()
                )),
            };
            if let Some(detail) = why {
                let r = Rejection {
                    reason: RejectReason::Replay,
                    detail,
                };
                return self.reject(r, cx);
            }
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
                if let Some(b) = self.gate.seal(region, name, cx.station_us) {
                    cx.send(to, b);
                }
            }
            Err(e) => warn!(error = %e, "cannot re-sign a message to pass on"),
        }
    }
}

#[cfg(test)]
mod tests {
    //! Time requests and the gate, with injected router time and the
    //! station's real clock for stamps (as the gate reads it).
    use std::time::Duration;

    use mech_proto::auth::Key;
    use mech_proto::{Envelope, Header};
    use tokio::time::Instant;

    use super::*;
    use crate::auth::Identity;
    use crate::router::RouterConfig;
    use crate::router::tables::{Effects, Outbox};

    const SECOND: u64 = 1_000_000;

    fn key() -> Key {
        Key::new(&[9; 32])
    }

    /// Tables with robot_1's key, started now (stamps before now are from
    /// before the router started).
    fn tables() -> Tables {
        let robot = Identity::new(Role::Robot, "robot_1", key(), vec![]);
        let ring = Keyring::new(
            vec![robot],
            Duration::from_secs(10),
            mech_proto::unix_micros(),
        );
        Tables::new(RouterConfig::default(), Some(ring))
    }

    fn peer(port: u16) -> Peer {
        Peer::Udp(([127, 0, 0, 1], port).into())
    }

    /// robot_1's time request with `nonce`, signed at `stamp_us`.
    fn request(nonce: u64, stamp_us: u64) -> Vec<u8> {
        let header = Header {
            sender: "robot_1".into(),
            destination: "router".into(),
            ..Header::default()
        };
        let body = Body::TimeRequest(TimeRequest { nonce });
        let mut b = mech_proto::encode(&Envelope::new(header, body)).unwrap();
        key().seal(&mut b, 0, stamp_us).unwrap();
        b
    }

    /// Decides `bytes` from `from` at `now`; returns the peers answered
    /// with a Time carrying the request's nonce.
    fn decide(t: &mut Tables, bytes: &[u8], from: Peer, now: Instant) -> Vec<Peer> {
        let mut fx = Effects::default();
        t.handle(bytes, &mut Ctx::new(now, from, &mut fx));
        let Outbox { owned, .. } = fx.out;
        owned
            .into_iter()
            .filter(|(_, b)| matches!(mech_proto::decode(b).unwrap().body, Body::Time(_)))
            .map(|(p, _)| p)
            .collect()
    }

    /// The attack: one request of a robot without a clock,
    /// captured and replayed every 10 ms (from the attacker's address and
    /// spoofed from the robot's), while the robot asks again every 250 ms
    /// with new nonces and rising stamps: every request of the robot is
    /// answered at once, and no copy is answered again.
    #[test]
    fn copies_of_a_time_request_never_take_the_robots_turn() {
        let (robot, attacker) = (peer(9000), peer(6666));
        let mut t = tables();
        let t0 = Instant::now();
        let booted = 5 * SECOND; // the robot's clock: 1970
        let captured = request(1, booted);
        assert_eq!(decide(&mut t, &captured, robot, t0), [robot]);
        for step in 1..=300u64 {
            let now = t0 + Duration::from_millis(step * 10);
            let from = if step % 3 == 0 { robot } else { attacker };
            assert_eq!(decide(&mut t, &captured, from, now), [], "copy {step}");
            if step % 25 == 0 {
                let mine = request(step, booted + step * 10_000);
                assert_eq!(decide(&mut t, &mine, robot, now), [robot], "at {step}");
            }
        }
        assert_eq!(t.rejections().replay, 300, "every copy refused, counted");
    }

    /// After a station restart the nonces answered before are forgotten:
    /// an old copy gets one answer (signed for the robot, with the old
    /// nonce the robot ignores), never a second.
    #[test]
    fn after_a_restart_an_old_copy_is_answered_once() {
        let (t0, attacker) = (Instant::now(), peer(6666));
        let captured = request(7, 5 * SECOND);
        let mut t = tables();
        assert_eq!(decide(&mut t, &captured, peer(9000), t0), [peer(9000)]);
        let mut restarted = tables();
        let later = t0 + Duration::from_secs(60);
        assert_eq!(
            decide(&mut restarted, &captured, attacker, later),
            [attacker]
        );
        let later = later + Duration::from_secs(1);
        assert_eq!(decide(&mut restarted, &captured, attacker, later), []);
    }

    /// A time request whose freshness could not be judged (from a robot
    /// with no clock yet) is answered, but proves nothing about where it
    /// came from: anyone may have captured it. Its address is not vouched
    /// for (a flood from it is shed like a stranger's), and over TCP it
    /// does not prove the connection. One near the clock does.
    #[test]
    fn a_time_request_without_a_clock_vouches_for_no_address() {
        let (t0, attacker, robot) = (Instant::now(), peer(6666), peer(9000));
        let mut t = tables();
        let mut fx = Effects::default();
        let copy = request(1, 5 * SECOND);
        t.handle(&copy, &mut Ctx::new(t0, attacker, &mut fx));
        assert!(fx.unproven, "answered, unproven");
        let Peer::Udp(a) = attacker else {
            unreachable!()
        };
        assert!(!t.sources.known(a, t0), "a copy vouches for no address");
        let mut fx = Effects::default();
        let fresh = request(2, mech_proto::unix_micros() + 1000);
        t.handle(&fresh, &mut Ctx::new(t0, robot, &mut fx));
        assert!(!fx.unproven);
        let Peer::Udp(r) = robot else { unreachable!() };
        assert!(t.sources.known(r, t0), "a fresh request does");
    }

    /// A request whose stamp is near the station's clock comes from a
    /// robot whose clock is right: it is judged like any message. Stamped
    /// before the router started, or not newer than the robot's stream,
    /// it is a copy.
    #[test]
    fn a_time_request_near_the_clock_must_be_fresh() {
        let (t0, robot) = (Instant::now(), peer(9000));
        let mut t = tables();
        let now_us = mech_proto::unix_micros();
        let before_start = request(1, now_us - 2 * SECOND);
        assert_eq!(decide(&mut t, &before_start, robot, t0), []);
        assert_eq!(t.rejections().replay, 1);
        let fresh = request(2, now_us + 1000);
        assert_eq!(decide(&mut t, &fresh, robot, t0), [robot]);
        // A copy of it with a new nonce cannot exist (the tag covers it);
        // the same bytes again are refused by the stream.
        assert_eq!(decide(&mut t, &fresh, robot, t0), []);
        assert_eq!(t.rejections().replay, 2);
    }

    /// A planner whose key may publish on `wp/planner` only.
    fn planner_tables() -> Tables {
        let planner = Identity::new(
            Role::Controller,
            "planner",
            Key::new(&[7; 32]),
            vec!["wp/planner".into()],
        );
        let ring = Keyring::new(
            vec![planner],
            Duration::from_secs(10),
            mech_proto::unix_micros(),
        );
        Tables::new(RouterConfig::default(), Some(ring))
    }

    /// `body` from the planner to robot_1 on `channel`, signed with `key`
    /// at `stamp_us`.
    fn from_planner(body: Body, channel: &str, key: &Key, stamp_us: u64) -> Vec<u8> {
        let header = Header {
            sender: "planner".into(),
            destination: "robot_1".into(),
            channel: channel.into(),
            ..Header::default()
        };
        let mut b = mech_proto::encode(&Envelope::new(header, body)).unwrap();
        key.seal(&mut b, 0, stamp_us).unwrap();
        b
    }

    /// Everything the router sent for `bytes` from `from` at `now`.
    fn answers(t: &mut Tables, bytes: &[u8], from: Peer, now: Instant) -> Vec<(Peer, Envelope)> {
        let mut fx = Effects::default();
        t.handle(bytes, &mut Ctx::new(now, from, &mut fx));
        let Outbox { owned, .. } = fx.out;
        owned
            .into_iter()
            .map(|(p, b)| (p, mech_proto::decode(&b).unwrap()))
            .collect()
    }

    /// A holder refused by the station's permissions is told why, in its
    /// own answer: a mission gets robot_1's refusing MissionAck, a command
    /// a not-permitted notice; at most `Told::BURST` a second per key, and
    /// a forgery in the holder's name gets nothing back.
    #[test]
    fn a_holder_refused_by_permissions_is_told_why_a_few_times_a_second() {
        let mut t = planner_tables();
        let (key, from, t0) = (Key::new(&[7; 32]), peer(9300), Instant::now());
        let stamp = mech_proto::unix_micros();
        let mission = Body::Mission(mech_proto::Mission {
            id: 17,
            waypoints: vec![],
            looped: false,
            arrival_radius: 0.1,
            start_index: 0,
        });
        let sent = answers(
            &mut t,
            &from_planner(mission.clone(), "wp/gcs", &key, stamp),
            from,
            t0,
        );
        assert_eq!(sent.len(), 1, "{sent:?}");
        let (to, env) = &sent[0];
        assert_eq!(*to, from);
        assert_eq!(env.header.sender, "robot_1");
        assert_eq!(env.header.destination, "planner");
        let Body::MissionAck(ack) = &env.body else {
            panic!("{env:?}");
        };
        assert_eq!(ack.id, 17);
        assert!(!ack.accepted);
        assert_eq!(
            ack.reason,
            "refused by the station: controller planner may not publish on \"wp/gcs\""
        );
        let twist = Body::Command(mech_proto::Command::Twist(mech_proto::Twist::default()));
        let sent = answers(
            &mut t,
            &from_planner(twist.clone(), "ext/x", &key, stamp + 1),
            from,
            t0,
        );
        let Body::Notice(n) = &sent[0].1.body else {
            panic!("{sent:?}");
        };
        assert_eq!(n.code, NoticeCode::NotPermitted);
        assert!(
            n.text.contains("may not publish on \"ext/x\""),
            "{}",
            n.text
        );
        // Ten more in the same second: two more answers (four in all).
        let told: usize = (2..12)
            .map(|k| {
                let b = from_planner(twist.clone(), "ext/x", &key, stamp + k);
                answers(&mut t, &b, from, t0 + Duration::from_millis(k * 10)).len()
            })
            .sum();
        assert_eq!(told, 2);
        assert_eq!(t.gate.rejections().not_permitted, 12);
        // A second later, told again.
        let b = from_planner(twist.clone(), "ext/x", &key, stamp + 20);
        assert_eq!(
            answers(&mut t, &b, from, t0 + Duration::from_secs(1)).len(),
            1
        );
        // Signed with another key in the planner's name: refused earlier,
        // and never answered.
        let later = t0 + Duration::from_secs(5);
        let forged = from_planner(mission, "wp/gcs", &Key::new(&[8; 32]), stamp + 30);
        assert!(answers(&mut t, &forged, peer(9301), later).is_empty());
        // A copy of a refused message (its stamp no longer fresh): nothing.
        let copy = from_planner(twist, "ext/x", &key, stamp + 20);
        assert!(answers(&mut t, &copy, peer(9302), later).is_empty());
    }
}
