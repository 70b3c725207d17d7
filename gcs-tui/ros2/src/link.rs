//! The bridge's connection to the station's router: one UDP socket per
//! identity (the controller key, and the e-stop key when there is one),
//! speaking the MECH protocol like any other external controller. It
//! subscribes to telemetry, publishes commands and missions, engages the
//! e-stop; what the router sends back arrives as [`FromStation`].

pub mod seal;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_proto::auth::Key;
use mech_proto::{
    Body, Command, EStop, Mission, MissionAck, Notice, Subscribe, Telemetry, TimeRequest,
};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tracing::{debug, info, warn};

use crate::stats::{Stats, worth_logging};
use seal::{Opener, SealError, Sealer};

/// What the router sent that the bridge acts on.
#[derive(Debug, Clone, PartialEq)]
pub enum FromStation {
    /// A robot's telemetry (the router's fan-out to subscribers): the
    /// robot's name and its own stamp, µs.
    Telemetry {
        robot: String,
        stamp_us: u64,
        telemetry: Telemetry,
    },
    /// A robot acknowledged a mission the bridge sent.
    MissionAck { robot: String, ack: MissionAck },
    /// A notice for the bridge (the router's refusals, for instance).
    Notice { from: String, notice: Notice },
}

/// Why the link could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("cannot open a UDP socket to the router at {addr}: {source}")]
    Socket {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error(
        "the router at {0} did not answer a time request within 3 s (is the station running, and does its [auth] list this key?)"
    )]
    NoTime(SocketAddr),
}

/// Microseconds since the Unix epoch on this machine's clock.
pub fn local_us() -> u64 {
    mech_proto::unix_micros()
}

/// One identity's socket to the router. Sending takes the sealer's lock for
/// the time it takes to encode and sign one message, and sends on a
/// non-blocking copy of the socket, so any thread or task may send; the
/// socket itself is read by the task [`StationLink::spawn_reader`] starts.
#[derive(Debug)]
pub struct StationLink {
    socket: Arc<UdpSocket>,
    sender: std::net::UdpSocket,
    sealer: Mutex<Sealer>,
    router: SocketAddr,
    stats: Arc<Stats>,
}

impl StationLink {
    /// Opens a socket connected to `router` (so only the router's
    /// datagrams arrive) for `name`, signing with `key` if given; with a
    /// key, takes the station's time first, as a robot without a clock
    /// does, so stamps are fresh even if this machine's clock is off.
    pub async fn open(
        router: SocketAddr,
        name: &str,
        key: Option<Key>,
        stats: Arc<Stats>,
    ) -> Result<StationLink, LinkError> {
        let sock_err = |source| LinkError::Socket {
            addr: router,
            source,
        };
        let bind: SocketAddr = if router.ip().is_loopback() {
            SocketAddr::from(([127, 0, 0, 1], 0))
        } else if router.is_ipv6() {
            SocketAddr::from(([0u16; 8], 0))
        } else {
            SocketAddr::from(([0, 0, 0, 0], 0))
        };
        let socket = std::net::UdpSocket::bind(bind).map_err(sock_err)?;
        socket.connect(router).map_err(sock_err)?;
        socket.set_nonblocking(true).map_err(sock_err)?;
        let sender = socket.try_clone().map_err(sock_err)?;
        let socket = UdpSocket::from_std(socket).map_err(sock_err)?;
        let signs = key.is_some();
        let opener_key = key.clone();
        let link = StationLink {
            socket: Arc::new(socket),
            sender,
            sealer: Mutex::new(Sealer::new(name, key)),
            router,
            stats,
        };
        if signs {
            link.sync_time(opener_key).await?;
        }
        Ok(link)
    }

    /// Asks the router for its clock (TimeRequest with a random nonce,
    /// retried every 200 ms) and adopts the answer's.
    async fn sync_time(&self, key: Option<Key>) -> Result<(), LinkError> {
        let mut nonce = [0u8; 8];
        getrandom::fill(&mut nonce).map_err(|e| LinkError::Socket {
            addr: self.router,
            source: std::io::Error::other(e.to_string()),
        })?;
        let nonce = u64::from_le_bytes(nonce);
        // This machine's clock may be off: the nonce, not the stamp, makes
        // the answer fresh.
        let mut opener = Opener::any_time(key);
        let mut buf = vec![0u8; mech_proto::MAX_MESSAGE_LEN + 1];
        for _ in 0..15 {
            let sent = local_us();
            self.send("router", "", Body::TimeRequest(TimeRequest { nonce }));
            let deadline = tokio::time::Instant::now() + Duration::from_millis(200);
            while let Ok(Ok(n)) =
                tokio::time::timeout_at(deadline, self.socket.recv(&mut buf)).await
            {
                let Ok(env) = opener.open(&buf[..n], sent) else {
                    continue;
                };
                if let Body::Time(t) = env.body
                    && t.nonce == nonce
                {
                    let received = local_us();
                    let local = sent + (received - sent) / 2;
                    let mut sealer = self.sealer();
                    sealer.sync(t.station_us, local);
                    info!(
                        offset_us = t.station_us as i64 - local as i64,
                        "station time taken from the router"
                    );
                    return Ok(());
                }
            }
        }
        Err(LinkError::NoTime(self.router))
    }

    fn sealer(&self) -> std::sync::MutexGuard<'_, Sealer> {
        self.sealer.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The router's address.
    pub fn router(&self) -> SocketAddr {
        self.router
    }

    /// Whether this identity signs (the station authenticates).
    pub fn signs(&self) -> bool {
        self.sealer().signs()
    }

    /// Sends one message; a failure is counted and logged, not returned:
    /// UDP gives no delivery promise anyway, and the callers resend what
    /// must arrive.
    pub fn send(&self, destination: &str, channel: &str, body: Body) {
        let bytes = {
            let mut sealer = self.sealer();
            sealer.seal(destination, channel, body, local_us())
        };
        let result = match bytes {
            Ok(b) => self.sender.send(&b).map(|_| ()).map_err(|e| e.to_string()),
            Err(e) => Err(e.to_string()),
        };
        if let Err(e) = result {
            let n = self
                .stats
                .send_failed
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
                + 1;
            if worth_logging(n) {
                warn!(router = %self.router, failures = n, "cannot send to the router: {e}");
            }
        }
    }

    /// Publishes `command` for `robot` on `channel`.
    pub fn command(&self, robot: &str, channel: &str, command: Command) {
        self.send(robot, channel, Body::Command(command));
    }

    /// Sends `mission` to `robot` on `channel`.
    pub fn mission(&self, robot: &str, channel: &str, mission: Mission) {
        self.send(robot, channel, Body::Mission(mission));
    }

    /// Asks for (or renews) every robot's telemetry.
    pub fn subscribe(&self, telemetry: bool) {
        self.send(
            mech_proto::ROUTER,
            "",
            Body::Subscribe(Subscribe { telemetry }),
        );
    }

    /// Engages the e-stop of every robot. There is no way to release it
    /// from here: a release is an operator's, at the station.
    pub fn engage_estop(&self) {
        self.send(
            mech_proto::ROUTER,
            "",
            Body::EStop(EStop {
                engage: true,
                id: 0,
            }),
        );
    }

    /// Starts the task that reads what the router sends, opens it (with a
    /// key: only what the router signed for it) and passes on what the
    /// bridge acts on. It ends when `to` is closed.
    pub fn spawn_reader(self: &Arc<Self>, key: Option<Key>, to: mpsc::Sender<FromStation>) {
        let link = Arc::clone(self);
        tokio::spawn(async move {
            let mut opener = Opener::new(key, local_us());
            let mut buf = vec![0u8; mech_proto::MAX_MESSAGE_LEN + 1];
            loop {
                let n = match link.socket.recv(&mut buf).await {
                    Ok(n) => n,
                    Err(e) => {
                        // ICMP port unreachable while the station is down:
                        // keep reading, it may come back.
                        debug!("router socket: {e}");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                        continue;
                    }
                };
                let now = link.sealer().station_us(local_us());
                let env = match opener.open(&buf[..n], now) {
                    Ok(env) => env,
                    Err(e) => {
                        link.rejected(&e);
                        continue;
                    }
                };
                let h = env.header;
                let event = match env.body {
                    Body::Telemetry(telemetry) => FromStation::Telemetry {
                        robot: h.sender,
                        stamp_us: h.stamp_us,
                        telemetry,
                    },
                    Body::MissionAck(ack) => FromStation::MissionAck {
                        robot: h.sender,
                        ack,
                    },
                    Body::Notice(notice) => FromStation::Notice {
                        from: h.sender,
                        notice,
                    },
                    _ => continue,
                };
                if to.send(event).await.is_err() {
                    return;
                }
            }
        });
    }

    fn rejected(&self, e: &SealError) {
        let n = self
            .stats
            .link_rejected
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            + 1;
        if worth_logging(n) {
            warn!(router = %self.router, rejected = n, "refused a datagram from the router: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{Envelope, Header};
    use std::sync::atomic::Ordering;

    /// A stand-in router: a UDP socket on loopback, and a link to it.
    async fn router_and_link() -> (UdpSocket, Arc<StationLink>, Arc<Stats>) {
        let router = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let stats = Arc::new(Stats::default());
        let addr = router.local_addr().unwrap();
        let link = StationLink::open(addr, "ros2", None, Arc::clone(&stats))
            .await
            .unwrap();
        (router, Arc::new(link), stats)
    }

    async fn receive(router: &UdpSocket) -> (Envelope, SocketAddr) {
        let mut buf = vec![0u8; 2048];
        let (n, from) = router.recv_from(&mut buf).await.unwrap();
        (mech_proto::decode(&buf[..n]).unwrap(), from)
    }

    #[tokio::test]
    async fn the_only_estop_the_bridge_sends_is_an_engage_to_the_router() {
        let (router, link, _) = router_and_link().await;
        link.engage_estop();
        let (env, _) = receive(&router).await;
        assert_eq!(env.header.destination, mech_proto::ROUTER);
        assert_eq!(env.header.sender, "ros2");
        assert!(
            matches!(env.body, Body::EStop(EStop { engage: true, .. })),
            "{env:?}"
        );
    }

    #[tokio::test]
    async fn what_the_router_sends_is_passed_on_and_garbage_is_counted() {
        let (router, link, stats) = router_and_link().await;
        let (tx, mut rx) = mpsc::channel(8);
        link.spawn_reader(None, tx);
        link.subscribe(true);
        let (env, bridge) = receive(&router).await;
        assert!(matches!(
            env.body,
            Body::Subscribe(Subscribe { telemetry: true })
        ));

        router.send_to(&[0x93, 0x01], bridge).await.unwrap();
        let telemetry = crate::fleet::tests::telemetry(1.5, 0.3);
        let env = Envelope::new(
            Header {
                seq: 9,
                stamp_us: 1_700_000_000_000_000,
                sender: "robot_1".into(),
                destination: "ros2".into(),
                channel: String::new(),
            },
            Body::Telemetry(telemetry.clone()),
        );
        router
            .send_to(&mech_proto::encode(&env).unwrap(), bridge)
            .await
            .unwrap();
        let got = rx.recv().await.unwrap();
        assert_eq!(
            got,
            FromStation::Telemetry {
                robot: "robot_1".into(),
                stamp_us: 1_700_000_000_000_000,
                telemetry
            }
        );
        assert_eq!(
            stats.link_rejected.load(Ordering::Relaxed),
            1,
            "the garbage before it"
        );
    }
}
