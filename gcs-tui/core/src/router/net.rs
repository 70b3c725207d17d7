//! The router's tasks: UDP worker threads, the TCP acceptor with a reader
//! and a writer task per peer, and the timer task (heartbeats, link states,
//! retries). Each hands bytes to the tables through [`super::Shared`].
//! Every task watches the router's stop signal and ends on it; the acceptor
//! waits for its peers, so [`super::Router::shutdown`] waits for them all.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use mech_proto::framing::StreamDecoder;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tokio::time::{Instant, MissedTickBehavior};
use tracing::{debug, info, warn};

use std::os::fd::AsRawFd;

use nix::sys::socket::MsgFlags;

use super::batch::{RecvBatch, SendBatch};
use super::tables::{Outbox, Peer};
use super::{Decided, Shared};
use crate::sync::lock;

/// One UDP worker, a thread of its own: owns one socket of the router's
/// `SO_REUSEPORT` group, so the kernel hands it every datagram of the
/// senders hashed to it. A sender's datagrams are therefore received,
/// decided and sent on by one worker, in the order they arrived, whatever
/// the number of workers, and workers never contend for a socket.
///
/// It blocks in `recvmmsg` until a datagram arrives (the kernel wakes this
/// thread directly: no event loop between), takes what else is waiting in
/// the same call, decides the batch under one hold of the tables' lock, and
/// sends what it decided with `sendmmsg`. At low rates a batch is the one
/// datagram that woke it: nothing waits to fill one. While traffic is
/// dense it polls its socket for a moment before sleeping again
/// ([`Poll`]), so that a busy sender does not pay a wake-up per datagram.
pub(super) fn udp_worker(shared: Arc<Shared>, socket: Arc<std::net::UdpSocket>, poll: Duration) {
    let mut received = RecvBatch::new();
    let mut sender = SendBatch::new();
    let mut decided = Decided::default();
    let mut poll = Poll::new(poll);
    let fd = socket.as_raw_fd();
    // Set while traffic is dense: until then, take what comes next
    // without going to sleep.
    let mut polling_until = None;
    while !shared.stopped() {
        let polling = polling_until.is_some_and(|t| std::time::Instant::now() < t);
        let flags = if polling {
            MsgFlags::MSG_DONTWAIT
        } else {
            MsgFlags::MSG_WAITFORONE
        };
        let n = match received.recv(fd, flags) {
            Ok(n) if n > 0 => n,
            // 0: shut down for reading (the stop signal is set).
            Ok(_) => continue,
            Err(e) => {
                receive_error(&e);
                if polling {
                    // Nothing yet: let a thread that has work (the sender,
                    // perhaps) have this core meanwhile.
                    std::thread::yield_now();
                }
                continue;
            }
        };
        if !polling {
            poll.woke_with(n);
        }
        shared.decide_batch(&received, n, &mut decided);
        shared.send_decided(fd, &mut sender, &received, &mut decided);
        polling_until = poll.until();
    }
}

/// A receive error concerns one peer (ICMP errors from earlier sends
/// surface here) or none (nothing waiting, a signal), never the router:
/// logged when worth it, and the worker carries on.
fn receive_error(e: &std::io::Error) {
    if !matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock
            | std::io::ErrorKind::TimedOut
            | std::io::ErrorKind::Interrupted
    ) {
        debug!(error = %e, "UDP receive error");
    }
}

/// When a UDP worker polls its socket instead of sleeping.
///
/// Sleeping in `recvmmsg` costs the next datagram's sender a wake-up of this
/// thread (on a virtual machine, an inter-processor interrupt and a
/// hypervisor exit), and this thread a context switch. When datagrams queue
/// up faster than the worker wakes for them, that is most of the cost of a
/// datagram. So when a wake-up finds more than one datagram waiting, the
/// worker polls (yielding the core between tries) for up to `budget` after
/// each batch, for as long as datagrams keep coming within it, and only
/// then sleeps. A wake-up that finds one datagram means the worker keeps
/// up: it sleeps at once, so traffic it keeps up with (a 2 kHz command
/// stream, a fleet's telemetry) costs no polling CPU and no latency. A
/// zero budget turns polling off.
#[derive(Debug, Clone, Copy)]
pub(super) struct Poll {
    budget: Duration,
    queued: bool,
}

impl Poll {
    pub(super) fn new(budget: Duration) -> Poll {
        Poll {
            budget,
            queued: false,
        }
    }

    /// A blocking receive returned `n` datagrams.
    pub(super) fn woke_with(&mut self, n: usize) {
        self.queued = !self.budget.is_zero() && n >= 2;
    }

    /// Until when to poll after a batch just handled; `None`: sleep at once.
    pub(super) fn until(&self) -> Option<std::time::Instant> {
        self.queued.then(|| std::time::Instant::now() + self.budget)
    }
}

/// Drives every timer of the router at the configured resolution.
pub(super) async fn timers(shared: Arc<Shared>, tick: Duration) {
    let mut interval = tokio::time::interval(tick);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut stop = shared.stop.subscribe();
    loop {
        tokio::select! {
            _ = interval.tick() => {}
            _ = stop.wait_for(|s| *s) => return,
        }
        shared.apply(|t, now, out, ev| t.tick(now, out, ev)).await;
    }
}

/// Accepts TCP controllers and tools, a task per peer; on stop, waits for
/// every peer task to end.
pub(super) async fn tcp_accept(shared: Arc<Shared>, listener: TcpListener) {
    let mut peers = JoinSet::new();
    let mut stop = shared.stop.subscribe();
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            Some(_) = peers.join_next(), if !peers.is_empty() => continue,
            _ = stop.wait_for(|s| *s) => break,
        };
        match accepted {
            Ok((stream, addr)) => {
                let conn = shared.next_conn.fetch_add(1, Ordering::Relaxed);
                info!(%addr, conn, "TCP peer connected");
                peers.spawn(tcp_peer(shared.clone(), stream, conn));
            }
            Err(e) => {
                warn!(error = %e, "TCP accept failed");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
    drop(listener);
    while peers.join_next().await.is_some() {}
}

/// One TCP peer: frames in, dispatched like datagrams; frames out through a
/// bounded queue so a slow peer only loses its own messages.
async fn tcp_peer(shared: Arc<Shared>, stream: TcpStream, conn: u64) {
    let _ = stream.set_nodelay(true);
    let (mut rd, mut wr) = stream.into_split();
    let (tx, mut rx) = mpsc::channel::<Vec<u8>>(shared.subscriber_queue);
    lock(&shared.tcp_peers).insert(conn, tx);
    let writer = tokio::spawn(async move {
        while let Some(frame) = rx.recv().await {
            if wr.write_all(&frame).await.is_err() {
                break;
            }
        }
    });
    let mut decoder = StreamDecoder::new();
    let mut buf = vec![0u8; 65_536];
    let mut out = Outbox::default();
    let mut events = Vec::new();
    let started = Instant::now();
    let mut stop = shared.stop.subscribe();
    'read: loop {
        let read = tokio::select! {
            r = rd.read(&mut buf) => r,
            _ = stop.wait_for(|s| *s) => break,
        };
        let n = match read {
            Ok(0) | Err(_) => break,
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
                    shared
                        .apply(|t, _, _, ev| t.count_bad(Peer::Tcp(conn), e.to_string(), ev))
                        .await;
                    break 'read;
                }
            };
            shared
                .dispatch(&frame, Peer::Tcp(conn), &mut out, &mut events)
                .await;
        }
    }
    lock(&shared.tcp_peers).remove(&conn);
    lock(&shared.tables).forget_peer(Peer::Tcp(conn));
    writer.abort();
    let _ = writer.await;
    info!(
        conn,
        secs = started.elapsed().as_secs_f64(),
        "TCP peer disconnected"
    );
}

#[cfg(test)]
mod tests {
    use super::Poll;
    use std::time::Duration;

    #[test]
    fn a_worker_polls_only_when_datagrams_queue_up() {
        let mut poll = Poll::new(Duration::from_micros(30));
        // Before any traffic, and while each wake-up finds one datagram
        // (the worker keeps up), it sleeps at once after each batch.
        assert!(poll.until().is_none());
        poll.woke_with(1);
        assert!(poll.until().is_none());
        // Datagrams queued while it slept: it polls, for the budget.
        poll.woke_with(2);
        let until = poll.until().expect("polls");
        assert!(until <= std::time::Instant::now() + Duration::from_micros(30));
        poll.woke_with(32);
        assert!(poll.until().is_some());
        // Keeping up again: back to sleeping at once.
        poll.woke_with(1);
        assert!(poll.until().is_none());
        // Off: never polls.
        let mut off = Poll::new(Duration::ZERO);
        off.woke_with(32);
        assert!(off.until().is_none());
    }
}
