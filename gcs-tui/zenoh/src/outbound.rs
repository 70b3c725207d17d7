//! This station's robots, onto Zenoh: the bridge follows the router's
//! events and publishes each robot's registration, telemetry, link state
//! and route under `mech/<station>/<robot>/...`, and holds a liveliness
//! token `mech/<station>/<robot>` while the robot is not lost. State is
//! read from the fleet model (the router updated it before any subscriber
//! saw the event), so what is published is always the latest; if the
//! subscription ever lags, everything is published again from the model.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use mech_core::event::{Event, LinkState, Stamped};
use mech_core::fleet::Robot;
use mech_core::{Gcs, Subscription};
use mech_proto::Telemetry;
use tracing::{info, warn};
use zenoh::Session;
use zenoh::bytes::Encoding;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};

use crate::keys::{self, Topic};
use crate::payload::{InfoMsg, LinkMsg, Origin, RouteMsg, TelemetryMsg, to_json};
use crate::stats::Stats;

/// What the bridge keeps per published robot.
#[derive(Debug)]
struct RobotOut {
    /// Declared once: a telemetry sample then carries a numeric key id.
    telemetry: Publisher<'static>,
    /// Held while the robot is not lost.
    token: Option<LivelinessToken>,
}

/// The publishing half of the bridge.
#[derive(Debug)]
pub(crate) struct Outbound {
    pub(crate) session: Session,
    pub(crate) station: String,
    pub(crate) gcs: Gcs,
    pub(crate) stats: Arc<Stats>,
    /// Unix time (µs) of router time zero, to stamp telemetry.
    pub(crate) origin_us: u64,
    robots: HashMap<String, RobotOut>,
    /// Robot names already reported as impossible keys (reported once).
    refused: HashSet<String>,
}

impl Outbound {
    pub(crate) fn new(session: Session, station: &str, gcs: Gcs, stats: Arc<Stats>) -> Outbound {
        let elapsed = gcs.router().elapsed().as_micros() as u64;
        Outbound {
            session,
            station: station.to_string(),
            origin_us: mech_proto::unix_micros().saturating_sub(elapsed),
            gcs,
            stats,
            robots: HashMap::new(),
            refused: HashSet::new(),
        }
    }

    /// Publishes until the router shuts down. Robots registered before the
    /// bridge started are published first.
    pub(crate) async fn run(mut self, mut events: Subscription) {
        self.republish().await;
        let mut missed = 0;
        while let Some(ev) = events.recv().await {
            self.on_event(&ev).await;
            if events.dropped() != missed {
                let lost = events.dropped() - missed;
                missed = events.dropped();
                self.stats
                    .events_missed
                    .fetch_add(lost, std::sync::atomic::Ordering::Relaxed);
                warn!(
                    lost,
                    "the Zenoh bridge fell behind the router; publishing all state again"
                );
                self.republish().await;
            }
        }
    }

    async fn on_event(&mut self, ev: &Stamped) {
        match &ev.event {
            Event::Telemetry { robot, telemetry } => {
                self.publish_telemetry(robot, telemetry, ev.at.as_micros() as u64)
                    .await
            }
            Event::Registered { hello, .. } => self.publish_state(&hello.name, true).await,
            Event::Link { robot, .. } | Event::Bye { robot, .. } => {
                self.publish_state(robot, false).await
            }
            Event::RouteChanged { robot, .. } | Event::RouteAcked { robot, .. } => {
                self.publish_route(robot).await
            }
            _ => {}
        }
    }

    /// Publishes every robot's registration, link and route again.
    async fn republish(&mut self) {
        let names: Vec<String> = self
            .gcs
            .with_fleet(|f| f.local_robots().map(|r| r.name.clone()).collect());
        for name in names {
            self.publish_state(&name, true).await;
        }
    }

    /// The robot's entry, declared on first use; `None` if its name cannot
    /// be a key chunk (reported once, counted each time).
    async fn robot(&mut self, name: &str) -> Option<&mut RobotOut> {
        if let Err(e) = keys::check_name("robot", name) {
            Stats::bump(&self.stats.names_rejected);
            if self.refused.insert(name.to_string()) {
                warn!("not published on Zenoh: {e}");
                let text = format!("zenoh: not published: {e}");
                self.gcs
                    .update_fleet(|f| f.log(mech_core::fleet::Severity::Warn, text));
            }
            return None;
        }
        if !self.robots.contains_key(name) {
            let key = keys::state_key(&self.station, name, Topic::Telemetry);
            let publisher = self
                .session
                .declare_publisher(key)
                .encoding(Encoding::APPLICATION_JSON)
                .congestion_control(CongestionControl::Drop)
                .priority(Priority::DataHigh)
                .express(true)
                .await;
            let telemetry = match publisher {
                Ok(p) => p,
                Err(e) => {
                    warn!(robot = name, error = %e, "cannot declare a Zenoh publisher");
                    Stats::bump(&self.stats.publish_failed);
                    return None;
                }
            };
            let entry = RobotOut {
                telemetry,
                token: None,
            };
            self.robots.insert(name.to_string(), entry);
        }
        self.robots.get_mut(name)
    }

    async fn publish_telemetry(&mut self, robot: &str, t: &Telemetry, at_us: u64) {
        let stamp = self.origin_us + at_us;
        let station = self.station.clone();
        let stats = self.stats.clone();
        let Some(out) = self.robot(robot).await else {
            return;
        };
        let payload = to_json(&TelemetryMsg::new(&station, robot, t, stamp));
        match out.telemetry.put(payload).await {
            Ok(()) => Stats::bump(&stats.published),
            Err(_) => Stats::bump(&stats.publish_failed),
        }
    }

    /// Publishes a robot's link (and, with `registered`, its registration
    /// and route), and holds or drops its liveliness token to match.
    async fn publish_state(&mut self, name: &str, registered: bool) {
        let Some(robot) = self.gcs.with_fleet(|f| f.robot(name).cloned()) else {
            return;
        };
        if !robot.is_local() || self.robot(name).await.is_none() {
            return;
        }
        if registered {
            let info = InfoMsg::new(&self.station, name, &robot.registration);
            self.put(name, Topic::Info, to_json(&info)).await;
            self.publish_route(name).await;
        }
        let link = LinkMsg {
            origin: Origin::new(&self.station, name),
            state: robot.link,
        };
        self.put(name, Topic::Link, to_json(&link)).await;
        self.hold_token(name, &robot).await;
    }

    /// Declares the robot's token while it is not lost; drops it (other
    /// stations see it lost at once) when it is.
    async fn hold_token(&mut self, name: &str, robot: &Robot) {
        let key = keys::robot_token(&self.station, name);
        let session = self.session.clone();
        let Some(out) = self.robots.get_mut(name) else {
            return;
        };
        match (robot.link, out.token.is_some()) {
            (LinkState::Lost, true) => {
                if let Some(token) = out.token.take() {
                    let _ = token.undeclare().await;
                }
                info!(
                    robot = name,
                    "robot lost: its Zenoh liveliness token is withdrawn"
                );
            }
            (LinkState::Connected | LinkState::Stale, false) => {
                match session.liveliness().declare_token(key).await {
                    Ok(token) => out.token = Some(token),
                    Err(e) => warn!(robot = name, error = %e, "cannot declare a liveliness token"),
                }
            }
            _ => {}
        }
    }

    async fn publish_route(&mut self, name: &str) {
        let route = self.gcs.with_fleet(|f| {
            f.robot(name)
                .filter(|r| r.is_local())
                .map(|r| r.route.clone())
        });
        if let Some(route) = route {
            let msg = RouteMsg::new(&self.station, name, &route);
            self.put(name, Topic::Route, to_json(&msg)).await;
        }
    }

    /// Puts one state sample, reliably (blocking rather than dropping when
    /// the network is congested: a link or route change must arrive).
    async fn put(&self, robot: &str, topic: Topic, payload: Vec<u8>) {
        let key = keys::state_key(&self.station, robot, topic);
        let put = self
            .session
            .put(key, payload)
            .encoding(Encoding::APPLICATION_JSON)
            .congestion_control(CongestionControl::Block)
            .await;
        match put {
            Ok(()) => Stats::bump(&self.stats.published),
            Err(e) => {
                warn!(robot, topic = topic.as_str(), error = %e, "Zenoh put failed");
                Stats::bump(&self.stats.publish_failed);
            }
        }
    }
}
