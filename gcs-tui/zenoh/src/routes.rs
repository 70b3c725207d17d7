//! Route requests between stations. Another station's operator routes one
//! of this station's robots only by asking this station
//! (`mech/<station>/<robot>/route/request`, a query), and this station
//! decides: by default the request must be signed with an operator key this
//! station lists in `[auth]` (checked by the router's keyring: a fresh tag
//! of that key, whose role is operator; every refusal counted there), and
//! the robot must be one of its own. The other half, [`RouteRequester`],
//! is what `route robot@station CHANNEL` uses here to ask another station.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures::future::BoxFuture;
use mech_control::lang::RemoteRoutes;
use mech_core::Gcs;
use mech_core::auth::{KeyFile, Role};
use mech_core::fleet::Severity;
use mech_core::sync::lock;
use mech_proto::auth::Signer;
use tokio::runtime::Handle;
use tracing::{debug, info, warn};
use zenoh::Session;
use zenoh::bytes::Encoding;
use zenoh::query::{Query, Queryable};

use crate::config::RouteRequests;
use crate::keys::{self, Key};
use crate::payload::{RouteReply, RouteRequest, VERSION, from_json, to_json};
use crate::stats::Stats;

/// How long a station waits for another to answer a route request.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);

/// What answering a request needs.
#[derive(Debug)]
struct Deciding {
    station: String,
    gcs: Gcs,
    policy: RouteRequests,
    stats: Arc<Stats>,
}

/// Declares the queryable that takes route requests for this station's
/// robots; each is decided on the runtime of the caller.
pub(crate) async fn declare(
    session: &Session,
    station: &str,
    gcs: Gcs,
    policy: RouteRequests,
    stats: Arc<Stats>,
) -> zenoh::Result<Queryable<()>> {
    let deciding = Arc::new(Deciding {
        station: station.to_string(),
        gcs,
        policy,
        stats,
    });
    let runtime = Handle::current();
    session
        .declare_queryable(keys::route_request_key(station, "*"))
        .callback(move |query| {
            if !is_route_request(query.key_expr().as_str()) {
                debug!(key = %query.key_expr(), "a query that names no one robot's route request: not answered");
                return;
            }
            runtime.spawn(deciding.clone().answer(query));
        })
        .await
}

/// Whether a query's key expression names one robot's route request
/// (`mech/<station>/<robot>/route/request`, no wildcard). A query that only
/// intersects the queryable, as a `get` on `mech/site-a/**` reading the
/// robots' state does, asks for no route and is left to the state
/// queryable: answering it with a refusal would count and log a refusal
/// nobody asked for.
fn is_route_request(key: &str) -> bool {
    matches!(keys::parse(key), Ok(Key::RouteRequest { .. }))
}

impl Deciding {
    async fn answer(self: Arc<Self>, query: Query) {
        let reply = match self.decide(&query).await {
            Ok(reply) => {
                Stats::bump(&self.stats.route_requests_done);
                info!("{}", reply.message);
                reply
            }
            Err(why) => {
                Stats::bump(&self.stats.route_requests_refused);
                warn!("route request refused: {why}");
                RouteReply::refused(why)
            }
        };
        let severity = if reply.ok {
            Severity::Info
        } else {
            Severity::Warn
        };
        let line = format!("zenoh: {}", reply.message);
        self.gcs.update_fleet(|f| f.log(severity, line));
        let sent = query
            .reply(query.key_expr().clone(), to_json(&reply))
            .encoding(Encoding::APPLICATION_JSON)
            .await;
        if let Err(e) = sent {
            warn!(error = %e, "cannot answer a route request");
        }
    }

    /// Routes the robot if the request holds up; else says why not.
    async fn decide(&self, query: &Query) -> Result<RouteReply, String> {
        let request = self.read(query)?;
        self.authorize(&request)?;
        let robot = request.robot.as_str();
        let local = self
            .gcs
            .with_fleet(|f| f.robot(robot).map(|r| r.is_local()));
        if local != Some(true) {
            return Err(format!("station {} has no robot {robot:?}", self.station));
        }
        let channel = request.channel.as_deref();
        let epoch = self
            .gcs
            .router()
            .set_route(robot, channel)
            .await
            .map_err(|e| e.to_string())?;
        Ok(RouteReply::done(
            format!(
                "{robot} of station {} routed to {} for operator {}",
                self.station,
                channel.unwrap_or("none"),
                request.operator
            ),
            epoch,
        ))
    }

    /// The request in the query, checked against its key and this station.
    fn read(&self, query: &Query) -> Result<RouteRequest, String> {
        let key = query.key_expr().as_str();
        let Ok(Key::RouteRequest { station, robot }) = keys::parse(key) else {
            return Err(format!("{key:?} is not a route request key"));
        };
        let payload = query
            .payload()
            .map(|p| p.to_bytes().into_owned())
            .unwrap_or_default();
        let request: RouteRequest =
            from_json("route request", &payload).map_err(|e| e.to_string())?;
        if request.v != VERSION || request.station != station || request.robot != robot {
            return Err(format!(
                "route request for {}/{} (version {}) sent to {key:?}",
                request.station, request.robot, request.v
            ));
        }
        if station != self.station {
            return Err(format!("route request for station {station:?}"));
        }
        let names_ok = mech_core::config::is_channel_name(&request.operator)
            && request
                .channel
                .as_deref()
                .is_none_or(mech_core::config::is_channel_name);
        if !names_ok {
            return Err("route request with a bad operator or channel name".into());
        }
        Ok(request)
    }

    /// Whether this station obeys the request, by `zenoh.route_requests`.
    fn authorize(&self, request: &RouteRequest) -> Result<(), String> {
        let tag = request.parsed_tag().map_err(|e| e.to_string())?;
        let router = self.gcs.router();
        match (self.policy, tag) {
            (RouteRequests::Off, _) => Err(format!(
                "station {} takes no route requests (zenoh.route_requests = \"off\")",
                self.station
            )),
            (RouteRequests::Signed, None) => Err(format!(
                "unsigned route request from {:?}: station {} takes only requests signed \
                 with an operator key it lists",
                request.operator, self.station
            )),
            (RouteRequests::Unsigned, None) => Ok(()),
            (RouteRequests::Unsigned, Some(_)) if !router.authenticated() => Ok(()),
            (_, Some(tag)) => {
                let source = format!("zenoh route request by {}", request.operator);
                router
                    .verify_signed(
                        &source,
                        &request.operator,
                        &request.region(),
                        tag,
                        Role::Operator,
                    )
                    .map_err(|r| r.detail)
            }
        }
    }
}

/// Asks other stations to route their robots: the bridge's half of `route
/// robot@station CHANNEL`, signing each request with this station's
/// operator key when it has one.
#[derive(Debug)]
pub struct RouteRequester {
    session: Session,
    /// The operator key's name; `None`: requests go unsigned, under the
    /// station's name.
    operator: Option<String>,
    station: String,
    /// Stamps and signs requests with the operator key, if there is one.
    signer: Mutex<Signer>,
}

impl RouteRequester {
    pub(crate) fn new(session: Session, station: &str, operator: Option<KeyFile>) -> Self {
        let (operator, key) = operator.map(|k| (k.name, k.key)).unzip();
        RouteRequester {
            session,
            operator,
            station: station.to_string(),
            signer: Mutex::new(Signer::new(key)),
        }
    }

    /// The request, signed when this station has an operator key.
    fn request(&self, station: &str, robot: &str, channel: Option<&str>) -> RouteRequest {
        let operator = self.operator.as_deref().unwrap_or(&self.station);
        let mut request = RouteRequest::new(station, robot, channel, operator);
        request.sign(&mut lock(&self.signer), mech_proto::unix_micros());
        request
    }

    /// Sends the request and reads the first answer.
    async fn ask(
        &self,
        station: &str,
        robot: &str,
        channel: Option<&str>,
    ) -> Result<String, String> {
        keys::check_name("station", station).map_err(|e| e.to_string())?;
        keys::check_name("robot", robot).map_err(|e| e.to_string())?;
        let payload = to_json(&self.request(station, robot, channel));
        let replies = self
            .session
            .get(keys::route_request_key(station, robot))
            .payload(payload)
            .encoding(Encoding::APPLICATION_JSON)
            .timeout(ANSWER_TIMEOUT)
            .await
            .map_err(|e| format!("cannot send the request: {e}"))?;
        let no_answer = || {
            format!(
                "no answer within {} s (is station {station} on the network?)",
                ANSWER_TIMEOUT.as_secs()
            )
        };
        let reply = replies.recv_async().await.map_err(|_| no_answer())?;
        let sample = reply.result().map_err(|e| {
            format!(
                "error reply: {}",
                e.payload().try_to_string().unwrap_or_default()
            )
        })?;
        let answer: RouteReply =
            from_json("route reply", &sample.payload().to_bytes()).map_err(|e| e.to_string())?;
        if answer.ok {
            Ok(answer.message)
        } else {
            Err(answer.message)
        }
    }
}

impl RemoteRoutes for RouteRequester {
    fn request_route(
        &self,
        station: &str,
        robot: &str,
        channel: Option<&str>,
    ) -> BoxFuture<'_, Result<String, String>> {
        let (station, robot) = (station.to_string(), robot.to_string());
        let channel = channel.map(str::to_string);
        Box::pin(async move { self.ask(&station, &robot, channel.as_deref()).await })
    }
}

#[cfg(test)]
mod tests {
    use super::is_route_request;

    #[test]
    fn only_a_key_naming_one_robot_is_a_route_request() {
        assert!(is_route_request("mech/site-a/robot_1/route/request"));
        for selector in [
            "mech/site-a/**",
            "mech/**",
            "mech/site-a/*/route/request",
            "mech/site-a/robot_1/**",
            "mech/site-a/$*/route/request",
            "mech/site-a/robot_1/route",
        ] {
            assert!(!is_route_request(selector), "{selector}");
        }
    }
}
