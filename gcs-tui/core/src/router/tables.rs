//! The router's shared state and the decision for each message: who is
//! registered where, the routing table, live channels, pending missions and
//! e-stops, external subscribers and counters.
//!
//! Everything here is synchronous and runs under one `std::sync::Mutex` held
//! for a few hash lookups; the socket tasks call [`Tables::handle`] and then
//! send what it put in the [`Outbox`] after releasing the lock. Events are
//! collected and emitted after the lock is released, too.
//!
//! [`Tables::handle`] reads the header, then hands the message to one
//! function per message kind, grouped by concern: [`registration`] (Hello,
//! Bye, liveness, heartbeats), [`commands`] (commands, fleet and cluster
//! commands: the hot path), [`routes`] (route changes and acks),
//! [`missions`], [`estop`] and [`telemetry`] (telemetry, subscriptions,
//! position fixes, channel discovery, notices), [`autopilot`] (operators'
//! requests to a robot's autopilot), [`links`] (a robot's links and
//! failover) and [`link_quality`] (each robot's measured link quality).
//! [`Tables::tick`] runs each concern's timers.
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;

mod autopilot;
mod commands;
mod estop;
mod gate;
mod link_quality;
mod links;
mod missions;
mod registration;
mod routes;
pub(crate) mod tap;
mod telemetry;

use mech_proto::{Body, Envelope, Header};
use tokio::time::Instant;
use tracing::{debug, warn};

use super::config::RouterConfig;
use super::rate::RateMeter;

use mech_proto::auth::Stamper;
use tap::{MessageTap, Tap};

use crate::auth::Keyring;
use crate::counters::{Counters, DropReason, Drops, Rejections, Traffic};
use crate::event::{Event, LinkState};

/// Where a message came from, and where a reply goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Peer {
    Udp(SocketAddr),
    /// A TCP connection, by the router's connection number.
    Tcp(u64),
    /// A serial radio, by its place in `router.serial`: every robot on it
    /// hears what is sent (the destination picks the robot).
    Serial(u16),
    /// A publisher inside the GCS process.
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

#[derive(Debug)]
struct RobotEntry {
    id: u16,
    /// Where the robot is heard (UDP, a radio), and so where to send.
    links: links::Links,
    last_seen: Instant,
    link: LinkState,
    route: Option<String>,
    epoch: u32,
    /// The robot acknowledged `epoch`.
    acked: bool,
    route_sent: Instant,
    heartbeat_sent: Instant,
    traffic: Traffic,
    /// Rates each way, loss and round trip (see [`link_quality`]).
    meter: link_quality::LinkMeter,
}

#[derive(Debug)]
struct ChannelEntry {
    publisher: String,
    last: Instant,
    rate: RateMeter,
    traffic: Traffic,
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

#[derive(Debug)]
struct EStopRun {
    engage: bool,
    id: u32,
    pending: HashSet<String>,
    last: Instant,
}

/// The router's state. See the module docs.
#[derive(Debug)]
pub(crate) struct Tables {
    config: RouterConfig,
    robots: HashMap<String, RobotEntry>,
    channels: HashMap<String, ChannelEntry>,
    /// Last address of each controller or tool, by sender name, for replies.
    peers: HashMap<String, Peer>,
    /// External telemetry subscribers: when their subscription lapses, and
    /// their name (to sign what they are sent).
    subscribers: HashMap<Peer, (Instant, String)>,
    missions: Vec<PendingMission>,
    estop: Option<EStopRun>,
    /// E-stop engaged and not released: robots that register get it too.
    estop_latched: Option<u32>,
    next_estop_id: u32,
    next_mission_id: u32,
    seq: u32,
    received: u64,
    forwarded: u64,
    dropped: Drops,
    fanout_dropped: u64,
    /// Keys and stream freshness; `None` when the station runs
    /// unauthenticated.
    auth: Option<Keyring>,
    /// Stamps of what the router signs.
    stamper: Stamper,
    rejected: Rejections,
    /// When each source's last rejection was logged.
    reject_logged: HashMap<String, Instant>,
    /// When each key's last time request was answered.
    time_answers: HashMap<u32, Instant>,
    /// When the router started, for the uptime in its heartbeats.
    started: Instant,
    /// The recorder's tap, while recording.
    pub(super) tap: Option<Tap>,
    /// Why the message being decided was refused or unreadable, kept for
    /// the tap (only while recording).
    refusal: Option<String>,
    /// When each unknown robot was last told to register again.
    unknown_told: HashMap<String, Instant>,
}

/// A seed for ids that must not repeat across GCS restarts (an agent treats a
/// repeated mission id as the same mission).
fn clock_seed() -> u32 {
    ((mech_proto::unix_micros() / 1_000_000) as u32)
        .max(1)
        .wrapping_mul(16)
}

/// A message being handled: its header and where it came from.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Incoming<'a> {
    pub(crate) header: &'a Header,
    /// The bytes as received, for messages forwarded unchanged.
    pub(crate) bytes: &'a [u8],
    pub(crate) from: Peer,
    pub(crate) now: Instant,
}

impl Tables {
    pub(crate) fn new(config: RouterConfig, auth: Option<Keyring>) -> Tables {
        let seed = clock_seed();
        Tables {
            config,
            robots: HashMap::new(),
            channels: HashMap::new(),
            peers: HashMap::new(),
            subscribers: HashMap::new(),
            missions: Vec::new(),
            estop: None,
            estop_latched: None,
            next_estop_id: seed,
            next_mission_id: seed,
            seq: 0,
            received: 0,
            forwarded: 0,
            dropped: Default::default(),
            fanout_dropped: 0,
            auth,
            stamper: Stamper::default(),
            rejected: Rejections::default(),
            reject_logged: HashMap::new(),
            time_answers: HashMap::new(),
            started: Instant::now(),
            tap: None,
            refusal: None,
            unknown_told: HashMap::new(),
        }
    }

    /// Encodes a message from the router itself, counted as sent to
    /// `destination` when that is a robot.
    fn make(&mut self, destination: &str, body: Body) -> Option<Vec<u8>> {
        self.seq = self.seq.wrapping_add(1);
        let header = Header {
            seq: self.seq,
            stamp_us: mech_proto::unix_micros(),
            sender: self.config.name.clone(),
            destination: destination.to_string(),
            channel: String::new(),
        };
        match mech_proto::encode(&Envelope::new(header, body)) {
            Ok(mut b) => {
                b.pop(); // the nil auth element: signed for the receiver
                let sealed = self.seal(&b, destination);
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

    fn bad(&mut self, from: Peer, error: String, events: &mut Vec<Event>) -> Delivery {
        self.dropped.count(DropReason::BadPacket);
        self.note_refusal(|| error.clone());
        let n = self.dropped.bad_packet;
        // Logged at warn for the 1st, 2nd, 4th, 8th... so a flood of garbage
        // cannot flood the log; every one is counted and reported as an event.
        if n.is_power_of_two() {
            warn!(%from, %error, count = n, "bad packet");
        } else {
            debug!(%from, %error, "bad packet");
        }
        events.push(Event::BadPacket {
            from: from.to_string(),
            error,
        });
        Delivery::Dropped(DropReason::BadPacket)
    }

    /// Keeps why the message being decided was refused, for the tap.
    fn note_refusal(&mut self, why: impl FnOnce() -> String) {
        if self.tap.is_some() {
            self.refusal = Some(why());
        }
    }

    /// Decides what to do with one received message, and offers it with the
    /// decision to the recorder's tap when recording.
    pub(crate) fn handle(
        &mut self,
        bytes: &[u8],
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        self.received += 1;
        let delivery = self.decide(bytes, from, now, out, events);
        if let Some(tap) = &self.tap {
            tap.message(MessageTap {
                now,
                number: self.received,
                from,
                bytes,
                delivery,
                detail: self.refusal.take(),
            });
        }
        delivery
    }

    /// The decision for one received message.
    fn decide(
        &mut self,
        bytes: &[u8],
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let head = match mech_proto::peek(bytes) {
            Ok(h) => h,
            Err(e) => return self.bad(from, e.to_string(), events),
        };
        if head.kind == mech_proto::COMMAND_KIND {
            // The body is checked (a truncated or out-of-range command is
            // never forwarded) but not re-encoded: the received bytes go on.
            // Checked in place: no envelope is built for a forwarded command.
            let command = match mech_proto::check_command(bytes, &head) {
                Ok(c) => c,
                Err(e) => return self.bad(from, e.to_string(), events),
            };
            let admitted = match self.admit(bytes, head.sender, from, true, events) {
                Ok((id, _)) => id,
                Err(d) => return d,
            };
            let body = Body::Command(command);
            if let Err(d) = self.permit(admitted, &body, head.channel, from, events) {
                return d;
            }
            return self.route_command(&head, bytes, from, now, out, events);
        }
        let env = match mech_proto::decode(bytes) {
            Ok(env) => env,
            Err(e) => return self.bad(from, e.to_string(), events),
        };
        let sender = env.header.sender.as_str();
        // A time request is answered whatever its stamp: the requester does
        // not know the station's time yet.
        let fresh = !matches!(env.body, Body::TimeRequest(_));
        let (admitted, tag) = match self.admit(bytes, sender, from, fresh, events) {
            Ok(a) => a,
            Err(d) => return d,
        };
        if let Err(d) = self.permit(admitted, &env.body, &env.header.channel, from, events) {
            return d;
        }
        if let Body::TimeRequest(request) = env.body {
            return self.answer_time(request, tag, sender, from, now, out);
        }
        if matches!(from, Peer::Udp(_) | Peer::Serial(_)) {
            self.seen_robot(sender, env.header.seq, from, now, events);
        }
        let m = Incoming {
            header: &env.header,
            bytes,
            from,
            now,
        };
        self.dispatch(m, env.body, out, events)
    }

    /// One function per message kind (commands took the hot path above).
    fn dispatch(
        &mut self,
        m: Incoming<'_>,
        body: Body,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        match body {
            Body::Hello(hello) => self.on_hello(m, hello, out, events),
            Body::Heartbeat(hb) => self.on_heartbeat(m, hb, out),
            Body::Telemetry(t) => self.on_telemetry(m, t, out, events),
            Body::FleetCommand(fc) => self.on_fleet_command(m, fc, out, events),
            Body::Mission(mission) => self.on_mission(m, mission, out, events),
            Body::MissionAck(ack) => self.on_mission_ack(m, ack, out, events),
            Body::RouteAck(ack) => self.on_route_ack(m, ack, events),
            Body::EStop(e) => self.on_estop(m, e, out, events),
            Body::EStopAck(ack) => self.on_estop_ack(m, ack, events),
            Body::ChannelsRequest(_) => self.on_channels_request(m, out),
            Body::Subscribe(s) => self.on_subscribe(m, s),
            Body::PositionFix(fix) => self.on_position_fix(m, fix, out),
            Body::Notice(notice) => self.on_notice(m, notice, events),
            Body::Cluster(command) => self.on_cluster(m, command, events),
            Body::Bye(bye) => self.on_bye(m, bye, events),
            Body::TimeRequest(_) => Delivery::Consumed,
            Body::Autopilot(request) => self.on_autopilot(m, request, out),
            Body::Command(_)
            | Body::Welcome(_)
            | Body::Route(_)
            | Body::Channels(_)
            | Body::Time(_)
            | Body::Arena(_)
            | Body::ArenaAck(_)
            | Body::Neighbours(_) => {
                let what = format!("unexpected {} message", body.kind());
                self.bad(m.from, what, events)
            }
        }
    }

    /// Timers: link states, heartbeats, retries, lapsed subscriptions.
    pub(crate) fn tick(&mut self, now: Instant, out: &mut Outbox, events: &mut Vec<Event>) {
        self.update_links(now, events);
        self.report_links(now, events);
        self.roll_link_quality(now, events);
        self.send_heartbeats(now, out);
        self.retry_routes(now, out);
        self.retry_estop(now, out);
        self.retry_missions(now, out, events);
        self.subscribers.retain(|_, (until, _)| *until > now);
    }

    pub(crate) fn counters(&self) -> Counters {
        Counters {
            robots: self
                .robots
                .iter()
                .map(|(n, r)| (n.clone(), r.traffic))
                .collect(),
            channels: self
                .channels
                .iter()
                .map(|(n, c)| (n.clone(), c.traffic))
                .collect(),
            received: self.received,
            forwarded: self.forwarded,
            dropped: self.dropped,
            fanout_dropped: self.fanout_dropped,
            rejected: self.rejected,
        }
    }

    /// Messages received so far.
    pub(crate) fn counters_received(&self) -> u64 {
        self.received
    }

    pub(crate) fn rejections(&self) -> Rejections {
        self.rejected
    }

    pub(crate) fn count_send_failure(&mut self, fanout: bool) {
        if fanout {
            self.fanout_dropped += 1;
        } else {
            self.dropped.count(DropReason::SendFailed);
        }
    }

    /// Counts a bad frame seen outside [`Tables::handle`].
    pub(crate) fn count_bad(&mut self, from: Peer, error: String, events: &mut Vec<Event>) {
        self.bad(from, error, events);
    }

    /// Forgets a peer that went away (its subscription and reply address).
    pub(crate) fn forget_peer(&mut self, peer: Peer) {
        self.subscribers.remove(&peer);
        self.peers.retain(|_, p| *p != peer);
    }

    /// Adds a key to the keyring (none when unauthenticated).
    pub(crate) fn add_key(&mut self, identity: crate::auth::Identity) {
        if let Some(keys) = self.auth.as_mut() {
            keys.add(identity);
        }
    }

    /// The identity of a key id, when authenticating.
    pub(crate) fn identity(&self, key_id: u32) -> Option<crate::auth::Identity> {
        self.auth.as_ref()?.identity(key_id).cloned()
    }

    /// The configured serial radios.
    pub(crate) fn radio_config(&self) -> Vec<super::config::SerialEndpoint> {
        self.config.serial.clone()
    }

    /// Whether `robot` is registered.
    pub(crate) fn knows_robot(&self, robot: &str) -> bool {
        self.robots.contains_key(robot)
    }
}

#[cfg(test)]
mod tests {
    //! The timing rules, with injected time: exact thresholds that the
    //! socket-level tests (real time, real threads) can only bound.
    use std::time::Duration;

    use mech_proto::{Body, Envelope, Header, Hello, Mission, Waypoint};

    use super::*;

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
        t.handle(&hello("robot_1"), robot, t0, &mut out, &mut ev);
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
        t.tick(ms(499), &mut out, &mut ev);
        assert!(links(&ev).is_empty());
        t.tick(ms(500), &mut out, &mut ev);
        assert_eq!(links(&ev), vec![LinkState::Stale]);
        t.tick(ms(999), &mut out, &mut ev);
        t.tick(ms(1000), &mut out, &mut ev);
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
            t.handle(&hello(name), peer, t0, &mut out, &mut ev);
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
        t.farewell(&mut out);
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
            t.tick(t0 + Duration::from_millis(ms), &mut out, &mut ev);
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
        t.handle(&numbered(1, hello), robot, t0, &mut out, &mut ev);
        // The router's heartbeat at 260 ms; its sequence number is the echo's.
        t.tick(t0 + Duration::from_millis(260), &mut out, &mut ev);
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
            t.handle(&numbered(seq, hb), robot, at, &mut out, &mut ev);
        }
        ev.clear();
        t.tick(t0 + Duration::from_millis(1000), &mut out, &mut ev);
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

    #[test]
    fn a_mission_is_resent_every_200_ms_and_given_up_after_5_s() {
        let t0 = Instant::now();
        let (mut t, robot) = registered(t0);
        let mission = Body::Mission(Mission {
            id: 7,
            waypoints: vec![Waypoint {
                x: 1.0,
                y: 0.0,
                z: 0.0,
                time: None,
            }],
            looped: false,
            arrival_radius: 0.1,
            start_index: 0,
        });
        let (mut out, mut ev) = (Outbox::default(), Vec::new());
        t.handle(
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
        t.tick(t0 + Duration::from_millis(199), &mut out, &mut ev);
        assert_eq!(sends(&out), 0);
        t.tick(t0 + Duration::from_millis(200), &mut out, &mut ev);
        assert_eq!(sends(&out), 1);
        t.tick(t0 + Duration::from_millis(4_999), &mut out, &mut ev);
        assert!(!ev.iter().any(|e| matches!(e, Event::MissionFailed { .. })));
        t.tick(t0 + Duration::from_millis(5_000), &mut out, &mut ev);
        assert!(
            ev.iter()
                .any(|e| matches!(e, Event::MissionFailed { id: 7, .. }))
        );
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
        t.handle(&hb, radio, ms(10), &mut out, &mut ev);
        t.set_route("robot_1", Some("joy/0"), ms(20), &mut out, &mut ev);
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
            t.handle(&twist, Peer::Local, at, &mut out, &mut Vec::new());
            out.raw
        };
        assert_eq!(sent_to(&mut t, ms(100)), vec![wifi], "UDP while live");
        t.handle(&hb, radio, ms(350), &mut out, &mut ev);
        assert_eq!(
            sent_to(&mut t, ms(400)),
            vec![radio],
            "UDP silent 400 ms: the radio"
        );
        t.handle(&hb, wifi, ms(500), &mut out, &mut ev);
        assert_eq!(sent_to(&mut t, ms(510)), vec![wifi], "UDP back");
        let mut out = Outbox::default();
        t.start_estop(true, ms(520), &mut out, &mut ev);
        let estops: Vec<Peer> = out.owned.iter().map(|(p, _)| *p).collect();
        assert_eq!(estops, vec![wifi, radio], "the e-stop on every link");
        let mut ev = Vec::new();
        t.tick(ms(530), &mut Outbox::default(), &mut ev);
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
        t.handle(&sub, tool, t0, &mut out, &mut ev);
        t.tick(t0 + Duration::from_millis(4_999), &mut out, &mut ev);
        assert!(t.subscribers.contains_key(&tool));
        t.tick(t0 + Duration::from_millis(5_001), &mut out, &mut ev);
        assert!(!t.subscribers.contains_key(&tool), "lapsed");
        let _ = robot;
    }
}
