//! The router's state and the decision for each message, split by concern.
//! Each file under `tables/` owns its part of the state, so the rules that
//! hold over it read in one place, and handles the message kinds of its
//! concern:
//! - [`registration`]: the registry of robots (Hello, Bye, liveness, the
//!   router's heartbeats, senders that must register again);
//! - [`routes`]: each robot's route, its changes and acknowledgements;
//! - [`commands`]: commands, fleet and cluster commands (the hot path);
//! - [`channels`]: live channels, their publishers and rates, discovery;
//! - [`missions`], [`estop`], [`autopilot`];
//! - [`safety`]: the arena and each robot's safety switch, delivered
//!   reliably, the neighbour lists, what robots report of their layer;
//! - [`telemetry`]: telemetry and its external subscribers, position
//!   fixes, notices;
//! - [`links`] (a robot's links and failover) and [`link_quality`] (each
//!   robot's measured link quality);
//! - [`gate`]: the authenticated control plane (what comes in is checked,
//!   what goes out is signed);
//! - [`traffic`]: the traffic ledger (what is counted received,
//!   forwarded and dropped, router-wide, per robot and per channel);
//! - [`refusals`]: how refused traffic is reported (counted summaries);
//! - [`sources`]: known peers first and failure budgets, under a flood;
//! - [`tap`]: the recorder's tap.
//!
//! Everything here is synchronous and runs under the router's tables lock,
//! held for one decision (or one batch of datagrams): the header read, a
//! command's body checked in place (any other message decoded), a few hash
//! lookups, and for signed traffic a MAC check and a MAC. A decision does
//! no I/O and calls nothing outside the tables: it leaves what to send and
//! what happened in its [`Ctx`]. The caller queues the events in order
//! before it releases the lock, then delivers them and sends (see
//! `super::Shared`).
//!
//! [`Tables::handle`] reads the header, then hands the message to one
//! function per message kind; [`Tables::tick`] runs each concern's timers.

use std::net::SocketAddr;

mod autopilot;
mod channels;
mod commands;
mod estop;
mod gate;
mod link_quality;
mod links;
mod missions;
mod refusals;
mod registration;
mod routes;
mod safety;
mod sources;
pub(crate) mod tap;
mod telemetry;
mod traffic;

use mech_proto::{Body, Envelope, Header};
use tokio::time::Instant;
use tracing::warn;

use super::config::RouterConfig;
use tap::{MessageTap, Tap, TapSlot};

pub(crate) use sources::Treatment;

use crate::auth::{Identity, Keyring};
use crate::counters::{Counters, DropReason, Rejections};
use crate::event::Event;

/// Where a message came from, and where a reply goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Peer {
    Udp(SocketAddr),
    /// A TCP connection, by the router's connection number.
    Tcp(u64),
    /// A serial radio, by its place in `router.serial`: every robot on it
    /// hears what is sent (the destination picks the robot).
    Serial(u16),
    /// The station itself: a publisher inside the GCS process, the
    /// router's handle or its timers.
    Local,
}

impl std::fmt::Display for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Peer::Udp(a) => write!(f, "udp:{a}"),
            Peer::Tcp(n) => write!(f, "tcp#{n}"),
            Peer::Serial(n) => write!(f, "radio#{n}"),
            Peer::Local => f.write_str("gcs"),
        }
    }
}

/// Messages to send once the table lock is released: `raw` targets get the
/// received bytes unchanged (the hot path: no re-encoding), `owned` ones get
/// messages the router made.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    pub(crate) raw: Vec<Peer>,
    pub(crate) owned: Vec<(Peer, Vec<u8>)>,
}

impl Outbox {
    pub(crate) fn is_empty(&self) -> bool {
        self.raw.is_empty() && self.owned.is_empty()
    }

    pub(crate) fn clear(&mut self) {
        self.raw.clear();
        self.owned.clear();
    }
}

/// What decisions make: messages to send and events. Kept by each caller
/// between decisions, so its allocations are reused.
#[derive(Debug, Default)]
pub(crate) struct Effects {
    pub(crate) out: Outbox,
    pub(crate) events: Vec<Event>,
    /// The last message decided passed the gate without its freshness
    /// being judged (a time request from a robot that has no clock yet):
    /// anyone may have captured and sent it again, so it proves nothing
    /// about where it came from.
    pub(crate) unproven: bool,
}

/// One decision's context: when it is made, who asked, and where what it
/// makes goes.
#[derive(Debug)]
pub(crate) struct Ctx<'a> {
    pub(crate) now: Instant,
    /// The station's clock (µs since the Unix epoch) at `now`: what
    /// freshness is judged by and what the router stamps.
    pub(crate) station_us: u64,
    /// Where the message being decided came from; [`Peer::Local`] for the
    /// station's own requests and timers.
    pub(crate) from: Peer,
    fx: &'a mut Effects,
}

impl<'a> Ctx<'a> {
    /// A context at `now`, reading the station's clock.
    pub(crate) fn new(now: Instant, from: Peer, fx: &'a mut Effects) -> Ctx<'a> {
        Ctx::at(now, mech_proto::unix_micros(), from, fx)
    }

    /// A context at `now` and station time `station_us`, read once for a
    /// batch of messages.
    pub(crate) fn at(now: Instant, station_us: u64, from: Peer, fx: &'a mut Effects) -> Ctx<'a> {
        Ctx {
            now,
            station_us,
            from,
            fx,
        }
    }

    /// Sends the received message on to `to`, bytes unchanged.
    fn forward(&mut self, to: Peer) {
        self.fx.out.raw.push(to);
    }

    /// Sends `bytes`, a message the router made or signed, to `to`.
    fn send(&mut self, to: Peer, bytes: Vec<u8>) {
        self.fx.out.owned.push((to, bytes));
    }

    /// Reports what happened.
    fn event(&mut self, e: Event) {
        self.fx.events.push(e);
    }
}

/// What happened to one message, for in-process publishers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Forwarded to this many robots.
    Forwarded(usize),
    /// Not forwarded, for this reason.
    Dropped(DropReason),
    /// A message for the router itself (registration, discovery, acks...).
    Consumed,
}

/// The router's state. See the module docs.
#[derive(Debug)]
pub(crate) struct Tables {
    config: RouterConfig,
    robots: registration::Robots,
    channels: channels::Channels,
    subscribers: telemetry::Subscribers,
    notices: telemetry::Notices,
    missions: missions::Missions,
    estop: estop::EStops,
    safety: safety::SiteSafety,
    gate: gate::Gate,
    refusals: refusals::Refusals,
    sources: sources::Sources,
    ledger: traffic::Ledger,
    tap: TapSlot,
    /// Sequence number of the router's own messages.
    seq: u32,
}

/// A seed for ids that must not repeat across GCS restarts (an agent treats a
/// repeated mission id as the same mission).
fn clock_seed() -> u32 {
    ((mech_proto::unix_micros() / 1_000_000) as u32)
        .max(1)
        .wrapping_mul(16)
}

/// A message being decided: its header and its bytes as received (for
/// messages forwarded unchanged).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Incoming<'a> {
    pub(crate) header: &'a Header,
    pub(crate) bytes: &'a [u8],
}

impl Tables {
    pub(crate) fn new(config: RouterConfig, auth: Option<Keyring>) -> Tables {
        let seed = clock_seed();
        let now = Instant::now();
        Tables {
            config,
            robots: registration::Robots::new(now),
            channels: channels::Channels::default(),
            subscribers: telemetry::Subscribers::default(),
            notices: telemetry::Notices::default(),
            missions: missions::Missions::new(seed),
            estop: estop::EStops::new(seed),
            safety: safety::SiteSafety::new(seed),
            gate: gate::Gate::new(auth),
            refusals: refusals::Refusals::default(),
            sources: sources::Sources::default(),
            ledger: traffic::Ledger::default(),
            tap: TapSlot::default(),
            seq: 0,
        }
    }

    /// Encodes a message from the router itself, counted as sent to
    /// `destination` when that is a robot.
    fn make(&mut self, destination: &str, body: Body) -> Option<Vec<u8>> {
        let sender = self.config.name.clone();
        self.make_as(&sender, destination, body)
    }

    /// [`Tables::make`] with another name as the header's sender: the
    /// router answering for a robot (a mission it refused before the robot
    /// saw it). Signed by the router, as everything it sends.
    fn make_as(&mut self, sender: &str, destination: &str, body: Body) -> Option<Vec<u8>> {
        self.seq = self.seq.wrapping_add(1);
        let station_us = mech_proto::unix_micros();
        let header = Header {
            seq: self.seq,
            stamp_us: station_us,
            sender: sender.to_string(),
            destination: destination.to_string(),
            channel: String::new(),
        };
        match mech_proto::encode(&Envelope::new(header, body)) {
            Ok(mut b) => {
                b.pop(); // the nil auth element: signed for the receiver
                let sealed = self.gate.seal(&b, destination, station_us);
                if sealed.is_some() {
                    self.count_sent(destination);
                }
                sealed
            }
            Err(e) => {
                warn!(error = %e, destination, "router could not encode its own message");
                None
            }
        }
    }

    /// A message that cannot be read or is not expected: counted, and
    /// reported and logged summarized (see [`refusals`]).
    fn bad(&mut self, error: String, cx: &mut Ctx<'_>) -> Delivery {
        self.ledger.dropped(DropReason::BadPacket);
        self.tap.note_refusal(cx.now, || error.clone());
        let from = refusals::Source::Peer(cx.from);
        self.refused(refusals::Why::BadPacket, from, || error, cx);
        Delivery::Dropped(DropReason::BadPacket)
    }

    /// Reports a refusal, summarized: the first after a quiet second at
    /// once, the rest counted into the next summary (see [`Tables::tick`]).
    fn refused(
        &mut self,
        why: refusals::Why,
        from: refusals::Source,
        detail: impl FnOnce() -> String,
        cx: &mut Ctx<'_>,
    ) {
        if let Some(e) = self.refusals.note(why, from, detail, cx.now) {
            cx.event(e);
        }
    }

    /// Decides what to do with one received message, and offers it with the
    /// decision to the recorder's tap when recording.
    pub(crate) fn handle(&mut self, bytes: &[u8], cx: &mut Ctx<'_>) -> Delivery {
        self.ledger.received();
        cx.fx.unproven = false;
        let delivery = self.decide(bytes, cx);
        if let Peer::Udp(addr) = cx.from {
            match delivery {
                Delivery::Dropped(DropReason::Rejected | DropReason::BadPacket) => {
                    self.sources.refused(addr.ip(), cx.now);
                }
                Delivery::Dropped(DropReason::Stopped | DropReason::Shed) => {}
                _ if cx.fx.unproven => {}
                _ => self.sources.vouch(addr, cx.now),
            }
        }
        self.offer(bytes, delivery, cx);
        delivery
    }

    /// Orders a batch of `n` received datagrams from `from(i)` (see
    /// [`sources`]): read it with [`Tables::batch_item`].
    pub(crate) fn order_batch(
        &mut self,
        n: usize,
        from: impl Fn(usize) -> Peer,
        behind: bool,
        now: Instant,
    ) {
        let addr = |i| match from(i) {
            Peer::Udp(a) => Some(a),
            _ => None,
        };
        self.sources.order(n, addr, behind, now);
    }

    /// The `k`-th datagram of the batch last ordered, and what it gets.
    pub(crate) fn batch_item(&self, k: usize) -> (usize, Treatment) {
        self.sources.ordered(k)
    }

    /// A datagram shed unread (see [`sources`]): counted, reported
    /// (summarized) and offered to the recording.
    pub(crate) fn shed(&mut self, bytes: &[u8], cx: &mut Ctx<'_>) -> Delivery {
        self.ledger.received();
        let delivery = self.ledger.dropped(DropReason::Shed);
        if let Peer::Udp(addr) = cx.from {
            let refused = self.sources.failing(addr.ip(), cx.now).unwrap_or(0);
            let why = || {
                format!(
                    "not read: the router was behind, and {} had {refused} messages refused \
                     in the last second",
                    addr.ip()
                )
            };
            self.tap.note_refusal(cx.now, why);
            let from = refusals::Source::Peer(cx.from);
            self.refused(refusals::Why::Shed, from, why, cx);
        }
        self.offer(bytes, delivery, cx);
        delivery
    }

    /// Offers a decided message to the recording, when recording.
    fn offer(&mut self, bytes: &[u8], delivery: Delivery, cx: &mut Ctx<'_>) {
        let detail = self.tap.take_refusal();
        if let Some(tap) = self.tap.for_message(delivery, cx.now) {
            tap.message(MessageTap {
                now: cx.now,
                number: self.ledger.received_so_far(),
                from: cx.from,
                bytes,
                delivery,
                detail,
            });
        }
    }

    /// The decision for one received message.
    fn decide(&mut self, bytes: &[u8], cx: &mut Ctx<'_>) -> Delivery {
        let head = match mech_proto::peek(bytes) {
            Ok(h) => h,
            Err(e) => return self.bad(e.to_string(), cx),
        };
        if let Err(d) = self.screen(bytes, head.sender, cx) {
            return d;
        }
        if head.kind == mech_proto::COMMAND_KIND {
            // The body is checked (a truncated or out-of-range command is
            // never forwarded) but not re-encoded: the received bytes go on.
            // Checked in place: no envelope is built for a forwarded command.
            let command = match mech_proto::check_command(bytes, &head) {
                Ok(c) => c,
                Err(e) => return self.bad(e.to_string(), cx),
            };
            let admitted = match self.admit(bytes, head.sender, gate::Fresh::Always, cx) {
                Ok((id, _)) => id,
                Err(d) => return d,
            };
            let body = Body::Command(command);
            let to = (head.destination, head.channel);
            if let Err(d) = self.permit(admitted, &body, to, head.sender, cx) {
                return d;
            }
            return self.route_command(&head, bytes, cx);
        }
        let env = match mech_proto::decode(bytes) {
            Ok(env) => env,
            Err(e) => return self.bad(e.to_string(), cx),
        };
        let sender = env.header.sender.as_str();
        // A time request's stamp can be judged only if the requester's
        // clock is right: it may not know the station's time yet.
        let fresh = match env.body {
            Body::TimeRequest(_) => gate::Fresh::NearClock,
            _ => gate::Fresh::Always,
        };
        let (admitted, tag) = match self.admit(bytes, sender, fresh, cx) {
            Ok(a) => a,
            Err(d) => return d,
        };
        let to = (env.header.destination.as_str(), env.header.channel.as_str());
        if let Err(d) = self.permit(admitted, &env.body, to, sender, cx) {
            return d;
        }
        if let Body::TimeRequest(request) = env.body {
            return self.answer_time(request, tag, sender, cx);
        }
        if matches!(cx.from, Peer::Udp(_) | Peer::Serial(_)) {
            self.seen_robot(sender, env.header.seq, cx);
        }
        let m = Incoming {
            header: &env.header,
            bytes,
        };
        self.dispatch(m, env.body, cx)
    }

    /// One function per message kind (commands took the hot path above).
    fn dispatch(&mut self, m: Incoming<'_>, body: Body, cx: &mut Ctx<'_>) -> Delivery {
        match body {
            Body::Hello(hello) => self.on_hello(m, hello, cx),
            Body::Heartbeat(hb) => self.on_heartbeat(m, hb, cx),
            Body::Telemetry(t) => self.on_telemetry(m, t, cx),
            Body::FleetCommand(fc) => self.on_fleet_command(m, fc, cx),
            Body::Mission(mission) => self.on_mission(m, mission, cx),
            Body::MissionAck(ack) => self.on_mission_ack(m, ack, cx),
            Body::RouteAck(ack) => self.on_route_ack(m, ack, cx),
            Body::EStop(e) => self.on_estop(m, e, cx),
            Body::EStopAck(ack) => self.on_estop_ack(m, ack, cx),
            Body::ChannelsRequest(_) => self.on_channels_request(m, cx),
            Body::Subscribe(s) => self.on_subscribe(m, s, cx),
            Body::PositionFix(fix) => self.on_position_fix(m, fix, cx),
            Body::Notice(notice) => self.on_notice(m, notice, cx),
            Body::Cluster(command) => self.on_cluster(m, command, cx),
            Body::Bye(bye) => self.on_bye(m, bye, cx),
            Body::TimeRequest(_) => Delivery::Consumed,
            Body::Autopilot(request) => self.on_autopilot(m, request, cx),
            Body::ArenaAck(ack) => self.on_arena_ack(m, ack, cx),
            Body::Command(_)
            | Body::Welcome(_)
            | Body::Route(_)
            | Body::Channels(_)
            | Body::Time(_)
            | Body::Arena(_)
            | Body::Neighbours(_) => {
                let what = format!("unexpected {} message", body.kind());
                self.bad(what, cx)
            }
        }
    }

    /// Timers: link states, heartbeats, retries, lapsed subscriptions.
    pub(crate) fn tick(&mut self, cx: &mut Ctx<'_>) {
        self.update_links(cx);
        self.report_links(cx);
        self.roll_link_quality(cx);
        self.send_heartbeats(cx);
        self.retry_routes(cx);
        self.retry_estop(cx);
        self.retry_missions(cx);
        self.retry_arenas(cx);
        self.subscribers.lapse(cx.now);
        self.report_held_notices(cx);
        if let Some(e) = self.refusals.due(cx.now) {
            cx.event(e);
        }
    }

    /// A copy of the counters the tables keep (send failures are added by
    /// the caller, from `super::net`).
    pub(crate) fn counters(&self) -> Counters {
        let (robots, channels) = (self.robots.traffic(), self.channels.traffic());
        self.ledger
            .counters(robots, channels, self.gate.rejections())
    }

    /// Messages received so far.
    pub(crate) fn received(&self) -> u64 {
        self.ledger.received_so_far()
    }

    pub(crate) fn rejections(&self) -> Rejections {
        self.gate.rejections()
    }

    /// Counts a bad frame seen outside [`Tables::handle`] (a radio frame
    /// that failed its checksum, a TCP stream out of step).
    pub(crate) fn count_bad(&mut self, error: String, cx: &mut Ctx<'_>) {
        self.bad(error, cx);
    }

    /// Forgets a peer that went away (its telemetry subscription).
    pub(crate) fn forget_peer(&mut self, peer: Peer) {
        self.subscribers.remove(peer);
    }

    /// Whether messages are checked and signed.
    pub(crate) fn auth_on(&self) -> bool {
        self.gate.on()
    }

    /// Adds a key to the keyring (none when unauthenticated).
    pub(crate) fn add_key(&mut self, identity: Identity) {
        self.gate.add_key(identity);
    }

    /// The identity of a key id, when authenticating.
    pub(crate) fn identity(&self, key_id: u32) -> Option<Identity> {
        self.gate.identity(key_id)
    }

    /// Whether `robot` is registered.
    pub(crate) fn knows_robot(&self, robot: &str) -> bool {
        self.robots.contains(robot)
    }

    /// The recorder's tap, while recording.
    pub(crate) fn tap(&self) -> Option<&Tap> {
        self.tap.get()
    }

    /// Puts a tap on (or takes it off), returning the one that was on.
    pub(crate) fn set_tap(&mut self, tap: Option<Tap>) -> Option<Tap> {
        self.tap.set(tap)
    }
}

#[cfg(test)]
mod tests {
    //! The timing rules, with injected time: exact thresholds that the
    //! socket-level tests (real time, real threads) can only bound.
    use std::time::Duration;

    use mech_proto::{Body, Envelope, Header, Hello, Mission, Waypoint};

    use crate::event::LinkState;

    use super::*;

    /// Runs `f` in a context at `now` from `from`, its messages and events
    /// appended to `out` and `ev`.
    fn in_ctx<R>(
        now: Instant,
        from: Peer,
        out: &mut Outbox,
        ev: &mut Vec<Event>,
        f: impl FnOnce(&mut Ctx<'_>) -> R,
    ) -> R {
        let mut fx = Effects {
            out: std::mem::take(out),
            events: std::mem::take(ev),
            unproven: false,
        };
        let r = f(&mut Ctx::new(now, from, &mut fx));
        (*out, *ev) = (fx.out, fx.events);
        r
    }

    /// The tables' entry points with time, source and effects spelt out.
    impl Tables {
        fn handle_at(
            &mut self,
            bytes: &[u8],
            from: Peer,
            now: Instant,
            out: &mut Outbox,
            ev: &mut Vec<Event>,
        ) -> Delivery {
            in_ctx(now, from, out, ev, |cx| self.handle(bytes, cx))
        }

        fn tick_at(&mut self, now: Instant, out: &mut Outbox, ev: &mut Vec<Event>) {
            in_ctx(now, Peer::Local, out, ev, |cx| self.tick(cx))
        }

        fn set_route_at(
            &mut self,
            robot: &str,
            channel: Option<&str>,
            now: Instant,
            out: &mut Outbox,
            ev: &mut Vec<Event>,
        ) -> Option<u32> {
            in_ctx(now, Peer::Local, out, ev, |cx| {
                self.set_route(robot, channel, cx)
            })
        }

        fn start_estop_at(
            &mut self,
            engage: bool,
            now: Instant,
            out: &mut Outbox,
            ev: &mut Vec<Event>,
        ) -> u32 {
            in_ctx(now, Peer::Local, out, ev, |cx| self.start_estop(engage, cx))
        }

        fn farewell_at(&mut self, out: &mut Outbox) {
            let now = Instant::now();
            in_ctx(now, Peer::Local, out, &mut Vec::new(), |cx| {
                self.farewell(cx)
            })
        }
    }

    fn bytes(sender: &str, destination: &str, channel: &str, body: Body) -> Vec<u8> {
        let header = Header {
            sender: sender.into(),
            destination: destination.into(),
            channel: channel.into(),
            ..Header::default()
        };
        mech_proto::encode(&Envelope::new(header, body)).unwrap()
    }

    fn hello(name: &str) -> Vec<u8> {
        let h = Hello {
            name: name.into(),
            platform: "diff-drive".into(),
            capabilities: vec![],
            motors: 2,
            max_speed: 1.0,
            max_yaw_rate: 2.0,
            agent_version: "t".into(),
        };
        bytes(name, "router", "", Body::Hello(h))
    }

    fn registered(t0: Instant) -> (Tables, Peer) {
        let mut t = Tables::new(RouterConfig::default(), None);
        let robot = Peer::Udp("127.0.0.1:9000".parse().unwrap());
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        t.handle_at(&hello("robot_1"), robot, t0, &mut out, &mut ev);
        (t, robot)
    }

    fn links(ev: &[Event]) -> Vec<LinkState> {
        ev.iter()
            .filter_map(|e| match e {
                Event::Link { state, .. } => Some(*state),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_silent_robot_is_stale_at_half_a_second_and_lost_at_one() {
        let t0 = Instant::now();
        let (mut t, _) = registered(t0);
        let ms = |v| t0 + Duration::from_millis(v);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        t.tick_at(ms(499), &mut out, &mut ev);
        assert!(links(&ev).is_empty());
        t.tick_at(ms(500), &mut out, &mut ev);
        assert_eq!(links(&ev), vec![LinkState::Stale]);
        t.tick_at(ms(999), &mut out, &mut ev);
        t.tick_at(ms(1000), &mut out, &mut ev);
        assert_eq!(links(&ev), vec![LinkState::Stale, LinkState::Lost]);
    }

    fn welcomed_ids(ev: &[Event]) -> Vec<(String, u16)> {
        ev.iter()
            .filter_map(|e| match e {
                Event::Registered { hello, id, .. } => Some((hello.name.clone(), *id)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_robot_gets_the_number_its_name_ends_with_whatever_the_order() {
        let t0 = Instant::now();
        let mut t = Tables::new(RouterConfig::default(), None);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        for (k, name) in [
            "robot_10", "rover", "robot_2", "rover_2", "robot_1", "robot_10",
        ]
        .into_iter()
        .enumerate()
        {
            let peer = Peer::Udp(format!("127.0.0.1:{}", 9000 + k).parse().unwrap());
            t.handle_at(&hello(name), peer, t0, &mut out, &mut ev);
        }
        assert_eq!(
            welcomed_ids(&ev),
            [
                ("robot_10".to_string(), 10),
                ("rover".to_string(), 65535),
                ("robot_2".to_string(), 2),
                ("rover_2".to_string(), 65534),
                ("robot_1".to_string(), 1),
                ("robot_10".to_string(), 10),
            ],
            "the name's number; taken or none: the highest free id; again: the same id"
        );
    }

    #[test]
    fn a_stopping_router_says_bye_to_every_robot() {
        let (mut t, robot) = registered(Instant::now());
        let mut out = Outbox::default();
        t.farewell_at(&mut out);
        let byes: Vec<_> = out
            .owned
            .iter()
            .map(|(p, b)| (*p, mech_proto::decode(b).unwrap()))
            .filter(|(_, m)| matches!(m.body, Body::Bye(_)))
            .collect();
        assert_eq!(byes.len(), 1);
        assert_eq!(byes[0].0, robot);
        assert_eq!(byes[0].1.header.destination, "robot_1");
    }

    #[test]
    fn heartbeats_go_out_every_quarter_second() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let beats = |out: &Outbox| {
            out.owned
                .iter()
                .filter(|(p, b)| {
                    *p == robot && matches!(mech_proto::decode(b).unwrap().body, Body::Heartbeat(_))
                })
                .count()
        };
        let mut out = Outbox::default();
        let mut ev = Vec::new();
        for ms in (20..=1000).step_by(20) {
            t.tick_at(t0 + Duration::from_millis(ms), &mut out, &mut ev);
        }
        // A quarter second after the last, on the 20 ms timer grid: at
        // 0.26, 0.52 and 0.78 s (the next is due at 1.03 s).
        assert_eq!(beats(&out), 3);
    }

    /// The robot's link, measured from what it sends: its Hello was number 1
    /// (see `registered`), then heartbeats numbered 2..=41 with every
    /// fourth missing, the last echoing the router's heartbeat.
    #[test]
    fn link_quality_is_reported_every_second_from_sequence_gaps_and_echoes() {
        let t0 = Instant::now();
        let mut t = Tables::new(RouterConfig::default(), None);
        let robot = Peer::Udp("127.0.0.1:9000".parse().unwrap());
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let numbered = |seq: u32, body: Body| {
            let header = Header {
                seq,
                sender: "robot_1".into(),
                destination: "router".into(),
                ..Header::default()
            };
            mech_proto::encode(&Envelope::new(header, body)).unwrap()
        };
        let hello = match mech_proto::decode(&hello("robot_1")).unwrap().body {
            b @ Body::Hello(_) => b,
            _ => unreachable!(),
        };
        t.handle_at(&numbered(1, hello), robot, t0, &mut out, &mut ev);
        // The router's heartbeat at 260 ms; its sequence number is the echo's.
        t.tick_at(t0 + Duration::from_millis(260), &mut out, &mut ev);
        let beat = out
            .owned
            .iter()
            .map(|(_, b)| mech_proto::decode(b).unwrap())
            .find(|e| matches!(e.body, Body::Heartbeat(_)))
            .expect("a router heartbeat");
        for seq in (2..=41).filter(|s| s % 4 != 0) {
            let at = t0 + Duration::from_millis(300 + u64::from(seq) * 10);
            let echo = (seq == 41).then_some(mech_proto::Echo {
                seq: beat.header.seq,
                held_us: 400_000,
            });
            let hb = Body::Heartbeat(mech_proto::Heartbeat { uptime_ms: 0, echo });
            t.handle_at(&numbered(seq, hb), robot, at, &mut out, &mut ev);
        }
        ev.clear();
        t.tick_at(t0 + Duration::from_millis(1000), &mut out, &mut ev);
        let q = ev
            .iter()
            .find_map(|e| match e {
                Event::LinkQuality { robot, quality } if robot == "robot_1" => Some(*quality),
                _ => None,
            })
            .expect("a link report after a second");
        // 31 of 41 arrived (10 of 2..=41 are multiples of 4).
        assert_eq!((q.received, q.lost), (31, 10));
        assert!((q.loss.unwrap() - 10.0 / 41.0).abs() < 1e-9, "{q:?}");
        assert!((q.rx_hz - 31.0).abs() < 1e-9, "{q:?}");
        // Sent: the Welcome and the heartbeat.
        assert_eq!(q.sent, 2);
        // Heartbeat out at 260 ms, echo back at 710 ms, held 400 ms.
        assert_eq!(q.rtt, Some(Duration::from_millis(50)));
    }

    /// Mission `id`: one waypoint, 1 m along x.
    fn one_waypoint_mission(id: u32) -> Body {
        Body::Mission(Mission {
            id,
            waypoints: vec![Waypoint {
                x: 1.0,
                y: 0.0,
                z: 0.0,
                time: None,
            }],
            looped: false,
            arrival_radius: 0.1,
            start_index: 0,
        })
    }

    #[test]
    fn a_mission_is_resent_every_200_ms_and_given_up_after_5_s() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let mission = one_waypoint_mission(7);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        t.handle_at(
            &bytes("gcs", "robot_1", "wp/gcs", mission),
            Peer::Local,
            t0,
            &mut out,
            &mut ev,
        );
        let sends = |out: &Outbox| {
            out.owned
                .iter()
                .filter(|(p, b)| {
                    *p == robot && matches!(mech_proto::decode(b).unwrap().body, Body::Mission(_))
                })
                .count()
        };
        assert_eq!(sends(&out), 1);
        let mut out = Outbox::default();
        t.tick_at(t0 + Duration::from_millis(199), &mut out, &mut ev);
        assert_eq!(sends(&out), 0);
        t.tick_at(t0 + Duration::from_millis(200), &mut out, &mut ev);
        assert_eq!(sends(&out), 1);
        t.tick_at(t0 + Duration::from_millis(4_999), &mut out, &mut ev);
        assert!(!ev.iter().any(|e| matches!(e, Event::MissionFailed { .. })));
        t.tick_at(t0 + Duration::from_millis(5_000), &mut out, &mut ev);
        assert!(
            ev.iter()
                .any(|e| matches!(e, Event::MissionFailed { id: 7, .. }))
        );
    }

    /// A sender outrunning a robot that never answers keeps at most
    /// `PENDING_PER_ROBOT` missions waiting (bytes held, resent every
    /// 200 ms): each past that gives up the oldest at once, reported like
    /// a timeout.
    #[test]
    fn missions_waiting_for_one_robot_are_capped_and_the_oldest_given_up() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let n = missions::PENDING_PER_ROBOT as u32 + 40;
        for id in 1..=n {
            let mission = one_waypoint_mission(id);
            t.handle_at(
                &bytes("gcs", "robot_1", "wp/gcs", mission),
                Peer::Local,
                t0,
                &mut out,
                &mut ev,
            );
        }
        let failed: Vec<u32> = ev
            .iter()
            .filter_map(|e| match e {
                Event::MissionFailed { id, .. } => Some(*id),
                _ => None,
            })
            .collect();
        assert_eq!(failed, (1..=40).collect::<Vec<_>>(), "the oldest, in order");
        // Only the newest are resent.
        let mut out = Outbox::default();
        t.tick_at(t0 + Duration::from_millis(200), &mut out, &mut ev);
        let resent: Vec<u32> = out
            .owned
            .iter()
            .filter(|(p, _)| *p == robot)
            .filter_map(|(_, b)| match mech_proto::decode(b).unwrap().body {
                Body::Mission(m) => Some(m.id),
                _ => None,
            })
            .collect();
        assert_eq!(resent, (41..=n).collect::<Vec<_>>());
    }

    #[test]
    fn a_robot_on_wifi_and_a_radio_is_commanded_on_the_live_link_and_estopped_on_both() {
        let t0 = Instant::now();
        let ms = |v| t0 + Duration::from_millis(v);
        let (mut t, wifi) = registered(t0);
        let radio = Peer::Serial(0);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let hb = bytes(
            "robot_1",
            "router",
            "",
            Body::Heartbeat(mech_proto::Heartbeat::new(1)),
        );
        t.handle_at(&hb, radio, ms(10), &mut out, &mut ev);
        t.set_route_at("robot_1", Some("joy/0"), ms(20), &mut out, &mut ev);
        let twist = bytes(
            "pad",
            "robot_1",
            "joy/0",
            Body::Command(mech_proto::Command::Twist(mech_proto::Twist {
                vx: 0.1,
                ..Default::default()
            })),
        );
        let sent_to = |t: &mut Tables, at| {
            let mut out = Outbox::default();
            t.handle_at(&twist, Peer::Local, at, &mut out, &mut Vec::new());
            out.raw
        };
        assert_eq!(sent_to(&mut t, ms(100)), vec![wifi], "UDP while live");
        t.handle_at(&hb, radio, ms(350), &mut out, &mut ev);
        assert_eq!(
            sent_to(&mut t, ms(400)),
            vec![radio],
            "UDP silent 400 ms: the radio"
        );
        t.handle_at(&hb, wifi, ms(500), &mut out, &mut ev);
        assert_eq!(sent_to(&mut t, ms(510)), vec![wifi], "UDP back");
        let mut out = Outbox::default();
        t.start_estop_at(true, ms(520), &mut out, &mut ev);
        let estops: Vec<Peer> = out.owned.iter().map(|(p, _)| *p).collect();
        assert_eq!(estops, vec![wifi, radio], "the e-stop on every link");
        let mut ev = Vec::new();
        t.tick_at(ms(530), &mut Outbox::default(), &mut ev);
        let links = ev.iter().find_map(|e| match e {
            Event::Links { links, .. } => Some(links.clone()),
            _ => None,
        });
        let links = links.expect("a radio robot's links are reported");
        assert!(links.udp && links.active == "udp" && links.radio.is_some());
    }

    #[test]
    fn a_subscription_lapses_after_five_seconds_unless_renewed() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let tool = Peer::Udp("127.0.0.1:9100".parse().unwrap());
        let sub = bytes(
            "plotter",
            "router",
            "",
            Body::Subscribe(mech_proto::Subscribe { telemetry: true }),
        );
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        t.handle_at(&sub, tool, t0, &mut out, &mut ev);
        t.tick_at(t0 + Duration::from_millis(4_999), &mut out, &mut ev);
        assert!(t.subscribers.contains(tool));
        t.tick_at(t0 + Duration::from_millis(5_001), &mut out, &mut ev);
        assert!(!t.subscribers.contains(tool), "lapsed");
        let _ = robot;
    }

    /// A peer's notices reach the log and the operators twenty a second;
    /// the rest are counted and said in one line once the second is over,
    /// and the next second shows them again.
    #[test]
    fn a_peer_flooding_notices_shows_twenty_a_second_and_the_count_of_the_rest() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let notice = |k: u32| {
            bytes(
                "robot_1",
                "router",
                "",
                Body::Notice(mech_proto::Notice {
                    level: mech_proto::Level::Error,
                    code: mech_proto::NoticeCode::Text,
                    text: format!("n{k}"),
                }),
            )
        };
        let shown = |ev: &[Event]| -> Vec<String> {
            ev.iter()
                .filter_map(|e| match e {
                    Event::Notice { notice, .. } => Some(notice.text.clone()),
                    _ => None,
                })
                .collect()
        };
        for k in 0..100 {
            let at = t0 + Duration::from_millis(5 * u64::from(k));
            t.handle_at(&notice(k), robot, at, &mut out, &mut ev);
        }
        let first: Vec<String> = (0..20).map(|k| format!("n{k}")).collect();
        assert_eq!(shown(&ev), first);
        ev.clear();
        t.tick_at(t0 + Duration::from_millis(999), &mut out, &mut ev);
        assert!(shown(&ev).is_empty(), "the second is not over");
        t.tick_at(t0 + Duration::from_millis(1_000), &mut out, &mut ev);
        assert_eq!(
            shown(&ev),
            ["80 more notices from robot_1 in a second were not shown"]
        );
        ev.clear();
        let later = t0 + Duration::from_millis(1_100);
        t.handle_at(&notice(100), robot, later, &mut out, &mut ev);
        assert_eq!(shown(&ev), ["n100"]);
    }

    /// Channel names are the publishers' to choose: the table keeps
    /// `CHANNELS`, a new one taking the place of the one silent longest.
    #[test]
    fn the_channel_table_keeps_the_channels_heard_from_last() {
        let t0 = Instant::now();
        let (mut t, _) = registered(t0);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let tool = Peer::Udp(SocketAddr::from(([127, 0, 0, 1], 9200)));
        let n = channels::CHANNELS + 10;
        for k in 0..n {
            let twist = Body::Command(mech_proto::Command::Twist(mech_proto::Twist::default()));
            let at = t0 + Duration::from_millis(k as u64);
            let b = bytes("tool", "robot_1", &format!("ext/{k}"), twist);
            t.handle_at(&b, tool, at, &mut out, &mut ev);
        }
        assert_eq!(t.channels.len(), channels::CHANNELS);
        assert!(!t.channels.contains("ext/0") && !t.channels.contains("ext/9"));
        assert!(t.channels.contains("ext/10") && t.channels.contains(&format!("ext/{}", n - 1)));
    }

    /// Every telemetry message goes to each subscriber, so one name cannot
    /// subscribe from more than `SUBSCRIBERS_PER_NAME` addresses, nor
    /// everyone together more than `SUBSCRIBERS`; a renewal always passes,
    /// and a refusal is counted as not permitted.
    #[test]
    fn telemetry_subscriptions_are_capped_per_name_and_in_all() {
        use super::telemetry::{SUBSCRIBERS, SUBSCRIBERS_PER_NAME};
        let t0 = Instant::now();
        let (mut t, _) = registered(t0);
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        let sub = |name: &str| {
            bytes(
                name,
                "router",
                "",
                Body::Subscribe(mech_proto::Subscribe { telemetry: true }),
            )
        };
        let at = |port: u16| Peer::Udp(SocketAddr::from(([127, 0, 0, 1], port)));
        for port in 0..SUBSCRIBERS_PER_NAME as u16 + 3 {
            t.handle_at(&sub("plotter"), at(10_000 + port), t0, &mut out, &mut ev);
        }
        let theirs = (0..SUBSCRIBERS_PER_NAME as u16 + 3)
            .filter(|p| t.subscribers.contains(at(10_000 + p)))
            .count();
        assert_eq!(theirs, SUBSCRIBERS_PER_NAME);
        assert_eq!(t.gate.rejections().not_permitted, 3);
        // A renewal from an address already subscribed passes.
        let d = t.handle_at(&sub("plotter"), at(10_000), t0, &mut out, &mut ev);
        assert_eq!(d, Delivery::Consumed);
        for k in 0..SUBSCRIBERS as u16 {
            t.handle_at(
                &sub(&format!("tool{k}")),
                at(20_000 + k),
                t0,
                &mut out,
                &mut ev,
            );
        }
        let all = (0..SUBSCRIBERS as u16)
            .filter(|k| t.subscribers.contains(at(20_000 + k)))
            .count();
        assert_eq!(all + SUBSCRIBERS_PER_NAME, SUBSCRIBERS);
    }
}
