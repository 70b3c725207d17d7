//! Datagrams in batches: one `recvmmsg(2)` takes up to [`BATCH`] waiting
//! datagrams off a socket and one `sendmmsg(2)` sends up to [`BATCH`], so
//! under load a datagram costs a fraction of a system call. Consecutive
//! datagrams of one size to one peer (a controller's command stream to its
//! robot) go out as one UDP segmentation offload send (`UDP_SEGMENT`): the
//! kernel's send path runs once for all of them. Nothing waits to fill a
//! batch: at low rates a batch is the one datagram that woke the worker,
//! sent on at once.
//!
//! The system calls go through `nix`'s safe wrappers; this module owns the
//! receive buffers and the message headers the calls fill in, made once
//! per worker and kept, so a batch allocates nothing: not per datagram,
//! not per system call. The headers hold raw pointers, which keeps
//! [`RecvBatch`] and [`SendBatch`] on the worker thread that made them.

use std::io::{IoSlice, IoSliceMut};
use std::net::{SocketAddr, SocketAddrV4, SocketAddrV6};
use std::os::fd::RawFd;

use nix::sys::socket::{
    ControlMessage, MsgFlags, MultiHeaders, SockaddrStorage, recvmmsg, sendmmsg, sendmsg,
};

/// Most datagrams moved by one system call.
pub(super) const BATCH: usize = 32;

/// Receive buffers and the datagrams the last [`RecvBatch::recv`] took.
pub(super) struct RecvBatch {
    /// One buffer per datagram, one byte longer than the largest message,
    /// so an oversized datagram shows as such instead of as a truncated one.
    bufs: [Vec<u8>; BATCH],
    /// The headers `recvmmsg` fills in (with their source addresses),
    /// pointed at `bufs` on each call. The kernel leaves in each header the
    /// length of the address it wrote, and takes it as the room for the
    /// next: every datagram on one socket has a source of the socket's own
    /// family, so that room is always enough.
    headers: MultiHeaders<SockaddrStorage>,
    /// Length and source of each datagram received.
    got: Vec<(usize, SocketAddr)>,
}

impl std::fmt::Debug for RecvBatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecvBatch")
            .field("got", &self.got.len())
            .finish()
    }
}

impl RecvBatch {
    pub(super) fn new() -> RecvBatch {
        RecvBatch {
            bufs: std::array::from_fn(|_| vec![0; mech_proto::MAX_MESSAGE_LEN + 1]),
            headers: MultiHeaders::preallocate(BATCH, None),
            got: Vec::with_capacity(BATCH),
        }
    }

    /// Takes datagrams from `fd`, at most [`BATCH`]: with
    /// `MSG_WAITFORONE` it blocks until one arrives (up to the socket's
    /// receive timeout) and takes what else is waiting; with `MSG_DONTWAIT`
    /// it never blocks (`WouldBlock` when nothing is waiting). 0 once the
    /// socket is shut down for reading.
    pub(super) fn recv(&mut self, fd: RawFd, flags: MsgFlags) -> std::io::Result<usize> {
        self.got.clear();
        let mut iovs = self.bufs.each_mut().map(|b| [IoSliceMut::new(b)]);
        let results = recvmmsg(fd, &mut self.headers, iovs.iter_mut(), flags, None)
            .map_err(std::io::Error::from)?;
        for m in results {
            // A datagram without an IP source cannot be answered or judged.
            if let Some(from) = m.address.as_ref().and_then(std_addr) {
                self.got.push((m.bytes, from));
            } else {
                self.got.push((0, SocketAddr::from(([0, 0, 0, 0], 0))));
            }
        }
        Ok(self.got.len())
    }

    /// Datagram `i` of the last receive: its bytes and source.
    pub(super) fn datagram(&self, i: usize) -> (&[u8], SocketAddr) {
        let (len, from) = self.got[i];
        (&self.bufs[i][..len], from)
    }
}

fn std_addr(a: &SockaddrStorage) -> Option<SocketAddr> {
    if let Some(v4) = a.as_sockaddr_in() {
        return Some(SocketAddr::V4(SocketAddrV4::from(*v4)));
    }
    a.as_sockaddr_in6()
        .map(|v6| SocketAddr::V6(SocketAddrV6::from(*v6)))
}

/// Sends batches with `sendmmsg`, and runs of equal datagrams to one peer
/// with segmentation offload while the kernel allows it.
#[derive(Debug)]
pub(super) struct SendBatch {
    /// Segmentation offload works (cleared the first time the kernel
    /// refuses it; everything then goes through `sendmmsg`).
    gso: bool,
    /// The headers `sendmmsg` fills in, each call setting every field it
    /// sends with (buffers, destination).
    headers: MultiHeaders<SockaddrStorage>,
    /// The destinations of one `sendmmsg`, kept for their allocation.
    addrs: Vec<Option<SockaddrStorage>>,
}

/// Most segments in one offloaded send (the kernel's limit is 64 or more).
const GSO_SEGMENTS: usize = 64;

/// How sending a batch went.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(super) struct Sent {
    /// Datagrams handed to the kernel.
    pub(super) sent: usize,
    /// Datagrams the kernel refused (an unreachable peer, say): counted and
    /// skipped, never retried.
    pub(super) failed: usize,
}

impl SendBatch {
    pub(super) fn new() -> SendBatch {
        SendBatch {
            gso: true,
            headers: MultiHeaders::preallocate(BATCH, None),
            addrs: Vec::with_capacity(BATCH),
        }
    }

    /// Sends `msgs` in order from `fd`, [`BATCH`] per system call. With
    /// `MSG_DONTWAIT` it returns what was sent when the socket's buffer
    /// fills (`sent + failed < msgs.len()`), and the caller sends the rest
    /// when it can, so nothing is reordered; without, it waits for room.
    pub(super) fn send(
        &mut self,
        fd: RawFd,
        msgs: &[(SocketAddr, &[u8])],
        flags: MsgFlags,
    ) -> Sent {
        let mut done = Sent::default();
        while done.sent + done.failed < msgs.len() {
            let rest = &msgs[done.sent + done.failed..];
            let run = same_peer_and_size(rest);
            if self.gso && run >= 2 {
                match self.send_segments(fd, &rest[..run], flags) {
                    Some(Ok(())) => {
                        done.sent += run;
                        continue;
                    }
                    Some(Err(())) => return done,
                    None => {} // offload refused: send them one by one
                }
            }
            // Up to the next run worth offloading.
            let singles = if self.gso {
                (1..rest.len())
                    .find(|&i| same_peer_and_size(&rest[i..]) >= 2)
                    .unwrap_or(rest.len())
            } else {
                rest.len()
            };
            let chunk = &rest[..singles.min(BATCH)];
            let mut iovs = [[IoSlice::new(&[])]; BATCH];
            for (iov, (_, b)) in iovs.iter_mut().zip(chunk) {
                *iov = [IoSlice::new(b)];
            }
            self.addrs.clear();
            self.addrs
                .extend(chunk.iter().map(|(a, _)| Some(SockaddrStorage::from(*a))));
            let sent = sendmmsg(
                fd,
                &mut self.headers,
                &iovs[..chunk.len()],
                &self.addrs,
                [],
                flags,
            );
            match sent {
                Ok(results) => {
                    let n = results.count();
                    if n == 0 {
                        return done;
                    }
                    done.sent += n;
                }
                Err(nix::errno::Errno::EAGAIN) => return done,
                Err(e) => {
                    // The first message of the chunk failed (sendmmsg reports
                    // an error only when none was sent): skip it.
                    tracing::debug!(to = %chunk[0].0, error = %e, "UDP send failed");
                    done.failed += 1;
                }
            }
        }
        done
    }

    /// Sends equal datagrams to one peer as one offloaded send. `None` if
    /// the kernel refuses offload (it is then off for good); `Some(Err)` if
    /// the socket's buffer is full.
    fn send_segments(
        &mut self,
        fd: RawFd,
        run: &[(SocketAddr, &[u8])],
        flags: MsgFlags,
    ) -> Option<Result<(), ()>> {
        let mut iovs = [IoSlice::new(&[]); GSO_SEGMENTS];
        for (iov, (_, b)) in iovs.iter_mut().zip(run) {
            *iov = IoSlice::new(b);
        }
        let size = run[0].1.len() as u16;
        let cmsg = [ControlMessage::UdpGsoSegments(&size)];
        let to = SockaddrStorage::from(run[0].0);
        match sendmsg(fd, &iovs[..run.len()], &cmsg, flags, Some(&to)) {
            Ok(_) => Some(Ok(())),
            Err(nix::errno::Errno::EAGAIN) => Some(Err(())),
            Err(e) => {
                tracing::info!(error = %e, "UDP segmentation offload unavailable; sending datagrams one by one");
                self.gso = false;
                None
            }
        }
    }
}

/// How many datagrams at the start of `msgs` go to the same peer with the
/// same size (at most [`GSO_SEGMENTS`], and only sizes offload can carry).
fn same_peer_and_size(msgs: &[(SocketAddr, &[u8])]) -> usize {
    let Some((to, first)) = msgs.first() else {
        return 0;
    };
    if first.is_empty() || first.len() > 1400 {
        return 1;
    }
    msgs.iter()
        .take(GSO_SEGMENTS)
        .take_while(|(a, b)| a == to && b.len() == first.len())
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nix::sys::socket::SockaddrLike;
    use std::os::fd::AsRawFd;

    /// Whether `addr` survives the trip through the wrappers' addresses.
    fn round_trips(addr: SocketAddr) -> bool {
        let s = SockaddrStorage::from(addr);
        std_addr(&s) == Some(addr) && s.len() > 0
    }

    #[test]
    fn a_batch_goes_out_and_comes_back_in_order() {
        let rx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let tx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let to = rx.local_addr().unwrap();
        // Runs of equal datagrams (offloaded) between datagrams of other
        // sizes (sent one by one), all in order.
        let payloads: Vec<Vec<u8>> = (0..70u8)
            .map(|i| vec![i; if i % 10 < 6 { 50 } else { 1 + i as usize }])
            .collect();
        let msgs: Vec<(SocketAddr, &[u8])> = payloads.iter().map(|p| (to, p.as_slice())).collect();
        let sent = SendBatch::new().send(tx.as_raw_fd(), &msgs, MsgFlags::empty());
        assert_eq!(
            sent,
            Sent {
                sent: 70,
                failed: 0
            }
        );
        let mut batch = RecvBatch::new();
        let mut got = Vec::new();
        while got.len() < 70 {
            let n = batch.recv(rx.as_raw_fd(), MsgFlags::MSG_DONTWAIT).unwrap();
            assert!(n <= BATCH);
            for i in 0..n {
                let (bytes, from) = batch.datagram(i);
                assert_eq!(from, tx.local_addr().unwrap());
                got.push(bytes.to_vec());
            }
        }
        assert_eq!(got, payloads);
        let e = batch
            .recv(rx.as_raw_fd(), MsgFlags::MSG_DONTWAIT)
            .unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::WouldBlock);
        assert!(round_trips("[::1]:7400".parse().unwrap()));
    }

    /// The headers a batch keeps between calls still give every datagram
    /// its own source and length, batch after batch, on either family.
    #[test]
    fn kept_headers_give_each_datagram_its_source_batch_after_batch() {
        for host in ["127.0.0.1:0", "[::1]:0"] {
            let rx = std::net::UdpSocket::bind(host).unwrap();
            let to = rx.local_addr().unwrap();
            let senders: Vec<std::net::UdpSocket> = (0..3)
                .map(|_| std::net::UdpSocket::bind(host).unwrap())
                .collect();
            let (mut out, mut batch) = (SendBatch::new(), RecvBatch::new());
            for round in 0..4usize {
                // A batch of a different size each round, its senders in
                // turn, each datagram as long as its place.
                let n = [BATCH, 3, BATCH - 1, 1][round];
                let mut expected = Vec::new();
                for i in 0..n {
                    let s = &senders[(i + round) % senders.len()];
                    let bytes = vec![round as u8; 1 + i];
                    let sent = out.send(s.as_raw_fd(), &[(to, &bytes)], MsgFlags::empty());
                    assert_eq!(sent.sent, 1);
                    expected.push((bytes, s.local_addr().unwrap()));
                }
                let mut got = Vec::new();
                while got.len() < n {
                    let k = batch.recv(rx.as_raw_fd(), MsgFlags::MSG_DONTWAIT).unwrap();
                    got.extend((0..k).map(|i| {
                        let (bytes, from) = batch.datagram(i);
                        (bytes.to_vec(), from)
                    }));
                }
                assert_eq!(got, expected, "{host} round {round}");
            }
        }
    }
}
