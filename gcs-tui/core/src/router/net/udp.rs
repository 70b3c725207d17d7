//! The UDP workers: a thread per socket of the router's `SO_REUSEPORT`
//! group, each receiving in batches, deciding a batch under one hold of the
//! tables lock, and sending what it decided in batches from its own socket.

use std::net::SocketAddr;
use std::os::fd::{AsRawFd, RawFd};
use std::sync::Arc;
use std::time::{Duration, Instant};

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
/// datagram that woke it: nothing waits to fill one. While datagrams
/// follow each other closely it polls its socket for a moment before
/// sleeping again ([`Poll`]), so that a busy sender does not pay a wake-up
/// per datagram.
fn udp_worker(shared: Arc<Shared>, socket: Arc<std::net::UdpSocket>, poll: Duration) {
    let mut received = RecvBatch::new();
    let mut sender = SendBatch::new();
    let mut decided = Decided::default();
    let mut fx = Effects::default();
    let mut poll = Poll::new(poll);
    let fd = socket.as_raw_fd();
    // When the last batch arrived, and until when to poll after it.
    let mut last_arrived = Instant::now();
    let mut polling_until = None;
    while !shared.stopped() {
        let polling = match polling_until {
            Some(t) if Instant::now() >= t => {
                poll.caught_nothing();
                polling_until = None;
                false
            }
            until => until.is_some(),
        };
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
        // When the batch arrived, for polling only: the tables read their
        // own time once they hold their lock, so their decisions (and the
        // recording's times) follow the order they are made in.
        let arrived = Instant::now();
        poll.came(arrived - last_arrived, n, polling);
        last_arrived = arrived;
        decided.clear();
        let message = |i| batch_message(&received, i);
        // A full batch: more datagrams wait in the socket.
        let behind = n == BATCH;
        let take = |i, fx: &mut Effects| decided.take(i, fx);
        let ticket = shared.decide_each(n, message, behind, &mut fx, take);
        shared.events.deliver(ticket);
        send_decided(&shared, fd, &mut sender, &received, &mut decided);
        polling_until = poll.next().map(|budget| arrived + budget);
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

/// The longest time between two batches' arrivals that polling pays for:
/// sleeping and being woken costs a thread about this much CPU (on the
/// project's 2-vCPU VM, 15-18 us per datagram at 2,000 datagrams/s,
/// where every datagram wakes the worker, against 6 us at 50,000/s), so
/// polling for datagrams that come closer than this (above 100,000 a
/// second) saves CPU, and polling for sparser ones spends more than the
/// wake-ups it spares.
const BREAK_EVEN: Duration = Duration::from_micros(10);

/// Longest back-off, in batches, after polls that caught nothing.
const MAX_BACKOFF: u32 = 1024;

/// The hit rate, in 1/256, at or above which a worker polls.
const POLL_AT: u32 = 192;

/// When a UDP worker polls its socket instead of sleeping: only while
/// polling pays for itself.
///
/// Sleeping in `recvmmsg` costs the next datagram's sender a wake-up of this
/// thread (on a virtual machine, an inter-processor interrupt and a
/// hypervisor exit), and this thread a context switch. When datagrams
/// follow each other closer than that costs, polling (yielding the core
/// between tries) is cheaper and faster; when they do not, every poll burns
/// its whole wait for nothing. So each batch counts a hit when it arrived
/// within [`BREAK_EVEN`] of the one before (or more than one datagram was
/// waiting), whether the worker polled or slept for it;
/// the worker polls, for up to `budget`, only while at least three of four
/// recent batches were hits. A poll that catches nothing also stops polling
/// for a back-off that doubles with each such poll in a row (1, 2, 4 ...
/// [`MAX_BACKOFF`] batches) and ends at the first poll that catches
/// something. So a dense stream (a sender at the router's peak) is polled
/// for, while a 2 kHz command stream or a steady 64 kHz stream, whose
/// datagrams come further apart than a wake-up costs, is slept for and
/// costs no polling CPU. A zero budget turns polling off.
#[derive(Debug, Clone, Copy)]
pub(super) struct Poll {
    budget: Duration,
    /// Recent batches that came quickly, in 1/256: a moving average over
    /// about the last eight.
    hits: u32,
    /// Batches still to sleep after, backing off.
    skip: u32,
    /// The next back-off, in batches.
    backoff: u32,
}

impl Poll {
    pub(super) fn new(budget: Duration) -> Poll {
        Poll {
            budget,
            hits: 0,
            skip: 0,
            backoff: 1,
        }
    }

    /// A receive returned `n` datagrams, `after` the last batch arrived;
    /// `polled`: the worker was polling for them (else it slept).
    pub(super) fn came(&mut self, after: Duration, n: usize, polled: bool) {
        let hit = n >= 2 || after <= BREAK_EVEN.min(self.budget);
        self.hits = self.hits - self.hits / 8 + if hit { 32 } else { 0 };
        if polled {
            self.backoff = 1;
        }
    }

    /// A poll ran its whole budget and caught nothing: sleep for the next
    /// back-off, and double it.
    pub(super) fn caught_nothing(&mut self) {
        self.skip = self.backoff;
        self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
    }

    /// How long to poll after a batch just handled; `None`: sleep at once.
    pub(super) fn next(&mut self) -> Option<Duration> {
        if self.skip > 0 {
            self.skip -= 1;
            return None;
        }
        (!self.budget.is_zero() && self.hits >= POLL_AT).then_some(self.budget)
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
    /// Room for a batch's UDP datagrams as `SendBatch` takes them, empty
    /// between batches (see [`emptied`]).
    udp: Vec<(SocketAddr, &'static [u8])>,
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
    let mut udp: Vec<(SocketAddr, &[u8])> = std::mem::take(&mut decided.udp);
    let bytes = |p: &Payload| match *p {
        Payload::Received(i) => batch.datagram(i).0,
        Payload::Owned(i) => decided.owned[i].as_slice(),
    };
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
    decided.udp = emptied(udp);
}

/// `v` emptied, its allocation kept for the next batch: a vector of
/// another lifetime, collected in place (same element layout), so a batch
/// allocates nothing to send.
fn emptied(mut v: Vec<(SocketAddr, &[u8])>) -> Vec<(SocketAddr, &'static [u8])> {
    v.clear();
    let nowhere = SocketAddr::from(([0, 0, 0, 0], 0));
    v.into_iter().map(|_| (nowhere, &[][..])).collect()
}

#[cfg(test)]
mod tests {
    use super::{BREAK_EVEN, MAX_BACKOFF, Poll, emptied};
    use std::net::SocketAddr;
    use std::time::Duration;

    #[test]
    fn a_batch_sends_from_the_room_the_last_one_left() {
        let payload = [7u8; 8];
        let mut udp: Vec<(SocketAddr, &[u8])> = Vec::with_capacity(32);
        udp.push(("127.0.0.1:9".parse().unwrap(), &payload));
        let (room, at) = (udp.capacity(), udp.as_ptr() as usize);
        let kept = emptied(udp);
        assert!(kept.is_empty());
        assert_eq!((kept.capacity(), kept.as_ptr() as usize), (room, at));
    }

    const BUDGET: Duration = Duration::from_micros(30);
    const QUICK: Duration = Duration::from_micros(2);
    /// A gap a wake-up costs less than: a 32 kHz stream's.
    const SLOW: Duration = Duration::from_micros(31);

    /// Batches until `poll` first polls, of at most `limit`, each found
    /// after `after` with `n` datagrams, the worker sleeping for them.
    fn batches_until_polling(poll: &mut Poll, after: Duration, n: usize, limit: usize) -> usize {
        (1..=limit)
            .find(|_| {
                poll.came(after, n, false);
                poll.next().is_some()
            })
            .unwrap_or(limit + 1)
    }

    #[test]
    fn a_worker_polls_only_when_datagrams_queue_up() {
        let mut poll = Poll::new(BUDGET);
        // Before any traffic, and while each wake-up finds one datagram
        // long after the last (the worker keeps up), it sleeps at once.
        assert!(poll.next().is_none());
        assert_eq!(batches_until_polling(&mut poll, SLOW, 1, 1000), 1001);
        // Datagrams queued while it slept, batch after batch: it polls,
        // for the budget, after a few batches.
        let queued = batches_until_polling(&mut poll, SLOW, 2, 100);
        assert!((2..=16).contains(&queued), "{queued}");
        assert_eq!(poll.next(), Some(BUDGET));
        poll.came(QUICK, 32, true);
        assert_eq!(poll.next(), Some(BUDGET));
        // Keeping up again: back to sleeping within a few batches.
        let sleeping = (1..=100)
            .find(|_| {
                poll.came(SLOW, 1, false);
                poll.next().is_none()
            })
            .expect("sleeps again");
        assert!(sleeping <= 4, "{sleeping}");
        // Off: never polls.
        let mut off = Poll::new(Duration::ZERO);
        assert_eq!(batches_until_polling(&mut off, QUICK, 32, 1000), 1001);
    }

    #[test]
    fn a_stream_closer_than_a_wake_up_is_polled_for_and_a_sparser_one_is_not() {
        let close = BREAK_EVEN / 2;
        let mut poll = Poll::new(BUDGET);
        assert!(batches_until_polling(&mut poll, close, 1, 100) <= 16);
        // Each poll catches the next datagram: polling goes on.
        for _ in 0..1000 {
            poll.came(close, 1, true);
            assert_eq!(poll.next(), Some(BUDGET));
        }
        // A steady stream further apart than a wake-up costs (at 64 kHz,
        // 15.6 us): never polled for.
        let mut poll = Poll::new(BUDGET);
        let apart = BREAK_EVEN + Duration::from_micros(1);
        assert_eq!(batches_until_polling(&mut poll, apart, 1, 10_000), 10_001);
    }

    #[test]
    fn polls_that_catch_nothing_back_off_exponentially_until_one_catches() {
        let mut poll = Poll::new(BUDGET);
        assert!(batches_until_polling(&mut poll, QUICK, 4, 100) <= 16);
        // Bursts: a poll that catches nothing, then batches that come
        // quickly again. Count the batches slept after, per poll missed.
        let mut slept = Vec::new();
        for _ in 0..12 {
            assert!(poll.next().is_some(), "polls between back-offs");
            poll.caught_nothing();
            let mut n = 0;
            loop {
                poll.came(QUICK, 4, false);
                if poll.next().is_some() {
                    break;
                }
                n += 1;
            }
            slept.push(n);
        }
        assert_eq!(slept, [1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 1024]);
        assert_eq!(MAX_BACKOFF, 1024);
        // A poll that catches a datagram ends the back-off.
        poll.came(QUICK, 1, true);
        poll.caught_nothing();
        poll.came(QUICK, 4, false);
        assert!(poll.next().is_none(), "one batch of back-off");
        poll.came(QUICK, 4, false);
        assert!(poll.next().is_some());
    }
}
