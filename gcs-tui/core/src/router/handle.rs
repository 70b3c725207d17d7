//! [`RouterHandle`]: the API the rest of the station uses, one group of
//! functions per job: where the router is and its time; commanding robots
//! (routes, missions, e-stop); fleet safety (the arena, each robot's
//! switch, neighbour lists); publishing in process (with
//! `super::publisher`); events; status; authentication; the recording
//! tap.
//!
//! Every call that makes the router decide takes the same path as a
//! message from a peer (`super::Shared`): when it returns, its events have
//! reached the fleet model.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use mech_proto::auth::Tag;
use mech_proto::{Body, Envelope, Header, Mission, Neighbours};
use tokio::time::Instant;

use super::bus::Subscription;
use super::net::RadioStatus;
use super::tables::tap::{OperatorRecord, Tap};
use super::tables::{Delivery, Effects, Peer};
use super::{RouterError, Shared};
use crate::arena::ArenaShape;
use crate::auth::{Identity, Rejection, Role, Security};
use crate::counters::{ChannelStatus, Counters, Rejections};
use crate::fleet::Fleet;
use crate::sync::lock;

/// A cheap, cloneable handle to a running router: publish, route, send
/// missions, e-stop, subscribe, and read channels and counters.
#[derive(Debug, Clone)]
pub struct RouterHandle {
    shared: Arc<Shared>,
}

/// Where the router is, who it is, and its clock.
impl RouterHandle {
    pub(super) fn new(shared: Arc<Shared>) -> RouterHandle {
        RouterHandle { shared }
    }

    pub(super) fn shared(&self) -> &Shared {
        &self.shared
    }

    /// The bound UDP endpoint (useful when configured with port 0).
    pub fn udp_addr(&self) -> SocketAddr {
        self.shared.net.udp_addr()
    }

    /// The bound TCP endpoint, if enabled.
    pub fn tcp_addr(&self) -> Option<SocketAddr> {
        self.shared.net.tcp_addr()
    }

    /// The router's sender name (agents check it on what they obey).
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// Time since the router started.
    pub fn elapsed(&self) -> Duration {
        self.shared.events.bus().elapsed()
    }

    /// When the router started (router time 0).
    pub(crate) fn started(&self) -> Instant {
        self.shared.events.start()
    }
}

/// Commanding robots: routes, missions, the e-stop.
impl RouterHandle {
    /// Routes `robot` to `channel` (`None` = none). Takes effect for the very
    /// next message; the agent is told, repeatedly until it acknowledges.
    /// Returns the new route epoch.
    pub async fn set_route(&self, robot: &str, channel: Option<&str>) -> Result<u32, RouterError> {
        self.shared
            .apply(|t, cx| t.set_route(robot, channel, cx))
            .await
            .ok_or_else(|| RouterError::UnknownRobot(robot.to_string()))
    }

    /// Sends a mission to `robot` on `channel` from `sender`, with a fresh id
    /// (the id in `mission` is replaced). It is repeated until the robot
    /// acknowledges the id, or reported failed after `mission_give_up`.
    pub async fn send_mission(
        &self,
        sender: &str,
        robot: &str,
        channel: &str,
        mut mission: Mission,
    ) -> Result<u32, RouterError> {
        mission.id = {
            let mut tables = lock(&self.shared.tables);
            if !tables.knows_robot(robot) {
                return Err(RouterError::UnknownRobot(robot.to_string()));
            }
            tables.mission_id()
        };
        let id = mission.id;
        let env = envelope(sender, robot, channel, 0, Body::Mission(mission));
        let bytes = mech_proto::encode(&env)?;
        self.inject(&bytes).await;
        Ok(id)
    }

    /// Engages the e-stop on every robot (repeated until each acknowledges;
    /// robots registering later get it too). Returns its id.
    pub async fn estop(&self) -> u32 {
        self.shared.apply(|t, cx| t.start_estop(true, cx)).await
    }

    /// Explicitly releases the e-stop on every robot. Returns its id.
    pub async fn release(&self) -> u32 {
        self.shared.apply(|t, cx| t.start_estop(false, cx)).await
    }
}

/// Fleet safety: the station's arena, each robot's safety switch, and the
/// neighbour lists of the station's broadcaster (`crate::neighbours`).
impl RouterHandle {
    /// The station's arena, if it has one.
    pub fn arena(&self) -> Option<ArenaShape> {
        lock(&self.shared.tables).arena().cloned()
    }

    /// Sets the station's arena (`None` clears it) and sends it to every
    /// robot, repeated until each acknowledges; robots registering later
    /// get it too.
    pub async fn set_arena(&self, arena: Option<ArenaShape>) {
        self.shared.apply(|t, cx| t.set_arena(arena, cx)).await;
    }

    /// Switches `robot`'s safety layer on or off: the robot is sent its
    /// arena with the switch, repeated until it acknowledges. Returns the
    /// arena id sent (0 when the station has no arena yet: the switch goes
    /// out with the next one).
    pub async fn set_safety(&self, robot: &str, enabled: bool) -> Result<u32, RouterError> {
        self.shared
            .apply(|t, cx| t.set_safety(robot, enabled, cx))
            .await
            .ok_or_else(|| RouterError::UnknownRobot(robot.to_string()))
    }

    /// Sends `n` to its robot, signed for it (once: the next list follows
    /// within the broadcaster's period). `false` if the robot is not
    /// registered, cannot be reached, or has its layer switched off.
    pub async fn send_neighbours(&self, n: Neighbours) -> bool {
        self.shared.apply(|t, cx| t.send_neighbours(n, cx)).await
    }
}

/// Publishing from inside the station (see also `publisher` and
/// `publishers`).
impl RouterHandle {
    /// Runs an encoded message through the router as if it had arrived from
    /// a peer inside the GCS process.
    pub async fn inject(&self, bytes: &[u8]) -> Delivery {
        let mut fx = Effects::default();
        self.shared.dispatch(bytes, Peer::Local, &mut fx).await
    }
}

/// Events: the fleet model gets every one; subscribers get them through a
/// bounded queue each.
impl RouterHandle {
    /// A subscription to router events. With `telemetry` it also gets every
    /// telemetry event (at the fleet's telemetry rate: size `capacity`
    /// accordingly) and each robot's link quality once a second. A full
    /// queue drops this subscriber's events only.
    pub fn subscribe(&self, capacity: usize, telemetry: bool) -> Subscription {
        self.shared.events.bus().subscribe(capacity, telemetry)
    }

    /// A subscription with the configured queue length.
    pub fn subscribe_default(&self, telemetry: bool) -> Subscription {
        let capacity = self.shared.subscriber_queue;
        self.shared.events.bus().subscribe(capacity, telemetry)
    }
}

/// Status: live channels, counters, radios.
impl RouterHandle {
    /// Live channels with their publisher, rate and routed robots.
    pub fn channels(&self) -> Vec<ChannelStatus> {
        lock(&self.shared.tables).channel_status(Instant::now())
    }

    /// A copy of every counter.
    pub fn counters(&self) -> Counters {
        let mut counters = lock(&self.shared.tables).counters();
        self.shared.net.add_failures(&mut counters);
        counters
    }

    /// Every serial radio: what it sent and what waits.
    pub fn radios(&self) -> Vec<RadioStatus> {
        self.shared.net.radios()
    }
}

/// The authenticated control plane: whether it is on, its keys, its
/// refusals, and the gate for requests that do not arrive as messages.
impl RouterHandle {
    /// Whether the router checks and signs messages (the authenticated
    /// control plane); `false` means anyone who reaches it can drive robots.
    pub fn authenticated(&self) -> bool {
        lock(&self.shared.tables).auth_on()
    }

    /// How exposed the router is: authenticated, unsigned on loopback only,
    /// or unauthenticated on the network.
    pub fn security(&self) -> Security {
        let loopback = self.udp_addr().ip().is_loopback()
            && self.tcp_addr().is_none_or(|a| a.ip().is_loopback());
        match (self.authenticated(), loopback) {
            (true, _) => Security::Authenticated,
            (false, true) => Security::LoopbackOnly,
            (false, false) => Security::Unauthenticated,
        }
    }

    /// Messages refused by the authenticated control plane, by reason.
    pub fn rejections(&self) -> Rejections {
        lock(&self.shared.tables).rejections()
    }

    /// Adds a key while running (simulated robots get theirs this way). Does
    /// nothing when the router runs unauthenticated.
    pub fn add_key(&self, identity: Identity) {
        lock(&self.shared.tables).add_key(identity);
    }

    /// The identity a key id belongs to (`None` when unknown or when the
    /// router runs unauthenticated): the station checks an attaching
    /// operator's key with it.
    pub fn identity(&self, key_id: u32) -> Option<Identity> {
        lock(&self.shared.tables).identity(key_id)
    }

    /// Checks that `sender`, a name with a key in `[auth]`, may send `body`
    /// on `channel`: the gate for an in-process publisher that carries
    /// messages from beyond the station under its own name (a bridge to
    /// other stations), whose messages the router would otherwise take as
    /// the station operator's. Always `Ok` when the station runs
    /// unauthenticated. A refusal is counted and reported, as the gate's.
    pub fn permit_as(&self, sender: &str, body: &Body, channel: &str) -> Result<(), Rejection> {
        self.shared.decide_now(Peer::Local, |t, cx| {
            t.permit_named(sender, body, channel, cx)
        })
    }

    /// Checks a request signed with a listed key outside the message
    /// protocol (a route request from another station, received from
    /// `source`): `tag` must be a fresh tag over `region` by the key of
    /// `sender`, a key with `role`. Refused when the station runs
    /// unauthenticated. A refusal is counted and reported, as the gate's.
    pub fn verify_signed(
        &self,
        source: &str,
        sender: &str,
        region: &[u8],
        tag: Tag,
        role: Role,
    ) -> Result<(), Rejection> {
        self.shared.decide_now(Peer::Local, |t, cx| {
            t.verify_signed(source, sender, (region, tag), role, cx)
        })
    }
}

/// The recording: the recorder's tap and the operator's commands.
impl RouterHandle {
    /// Puts `tap` on the router, returning the one it replaces. The tap
    /// first gets `fleet()`, the fleet model with every event the router
    /// made so far applied, taken while no event is delivered: nothing
    /// falls between it and what the tap sees next.
    pub(crate) fn put_tap(&self, tap: Tap, fleet: impl FnOnce() -> Fleet) -> Option<Tap> {
        self.shared.put_tap(tap, fleet)
    }

    /// Takes the tap off the router, returning it.
    pub(crate) fn take_tap(&self) -> Option<Tap> {
        lock(&self.shared.tables).set_tap(None)
    }

    /// Records an operator command in the recording, if one is being made
    /// (in order with the router's messages and events).
    pub fn record_operator(&self, record: OperatorRecord) {
        self.shared.record_operator(record);
    }
}

/// A message from `sender` inside the station, stamped now.
pub(super) fn envelope(
    sender: &str,
    destination: &str,
    channel: &str,
    seq: u32,
    body: Body,
) -> Envelope {
    Envelope::new(
        Header {
            seq,
            stamp_us: mech_proto::unix_micros(),
            sender: sender.to_string(),
            destination: destination.to_string(),
            channel: channel.to_string(),
        },
        body,
    )
}
