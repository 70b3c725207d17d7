//! The fleet model: the ground station's view of every robot, cluster,
//! channel, route, waypoint list and e-stop, derived from router events.
//!
//! The router applies each [`Event`] here before any subscriber sees it (the
//! model is the router's [`EventSink`]), so the model never misses a route
//! or link change even when a subscriber lags. One function per event kind
//! turns it into model changes and an operator log line. The TUI and the
//! script runner read the model through [`crate::Gcs::snapshot`] or
//! [`crate::Gcs::with_fleet`]; it holds no sockets and no UI types.

mod config;
mod remote;
mod robot;
mod safety;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::{FailsafeState, Health, Hello, Notice, Telemetry, Waypoint};

pub use config::FleetConfig;
pub use remote::remote_name;
pub use robot::{
    AutopilotState, MissionDelivery, PathPoint, Registration, Robot, RouteState, SentMission,
    WaypointList, held_mission_text,
};

use crate::arena::ArenaShape;
use crate::counters::{ChannelStatus, Counters};
use crate::event::{Event, EventSink, LinkAddr, LinkState, RobotLinks, Stamped};
use crate::sync::lock;

/// A named set of robots.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cluster {
    pub name: String,
    pub members: Vec<String>,
}

/// E-stop as the GCS last commanded it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EStopState {
    /// Engaged (latched) until an explicit release.
    pub engaged: bool,
    /// Id of the last e-stop or release.
    pub id: u32,
    /// Robots that have not acknowledged `id` yet.
    pub pending: BTreeSet<String>,
}

mech_proto::named_enum! {
    /// Severity of an event-log line.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
    pub enum Severity: "severity" {
        Debug => "debug",
        Info => "info",
        Warn => "warn",
        Error => "error",
    }
}

/// One line of the event log shown to the operator.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogEntry {
    /// Numbered from 1 in the order lines were logged, so a display that
    /// showed up to `seq` asks for what came after ([`Fleet::log_after`]).
    pub seq: u64,
    pub at: Duration,
    pub severity: Severity,
    pub text: String,
}

/// The GCS's whole view of the fleet.
#[derive(Debug, Clone)]
pub struct Fleet {
    pub robots: BTreeMap<String, Robot>,
    pub clusters: BTreeMap<String, Cluster>,
    /// Live channels, publisher and rate (copied in by [`crate::Gcs::snapshot`]).
    pub channels: Vec<ChannelStatus>,
    /// Router counters (copied in by [`crate::Gcs::snapshot`]).
    pub counters: Counters,
    pub estop: EStopState,
    /// Most recent last.
    pub log: VecDeque<LogEntry>,
    /// Other stations seen through a bridge, and whether they are alive
    /// (their robots are in `robots`, marked [`Robot::remote`]).
    pub stations: BTreeMap<String, LinkState>,
    /// Router endpoints once bound.
    pub udp: Option<SocketAddr>,
    pub tcp: Option<SocketAddr>,
    /// The arena robots are sent (and the map draws), if the station has
    /// one.
    pub arena: Option<ArenaShape>,
    /// Router time of the last applied event.
    pub now: Duration,
    /// Sequence number of the last log line.
    log_seq: u64,
    config: FleetConfig,
}

impl Fleet {
    pub fn new(config: FleetConfig) -> Fleet {
        Fleet {
            robots: BTreeMap::new(),
            clusters: BTreeMap::new(),
            channels: Vec::new(),
            counters: Counters::default(),
            estop: EStopState::default(),
            log: VecDeque::new(),
            stations: BTreeMap::new(),
            udp: None,
            tcp: None,
            arena: None,
            now: Duration::ZERO,
            log_seq: 0,
            config,
        }
    }

    pub fn robot(&self, name: &str) -> Option<&Robot> {
        self.robots.get(name)
    }

    pub fn robot_mut(&mut self, name: &str) -> Option<&mut Robot> {
        self.robots.get_mut(name)
    }

    /// Robots named by `target`: `all` (this station's own robots), a
    /// cluster name, or a robot name (another station's too).
    pub fn resolve(&self, target: &str) -> Option<Vec<String>> {
        if target == "all" {
            return Some(self.local_robots().map(|r| r.name.clone()).collect());
        }
        if let Some(c) = self.clusters.get(target) {
            return Some(c.members.clone());
        }
        self.robots
            .contains_key(target)
            .then(|| vec![target.to_string()])
    }

    /// This station's own robots (not other stations' shown read-only).
    pub fn local_robots(&self) -> impl Iterator<Item = &Robot> {
        self.robots.values().filter(|r| r.is_local())
    }

    /// Defines (or redefines) a cluster.
    pub fn set_cluster(&mut self, name: &str, members: Vec<String>) {
        self.clusters.insert(
            name.to_string(),
            Cluster {
                name: name.to_string(),
                members,
            },
        );
    }

    /// Appends an operator log line.
    pub fn log(&mut self, severity: Severity, text: impl Into<String>) {
        self.log_seq += 1;
        self.log.push_back(LogEntry {
            seq: self.log_seq,
            at: self.now,
            severity,
            text: text.into(),
        });
        while self.log.len() > self.config.event_log.max(1) {
            self.log.pop_front();
        }
    }

    /// Log lines logged after line `seq` (all kept lines for 0), oldest
    /// first. Lines that scrolled out of the kept window are gone.
    pub fn log_after(&self, seq: u64) -> impl Iterator<Item = &LogEntry> {
        let skip = self.log.partition_point(|e| e.seq <= seq);
        self.log.iter().skip(skip)
    }

    /// Updates the model from one router event: one function per kind.
    pub fn apply(&mut self, stamped: &Stamped) {
        self.now = self.now.max(stamped.at);
        let at = stamped.at;
        match &stamped.event {
            Event::Listening { udp, tcp } => self.listening(*udp, *tcp),
            Event::Registered {
                hello,
                id,
                addr,
                known,
            } => self.registered(hello, *id, addr, *known),
            Event::Link { robot, state } => self.link(robot, *state),
            Event::Links { robot, links } => self.links(robot, links),
            Event::Radio { port, up, reason } => self.radio(port, *up, reason),
            Event::Telemetry { robot, telemetry } => self.telemetry(robot, telemetry, at),
            Event::LinkQuality { robot, quality } => self.link_quality(robot, quality),
            Event::RouteChanged {
                robot,
                channel,
                epoch,
            } => self.route_changed(robot, channel, *epoch),
            Event::RouteAcked {
                robot,
                channel,
                epoch,
            } => self.route_acked(robot, channel, *epoch),
            Event::MissionSent {
                robot,
                channel,
                id,
                waypoints,
                looped,
            } => self.mission_sent(robot, channel, *id, waypoints, *looped),
            Event::MissionAcked {
                robot,
                id,
                accepted,
                reason,
            } => self.mission_acked(robot, *id, *accepted, reason),
            Event::MissionFailed { robot, id, reason } => self.mission_failed(robot, *id, reason),
            Event::EStop { engage, id } => self.estop(*engage, *id),
            Event::EStopAcked { robot, engage, id } => self.estop_acked(robot, *engage, *id),
            Event::EStopComplete { engage, id } => self.estop_complete(*engage, *id),
            Event::ChannelPublisher { channel, publisher } => self.log(
                Severity::Info,
                format!("channel {channel} published by {publisher}"),
            ),
            Event::ClusterCommand { .. } => {}
            Event::Bye { robot, reason } => self.bye(robot, reason),
            Event::Notice { from, notice } => self.notice(from, notice),
            Event::BadPacket { from, error } => {
                self.log(Severity::Warn, format!("bad packet from {from}: {error}"))
            }
            Event::Rejected {
                from,
                reason,
                detail,
            } => self.log(
                Severity::Warn,
                format!("rejected from {from} ({}): {detail}", reason.as_str()),
            ),
            Event::Refused {
                count,
                sources,
                by_reason,
                from,
                detail,
            } => self.log(
                Severity::Warn,
                refused_text(*count, *sources, by_reason, from, detail),
            ),
            Event::Arena { .. }
            | Event::SafetySwitched { .. }
            | Event::ArenaAcked { .. }
            | Event::Safety { .. } => self.safety_event(&stamped.event),
        }
    }

    fn listening(&mut self, udp: SocketAddr, tcp: Option<SocketAddr>) {
        self.udp = Some(udp);
        self.tcp = tcp;
        let tcp = tcp.map(|t| format!(", TCP {t}")).unwrap_or_default();
        self.log(
            Severity::Info,
            format!("router listening on UDP {udp}{tcp}"),
        );
    }

    fn registered(&mut self, hello: &Hello, id: u16, addr: &LinkAddr, known: bool) {
        let robot = &hello.name;
        let r = self
            .robots
            .entry(robot.clone())
            .or_insert_with(|| Robot::new(robot, id, addr.clone()));
        let moved = r.registration.addr != *addr;
        // A robot registering again may have restarted and lost its
        // mission: the next telemetry says (see `telemetry`).
        let count = r.registration.count + 1;
        r.registration = Registration {
            id,
            hello: hello.clone(),
            addr: addr.clone(),
            count,
        };
        r.link = LinkState::Connected;
        r.remote = None;
        let text = match (known, moved) {
            (false, _) => format!("{robot} ({}) connected from {addr}", hello.platform),
            (true, true) => format!("{robot} re-registered from new address {addr}"),
            (true, false) => format!("{robot} re-registered"),
        };
        self.log(Severity::Info, text);
    }

    fn links(&mut self, robot: &str, links: &RobotLinks) {
        let Some(r) = self.robots.get_mut(robot) else {
            return;
        };
        let was = std::mem::replace(&mut r.links, links.clone());
        if was.label() != links.label() {
            self.log(Severity::Info, format!("{robot} links {}", links.label()));
        }
    }

    fn link(&mut self, robot: &str, state: LinkState) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.link = state;
        }
        let severity = if state == LinkState::Lost {
            Severity::Warn
        } else {
            Severity::Info
        };
        self.log(severity, format!("{robot} link {}", state.as_str()));
    }

    fn telemetry(&mut self, robot: &str, t: &Telemetry, at: Duration) {
        let (spacing, history) = (self.config.path_spacing, self.config.path_history);
        let Some(r) = self.robots.get_mut(robot) else {
            return;
        };
        r.last_telemetry = Some(at);
        r.telemetry.clone_from(t);
        if t.health != Health::Fault && t.failsafe != FailsafeState::Fault {
            r.fault = None;
        }
        let lost = r.mission_lost();
        let far = r
            .path
            .back()
            .is_none_or(|p| (p.x - t.pose.x).hypot(p.y - t.pose.y) >= spacing);
        if far {
            r.path.push_back(PathPoint {
                at,
                x: t.pose.x,
                y: t.pose.y,
            });
            while r.path.len() > history {
                r.path.pop_front();
            }
        }
        if let Some(id) = lost {
            self.log(
                Severity::Warn,
                format!(
                    "{robot} registered again without mission {id} (its agent restarted?): \
                     it holds still; send the mission again to resume"
                ),
            );
        }
    }

    fn route_changed(&mut self, robot: &str, channel: &Option<String>, epoch: u32) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.route.requested = channel.clone();
            r.route.epoch = epoch;
        }
        self.log(
            Severity::Info,
            format!("{robot} routed to {} (pending)", show(channel)),
        );
    }

    fn route_acked(&mut self, robot: &str, channel: &Option<String>, epoch: u32) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.route.acknowledged = channel.clone();
            r.route.acked_epoch = epoch;
        }
        self.log(
            Severity::Info,
            format!("{robot} acknowledged route {}", show(channel)),
        );
    }

    fn mission_sent(
        &mut self,
        robot: &str,
        channel: &str,
        id: u32,
        waypoints: &[Waypoint],
        looped: bool,
    ) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.waypoints.sent = Some(SentMission {
                id,
                channel: channel.to_string(),
                waypoints: waypoints.to_vec(),
                looped,
                delivery: MissionDelivery::Sending,
            });
        }
        self.log(
            Severity::Info,
            format!(
                "mission {id} ({} waypoints) sent to {robot} on {channel}",
                waypoints.len()
            ),
        );
    }

    /// The delivery state of `robot`'s last mission, if it is mission `id`.
    fn sent_mission(&mut self, robot: &str, id: u32) -> Option<&mut SentMission> {
        self.robots
            .get_mut(robot)
            .and_then(|r| r.waypoints.sent.as_mut())
            .filter(|sent| sent.id == id)
    }

    fn mission_acked(&mut self, robot: &str, id: u32, accepted: bool, reason: &str) {
        if let Some(sent) = self.sent_mission(robot, id) {
            sent.delivery = if accepted {
                MissionDelivery::Acked
            } else {
                MissionDelivery::Refused(reason.to_string())
            };
        }
        if accepted {
            self.log(Severity::Info, format!("{robot} acknowledged mission {id}"));
            if let Some(held) = self.robots.get(robot).and_then(|r| {
                let sent = r.waypoints.sent.as_ref().filter(|s| s.id == id)?;
                sent.held(robot, r.route.requested.as_deref())
            }) {
                self.log(Severity::Warn, held);
            }
        } else {
            self.log(
                Severity::Warn,
                format!("{robot} refused mission {id}: {reason}"),
            );
        }
    }

    fn mission_failed(&mut self, robot: &str, id: u32, reason: &str) {
        if let Some(sent) = self.sent_mission(robot, id) {
            sent.delivery = MissionDelivery::Failed(reason.to_string());
        }
        self.log(
            Severity::Error,
            format!("mission {id} to {robot} failed: {reason}"),
        );
    }

    fn estop(&mut self, engage: bool, id: u32) {
        self.estop.engaged = engage;
        self.estop.id = id;
        self.estop.pending = self.local_robots().map(|r| r.name.clone()).collect();
        if engage {
            self.log(Severity::Error, format!("E-STOP engaged (id {id})"));
        } else {
            self.log(Severity::Warn, format!("e-stop released (id {id})"));
        }
    }

    fn estop_acked(&mut self, robot: &str, engage: bool, id: u32) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.estop_ack = Some((engage, id));
        }
        if id == self.estop.id && engage == self.estop.engaged {
            self.estop.pending.remove(robot);
        }
    }

    fn estop_complete(&mut self, engage: bool, id: u32) {
        if id == self.estop.id && engage == self.estop.engaged {
            self.estop.pending.clear();
        }
        let what = if engage { "e-stop" } else { "release" };
        self.log(
            Severity::Info,
            format!("every robot acknowledged {what} {id}"),
        );
    }

    fn bye(&mut self, robot: &str, reason: &str) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.link = LinkState::Lost;
        }
        self.log(Severity::Warn, format!("{robot} left: {reason}"));
    }

    fn notice(&mut self, from: &str, notice: &Notice) {
        if let Some(r) = self.robots.get_mut(from) {
            r.heard_notice(notice);
        }
        let severity = match notice.level {
            mech_proto::Level::Debug => Severity::Debug,
            mech_proto::Level::Info => Severity::Info,
            mech_proto::Level::Warn => Severity::Warn,
            mech_proto::Level::Error => Severity::Error,
        };
        self.log(severity, format!("{from}: {}", notice.text));
    }
}

/// A robot's link quality and the station's radios, as the router reports
/// them.
impl Fleet {
    fn link_quality(&mut self, robot: &str, quality: &crate::counters::LinkQuality) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.quality = *quality;
        }
    }

    /// One of the station's radios failed or came back: said once each
    /// way (the router keeps opening a failed one again).
    fn radio(&mut self, port: &str, up: bool, reason: &str) {
        let (severity, text) = match up {
            true => (Severity::Info, format!("radio {port} reopened")),
            false => (
                Severity::Error,
                format!("radio {port} failed: {reason}; reopening it until it returns"),
            ),
        };
        self.log(severity, text);
    }
}

/// The fleet model behind its lock is where the router delivers events.
impl EventSink for std::sync::Mutex<Fleet> {
    fn apply(&self, event: &Stamped) {
        lock(self).apply(event);
    }
}

fn show(channel: &Option<String>) -> &str {
    channel.as_deref().unwrap_or("none")
}

/// The event-log line of a refusal summary: `refused 19,980 messages in
/// the last second from 16 sources (4,000 bad-packet, 15,980 bad-tag),
/// e.g. from udp:10.0.0.9:4000: ...`.
fn refused_text(
    count: u64,
    sources: u64,
    by_reason: &std::collections::BTreeMap<String, u64>,
    from: &str,
    detail: &str,
) -> String {
    let reasons: Vec<String> = by_reason
        .iter()
        .map(|(r, n)| format!("{} {r}", thousands(*n)))
        .collect();
    let sources = match sources {
        1 => "1 source".to_string(),
        n if n as usize >= crate::event::REFUSED_SOURCES_COUNTED => {
            format!("{} or more sources", thousands(n))
        }
        n => format!("{} sources", thousands(n)),
    };
    format!(
        "refused {} messages in the last second from {sources} ({}), e.g. from {from}: {detail}",
        thousands(count),
        reasons.join(", ")
    )
}

/// `19980` as `19,980`.
fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{
        Computation, ControlMode, FailsafeState, Health, MissionProgress, NoticeCode, Pose,
        Velocity,
    };

    fn at(ms: u64, event: Event) -> Stamped {
        Stamped {
            at: Duration::from_millis(ms),
            event,
        }
    }

    fn registered(name: &str) -> Event {
        Event::Registered {
            hello: mech_proto::Hello {
                name: name.into(),
                platform: "diff-drive".into(),
                capabilities: vec![mech_proto::CommandKind::Twist],
                motors: 2,
                max_speed: 1.0,
                max_yaw_rate: 2.0,
                agent_version: "t".into(),
            },
            id: 1,
            addr: LinkAddr::Udp("127.0.0.1:9000".parse().unwrap()),
            known: false,
        }
    }

    fn telemetry(x: f64, mission: Option<MissionProgress>) -> Telemetry {
        Telemetry {
            pose: Pose {
                x,
                y: 0.0,
                z: 0.0,
                heading: 0.5,
            },
            velocity: Velocity {
                vx: 0.3,
                vy: 0.4,
                vz: 0.0,
                wz: 0.0,
            },
            mode: ControlMode::Twist,
            channel: "joy/0".into(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: Some(0.5),
            position_quality: 1.0,
            actuators: vec![0.1, 0.2],
            mission,
            stale: 0,
            velocity_source: mech_proto::VelocitySource::Commanded,
            safety: None,
        }
    }

    #[test]
    fn an_autopilots_state_is_kept_from_the_robots_notices() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("px4_1")));
        assert_eq!(f.robot("px4_1").unwrap().autopilot, None);
        let said = |ms: u64, text: &str| {
            at(
                ms,
                Event::Notice {
                    from: "px4_1".into(),
                    notice: Notice {
                        level: mech_proto::Level::Info,
                        code: NoticeCode::Text,
                        text: text.into(),
                    },
                },
            )
        };
        f.apply(&said(
            1,
            "autopilot found: PX4 MAV_TYPE_QUADROTOR, system 1 component 1",
        ));
        f.apply(&said(2, "autopilot mode POSCTL"));
        f.apply(&said(3, "arm sent to the autopilot"));
        f.apply(&said(4, "autopilot armed"));
        f.apply(&said(5, "autopilot mode OFFBOARD"));
        let ap = f.robot("px4_1").unwrap().autopilot.clone().unwrap();
        assert_eq!(ap.label(), "armed OFFBOARD");
        f.apply(&said(6, "autopilot lost: no heartbeat for 2.0 s"));
        let label = |f: &Fleet| f.robot("px4_1").unwrap().autopilot.clone().unwrap().label();
        assert_eq!(label(&f), "autopilot lost");
        f.apply(&said(7, "autopilot heard again"));
        f.apply(&said(8, "autopilot disarmed"));
        assert_eq!(label(&f), "disarmed OFFBOARD");
        assert!(
            f.log.iter().any(|l| l.text == "px4_1: autopilot armed"),
            "and every notice is logged"
        );
    }

    #[test]
    fn a_station_radio_failing_and_reopened_is_logged_once_each_way() {
        let mut f = Fleet::new(FleetConfig::default());
        let radio = |ms: u64, up: bool, reason: &str| {
            at(
                ms,
                Event::Radio {
                    port: "/dev/ttyUSB0".into(),
                    up,
                    reason: reason.into(),
                },
            )
        };
        f.apply(&radio(1, false, "Broken pipe"));
        f.apply(&radio(2, true, ""));
        let lines: Vec<(Severity, &str)> = f
            .log
            .iter()
            .map(|l| (l.severity, l.text.as_str()))
            .collect();
        assert_eq!(
            lines,
            [
                (
                    Severity::Error,
                    "radio /dev/ttyUSB0 failed: Broken pipe; reopening it until it returns"
                ),
                (Severity::Info, "radio /dev/ttyUSB0 reopened"),
            ]
        );
    }

    #[test]
    fn a_robot_not_heard_has_its_telemetry_aged() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(
            1_000,
            Event::Telemetry {
                robot: "robot_1".into(),
                telemetry: telemetry(1.0, None),
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert_eq!(r.stale_for(Duration::from_secs(5)), None, "heard: live");
        f.apply(&at(
            2_000,
            Event::Link {
                robot: "robot_1".into(),
                state: LinkState::Lost,
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert_eq!(
            r.stale_for(Duration::from_millis(4_200)),
            Some(Duration::from_millis(3_200))
        );
    }

    #[test]
    fn a_driver_fault_text_is_kept_while_telemetry_reports_the_fault() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        let faulted = Telemetry {
            failsafe: FailsafeState::Fault,
            health: Health::Fault,
            velocity_source: mech_proto::VelocitySource::Measured,
            ..telemetry(0.0, None)
        };
        let telemetry_event = |t: &Telemetry| Event::Telemetry {
            robot: "robot_1".into(),
            telemetry: t.clone(),
        };
        f.apply(&at(1, telemetry_event(&faulted)));
        f.apply(&at(
            2,
            Event::Notice {
                from: "robot_1".into(),
                notice: Notice {
                    level: mech_proto::Level::Error,
                    code: NoticeCode::DriverFault,
                    text: "left wheel stalled: driven at 60% for 0.50 s".into(),
                },
            },
        ));
        f.apply(&at(3, telemetry_event(&faulted)));
        let r = f.robot("robot_1").unwrap();
        assert_eq!(
            r.fault.as_deref(),
            Some("left wheel stalled: driven at 60% for 0.50 s")
        );
        assert_eq!(
            r.telemetry.velocity_source,
            mech_proto::VelocitySource::Measured
        );
        // Other notices are only logged.
        f.apply(&at(
            4,
            Event::Notice {
                from: "robot_1".into(),
                notice: Notice {
                    level: mech_proto::Level::Warn,
                    code: NoticeCode::NotRouted,
                    text: "not routed".into(),
                },
            },
        ));
        assert!(f.robot("robot_1").unwrap().fault.is_some());
        f.apply(&at(5, telemetry_event(&telemetry(0.0, None))));
        assert_eq!(
            f.robot("robot_1").unwrap().fault,
            None,
            "cleared with the fault"
        );
    }

    #[test]
    fn route_is_pending_until_acknowledged() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(
            1,
            Event::RouteChanged {
                robot: "robot_1".into(),
                channel: Some("joy/0".into()),
                epoch: 1,
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert!(r.route.is_pending());
        assert_eq!(r.route.requested.as_deref(), Some("joy/0"));
        assert_eq!(r.route.acknowledged, None);
        f.apply(&at(
            2,
            Event::RouteAcked {
                robot: "robot_1".into(),
                channel: Some("joy/0".into()),
                epoch: 1,
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert!(!r.route.is_pending());
        assert_eq!(r.route.acknowledged.as_deref(), Some("joy/0"));
    }

    #[test]
    fn telemetry_updates_pose_speed_and_a_spaced_trail() {
        let mut cfg = FleetConfig::default();
        cfg.path_history = 2;
        cfg.path_spacing = 0.5;
        let mut f = Fleet::new(cfg);
        f.apply(&at(0, registered("robot_1")));
        for (i, x) in [0.0, 0.1, 1.0, 2.0].into_iter().enumerate() {
            f.apply(&at(
                i as u64,
                Event::Telemetry {
                    robot: "robot_1".into(),
                    telemetry: telemetry(x, None),
                },
            ));
        }
        let r = f.robot("robot_1").unwrap();
        assert_eq!(r.telemetry.pose.x, 2.0);
        assert!((r.speed() - 0.5).abs() < 1e-12);
        let xs: Vec<f64> = r.path.iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![1.0, 2.0]);
    }

    #[test]
    fn arrival_needs_the_acked_mission_to_finish() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(
            1,
            Event::MissionSent {
                robot: "robot_1".into(),
                channel: "wp/gcs".into(),
                id: 7,
                waypoints: vec![Waypoint {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                    time: None,
                }],
                looped: false,
            },
        ));
        let done = Some(MissionProgress {
            id: 7,
            next: 1,
            total: 1,
        });
        f.apply(&at(
            2,
            Event::Telemetry {
                robot: "robot_1".into(),
                telemetry: telemetry(1.0, done),
            },
        ));
        assert!(
            !f.robot("robot_1").unwrap().arrived(),
            "not acknowledged yet"
        );
        f.apply(&at(
            3,
            Event::MissionAcked {
                robot: "robot_1".into(),
                id: 7,
                accepted: true,
                reason: String::new(),
            },
        ));
        assert!(f.robot("robot_1").unwrap().arrived());
        let other = Some(MissionProgress {
            id: 6,
            next: 1,
            total: 1,
        });
        f.apply(&at(
            4,
            Event::Telemetry {
                robot: "robot_1".into(),
                telemetry: telemetry(1.0, other),
            },
        ));
        assert!(
            !f.robot("robot_1").unwrap().arrived(),
            "an older mission finishing is not arrival"
        );
    }

    #[test]
    fn a_stored_mission_on_a_channel_the_robot_is_not_routed_to_says_how_to_start_it() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        let send_and_ack = |f: &mut Fleet, ms: u64, id: u32| {
            f.apply(&at(
                ms,
                Event::MissionSent {
                    robot: "robot_1".into(),
                    channel: "wp/gcs".into(),
                    id,
                    waypoints: vec![Waypoint {
                        x: 3.5,
                        y: 2.5,
                        z: 0.0,
                        time: None,
                    }],
                    looped: false,
                },
            ));
            f.apply(&at(
                ms + 1,
                Event::MissionAcked {
                    robot: "robot_1".into(),
                    id,
                    accepted: true,
                    reason: String::new(),
                },
            ));
        };
        let held = |f: &Fleet| -> Vec<(Severity, String)> {
            f.log
                .iter()
                .filter(|e| e.text.contains("holds mission"))
                .map(|e| (e.severity, e.text.clone()))
                .collect()
        };
        // Routed to none: acknowledged, and the log says why it stands still.
        send_and_ack(&mut f, 1, 3);
        assert_eq!(
            held(&f),
            vec![(
                Severity::Warn,
                "robot_1 holds mission 3; it starts when routed to wp/gcs \
                 (`route robot_1 wp/gcs`)"
                    .to_string()
            )]
        );
        // Routed to the mission's channel (even before the robot
        // acknowledges the route): nothing held, nothing said.
        f.apply(&at(
            10,
            Event::RouteChanged {
                robot: "robot_1".into(),
                channel: Some("wp/gcs".into()),
                epoch: 1,
            },
        ));
        send_and_ack(&mut f, 11, 4);
        assert_eq!(held(&f).len(), 1, "{:?}", f.log);
        // A refused mission is not held.
        f.apply(&at(
            20,
            Event::RouteChanged {
                robot: "robot_1".into(),
                channel: Some("joy/0".into()),
                epoch: 2,
            },
        ));
        f.apply(&at(
            21,
            Event::MissionAcked {
                robot: "robot_1".into(),
                id: 5,
                accepted: false,
                reason: "too many waypoints".into(),
            },
        ));
        assert_eq!(held(&f).len(), 1, "{:?}", f.log);
    }

    #[test]
    fn link_quality_is_kept_per_robot() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        let lines = f.log.len();
        let quality = crate::counters::LinkQuality {
            rx_hz: 16.0,
            loss: Some(0.2),
            window: Duration::from_secs(5),
            ..Default::default()
        };
        f.apply(&at(
            1000,
            Event::LinkQuality {
                robot: "robot_1".into(),
                quality,
            },
        ));
        assert_eq!(f.robot("robot_1").unwrap().quality, quality);
        assert_eq!(f.log.len(), lines, "a periodic report logs nothing");
    }

    #[test]
    fn a_robot_registering_again_without_its_mission_is_reported_and_the_mission_lost() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        let wp = Waypoint {
            x: 1.0,
            y: 0.0,
            z: 0.0,
            time: None,
        };
        f.apply(&at(
            1,
            Event::MissionSent {
                robot: "robot_1".into(),
                channel: "joy/0".into(),
                id: 7,
                waypoints: vec![wp],
                looped: false,
            },
        ));
        f.apply(&at(
            2,
            Event::MissionAcked {
                robot: "robot_1".into(),
                id: 7,
                accepted: true,
                reason: String::new(),
            },
        ));
        let running = Some(MissionProgress {
            id: 7,
            next: 0,
            total: 1,
        });
        let tm = |mission| Event::Telemetry {
            robot: "robot_1".into(),
            telemetry: telemetry(0.5, mission),
        };
        f.apply(&at(3, tm(running)));
        // Registered again (a link outage) and still holding it: fine.
        f.apply(&at(4, registered("robot_1")));
        f.apply(&at(5, tm(running)));
        let delivery = |f: &Fleet| {
            f.robot("robot_1")
                .unwrap()
                .waypoints
                .sent
                .clone()
                .unwrap()
                .delivery
        };
        assert_eq!(delivery(&f), MissionDelivery::Acked);
        // Its agent restarted: registered, reporting no mission.
        f.apply(&at(6, registered("robot_1")));
        f.apply(&at(7, tm(None)));
        assert_eq!(delivery(&f), MissionDelivery::Lost);
        let warned = f
            .log
            .iter()
            .filter(|l| l.severity == Severity::Warn && l.text.contains("without mission 7"))
            .count();
        f.apply(&at(8, tm(None)));
        assert_eq!(warned, 1);
        assert_eq!(
            f.log
                .iter()
                .filter(|l| l.text.contains("without mission 7"))
                .count(),
            1,
            "said once"
        );
    }

    #[test]
    fn live_links_reach_the_robot_and_changes_are_logged() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        let links = RobotLinks {
            udp: false,
            radio: Some("/dev/ttyUSB0".into()),
            active: "radio",
            radio_budget_hz: Some(14.0),
            down: Vec::new(),
        };
        f.apply(&at(
            1,
            Event::Links {
                robot: "robot_1".into(),
                links: links.clone(),
            },
        ));
        assert_eq!(f.robot("robot_1").unwrap().links, links);
        assert_eq!(links.label(), "radio");
        assert!(f.log.back().unwrap().text.contains("links radio"));
    }

    #[test]
    fn targets_resolve_to_robots_clusters_and_all() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(0, registered("robot_2")));
        f.set_cluster("c1", vec!["robot_2".into()]);
        assert_eq!(f.resolve("all").unwrap().len(), 2);
        assert_eq!(f.resolve("c1").unwrap(), vec!["robot_2".to_string()]);
        assert_eq!(f.resolve("robot_1").unwrap(), vec!["robot_1".to_string()]);
        assert!(f.resolve("robot_9").is_none());
    }

    #[test]
    fn event_log_is_bounded() {
        let mut cfg = FleetConfig::default();
        cfg.event_log = 3;
        let mut f = Fleet::new(cfg);
        for i in 0..10 {
            f.log(Severity::Info, format!("line {i}"));
        }
        assert_eq!(f.log.len(), 3);
        assert_eq!(f.log.back().unwrap().text, "line 9");
    }

    #[test]
    fn log_lines_are_numbered_and_read_after_a_number() {
        let mut cfg = FleetConfig::default();
        cfg.event_log = 4;
        let mut f = Fleet::new(cfg);
        for i in 1..=6 {
            f.log(Severity::Info, format!("line {i}"));
        }
        let seqs: Vec<u64> = f.log.iter().map(|e| e.seq).collect();
        assert_eq!(seqs, vec![3, 4, 5, 6]);
        let after = |f: &Fleet, n| f.log_after(n).map(|e| e.text.clone()).collect::<Vec<_>>();
        assert_eq!(after(&f, 4), vec!["line 5", "line 6"]);
        assert_eq!(after(&f, 0).len(), 4, "from the start: what is kept");
        assert!(after(&f, 6).is_empty());
        // The same text twice at the same time is still two lines.
        f.log(Severity::Info, "line 6");
        assert_eq!(after(&f, 6), vec!["line 6"]);
    }
}
