//! The live view's WebSocket server: accepts connections, completes the
//! handshake (which must ask for `foxglove.websocket.v1`, within a few
//! seconds), then runs each connection (`connection`) and logs how it
//! ended.
//!
//! Connections still in their handshake hold places of their own, as the
//! station's attach port's do (`crate::admission`): 16, at most 4 from one
//! address; a newcomer closes the one waiting longest. So connections that
//! never finish their handshake cost a stranger a descriptor each only
//! until the next connection comes, never the station's descriptors.
//! (Viewers through an SSH tunnel all come from 127.0.0.1, so 4 of them
//! can be in their handshake at once.) What the server says of each
//! connection (refused, timed out, closed, came and went) reaches the log
//! a few lines a second; the rest is counted into one line a second.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context;
use mech_core::Gcs;
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

use super::FoxgloveConfig;
use super::connection::{self, End, MAX_REQUEST};
use super::hub::Hub;
use super::protocol::SUBPROTOCOL;
use super::source::{Counts, Source};
use crate::admission::{self, Admission, Attaching, Door};

/// Time a connection has to complete the WebSocket handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// A running live view.
#[derive(Debug)]
pub struct LiveView {
    addr: SocketAddr,
    hub: Arc<Hub>,
    counts: Arc<Counts>,
    tasks: Vec<JoinHandle<()>>,
}

impl LiveView {
    /// Listens on `config.addr` and starts showing `gcs`'s fleet.
    pub async fn start(gcs: &Gcs, config: &FoxgloveConfig) -> anyhow::Result<LiveView> {
        let want = config.addr.context("no [foxglove] addr")?;
        let listener = TcpListener::bind(want)
            .await
            .with_context(|| format!("cannot listen for Foxglove on {want}"))?;
        let addr = listener.local_addr()?;
        if !addr.ip().is_loopback() {
            tracing::warn!(%addr, "the Foxglove live view has no authentication: anyone who reaches {addr} sees the fleet");
        }
        let hub = Arc::new(Hub::new(config.client_queue, config.max_clients));
        let (source, sub) = Source::new(gcs, hub.clone(), config.queue, config.scene_hz);
        let counts = source.counts.clone();
        let places = Arc::new(Admission::default());
        let tasks = vec![
            tokio::spawn(source.run(sub)),
            tokio::spawn(accept(listener, hub.clone(), places.clone())),
            tokio::spawn(admission::say_held(places, |n| {
                tracing::warn!(
                    "Foxglove live view: {n} more connections refused, cut or gone (not logged one by one)"
                );
            })),
        ];
        tracing::info!(%addr, "Foxglove live view listening (ws://{addr})");
        Ok(LiveView {
            addr,
            hub,
            counts,
            tasks,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops listening, closes every connection, and logs the totals.
    pub fn stop(self) {
        for t in &self.tasks {
            t.abort();
        }
        self.hub.close_all();
        let n = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
        let s = &self.hub.stats;
        tracing::info!(
            events = n(&self.counts.events),
            router_events_dropped = n(&self.counts.dropped),
            sent = n(&s.sent),
            client_messages_dropped = n(&s.dropped),
            clients = n(&s.clients),
            refused = n(&s.refused),
            bad_requests = n(&s.bad_requests),
            "Foxglove live view stopped"
        );
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

async fn accept(listener: TcpListener, hub: Arc<Hub>, places: Arc<Admission>) {
    loop {
        match listener.accept().await {
            Ok((stream, peer)) => {
                let place = places.attaching(Door::Tcp(peer.ip()));
                let logged = places.clone();
                tokio::spawn(connection(stream, peer, hub.clone(), place, logged));
            }
            Err(e) => {
                // Out of descriptors, say: wait rather than spin.
                tracing::warn!(error = %e, "Foxglove live view cannot accept");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}

/// Accepts the handshake only for a client that offers the subprotocol,
/// and names it in the response. (The signature is tungstenite's for a
/// handshake callback.)
#[allow(clippy::result_large_err)]
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("Sec-WebSocket-Protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if !offered {
        let mut refusal = ErrorResponse::new(Some(format!(
            "this is a Foxglove live view: connect with the {SUBPROTOCOL} subprotocol\n"
        )));
        *refusal.status_mut() = StatusCode::BAD_REQUEST;
        return Err(refusal);
    }
    resp.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static(SUBPROTOCOL),
    );
    Ok(resp)
}

/// Whether a line about a connection goes to the log now (a few a second;
/// the rest are counted, and said once a second).
fn loggable(places: &Admission) -> bool {
    places.log_refusal(Instant::now())
}

async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    hub: Arc<Hub>,
    place: Attaching,
    places: Arc<Admission>,
) {
    let _ = stream.set_nodelay(true);
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_REQUEST))
        .max_frame_size(Some(MAX_REQUEST));
    let handshake =
        tokio_tungstenite::accept_hdr_async_with_config(stream, choose_subprotocol, Some(config));
    let handshake = tokio::select! {
        done = tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake) => done,
        () = place.evicted() => {
            if loggable(&places) {
                tracing::info!(%peer, "Foxglove handshake cut: newer connections took its place");
            }
            return;
        }
    };
    drop(place);
    let mut ws = match handshake {
        Ok(Ok(ws)) => ws,
        Ok(Err(e)) => {
            if loggable(&places) {
                tracing::info!(%peer, error = %e, "Foxglove handshake refused");
            }
            return;
        }
        Err(_) => {
            if loggable(&places) {
                tracing::info!(%peer, "Foxglove handshake timed out");
            }
            return;
        }
    };
    let Some((id, rx)) = hub.connect() else {
        if loggable(&places) {
            tracing::warn!(%peer, "Foxglove client refused: too many clients ([foxglove] max_clients)");
        }
        let end = End::coded(CloseCode::Again, "too many clients");
        connection::close(&mut ws, &end, &hub).await;
        return;
    };
    let said_hello = loggable(&places);
    if said_hello {
        tracing::info!(%peer, client = id, "Foxglove client connected");
    }
    let end = connection::serve(&mut ws, rx, &hub, id).await;
    let dropped = hub.disconnect(id);
    // A client whose coming was logged has its leaving logged too.
    if said_hello || loggable(&places) {
        let why = &end.why;
        match end.code {
            Some(code) => tracing::warn!(
                %peer, client = id, dropped,
                "Foxglove client cut: {why} (close code {})", u16::from(code)
            ),
            None => tracing::info!(%peer, client = id, dropped, "Foxglove client left: {why}"),
        }
    }
    connection::close(&mut ws, &end, &hub).await;
}
