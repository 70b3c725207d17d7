//! Other stations' robots, from Zenoh into this station's fleet model,
//! read-only (`Fleet::remote_*`): their registration, telemetry, link and
//! route as their stations publish them, and whether each station and
//! robot is alive, from their liveliness tokens. A token withdrawn (the
//! robot lost at its station, or the station gone: its session closed, or
//! silent for the lease) shows the robot lost here at once. When a robot
//! appears, its latest state is asked for, so a station that joins late
//! shows it whole without waiting for its next change.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mech_core::{Gcs, LinkState};
use mech_proto::Hello;
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
    freshness: Freshness,
}

/// When each robot's state topics were last heard live, so that the answer
/// to a state query, which may arrive after later live samples (a route
/// that changed while the query was on its way), never overwrites them
/// with older state. Telemetry is not tracked: the next live sample, a
/// period later, replaces an older answer anyway, and tracking it would
/// cost a map update per sample.
#[derive(Debug, Default)]
struct Freshness {
    live: Mutex<HashMap<(String, String, Topic), Instant>>,
}

impl Freshness {
    /// A live sample of `topic` for `robot` of `station` arrived now.
    fn heard_live(&self, station: &str, robot: &str, topic: Topic) {
        mech_core::sync::lock(&self.live).insert(
            (station.to_string(), robot.to_string(), topic),
            Instant::now(),
        );
    }

    /// Whether the answer to a query sent at `asked` is still the latest
    /// of `topic`: no live sample of it came since.
    fn answer_is_latest(&self, station: &str, robot: &str, topic: Topic, asked: Instant) -> bool {
        mech_core::sync::lock(&self.live)
            .get(&(station.to_string(), robot.to_string(), topic))
            .is_none_or(|heard| *heard < asked)
    }
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
        freshness: Freshness::default(),
    });
    let h = hearing.clone();
    let state = session
        .declare_subscriber(format!("{}/*/*/*", keys::ROOT))
        .allowed_origin(Locality::Remote)
        .callback(move |sample| h.state(&sample, None))
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
    /// answered to a query sent at `asked` (the latest then: its age says
    /// nothing, and a live sample heard since is newer).
    fn state(&self, sample: &Sample, asked: Option<Instant>) {
        let live = asked.is_none();
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
        match asked {
            None if topic == Topic::Telemetry => {}
            None => self.freshness.heard_live(station, robot, topic),
            Some(_) if topic == Topic::Telemetry => {}
            Some(asked)
                if !self
                    .freshness
                    .answer_is_latest(station, robot, topic, asked) =>
            {
                return debug!(%key, "answer older than a live sample: not applied");
            }
            Some(_) => {}
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
        msg.check()?;
        let at = self.gcs.router().elapsed();
        let applied = self
            .gcs
            .update_fleet(|f| f.remote_telemetry(station, robot, &msg.telemetry, at));
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
        msg.check()?;
        let hello = Hello {
            name: robot.to_string(),
            ..msg.hello
        };
        Ok(self
            .gcs
            .update_fleet(|f| f.remote_info(station, robot, msg.id, &hello)))
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
        let asked = Instant::now();
        let replies = match self.session.get(&key).timeout(FETCH_TIMEOUT).await {
            Ok(r) => r,
            Err(e) => return debug!(%key, error = %e, "cannot ask for a robot's state"),
        };
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                self.state(sample, Some(asked));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_query_answer_never_overwrites_a_later_live_sample() {
        let f = Freshness::default();
        let asked = Instant::now();
        // Nothing heard live: the answer is the latest there is.
        assert!(f.answer_is_latest("site-s", "robot_1", Topic::Route, asked));
        // The route changes (live) while the query is on its way: the
        // answer, older, must not overwrite it.
        f.heard_live("site-s", "robot_1", Topic::Route);
        assert!(!f.answer_is_latest("site-s", "robot_1", Topic::Route, asked));
        // Other topics, robots and stations are apart.
        assert!(f.answer_is_latest("site-s", "robot_1", Topic::Link, asked));
        assert!(f.answer_is_latest("site-s", "robot_2", Topic::Route, asked));
        assert!(f.answer_is_latest("site-u", "robot_1", Topic::Route, asked));
        // A query sent after the live sample: its answer is newer.
        std::thread::sleep(Duration::from_millis(1));
        assert!(f.answer_is_latest("site-s", "robot_1", Topic::Route, Instant::now()));
    }
}
