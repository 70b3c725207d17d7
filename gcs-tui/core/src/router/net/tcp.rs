//! TCP controllers and tools: an acceptor, and a task per peer that reads
//! length-prefixed frames and has each decided like a datagram; what the
//! router sends a peer goes through the peer's bounded queue to a writer
//! task, so a slow peer only loses its own messages.
//!
//! Anyone who reaches the endpoint can connect, so what connections cost
//! is bounded ([`TcpLimits`]): a descriptor budget for all peers and a
//! share of it per IP address, and a deadline for a peer's first valid
//! message (one signed by a listed key, when the station authenticates).
//! When the budget or an address's share is taken, the oldest peer that
//! has not sent a valid message yet is closed to make room for the new
//! one, so idle connections never keep a controller out; a peer that has
//! sent one is never closed to make room. The acceptor owns this
//! bookkeeping; each peer's task reports its first valid message.

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use mech_proto::framing::StreamDecoder;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, mpsc};
use tokio::task::JoinSet;
use tokio::time::Instant;
use tracing::{info, warn};

use crate::counters::DropReason;
use crate::router::Shared;
use crate::router::net::PeerQueue;
use crate::router::tables::{Delivery, Effects, Peer};
use crate::sync::lock;

/// Descriptors the station keeps for everything but the router's TCP
/// peers (sockets, attached clients, log and recording files).
pub(in crate::router) const RESERVED_DESCRIPTORS: u64 = 256;

/// Shortest time between two log lines saying the budget is taken.
const FULL_LOG_EVERY: Duration = Duration::from_secs(10);

/// What TCP peers may cost (`[router]` `tcp_max_peers`,
/// `tcp_peers_per_address`, `tcp_idle`).
#[derive(Debug, Clone, Copy)]
pub(in crate::router) struct TcpLimits {
    /// Peers at once: the router's descriptor budget.
    pub max_peers: usize,
    /// Peers at once from one IP address.
    pub per_address: usize,
    /// Time a peer has for its first valid message.
    pub idle: Duration,
}

impl TcpLimits {
    /// The configured budget, within what the process may open: the soft
    /// descriptor limit is raised towards the hard one when the budget
    /// needs it, and the budget lowered (with a warning saying so) when
    /// even that is not enough.
    pub(in crate::router) fn within_descriptor_limit(mut self) -> TcpLimits {
        use nix::sys::resource::{Resource, getrlimit, setrlimit};
        let wanted = self.max_peers as u64 + RESERVED_DESCRIPTORS;
        let Ok((soft, hard)) = getrlimit(Resource::RLIMIT_NOFILE) else {
            return self;
        };
        let mut limit = soft;
        if soft < wanted {
            let raised = wanted.min(hard);
            if raised > soft && setrlimit(Resource::RLIMIT_NOFILE, raised, hard).is_ok() {
                info!(
                    from = soft,
                    to = raised,
                    "raised the open-file limit for TCP peers"
                );
                limit = raised;
            }
        }
        if limit < wanted {
            let budget = limit.saturating_sub(RESERVED_DESCRIPTORS).max(1) as usize;
            warn!(
                "router.tcp_max_peers = {} needs about {wanted} open files, but this process \
                 may open {limit} (LimitNOFILE in the service unit, ulimit -n): at most {budget} \
                 TCP peers will be served",
                self.max_peers
            );
            self.max_peers = budget;
        }
        self
    }
}

/// A connected peer, as the acceptor keeps it.
#[derive(Debug)]
struct Connected {
    ip: IpAddr,
    /// Set by the peer's task on its first valid message.
    valid: Arc<AtomicBool>,
    /// Tells the peer's task to close.
    close: Arc<Notify>,
}

/// The acceptor's record of its peers, by connection number (rising with
/// connection time, so the first is the oldest).
#[derive(Debug, Default)]
struct Peers {
    by_conn: BTreeMap<u64, Connected>,
    /// When the log last said the budget was taken, and how often it was
    /// taken since.
    full_logged: Option<Instant>,
    full_since_log: u64,
}

impl Peers {
    fn count_from(&self, ip: IpAddr) -> usize {
        self.by_conn.values().filter(|p| p.ip == ip).count()
    }

    /// The oldest peer (from `ip`, if given) without a valid message.
    fn oldest_unproven(&self, ip: Option<IpAddr>) -> Option<u64> {
        self.by_conn
            .iter()
            .find(|(_, p)| ip.is_none_or(|ip| p.ip == ip) && !p.valid.load(Ordering::Relaxed))
            .map(|(c, _)| *c)
    }

    /// Makes room for a peer from `ip` if the budget or the address's
    /// share is taken: closes the oldest unproven peer (of that address
    /// when its share is taken). An error, saying why, when there is none
    /// to close and the new peer must be turned away.
    fn make_room(&mut self, ip: IpAddr, limits: &TcpLimits) -> Result<(), &'static str> {
        let victim = if self.count_from(ip) >= limits.per_address {
            self.oldest_unproven(Some(ip))
                .ok_or("its address has as many peers as router.tcp_peers_per_address")?
        } else if self.by_conn.len() >= limits.max_peers {
            self.oldest_unproven(None)
                .ok_or("the router serves as many TCP peers as router.tcp_max_peers")?
        } else {
            return Ok(());
        };
        if let Some(p) = self.by_conn.remove(&victim) {
            p.close.notify_one();
        }
        Ok(())
    }

    /// Logs, at most every [`FULL_LOG_EVERY`], that the budget was taken.
    fn log_full(&mut self, addr: SocketAddr, outcome: &str, limits: &TcpLimits) {
        self.full_since_log += 1;
        let now = Instant::now();
        if self
            .full_logged
            .is_some_and(|t| now.duration_since(t) < FULL_LOG_EVERY)
        {
            return;
        }
        warn!(
            %addr,
            peers = self.by_conn.len(),
            max_peers = limits.max_peers,
            per_address = limits.per_address,
            times = self.full_since_log,
            "router TCP descriptor budget taken: {outcome}"
        );
        self.full_logged = Some(now);
        self.full_since_log = 0;
    }
}

/// Accepts TCP controllers and tools, a task per peer, within `limits`;
/// on stop, waits for every peer task to end.
pub(super) async fn accept(shared: Arc<Shared>, listener: TcpListener, limits: TcpLimits) {
    let mut tasks = JoinSet::new();
    let mut peers = Peers::default();
    let mut stop = shared.stop.subscribe();
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            Some(ended) = tasks.join_next(), if !tasks.is_empty() => {
                if let Ok(conn) = ended {
                    peers.by_conn.remove(&conn);
                }
                continue;
            }
            _ = stop.wait_for(|s| *s) => break,
        };
        let (stream, addr) = match accepted {
            Ok(a) => a,
            Err(e) => {
                let out_of_files = [nix::errno::Errno::EMFILE, nix::errno::Errno::ENFILE]
                    .iter()
                    .any(|n| e.raw_os_error() == Some(*n as i32));
                if out_of_files {
                    warn!(error = %e, "TCP accept failed: the process is out of file descriptors");
                } else {
                    warn!(error = %e, "TCP accept failed");
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let full = peers.by_conn.len() >= limits.max_peers
            || peers.count_from(addr.ip()) >= limits.per_address;
        match peers.make_room(addr.ip(), &limits) {
            Ok(()) if full => peers.log_full(
                addr,
                "closed the oldest peer without a valid message",
                &limits,
            ),
            Ok(()) => {}
            Err(why) => {
                peers.log_full(addr, why, &limits);
                drop(stream);
                continue;
            }
        }
        let conn = shared.net.next_conn.fetch_add(1, Ordering::Relaxed);
        info!(%addr, conn, "TCP peer connected");
        let entry = Connected {
            ip: addr.ip(),
            valid: Arc::new(AtomicBool::new(false)),
            close: Arc::new(Notify::new()),
        };
        let task = peer(
            shared.clone(),
            stream,
            conn,
            entry.valid.clone(),
            entry.close.clone(),
            limits.idle,
        );
        peers.by_conn.insert(conn, entry);
        tasks.spawn(task);
    }
    drop(listener);
    while tasks.join_next().await.is_some() {}
}

/// Whether a decision shows the message was valid (it passed the gate and
/// could be read), so its peer is no longer a stranger (unless its
/// freshness could not be judged: `Effects::unproven`).
fn was_valid(d: Delivery) -> bool {
    !matches!(
        d,
        Delivery::Dropped(DropReason::Rejected | DropReason::BadPacket | DropReason::Shed)
    )
}

/// One TCP peer: frames in, dispatched like datagrams; frames out through a
/// bounded queue so a slow peer only loses its own messages. Ends when the
/// peer leaves, the router stops, the acceptor closes it (`close`) or it
/// sends no valid message within `idle`; returns its connection number.
async fn peer(
    shared: Arc<Shared>,
    stream: TcpStream,
    conn: u64,
    proven: Arc<AtomicBool>,
    close: Arc<Notify>,
    idle: Duration,
) -> u64 {
    let _ = stream.set_nodelay(true);
    let (mut rd, mut wr) = stream.into_split();
    let (tx, mut rx) = mpsc::channel::<Vec<u8>>(shared.net.peer_queue);
    let queued = Arc::new(AtomicUsize::new(0));
    let queue = PeerQueue {
        tx,
        queued: queued.clone(),
    };
    lock(&shared.net.tcp_peers).insert(conn, queue);
    let writer = tokio::spawn(async move {
        while let Some(frame) = rx.recv().await {
            let written = wr.write_all(&frame).await;
            queued.fetch_sub(frame.len(), Ordering::Relaxed);
            if written.is_err() {
                break;
            }
        }
    });
    let mut decoder = StreamDecoder::new();
    let mut buf = vec![0u8; 65_536];
    let mut fx = Effects::default();
    let started = Instant::now();
    let deadline = started + idle;
    let mut stop = shared.stop.subscribe();
    let from = Peer::Tcp(conn);
    let why = 'read: loop {
        let waiting = !proven.load(Ordering::Relaxed);
        let read = tokio::select! {
            r = rd.read(&mut buf) => r,
            _ = stop.wait_for(|s| *s) => break "the router stopped",
            () = close.notified() => break "closed to make room for a new peer",
            () = tokio::time::sleep_until(deadline), if waiting => {
                break "no valid message in time (router.tcp_idle)"
            }
        };
        let n = match read {
            Ok(0) => break "the peer closed",
            Err(_) => break "read error",
            Ok(n) => n,
        };
        decoder.push(&buf[..n]);
        loop {
            let frame = match decoder.next_frame() {
                None => break,
                Some(Ok(frame)) => frame.to_vec(),
                Some(Err(e)) => {
                    // Only a bad length prefix is an error here, and it
                    // leaves the stream out of step for good.
                    warn!(conn, error = %e, "TCP stream out of step, closing it");
                    shared.count_bad(from, e.to_string());
                    break 'read "stream out of step";
                }
            };
            if was_valid(shared.dispatch(&frame, from, &mut fx).await) && !fx.unproven {
                proven.store(true, Ordering::Relaxed);
            }
        }
    };
    lock(&shared.net.tcp_peers).remove(&conn);
    lock(&shared.tables).forget_peer(from);
    writer.abort();
    let _ = writer.await;
    info!(
        conn,
        secs = started.elapsed().as_secs_f64(),
        why,
        "TCP peer disconnected"
    );
    conn
}
