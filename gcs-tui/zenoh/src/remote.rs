//! Other stations' robots, from Zenoh into this station's fleet model,
//! read-only (`Fleet::remote_*`): their registration, telemetry, link and
//! route as their stations publish them, and whether each station and
//! robot is alive, from their liveliness tokens. A token withdrawn (the
//! robot lost at its station, or the station gone: its session closed, or
//! silent for the lease) shows the robot lost here at once. When a robot
//! appears, its latest state is asked for, so a station that joins late
//! shows it whole without waiting for its next change.

use std::sync::Arc;
use std::time::Duration;

use mech_core::{Gcs, LinkState};
use tokio::runtime::Handle;
use tracing::debug;
use zenoh::Session;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Locality, Sample, SampleKind};

use crate::keys::{self, Key, Topic};
use crate::payload::{InfoMsg, LinkMsg, PayloadError, RouteMsg, TelemetryMsg, from_json};
use crate::stats::Stats;

/// How long a station is given to answer for a robot's state.
const FETCH_TIMEOUT: Duration = Duration::from_secs(2);

/// The subscriptions that hear other stations.
#[derive(Debug)]
pub(crate) struct Remote {
    pub(crate) state: Subscriber<()>,
    pub(crate) liveliness: Subscriber<()>,
}

/// What the callbacks share.
#[derive(Debug)]
struct Hearing {
    /// This station's name: its own samples are not remote.
    station: String,
    gcs: Gcs,
    stats: Arc<Stats>,
    session: Session,
    runtime: Handle,
}

/// Subscribes to every station's robots' state and liveliness.
pub(crate) async fn declare(
    session: &Session,
    station: &str,
    gcs: Gcs,
    stats: Arc<Stats>,
) -> zenoh::Result<Remote> {
    let hearing = Arc::new(Hearing {
        station: station.to_string(),
        gcs,
        stats,
        session: session.clone(),
        runtime: Handle::current(),
    });
    let h = hearing.clone();
    let state = session
        .declare_subscriber(format!("{}/*/*/*", keys::ROOT))
        .allowed_origin(Locality::Remote)
        .callback(move |sample| h.state(&sample, true))
        .await?;
    let liveliness = session
        .liveliness()
        .declare_subscriber(format!("{}/**", keys::ROOT))
        .history(true)
        .callback(move |sample| hearing.alive(&sample))
        .await?;
    Ok(Remote { state, liveliness })
}

impl Hearing {
    /// A state sample of another station's robot: `live` as published, or
    /// not (the latest, answered to a query: its age says nothing).
    fn state(&self, sample: &Sample, live: bool) {
        let key = sample.key_expr().as_str();
        let (station, robot, topic) = match keys::parse(key) {
            Ok(Key::State {
                station,
                robot,
                topic,
            }) => (station, robot, topic),
            Ok(_) => return self.stats.bad_input(&format!("{key:?} is not a state key")),
            Err(e) => return self.stats.bad_input(&e),
        };
        if station == self.station {
            return;
        }
        let bytes = sample.payload().to_bytes();
        let applied = match topic {
            Topic::Telemetry => self.telemetry(station, robot, &bytes, live),
            Topic::Info => self.info(station, robot, &bytes),
            Topic::Link => self.link(station, robot, &bytes),
            Topic::Route => self.route(station, robot, &bytes),
        };
        match applied {
            Ok(true) => Stats::bump(&self.stats.remote_updates),
            Ok(false) => self.stats.bad_input(&format!(
                "{robot} of station {station} is not shown: {} is one of this station's robots",
                mech_core::fleet::remote_name(robot, station)
            )),
            Err(e) => self.stats.bad_input(&format!("{key:?}: {e}")),
        }
    }

    fn telemetry(
        &self,
        station: &str,
        robot: &str,
        bytes: &[u8],
        live: bool,
    ) -> Result<bool, PayloadError> {
        let msg: TelemetryMsg = from_json("telemetry", bytes)?;
        msg.origin.check("telemetry", station, robot)?;
        let t = msg.telemetry()?;
        let at = self.gcs.router().elapsed();
        let applied = self
            .gcs
            .update_fleet(|f| f.remote_telemetry(station, robot, &t, at));
        if live {
            // From its station's router receiving it to this station's model.
            let age = mech_proto::unix_micros().saturating_sub(msg.stamp_us);
            self.stats.record_age(Duration::from_micros(age));
            Stats::bump(&self.stats.remote_telemetry);
        }
        Ok(applied)
    }

    fn info(&self, station: &str, robot: &str, bytes: &[u8]) -> Result<bool, PayloadError> {
        let msg: InfoMsg = from_json("info", bytes)?;
        msg.origin.check("info", station, robot)?;
        let info = msg.info()?;
        Ok(self
            .gcs
            .update_fleet(|f| f.remote_info(station, robot, &info)))
    }

    fn link(&self, station: &str, robot: &str, bytes: &[u8]) -> Result<bool, PayloadError> {
        let msg: LinkMsg = from_json("link", bytes)?;
        msg.origin.check("link", station, robot)?;
        Ok(self
            .gcs
            .update_fleet(|f| f.remote_link(station, robot, msg.state)))
    }

    fn route(&self, station: &str, robot: &str, bytes: &[u8]) -> Result<bool, PayloadError> {
        let msg: RouteMsg = from_json("route", bytes)?;
        msg.origin.check("route", station, robot)?;
        let route = msg.route()?;
        Ok(self
            .gcs
            .update_fleet(|f| f.remote_route(station, robot, route)))
    }

    /// A liveliness token appeared or went: a station, or a robot of one.
    fn alive(self: &Arc<Self>, sample: &Sample) {
        let key = sample.key_expr().as_str();
        let state = match sample.kind() {
            SampleKind::Put => LinkState::Connected,
            SampleKind::Delete => LinkState::Lost,
        };
        match keys::parse(key) {
            Ok(Key::Station { station }) if station != self.station => {
                self.gcs.update_fleet(|f| f.remote_station(station, state));
            }
            Ok(Key::Robot { station, robot }) if station != self.station => {
                self.gcs
                    .update_fleet(|f| f.remote_link(station, robot, state));
                if state == LinkState::Connected {
                    self.runtime
                        .spawn(self.clone().fetch(station.to_string(), robot.to_string()));
                }
            }
            Ok(_) => {}
            Err(e) => self.stats.bad_input(&e),
        }
    }

    /// Asks `station` for its robot's latest state.
    async fn fetch(self: Arc<Self>, station: String, robot: String) {
        let key = format!("{}/{station}/{robot}/*", keys::ROOT);
        let replies = match self.session.get(&key).timeout(FETCH_TIMEOUT).await {
            Ok(r) => r,
            Err(e) => return debug!(%key, error = %e, "cannot ask for a robot's state"),
        };
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                self.state(sample, false);
            }
        }
    }
}
