//! Answers `get` on this station's robots (`mech/<station>/*/*`): the
//! latest registration, telemetry, link and route of each, from the fleet
//! model. A station or program that joins late reads the state at once
//! instead of waiting for the next change.

use mech_core::Gcs;
use mech_core::fleet::Robot;
use tracing::debug;
use zenoh::bytes::Encoding;
use zenoh::key_expr::KeyExpr;
use zenoh::query::{Query, Queryable};
use zenoh::{Session, Wait};

use crate::keys::{self, Topic};
use crate::payload::{InfoMsg, LinkMsg, Origin, RouteMsg, TelemetryMsg, to_json};

/// Declares the queryable; it answers until dropped.
pub(crate) async fn declare(
    session: &Session,
    station: &str,
    gcs: Gcs,
    origin_us: u64,
) -> zenoh::Result<Queryable<()>> {
    let station = station.to_string();
    let key = format!("{}/{station}/*/*", keys::ROOT);
    session
        .declare_queryable(key)
        .callback(move |query| answer(&query, &station, &gcs, origin_us))
        .await
}

fn answer(query: &Query, station: &str, gcs: &Gcs, origin_us: u64) {
    let asked = query.key_expr();
    let samples = gcs.with_fleet(|f| {
        let mut out = Vec::new();
        for r in f.local_robots() {
            if keys::check_name("robot", &r.name).is_err() {
                continue;
            }
            for topic in Topic::ALL {
                let key = keys::state_key(station, &r.name, topic);
                let wanted = KeyExpr::try_from(key.as_str()).is_ok_and(|k| asked.intersects(&k));
                if !wanted {
                    continue;
                }
                if let Some(payload) = state(station, r, topic, origin_us) {
                    out.push((key, payload));
                }
            }
        }
        out
    });
    for (key, payload) in samples {
        if let Err(e) = query
            .reply(key, payload)
            .encoding(Encoding::APPLICATION_JSON)
            .wait()
        {
            debug!(error = %e, "cannot answer a Zenoh query");
        }
    }
}

/// One state payload of a robot, as the publishing side makes it (no
/// telemetry before the first has arrived).
fn state(station: &str, r: &Robot, topic: Topic, origin_us: u64) -> Option<Vec<u8>> {
    let name = r.name.as_str();
    Some(match topic {
        Topic::Info => to_json(&InfoMsg::new(station, name, &r.registration)),
        Topic::Link => to_json(&LinkMsg {
            origin: Origin::new(station, name),
            state: r.link,
        }),
        Topic::Route => to_json(&RouteMsg::new(station, name, &r.route)),
        Topic::Telemetry => {
            let at = r.last_telemetry?;
            let stamp = origin_us + at.as_micros() as u64;
            to_json(&TelemetryMsg::new(station, name, &r.telemetry, stamp))
        }
    })
}
