//! The UDP workers: a thread per socket of the router's `SO_REUSEPORT`
//! group, each receiving in batches, deciding a batch under one hold of the
//! tables lock, and sending what it decided in batches from its own socket.

use std::net::SocketAddr;
use std::os::fd::{AsRawFd, RawFd};
use std::sync::Arc;
use std::time::Duration;

use nix::sys::socket::MsgFlags;
use tracing::debug;

use super::batch::{BATCH, RecvBatch, SendBatch};
use crate::router::tables::{Effects, Peer};
use crate::router::{RouterError, Shared};

/// A running worker: its thread and its socket (shut down for reading to
/// wake it when the router stops).
pub(super) type Worker = (std::thread::JoinHandle<()>, Arc<std::net::UdpSocket>);

/// Starts a worker thread per socket of the group.
pub(super) fn start_workers(
    shared: &Arc<Shared>,
    sockets: Vec<Arc<std::net::UdpSocket>>,
    poll: Duration,
) -> Result<Vec<Worker>, RouterError> {
    let addr = shared.net.udp_addr();
    let mut threads = Vec::with_capacity(sockets.len());
    for (i, socket) in sockets.into_iter().enumerate() {
        let (s, sock) = (shared.clone(), socket.clone());
        let thread = std::thread::Builder::new()
            .name(format!("mech-udp-{i}"))
            .spawn(move || udp_worker(s, sock, poll))
            .map_err(|source| RouterError::Bind {
                what: "UDP worker",
                addr,
                source,
            })?;
        threads.push((thread, socket));
    }
    Ok(threads)
}

/// One UDP worker, a thread of its own: owns one socket of the router's
/// `SO_REUSEPORT` group, so the kernel hands it every datagram of the
/// senders hashed to it. A sender's datagrams are therefore received,
/// decided and sent on by one worker, in the order they arrived, whatever
/// the number of workers, and workers never contend for a socket.
///
/// It blocks in `recvmmsg` until a datagram arrives (the kernel wakes this
/// thread directly: no event loop between), takes what else is waiting in
/// the same call, decides the batch under one hold of the tables' lock,
/// delivers the batch's events once the lock is released (see
/// `crate::router::events`; a batch of commands has none), and sends what
/// it decided with `sendmmsg`. At low rates a batch is the one
/// datagram that woke it: nothing waits to fill one. While traffic is
/// dense it polls its socket for a moment before sleeping again
/// ([`Poll`]), so that a busy sender does not pay a wake-up per datagram.
fn udp_worker(shared: Arc<Shared>, socket: Arc<std::net::UdpSocket>, poll: Duration) {
    let mut received = RecvBatch::new();
    let mut sender = SendBatch::new();
    let mut decided = Decided::default();
    let mut fx = Effects::default();
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
        decided.clear();
        let message = |i| batch_message(&received, i);
        // A full batch: more datagrams wait in the socket.
        let behind = n == BATCH;
        let ticket = shared.decide_each(n, message, behind, &mut fx, |i, fx| decided.take(i, fx));
        shared.events.deliver(ticket);
        send_decided(&shared, fd, &mut sender, &received, &mut decided);
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

/// Datagram `i` of a batch, as the tables take it.
fn batch_message(batch: &RecvBatch, i: usize) -> (&[u8], Peer) {
    let (bytes, from) = batch.datagram(i);
    (bytes, Peer::Udp(from))
}

/// What a UDP worker's batch decided to send: each target with the bytes it
/// gets, either a received datagram passed on unchanged or a message the
/// tables made. Kept between batches so its allocations are reused.
#[derive(Debug, Default)]
struct Decided {
    sends: Vec<(Peer, Payload)>,
    owned: Vec<Vec<u8>>,
}

impl Decided {
    fn clear(&mut self) {
        self.sends.clear();
        self.owned.clear();
    }

    /// Takes what the decision of datagram `i` left in `fx.out`.
    fn take(&mut self, i: usize, fx: &mut Effects) {
        for peer in fx.out.raw.drain(..) {
            self.sends.push((peer, Payload::Received(i)));
        }
        for (peer, bytes) in fx.out.owned.drain(..) {
            self.sends.push((peer, Payload::Owned(self.owned.len())));
            self.owned.push(bytes);
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Payload {
    /// Datagram `i` of the batch, as received.
    Received(usize),
    /// `Decided::owned[i]`.
    Owned(usize),
}

/// Sends what a batch decided, in order, from a worker's thread: UDP
/// datagrams from its socket `fd` in batches (waiting for room when the
/// socket's buffer is full: never dropped or reordered), frames to TCP
/// peers and radios through their queues.
fn send_decided(
    shared: &Shared,
    fd: RawFd,
    sender: &mut SendBatch,
    batch: &RecvBatch,
    decided: &mut Decided,
) {
    if decided.sends.is_empty() || shared.stopped() {
        return;
    }
    let bytes = |p: &Payload| match *p {
        Payload::Received(i) => batch.datagram(i).0,
        Payload::Owned(i) => decided.owned[i].as_slice(),
    };
    let mut udp: Vec<(SocketAddr, &[u8])> = Vec::with_capacity(decided.sends.len());
    for (peer, payload) in &decided.sends {
        match peer {
            Peer::Udp(addr) => udp.push((*addr, bytes(payload))),
            other => shared.net.send_queued(*other, bytes(payload)),
        }
    }
    let sent = sender.send(fd, &udp, MsgFlags::empty());
    if sent.failed > 0 {
        shared.net.count_send_failures(sent.failed);
    }
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
