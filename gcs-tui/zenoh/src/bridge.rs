//! [`Bridge`]: one station on the Zenoh network. It opens the session,
//! says the station is alive (its liveliness token), and runs the four
//! halves: publishing this station's robots ([`crate::outbound`]) and
//! answering for their state ([`crate::answers`]), taking commands
//! ([`crate::inbound`]) and route requests ([`crate::routes`]), and
//! showing other stations' robots ([`crate::remote`]).

use std::sync::Arc;
use std::time::Duration;

use mech_control::lang::RemoteRoutes;
use mech_core::auth::{AuthMode, KeyFile};
use mech_core::{ConfigError, Gcs};
use tokio::task::JoinHandle;
use tracing::{info, warn};
use zenoh::Session;
use zenoh::liveliness::LivelinessToken;
use zenoh::query::Queryable;

use crate::config::{RouteRequests, ZenohConfig};
use crate::inbound::Intake;
use crate::outbound::Outbound;
use crate::remote::Remote;
use crate::routes::RouteRequester;
use crate::stats::{Stats, StatsSnapshot};
use crate::{answers, inbound, keys, remote, routes};

/// Router events queued for the publishing half (telemetry included).
const EVENT_QUEUE: usize = 65_536;

/// How long a starting bridge listens for another station of its name.
const DUPLICATE_CHECK: Duration = Duration::from_millis(300);

/// Why a bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("cannot open the Zenoh session: {0}")]
    Open(String),
    #[error("cannot declare {what} on Zenoh: {detail}")]
    Declare { what: &'static str, detail: String },
    #[error(
        "another station named {0:?} is already on the Zenoh network; give this one \
         another zenoh.station"
    )]
    Duplicate(String),
}

fn declare_err(what: &'static str) -> impl Fn(zenoh::Error) -> BridgeError {
    move |e| BridgeError::Declare {
        what,
        detail: e.to_string(),
    }
}

/// What a bridge declared on the session besides its token: the four
/// halves' subscribers and queryables.
#[derive(Debug)]
struct Declared {
    answers: Queryable<()>,
    intake: Option<Intake>,
    route_requests: Option<Queryable<()>>,
    remote: Remote,
}

impl Declared {
    async fn new(
        session: &Session,
        config: &ZenohConfig,
        gcs: &Gcs,
        stats: &Arc<Stats>,
        origin_us: u64,
    ) -> Result<Declared, BridgeError> {
        let station = config.station.as_str();
        let answers = answers::declare(session, station, gcs.clone(), origin_us)
            .await
            .map_err(declare_err("the state queryable"))?;
        let intake = match config.commands {
            true => Some(
                inbound::declare(
                    session,
                    station,
                    &config.identity,
                    gcs.clone(),
                    stats.clone(),
                )
                .await
                .map_err(declare_err("the command subscriber"))?,
            ),
            false => None,
        };
        let route_requests = match config.route_requests {
            RouteRequests::Off => None,
            policy => Some(
                routes::declare(session, station, gcs.clone(), policy, stats.clone())
                    .await
                    .map_err(declare_err("the route request queryable"))?,
            ),
        };
        let remote = remote::declare(session, station, gcs.clone(), stats.clone())
            .await
            .map_err(declare_err("the subscribers to other stations"))?;
        Ok(Declared {
            answers,
            intake,
            route_requests,
            remote,
        })
    }

    async fn undeclare(self) {
        if let Some(intake) = self.intake {
            intake.task.abort();
            let _ = intake.subscriber.undeclare().await;
        }
        let _ = self.remote.state.undeclare().await;
        let _ = self.remote.liveliness.undeclare().await;
        let _ = self.answers.undeclare().await;
        if let Some(q) = self.route_requests {
            let _ = q.undeclare().await;
        }
    }
}

/// A running bridge. Dropping it without [`Bridge::shutdown`] leaves the
/// session open until the process ends.
#[derive(Debug)]
pub struct Bridge {
    session: Session,
    station: String,
    stats: Arc<Stats>,
    publishing: JoinHandle<()>,
    declared: Declared,
    token: LivelinessToken,
    requester: Arc<RouteRequester>,
}

impl Bridge {
    /// Joins the Zenoh network as `config.station` of `gcs`.
    pub async fn start(gcs: &Gcs, config: &ZenohConfig) -> Result<Bridge, BridgeError> {
        let operator = check(gcs, config)?;
        let session = zenoh::open(config.session()?)
            .await
            .map_err(|e| BridgeError::Open(e.to_string()))?;
        let station = config.station.as_str();
        if let Err(e) = refuse_duplicate(&session, station).await {
            let _ = session.close().await;
            return Err(e);
        }
        let stats = Arc::new(Stats::default());
        let token = session
            .liveliness()
            .declare_token(keys::station_token(station))
            .await
            .map_err(declare_err("the station's liveliness token"))?;
        let events = gcs.router().subscribe(EVENT_QUEUE, true);
        let out = Outbound::new(session.clone(), station, gcs.clone(), stats.clone());
        let origin_us = out.origin_us;
        let publishing = tokio::spawn(out.run(events));
        let declared = match Declared::new(&session, config, gcs, &stats, origin_us).await {
            Ok(d) => d,
            Err(e) => {
                publishing.abort();
                let _ = session.close().await;
                return Err(e);
            }
        };
        let requester = Arc::new(RouteRequester::new(session.clone(), station, operator));
        info!(station, "on the Zenoh network");
        Ok(Bridge {
            session,
            station: station.to_string(),
            stats,
            publishing,
            declared,
            token,
            requester,
        })
    }

    /// This station's name on the network.
    pub fn station(&self) -> &str {
        &self.station
    }

    /// What the bridge did so far.
    pub fn stats(&self) -> StatsSnapshot {
        self.stats.snapshot()
    }

    /// Forgets the remote telemetry ages recorded so far.
    pub fn clear_ages(&self) {
        self.stats.clear_ages();
    }

    /// What `route robot@station CHANNEL` uses to ask other stations.
    pub fn route_requests(&self) -> Arc<dyn RemoteRoutes> {
        self.requester.clone()
    }

    /// Leaves the network: other stations see this station and its robots
    /// lost at once.
    pub async fn shutdown(self) {
        self.publishing.abort();
        self.declared.undeclare().await;
        let _ = self.token.undeclare().await;
        if let Err(e) = self.session.close().await {
            warn!(error = %e, "closing the Zenoh session");
        }
        info!(station = %self.station, "left the Zenoh network");
    }
}

/// Checks the configuration against the station before anything opens;
/// returns the operator key, if one is configured.
fn check(gcs: &Gcs, config: &ZenohConfig) -> Result<Option<KeyFile>, BridgeError> {
    config.validate()?;
    let core = gcs.config();
    let authenticated = gcs.router().authenticated();
    if config.commands && authenticated && !core.auth.keys.iter().any(|k| k.name == config.identity)
    {
        return Err(ConfigError(format!(
            "zenoh.identity {:?} has no key in [auth]: commands from Zenoh would all be \
             refused. List a key of that name (role controller with the channels Zenoh may \
             publish on, or operator), or set zenoh.commands = false",
            config.identity
        ))
        .into());
    }
    let trusted = core.auth.mode == Some(AuthMode::Off);
    if config.commands && !authenticated && !trusted && !config.loopback_only() {
        return Err(ConfigError::new(
            "the Zenoh bridge reaches beyond this machine and the station runs \
             unauthenticated: anyone on that network could drive robots routed to any \
             channel. List keys in [auth] (with zenoh.identity), set zenoh.commands = false, \
             or set auth.mode = \"off\" to trust the network",
        )
        .into());
    }
    if config.route_requests == RouteRequests::Signed && !authenticated {
        warn!("the station runs unauthenticated: it will refuse every signed route request");
    }
    let operator = match &config.operator_key {
        Some(path) => {
            Some(KeyFile::load(path).map_err(|e| ConfigError(format!("zenoh.operator_key: {e}")))?)
        }
        None => None,
    };
    Ok(operator)
}

/// Refuses to join as a station whose name is already on the network.
async fn refuse_duplicate(session: &Session, station: &str) -> Result<(), BridgeError> {
    let replies = session
        .liveliness()
        .get(keys::station_token(station))
        .timeout(DUPLICATE_CHECK)
        .await
        .map_err(declare_err("the liveliness query"))?;
    while let Ok(reply) = replies.recv_async().await {
        if reply.result().is_ok() {
            return Err(BridgeError::Duplicate(station.to_string()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_bridge_beyond_loopback_needs_keys_or_an_explicit_off() {
        let mut core = mech_core::CoreConfig::default();
        core.router.udp = "127.0.0.1:0".parse().unwrap();
        core.router.tcp = None;
        let gcs = Gcs::start(core).await.unwrap();
        let wide = ZenohConfig {
            listen: vec!["tcp/0.0.0.0:0".into()],
            ..ZenohConfig::default()
        };
        let e = check(&gcs, &wide).unwrap_err().to_string();
        assert!(e.contains("unauthenticated"), "{e}");
        let receive_only = ZenohConfig {
            commands: false,
            ..wide.clone()
        };
        check(&gcs, &receive_only).unwrap();
        check(&gcs, &ZenohConfig::default()).unwrap();
        let missing = ZenohConfig {
            operator_key: Some("/nonexistent/op.key".into()),
            ..ZenohConfig::default()
        };
        assert!(
            check(&gcs, &missing)
                .unwrap_err()
                .to_string()
                .contains("operator_key")
        );
        gcs.shutdown().await;
    }
}
