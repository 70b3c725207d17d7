//! The bridge: the station link on one side, the ROS 2 node on the other,
//! and one task between them that owns the fleet view. Telemetry becomes
//! odometry and TF as it arrives; battery, diagnostics and markers go out
//! once a second; cmd_vel, goals and e-stop requests are checked
//! ([`crate::inbound`]) and forwarded or refused and counted.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use mech_proto::NoticeCode;
use mech_proto::auth::{Key, KeyText, private_mode};
use tokio::sync::mpsc;
use tracing::{error, info, warn};

use crate::config::Ros2Config;
use crate::fleet::{Fleet, Goal, ros_name_ok};
use crate::inbound::cmd_vel::{self, CmdVelLimits};
use crate::inbound::goal::{self, GoalRules};
use crate::inbound::{Refusal, Refused};
use crate::link::{FromStation, StationLink, local_us};
use crate::msgs::builtin::Time;
use crate::msgs::diagnostic::DiagnosticArray;
use crate::msgs::nav::TfMessage;
use crate::msgs::std::{Header, TriggerResponse};
use crate::msgs::visualization::MarkerArray;
use crate::outbound::{self, Frames, diagnostics, odom};
use crate::ros::{CmdVel, FromRos, RosNode};
use crate::station::{AttachTo, StationView};
use crate::stats::{Stats, StatsSnapshot, worth_logging};

/// Subscriptions are renewed this often (the router drops a subscriber
/// after 5 s).
const RENEW_EVERY: Duration = Duration::from_secs(2);
/// A goal is resent to the router this often until its robot acknowledges.
const GOAL_RETRY: Duration = Duration::from_millis(200);
/// ... for at most this long.
const GOAL_GIVE_UP: Duration = Duration::from_secs(5);
/// An e-stop request is resent this often until every robot reports
/// e-stopped, for at most [`ESTOP_FOR`].
const ESTOP_RETRY: Duration = Duration::from_millis(100);
const ESTOP_FOR: Duration = Duration::from_secs(1);

/// Why the bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("key file {path}: {reason}")]
    Key { path: String, reason: String },
    #[error(transparent)]
    Link(#[from] crate::link::LinkError),
    #[error(transparent)]
    Ros(#[from] crate::ros::RosError),
    #[error("{0}")]
    Config(String),
}

/// Reads a key file as the station does: private (mode 0600), one name
/// and secret.
pub fn read_key(path: &std::path::Path) -> Result<KeyText, StartError> {
    let fail = |reason: String| StartError::Key {
        path: path.display().to_string(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| fail(e.to_string()))?;
    {
        use std::os::unix::fs::PermissionsExt;
        private_mode(meta.permissions().mode()).map_err(fail)?;
    }
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    KeyText::parse(&text).map_err(fail)
}

/// A running bridge, with what it shares with its tasks.
#[derive(Debug)]
pub struct Bridge {
    config: Ros2Config,
    stats: Arc<Stats>,
    link: Arc<StationLink>,
    /// The e-stop key's own socket, when there is one.
    estop_link: Option<Arc<StationLink>>,
    ros: RosNode,
    fleet: Fleet,
    from_station: mpsc::Receiver<FromStation>,
    from_ros: mpsc::Receiver<FromRos>,
    next_mission_id: u32,
    /// Until when an e-stop request is repeated.
    estop_until: Option<Instant>,
    /// Names refused as not ROS 2 names (each logged once).
    bad_names: std::collections::BTreeSet<String>,
    /// The station's own view, when the bridge attaches to it.
    station: Option<tokio::sync::watch::Receiver<StationView>>,
    /// Said once that the station requires keys and the bridge has none.
    keyless_said: bool,
}

impl Bridge {
    /// Opens the station link(s), subscribes to telemetry and joins DDS.
    pub async fn start(config: Ros2Config) -> Result<Bridge, StartError> {
        config.check().map_err(StartError::Config)?;
        let stats = Arc::new(Stats::default());
        let key = config.key.as_deref().map(read_key).transpose()?;
        let name = match &key {
            Some(k) => {
                if k.name != config.name && config.name != Ros2Config::default().name {
                    warn!(
                        "ros2.name {:?} is not the key's name {:?}: the key's is used",
                        config.name, k.name
                    );
                }
                k.name.clone()
            }
            None => config.name.clone(),
        };
        let key: Option<Key> = key.map(|k| k.key);
        let link = Arc::new(
            StationLink::open(config.router, &name, key.clone(), Arc::clone(&stats)).await?,
        );
        let estop_link = match config.estop_key.as_deref().map(read_key).transpose()? {
            Some(k) => Some(Arc::new(
                StationLink::open(config.router, &k.name, Some(k.key), Arc::clone(&stats)).await?,
            )),
            None => None,
        };
        let (to_bridge, from_station) = mpsc::channel(4096);
        link.spawn_reader(key, to_bridge);
        link.subscribe(true);
        let domain = config.domain().map_err(StartError::Config)?;
        let (to_bridge, from_ros) = mpsc::channel(4096);
        let ros = RosNode::start(
            domain,
            config.cmd_vel,
            config.estop,
            config.estop_service,
            to_bridge,
            Arc::clone(&stats),
        )?;
        if config.router.ip().is_loopback() && dds_port(domain, config.router.port()) {
            warn!(
                router = %config.router,
                domain,
                "the station's UDP port is one DDS domain {domain} uses; a station bound to \
                 0.0.0.0 on it shares its datagrams with DDS on this machine: move the station \
                 or set ROS_DOMAIN_ID"
            );
        }
        let station = follow_station(&config, &name)?;
        let first_id = (local_us() / 1_000_000).wrapping_mul(16) as u32;
        info!(
            router = %config.router, name, domain,
            signed = link.signs(), estop_key = estop_link.is_some(),
            "bridging MECH to ROS 2 as node /mech_ros2"
        );
        Ok(Bridge {
            config,
            stats,
            link,
            estop_link,
            ros,
            fleet: Fleet::default(),
            from_station,
            from_ros,
            next_mission_id: first_id,
            estop_until: None,
            bad_names: Default::default(),
            station,
            keyless_said: false,
        })
    }

    /// The counters, shared.
    pub fn stats(&self) -> Arc<Stats> {
        Arc::clone(&self.stats)
    }

    /// Runs until `shutdown` resolves; unsubscribes and logs a last
    /// summary.
    pub async fn run(mut self, shutdown: impl std::future::Future<Output = ()>) -> StatsSnapshot {
        let mut shutdown = std::pin::pin!(shutdown);
        let mut second = tokio::time::interval(Duration::from_secs(1));
        let mut renew = tokio::time::interval(RENEW_EVERY);
        let mut retry = tokio::time::interval(ESTOP_RETRY);
        let summary_every = Duration::from_secs_f64(self.config.summary_every.max(0.001));
        let mut summary = tokio::time::interval(summary_every);
        for t in [&mut second, &mut renew, &mut retry, &mut summary] {
            t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        }
        loop {
            tokio::select! {
                _ = &mut shutdown => break,
                Some(ev) = self.from_station.recv() => self.on_station(ev),
                Some(ev) = self.from_ros.recv() => self.on_ros(ev),
                _ = second.tick() => self.every_second(),
                _ = renew.tick() => self.link.subscribe(true),
                _ = retry.tick() => self.retry(Instant::now()),
                _ = summary.tick() => {
                    if self.config.summary_every > 0.0 {
                        self.log_summary();
                    }
                }
            }
        }
        self.link.subscribe(false);
        self.log_summary();
        self.stats.snapshot()
    }

    fn log_summary(&self) {
        let s = self.stats.snapshot();
        info!(robots = self.fleet.len(), "ros2 bridge: {s}");
    }

    fn on_station(&mut self, ev: FromStation) {
        match ev {
            FromStation::Telemetry {
                robot,
                stamp_us,
                telemetry,
            } => {
                self.stats.telemetry.fetch_add(1, Ordering::Relaxed);
                if !ros_name_ok(&robot) {
                    if self.bad_names.insert(robot.clone()) {
                        self.stats.names_rejected.fetch_add(1, Ordering::Relaxed);
                        warn!(
                            %robot,
                            "robot name cannot be a ROS 2 name (letters, digits, '_', not \
                             starting with a digit): it is not bridged"
                        );
                    }
                    return;
                }
                let now = Instant::now();
                if self.fleet.update(&robot, telemetry.clone(), stamp_us, now) {
                    info!(%robot, "bridging robot: /{robot}/odom, /{robot}/cmd_vel on {}", self.config.cmd_channel(&robot));
                    if let Err(e) = self.ros.add_robot(&robot) {
                        error!(%robot, "cannot make its ROS 2 topics: {e}");
                    }
                }
                let stamp = Time::from_micros(if stamp_us == 0 { local_us() } else { stamp_us });
                let frames = Frames::new(&self.config.map_frame, &robot);
                self.ros
                    .odometry(&robot, odom::odometry(&telemetry, stamp, &frames));
                self.ros.tf(TfMessage {
                    transforms: vec![odom::transform(&telemetry, stamp, &frames)],
                });
            }
            FromStation::MissionAck { robot, ack } => {
                let Some(r) = self.fleet.get_mut(&robot) else {
                    return;
                };
                let Some(goal) = r.goal.as_mut() else {
                    return;
                };
                if goal.mission.id != ack.id || goal.ack.is_some() {
                    return;
                }
                self.stats.goals_acked.fetch_add(1, Ordering::Relaxed);
                if ack.accepted {
                    info!(%robot, id = ack.id, "goal accepted");
                } else {
                    // The robot's reason, or the station's when its
                    // permissions refused the goal before the robot saw it.
                    warn!(%robot, id = ack.id, "goal refused: {}", ack.reason);
                }
                goal.ack = Some((ack.accepted, ack.reason));
            }
            FromStation::Notice { from, notice } => {
                let n = self.stats.notices.fetch_add(1, Ordering::Relaxed) + 1;
                // A refusal by the station's permissions is always said:
                // the station sends a few a second at most.
                if notice.code == NoticeCode::NotPermitted {
                    self.stats.station_refusals.fetch_add(1, Ordering::Relaxed);
                    warn!(%from, "the station refused a message of this bridge: {}", notice.text);
                } else if worth_logging(n) {
                    warn!(%from, code = ?notice.code, notices = n, "notice from the station: {}", notice.text);
                }
            }
        }
    }

    fn on_ros(&mut self, ev: FromRos) {
        match ev {
            FromRos::CmdVel { robot, twist } => {
                let limits = CmdVelLimits {
                    max_speed: self.config.max_speed,
                    max_yaw_rate: self.config.max_yaw_rate,
                };
                let command = self.known(&robot).and_then(|()| match &twist {
                    CmdVel::Plain(t) => cmd_vel::from_twist(t, limits),
                    CmdVel::Stamped(t) => cmd_vel::from_stamped(t, &robot, limits),
                });
                match command {
                    Ok(c) => {
                        self.link
                            .command(&robot, &self.config.cmd_channel(&robot), c);
                        self.stats.cmd_forwarded.fetch_add(1, Ordering::Relaxed);
                        if let Some(r) = self.fleet.get_mut(&robot) {
                            r.cmd_forwarded += 1;
                        }
                    }
                    Err(e) => self.refused(&robot, "cmd_vel", e),
                }
            }
            FromRos::Goal { robot, goal } => {
                let rules = self.goal_rules();
                match self
                    .known(&robot)
                    .and_then(|()| goal::waypoint(&goal, &rules))
                {
                    Ok(w) => self.send_goal(&robot, goal::mission(0, w, &rules)),
                    Err(e) => self.refused(&robot, "goal_pose", e),
                }
            }
            FromRos::EStop { reply } => {
                let answer = self.estop();
                if let Some(reply) = reply {
                    let _ = reply.send(answer);
                }
            }
        }
    }

    fn goal_rules(&self) -> GoalRules {
        GoalRules {
            map_frame: self.config.map_frame.clone(),
            max_distance: self.config.max_goal_distance,
            arrival_radius: self.config.arrival_radius,
        }
    }

    /// Ok if the station has reported robot `robot`; else why not, as
    /// far as the bridge can tell (the station's own view, when attached,
    /// says whether it has the robot and whether it requires keys).
    fn known(&self, robot: &str) -> Result<(), Refused> {
        if self.fleet.knows(robot) {
            return Ok(());
        }
        let detail = match &self.station {
            Some(view) => view.borrow().why_unknown(robot, self.link.signs()),
            None => format!("{robot} is not a robot of the station"),
        };
        Err(Refused {
            reason: Refusal::UnknownRobot,
            detail,
        })
    }

    fn refused(&self, robot: &str, topic: &str, e: Refused) {
        self.stats.refuse(e.reason);
        let n = self.stats.refused(e.reason);
        if worth_logging(n) {
            warn!(%robot, reason = %e.reason, count = n, "refused /{robot}/{topic}: {}", e.detail);
        }
    }

    fn send_goal(&mut self, robot: &str, mut mission: mech_proto::Mission) {
        self.next_mission_id = self.next_mission_id.wrapping_add(1);
        mission.id = self.next_mission_id;
        let channel = self.config.goal_channel(robot);
        let now = Instant::now();
        info!(%robot, id = mission.id, %channel, waypoint = ?mission.waypoints.first(), "goal sent as a mission");
        self.link.mission(robot, &channel, mission.clone());
        self.stats.goals_sent.fetch_add(1, Ordering::Relaxed);
        if let Some(r) = self.fleet.get_mut(robot) {
            r.goal = Some(Goal {
                mission,
                channel,
                first_sent: now,
                last_sent: now,
                ack: None,
                unacked: false,
            });
        }
    }

    /// Engages the e-stop through the e-stop key's socket, or, at a station
    /// that does not authenticate, through the bridge's own; says which, as
    /// the `/mech/estop` service answers.
    fn estop(&mut self) -> TriggerResponse {
        let link = match (&self.estop_link, self.link.signs()) {
            (Some(l), _) => Arc::clone(l),
            (None, false) => Arc::clone(&self.link),
            (None, true) => {
                let n = self.stats.estops_refused.fetch_add(1, Ordering::Relaxed) + 1;
                let message = "ros2.estop_key is not set: the station accepts e-stops only \
                               from an e-stop or operator key";
                if worth_logging(n) {
                    error!("e-stop requested on /mech/estop, but {message}");
                }
                return TriggerResponse {
                    success: false,
                    message: message.into(),
                };
            }
        };
        warn!(
            robots = self.fleet.len(),
            "E-STOP requested on /mech/estop: engaging"
        );
        link.engage_estop();
        self.stats.estops_sent.fetch_add(1, Ordering::Relaxed);
        self.estop_until = Some(Instant::now() + ESTOP_FOR);
        TriggerResponse {
            success: true,
            message: format!(
                "e-stop engage sent to the station for every robot ({} known here); only an \
                 operator at the station releases it",
                self.fleet.len()
            ),
        }
    }

    /// Repeats an e-stop until every robot reports it, and goals until
    /// their robot acknowledges them.
    fn retry(&mut self, now: Instant) {
        if let Some(until) = self.estop_until {
            if self.fleet.all_estopped() || now >= until {
                self.estop_until = None;
            } else {
                let link = self.estop_link.as_ref().unwrap_or(&self.link);
                link.engage_estop();
            }
        }
        let due = self.fleet.goals_due(now, GOAL_RETRY, GOAL_GIVE_UP);
        for (robot, id) in due.given_up {
            self.stats.goals_unacked.fetch_add(1, Ordering::Relaxed);
            warn!(%robot, id, "goal not acknowledged within 5 s: given up");
        }
        for (robot, channel, mission) in due.resend {
            self.link.mission(&robot, &channel, mission);
        }
    }

    /// Battery (stamped with the sample it comes from), diagnostics and
    /// markers; reads cmd_vel of names other nodes publish for, so that
    /// samples for robots the station does not have are counted.
    fn every_second(&mut self) {
        let now = Instant::now();
        let stamp = Time::from_micros(local_us());
        let view = self
            .station
            .as_ref()
            .map(|s| s.borrow().clone())
            .unwrap_or_default();
        if view.requires_keys() && !self.link.signs() && !self.keyless_said {
            self.keyless_said = true;
            error!("{}", crate::station::KEYLESS);
        }
        let out = outbound::periodic(&self.fleet, &view, &self.config, now, stamp);
        for (robot, b) in out.batteries {
            self.ros.battery(&robot, b);
        }
        let mut status = out.status;
        let snapshot = self.stats.snapshot();
        status.push(diagnostics::bridge_status(
            self.link_name(),
            self.fleet.len(),
            self.station.as_ref().map(|_| view.attached),
            &snapshot,
        ));
        let header = Header {
            stamp,
            frame_id: String::new(),
        };
        self.ros.diagnostics(DiagnosticArray { header, status });
        if !out.markers.is_empty() {
            self.ros.markers(MarkerArray {
                markers: out.markers,
            });
        }
        for name in self.ros.unwatched_publishers() {
            if !ros_name_ok(&name) {
                continue;
            }
            if let Err(e) = self.ros.watch(&name) {
                warn!(%name, "cannot read its cmd_vel: {e}");
            } else if !self.fleet.knows(&name) {
                info!(%name, "another node publishes for {name}, which the station has not reported: its samples are refused");
            }
        }
    }

    fn link_name(&self) -> &str {
        &self.config.name
    }
}

/// The station's own view, followed when `ros2.attach` names the station
/// (as operator `<name>-bridge`, or over TCP as the operator key's name).
fn follow_station(
    config: &Ros2Config,
    name: &str,
) -> Result<Option<tokio::sync::watch::Receiver<StationView>>, StartError> {
    let Some(address) = config.attach.as_deref() else {
        return Ok(None);
    };
    let key = config.attach_key.as_deref().map(read_key).transpose()?;
    let operator = key
        .as_ref()
        .map_or_else(|| Ros2Config::attach_operator(name), |k| k.name.clone());
    Ok(Some(crate::station::follow(AttachTo {
        address: mech_station::client::Address::parse(address),
        key: key.map(|k| mech_station::client::KeyFileRef {
            name: k.name,
            key: k.key,
        }),
        operator,
    })))
}

/// Whether UDP port `port` is one the DDS domain `domain` uses on this
/// machine (RTPS: 7400 + 250 x domain, then discovery and user ports of
/// up to 120 participants).
pub fn dds_port(domain: u16, port: u16) -> bool {
    let base = 7400u32 + 250 * u32::from(domain);
    (base..base + 250).contains(&u32::from(port))
}

#[cfg(test)]
mod tests {
    use super::{dds_port, read_key};
    use mech_proto::auth::KeyText;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn a_key_file_others_can_read_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ros2.key");
        std::fs::write(&path, KeyText::render("ros2", &[3; 32])).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(read_key(&path).unwrap().name, "ros2");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = read_key(&path).unwrap_err().to_string();
        assert!(e.contains("chmod 600") && e.contains("ros2.key"), "{e}");
        assert!(read_key(&dir.path().join("missing.key")).is_err());
    }

    #[test]
    fn the_station_port_is_checked_against_the_dds_domain() {
        assert!(
            dds_port(0, 7400),
            "domain 0's discovery port is MECH's default"
        );
        assert!(dds_port(0, 7411));
        assert!(!dds_port(1, 7400));
        assert!(dds_port(1, 7650));
        assert!(!dds_port(0, 7300));
    }
}
