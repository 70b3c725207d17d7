//! The station's own view of the fleet, for what the protocol gives no
//! external controller: each robot's link as the router measures it (state,
//! loss, round trip, rates, which links are live), the missions the station
//! sent, and the arena. The bridge
//! reads it by attaching to the station as the TUI does (`--attach`, the
//! station's control socket or its TCP attach port with an operator key),
//! asking for fleet snapshots only; it sends the station no command. It
//! attaches again (every [`RETRY`]) whenever the station goes away, and
//! meanwhile the view is empty, so `/diagnostics` says the bridge is not
//! attached instead of showing old figures.

use std::collections::HashMap;
use std::time::Duration;

use mech_core::arena::ArenaShape;
use mech_core::counters::LinkQuality;
use mech_core::event::LinkState;
use mech_station::client::{Address, AttachOptions, KeyFileRef, attach};
use mech_station::view::{FleetSnapshot, MissionView, Security};
use mech_station::wire::{FromStation, Streams};
use tokio::sync::watch;
use tracing::{info, warn};

/// How long the bridge waits before attaching again.
pub const RETRY: Duration = Duration::from_secs(2);

/// One robot's link as the station's router measures it.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotLink {
    pub state: LinkState,
    pub quality: LinkQuality,
    /// Live links and radio budget of a robot with several
    /// (`wifi*+radio 14Hz`); empty for a robot on one.
    pub links: String,
}

/// What the bridge knows from the station itself.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StationView {
    /// Attached, and a snapshot arrived.
    pub attached: bool,
    pub robots: HashMap<String, RobotLink>,
    /// The mission the station itself last sent each robot (an operator's
    /// waypoints, a script's).
    pub missions: HashMap<String, MissionView>,
    /// The station's arena, when it has one.
    pub arena: Option<ArenaShape>,
    /// Whether the station checks signatures (`None` until attached).
    pub security: Option<Security>,
}

impl StationView {
    /// The view in one of the station's snapshots (its own robots only:
    /// robots another station shares through a bridge are not routed
    /// here).
    pub fn from_snapshot(fleet: &FleetSnapshot) -> StationView {
        let robots = fleet
            .robots
            .iter()
            .filter(|r| r.remote.is_none())
            .map(|r| {
                let link = RobotLink {
                    state: r.link,
                    quality: r.quality,
                    links: r.links.clone(),
                };
                (r.name.clone(), link)
            })
            .collect();
        let missions = fleet
            .robots
            .iter()
            .filter(|r| r.remote.is_none())
            .filter_map(|r| Some((r.name.clone(), r.sent_mission.clone()?)))
            .collect();
        StationView {
            attached: true,
            robots,
            missions,
            arena: fleet.arena.clone(),
            security: Some(fleet.security),
        }
    }

    /// Whether the station requires keys, as its attach protocol says.
    /// Only the station's own answer to the bridge's attach tells; the
    /// router never answers a message it refuses, so a bridge without a
    /// key learns it here or not at all.
    pub fn requires_keys(&self) -> bool {
        self.attached && self.security == Some(Security::Authenticated)
    }

    /// Why `robot`, which the bridge has not heard of through the router,
    /// is not served: a robot the station has, at a station that requires
    /// keys, while the bridge signs nothing (`signs` false), is refused for
    /// want of a key; one the station has is otherwise not yet heard from;
    /// any other is not the station's.
    pub fn why_unknown(&self, robot: &str, signs: bool) -> String {
        if !self.robots.contains_key(robot) {
            return format!("{robot} is not a robot of the station");
        }
        if !signs && self.requires_keys() {
            return format!("{robot} is a robot of the station, but {KEYLESS}");
        }
        format!("{robot} is a robot of the station, but no telemetry of it has reached the bridge")
    }
}

/// What a bridge without a key is told at a station that requires keys.
pub const KEYLESS: &str = "the station needs keys and this bridge has none: the router refuses its \
     unsigned messages (give it a controller key the station's [auth] lists: --key, ros2.key)";

/// Where and how to attach.
#[derive(Debug, Clone)]
pub struct AttachTo {
    pub address: Address,
    /// An operator key, for a station's TCP attach port.
    pub key: Option<KeyFileRef>,
    /// The name the station logs the bridge's session under.
    pub operator: String,
}

/// Follows the station's view from now on (a task of its own, which
/// ends when the receiver is dropped); the receiver always holds the
/// latest.
pub fn follow(to: AttachTo) -> watch::Receiver<StationView> {
    let (tx, rx) = watch::channel(StationView::default());
    tokio::spawn(async move {
        tokio::select! {
            _ = tx.closed() => {}
            _ = keep_attached(&to, &tx) => {}
        }
    });
    rx
}

/// A station that sends no snapshot for this long is taken as gone (it
/// sends several a second): a cable pulled, a station stopped without
/// closing the connection.
pub const SILENT: Duration = Duration::from_secs(5);

/// Longest wait for a connection and the handshake.
const CONNECT: Duration = Duration::from_secs(10);

/// A session shorter than this is a flap: after the first, attaching and
/// detaching are logged again only once a session lasts.
const FLAP: Duration = Duration::from_secs(10);

/// Attaches, follows the snapshots until the station goes, and again,
/// for as long as anyone reads `tx`.
async fn keep_attached(to: &AttachTo, tx: &watch::Sender<StationView>) {
    let mut last_error = None;
    let mut flaps = 0u32;
    loop {
        let opts = AttachOptions {
            operator: Some(to.operator.clone()),
            key: to.key.clone(),
            stream: Streams {
                snapshots: true,
                ..Streams::default()
            },
        };
        match tokio::time::timeout(CONNECT, attach(&to.address, opts)).await {
            Ok(Ok(mut attached)) => {
                last_error = None;
                if flaps == 0 {
                    info!(station = %to.address, "attached to the station: link quality and the arena on /diagnostics and /mech/markers");
                }
                let since = std::time::Instant::now();
                let why = follow_snapshots(&mut attached.from, tx).await;
                if tx.send(StationView::default()).is_err() {
                    return;
                }
                flaps = if since.elapsed() < FLAP { flaps + 1 } else { 0 };
                match flaps {
                    0 | 1 => {
                        warn!(station = %to.address, "detached from the station ({why}); attaching again")
                    }
                    2 => {
                        warn!(station = %to.address, "the station keeps ending the session ({why}); attaching again every {RETRY:?}, quietly until a session lasts")
                    }
                    _ => {}
                }
            }
            result => {
                let text = match result {
                    Ok(Err(e)) => e.to_string(),
                    _ => format!("no answer within {CONNECT:?}"),
                };
                if last_error.as_ref() != Some(&text) {
                    warn!(station = %to.address, "cannot attach to the station: {text}; trying again every {RETRY:?}");
                    last_error = Some(text);
                }
            }
        }
        tokio::time::sleep(RETRY).await;
    }
}

/// Passes each snapshot on until the session ends; why it ended.
async fn follow_snapshots(
    from: &mut tokio::sync::mpsc::Receiver<FromStation>,
    tx: &watch::Sender<StationView>,
) -> String {
    loop {
        match tokio::time::timeout(SILENT, from.recv()).await {
            Ok(Some(FromStation::Snapshot { fleet, .. })) => {
                if tx.send(StationView::from_snapshot(&fleet)).is_err() {
                    return "the bridge stops".into();
                }
            }
            Ok(Some(FromStation::Bye { reason })) => return format!("the station said: {reason}"),
            Ok(Some(_)) => {}
            Ok(None) => return "the connection closed".into(),
            Err(_) => return format!("no snapshot for {SILENT:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_station::view::RobotView;

    #[test]
    fn a_snapshot_gives_each_own_robots_link_and_the_arena() {
        let robot = |name: &str, remote: Option<&str>| {
            let mut r = RobotView::at(name, 1, "diff-drive", 0.0, 0.0, 0.0);
            r.link = LinkState::Stale;
            r.links = "wifi*+radio 14Hz".into();
            r.remote = remote.map(str::to_string);
            r.sent_mission = Some(MissionView {
                id: 4,
                channel: "wp/gcs".into(),
                waypoints: vec![],
                looped: false,
            });
            r.quality.loss = Some(0.25);
            r
        };
        let fleet = FleetSnapshot {
            robots: vec![robot("robot_1", None), robot("far_1", Some("lab2"))],
            arena: Some(mech_core::ArenaConfig::demo().shape()),
            ..FleetSnapshot::default()
        };
        let v = StationView::from_snapshot(&fleet);
        assert!(v.attached);
        assert_eq!(v.robots.len(), 1, "a remote robot is not this station's");
        let l = &v.robots["robot_1"];
        assert_eq!(
            (l.state, l.quality.loss, l.links.as_str()),
            (LinkState::Stale, Some(0.25), "wifi*+radio 14Hz")
        );
        assert_eq!(v.arena.as_ref().map(|a| a.boundary.len()), Some(4));
        assert_eq!(v.missions.len(), 1);
        assert_eq!(v.missions["robot_1"].id, 4);
        assert!(!StationView::default().attached);
    }

    #[test]
    fn a_keyless_bridge_at_a_station_that_requires_keys_is_told_why_its_robots_are_refused() {
        let snapshot = |security| FleetSnapshot {
            robots: vec![RobotView::at("rb_1", 1, "diff-drive", 0.0, 0.0, 0.0)],
            security,
            ..FleetSnapshot::default()
        };
        let keyed = StationView::from_snapshot(&snapshot(Security::Authenticated));
        assert!(keyed.requires_keys());
        assert_eq!(
            keyed.why_unknown("rb_1", false),
            format!("rb_1 is a robot of the station, but {KEYLESS}")
        );
        // With a key, keys are not the reason; a robot the station does
        // not have is not its robot, key or not.
        assert!(!keyed.why_unknown("rb_1", true).contains("needs keys"));
        assert_eq!(
            keyed.why_unknown("rb_9", false),
            "rb_9 is not a robot of the station"
        );
        // A station without keys, or one not attached: never blamed on keys.
        let open = StationView::from_snapshot(&snapshot(Security::LoopbackOnly));
        assert!(!open.requires_keys());
        assert!(!open.why_unknown("rb_1", false).contains("needs keys"));
        assert!(!StationView::default().requires_keys());
        assert_eq!(
            StationView::default().why_unknown("rb_1", false),
            "rb_1 is not a robot of the station"
        );
    }
}
