//! The router's network side: it binds the endpoints ([`bind`]), runs the
//! tasks that receive ([`udp`]: a worker thread per socket of the UDP
//! group; [`tcp`]: an acceptor and a task per peer; [`radio`]: a reader
//! and a writer thread per serial radio; and the timer task), and sends
//! what the tables decided ([`Net`]: `sendto`, `sendmmsg` and segmentation
//! offload in [`batch`], the TCP peers' queues, the radios' queues).
//!
//! Each receiving task hands what it receives to `super::Shared`, which
//! decides under the tables lock and delivers the events; the sending is
//! done here, after the lock is released. Every task watches the router's
//! stop signal and ends on it; [`Tasks::stop`] waits for them all.

mod batch;
mod bind;
mod radio;
mod tcp;
mod udp;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::os::fd::AsRawFd;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use nix::sys::socket::{MsgFlags, SockaddrStorage, sendto};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::MissedTickBehavior;

pub(super) use bind::{Bound, bind};
pub use radio::RadioStatus;
pub(super) use radio::{RadioPort, open_radios};
pub(super) use tcp::TcpLimits;

use super::Shared;
use super::config::SerialEndpoint;
use super::tables::{Outbox, Peer};
use crate::counters::Counters;
use crate::sync::lock;
use radio::RadioQueue;

/// Times a send from a task or a plain thread retries a full socket buffer
/// before the datagram counts as a send failure.
const FULL_BUFFER_TRIES: usize = 1000;

/// Where the router sends from: its UDP socket, the TCP peers' queues and
/// the radios' queues, and the count of what could not be sent.
#[derive(Debug)]
pub(super) struct Net {
    /// The socket that the timers, TCP peers, radio readers and in-process
    /// publishers send from (the first of the UDP workers' group; every
    /// one has the same address). The workers send from their own.
    udp: Arc<std::net::UdpSocket>,
    udp_addr: SocketAddr,
    tcp_addr: Option<SocketAddr>,
    /// Outgoing frame queues of the TCP peers, by connection number.
    tcp_peers: Mutex<HashMap<u64, PeerQueue>>,
    next_conn: AtomicU64,
    /// Length of each TCP peer's queue.
    peer_queue: usize,
    /// Outgoing queues of the serial radios, by place in `router.serial`.
    radios: Vec<Arc<RadioQueue>>,
    serial: Vec<SerialEndpoint>,
    /// Datagrams the kernel refused (counted as dropped, `send-failed`).
    send_failed: AtomicU64,
    /// Frames dropped because a TCP peer's queue was full.
    fanout_dropped: AtomicU64,
}

impl Net {
    /// The sending side over the bound endpoints, with a queue per radio
    /// in `serial`.
    pub(super) fn new(bound: &Bound, serial: Vec<SerialEndpoint>, peer_queue: usize) -> Net {
        Net {
            udp: bound.udp[0].clone(),
            udp_addr: bound.udp_addr,
            tcp_addr: bound.tcp_addr,
            tcp_peers: Mutex::new(HashMap::new()),
            next_conn: AtomicU64::new(1),
            peer_queue,
            radios: serial.iter().map(|_| Arc::default()).collect(),
            serial,
            send_failed: AtomicU64::new(0),
            fanout_dropped: AtomicU64::new(0),
        }
    }

    /// The bound UDP endpoint.
    pub(super) fn udp_addr(&self) -> SocketAddr {
        self.udp_addr
    }

    /// The bound TCP endpoint, if enabled.
    pub(super) fn tcp_addr(&self) -> Option<SocketAddr> {
        self.tcp_addr
    }

    /// Adds the send failures counted here to `counters`.
    pub(super) fn add_failures(&self, counters: &mut Counters) {
        counters.dropped.send_failed += self.send_failed.load(Ordering::Relaxed);
        counters.fanout_dropped += self.fanout_dropped.load(Ordering::Relaxed);
    }

    /// How radio `port` (its place in `router.serial`) is named: its device.
    pub(super) fn radio_name(&self, port: u16) -> String {
        self.serial
            .get(usize::from(port))
            .map_or_else(|| format!("#{port}"), |s| s.port.clone())
    }

    /// Every serial radio: what it sent and what waits.
    pub(super) fn radios(&self) -> Vec<RadioStatus> {
        self.serial
            .iter()
            .zip(&self.radios)
            .map(|(s, q)| q.status(s))
            .collect()
    }

    /// Sends the outbox from a tokio task: `raw` targets get `raw`,
    /// `owned` ones their own bytes. The outbox keeps its allocations.
    pub(super) async fn flush(&self, raw: &[u8], out: &mut Outbox) {
        for i in 0..out.raw.len() {
            self.send(out.raw[i], raw).await;
        }
        out.raw.clear();
        for (peer, bytes) in out.owned.drain(..) {
            self.send(peer, &bytes).await;
        }
    }

    /// Sends the outbox from a plain thread (a radio's reader).
    pub(super) fn flush_now(&self, raw: &[u8], out: &mut Outbox) {
        for peer in out.raw.drain(..) {
            self.send_now(peer, raw);
        }
        for (peer, bytes) in out.owned.drain(..) {
            self.send_now(peer, &bytes);
        }
    }

    /// Sends from a tokio task. The worker threads own blocking sockets;
    /// this path must not block a tokio thread, so it sends without
    /// waiting and, in the rare case of a full buffer, tries again after
    /// yielding.
    async fn send(&self, peer: Peer, bytes: &[u8]) {
        let Peer::Udp(addr) = peer else {
            return self.send_queued(peer, bytes);
        };
        let to = SockaddrStorage::from(addr);
        let fd = self.udp.as_raw_fd();
        for _ in 0..FULL_BUFFER_TRIES {
            match sendto(fd, bytes, &to, MsgFlags::MSG_DONTWAIT) {
                Ok(_) => return,
                Err(nix::errno::Errno::EAGAIN) => tokio::task::yield_now().await,
                Err(e) => {
                    tracing::debug!(%addr, error = %e, "UDP send failed");
                    break;
                }
            }
        }
        self.send_failed.fetch_add(1, Ordering::Relaxed);
    }

    /// Sends from a plain thread: UDP without blocking for long, others
    /// through their queues.
    fn send_now(&self, peer: Peer, bytes: &[u8]) {
        let Peer::Udp(addr) = peer else {
            return self.send_queued(peer, bytes);
        };
        let to = SockaddrStorage::from(addr);
        for _ in 0..FULL_BUFFER_TRIES {
            match sendto(self.udp.as_raw_fd(), bytes, &to, MsgFlags::MSG_DONTWAIT) {
                Ok(_) => return,
                Err(nix::errno::Errno::EAGAIN) => std::thread::yield_now(),
                Err(_) => break,
            }
        }
        self.send_failed.fetch_add(1, Ordering::Relaxed);
    }

    /// Sends to a peer that is not a UDP address: a TCP peer gets a
    /// length-prefixed frame through its bounded queue (a full queue drops
    /// and counts, never waits), a radio gets the message in its priority
    /// queue; in-process publishers get nothing.
    fn send_queued(&self, peer: Peer, bytes: &[u8]) {
        if let Peer::Serial(port) = peer {
            if let Some(q) = self.radios.get(usize::from(port)) {
                q.push(bytes);
            }
            return;
        }
        let Peer::Tcp(conn) = peer else { return };
        let q = lock(&self.tcp_peers).get(&conn).cloned();
        let Some(q) = q else { return };
        let len = bytes.len() + 4;
        if q.queued.load(Ordering::Relaxed) + len > PEER_QUEUE_BYTES {
            self.fanout_dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let mut frame = Vec::with_capacity(len);
        frame.extend_from_slice(&(bytes.len() as u32).to_be_bytes());
        frame.extend_from_slice(bytes);
        match q.tx.try_send(frame) {
            Ok(()) => {
                q.queued.fetch_add(len, Ordering::Relaxed);
            }
            Err(_) => {
                self.fanout_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Counts datagrams a worker's batch send could not hand the kernel.
    fn count_send_failures(&self, n: usize) {
        self.send_failed.fetch_add(n as u64, Ordering::Relaxed);
    }
}

/// Most bytes queued for one TCP peer. Its queue is also `peer_queue`
/// frames long, but frames run up to 60 KB (a channel listing of a busy
/// site), and a peer that asks and does not read must not hold more.
pub(super) const PEER_QUEUE_BYTES: usize = 4 << 20;

/// A TCP peer's outgoing frames, and how many bytes of them wait.
#[derive(Debug, Clone)]
pub(super) struct PeerQueue {
    pub(super) tx: mpsc::Sender<Vec<u8>>,
    /// Bytes queued and not yet written (the writer takes off what it
    /// wrote).
    pub(super) queued: Arc<AtomicUsize>,
}

/// The router's running tasks: the UDP workers' threads (with their
/// sockets), the radios' threads, and the tokio tasks (timers, the TCP
/// acceptor).
#[derive(Debug)]
pub(super) struct Tasks {
    tokio: Vec<JoinHandle<()>>,
    workers: Vec<udp::Worker>,
    /// The radios' reader and writer threads.
    radio_threads: Vec<std::thread::JoinHandle<()>>,
}

impl Tasks {
    /// Starts every task on the bound endpoints and the radios: a thread
    /// per UDP socket (polling for up to `poll`), a reader (which opens
    /// the port, and opens it again whenever it fails) and a writer thread
    /// per radio, the timers every `tick`, the TCP acceptor (its peers
    /// within `tcp`, fitted to the descriptor limit).
    pub(super) fn start(
        shared: &Arc<Shared>,
        bound: Bound,
        ports: Vec<RadioPort>,
        poll: Duration,
        tick: Duration,
        tcp: TcpLimits,
    ) -> Result<Tasks, super::RouterError> {
        let workers = udp::start_workers(shared, bound.udp, poll)?;
        let radio_threads = radio::start(shared, ports)?;
        let mut tokio = vec![tokio::spawn(timers(shared.clone(), tick))];
        if let Some(listener) = bound.tcp {
            let limits = tcp.within_descriptor_limit();
            tokio.push(tokio::spawn(tcp::accept(shared.clone(), listener, limits)));
        }
        Ok(Tasks {
            tokio,
            workers,
            radio_threads,
        })
    }

    /// Waits until every task has ended (the stop signal is set): wakes
    /// each UDP worker out of its receive, waits for the tokio tasks (the
    /// acceptor waits for its peers), closes the radios' queues and waits
    /// for their threads, then drops every TCP peer's queue.
    pub(super) async fn stop(self, net: &Net) {
        for (thread, socket) in self.workers {
            // Wakes the worker out of its receive at once.
            let _ =
                nix::sys::socket::shutdown(socket.as_raw_fd(), nix::sys::socket::Shutdown::Read);
            if tokio::task::spawn_blocking(move || thread.join())
                .await
                .is_err()
            {
                tracing::warn!("a UDP worker ended abnormally");
            }
        }
        for t in self.tokio {
            if let Err(e) = t.await {
                tracing::warn!(error = %e, "a router task ended abnormally");
            }
        }
        for q in &net.radios {
            q.close();
        }
        for thread in self.radio_threads {
            // Readers notice the stop within their port's read timeout, or
            // their wait before opening a failed port again.
            if tokio::task::spawn_blocking(move || thread.join())
                .await
                .is_err()
            {
                tracing::warn!("a radio thread ended abnormally");
            }
        }
        lock(&net.tcp_peers).clear();
    }
}

/// Drives every timer of the router at the configured resolution.
async fn timers(shared: Arc<Shared>, tick: Duration) {
    let mut interval = tokio::time::interval(tick);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut stop = shared.stop.subscribe();
    loop {
        tokio::select! {
            _ = interval.tick() => {}
            _ = stop.wait_for(|s| *s) => return,
        }
        shared.apply(|t, cx| t.tick(cx)).await;
    }
}
